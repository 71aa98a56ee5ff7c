"""``millsense commission``: the standard commissioning tests of one axis on the virtual machine.

Writes one recording per test (:func:`millsense.simulator.commissioning.write_commissioning_set`)
and prints the ``millsense identify`` command that reads each, so that the identification
workflow a machine needs (friction, drive or disturbance path, spindle, idle table) can be run
end to end on the simulator before it is run on a machine.
"""

from __future__ import annotations

from pathlib import Path

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError


def identify_commands(machine: str, axis: str, files: dict[str, Path]) -> list[str]:
    """The ``millsense identify`` command line for each group of commissioning recordings, in
    the order they run.

    ``machine`` is the nameplate the identification starts from (decision
    docs/decisions/0991-nameplate-machine-files.md): friction and the drive are identified with
    it; the disturbance path needs the C3 stage (friction, J_e), so a ``millsense merge`` of
    those two fragments into ``<axis>_stage1.toml`` comes first and the path commands read it.
    """
    m = f"--machine {machine} --axis {axis}"
    out = []
    stage1: list[str] = []
    if "friction" in files:
        rec = " ".join(str(files[k]) for k in ("friction", "presliding") if k in files)
        out.append(f"millsense identify friction {rec} {m} -o {axis}_friction.toml")
        stage1.append(f"{axis}_friction.toml")
    if "drive_sweep" in files:
        rec = " ".join(str(files[k]) for k in ("drive_sweep", "acceleration") if k in files)
        out.append(f"millsense identify drive {rec} {m} -o {axis}_drive.toml")
        stage1.append(f"{axis}_drive.toml")
    elif "acceleration" in files:
        out.append(f"millsense identify drive {files['acceleration']} {m} -o {axis}_inertia.toml")
        stage1.append(f"{axis}_inertia.toml")
    paths = [k for k in ("table_load_sweep", "table_load_sweep_at_rest") if k in files]
    if paths:
        staged = f"{axis}_stage1.toml"
        out.append(f"millsense merge {machine} {' '.join(stage1)} -o {staged}")
        for key in paths:
            suffix = key.removeprefix("table_load_sweep")
            out.append(
                f"millsense identify path {files[key]} --machine {staged} --axis {axis} "
                f"--input-channel {axis}/load -o {axis}_path{suffix}.toml"
            )
    idle = [str(p) for k, p in sorted(files.items()) if k.startswith("idle_")]
    if idle:
        out.append(f"millsense identify idle {' '.join(idle)} {m} -o {axis}_idle.toml")
    if "spindle_sweep" in files:
        rec = " ".join(str(files[k]) for k in ("spindle_sweep", "spindle_friction") if k in files)
        out.append(f"millsense identify spindle {rec} --machine {machine} -o spindle.toml")
    return out


@app.command()
def commission(
    machine: str = typer.Option(..., "--machine", help="Machine preset or .toml."),
    axis: str = typer.Option("x", "--axis", help="Feed axis tested."),
    out: Path = typer.Option(..., "-o", "--output", help="Directory the recordings go to."),
    spindle: bool = typer.Option(True, "--spindle/--no-spindle", help="Also the spindle tests."),
    ideal: bool = typer.Option(
        False,
        "--ideal",
        help="Debugging only: test the machine file's model, not the simulator's truth.",
    ),
) -> None:
    """Simulate the commissioning tests of an axis (and the spindle) and write the recordings."""
    from millsense.io.safe_output import check_outputs
    from millsense.simulator.commissioning import write_commissioning_set
    from millsense.simulator.machine_file import simulator_machine

    check_outputs({"the machine file": machine}, {"-o": out})
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a directory")
    simulator_machine(machine).axis(axis)  # one-line errors before anything is written
    files = write_commissioning_set(machine, out, axis, spindle=spindle, ideal=ideal)
    for name, path in files.items():
        typer.echo(f"wrote {path} ({name})")
    typer.echo("identify with:")
    commands = identify_commands(machine, axis, files)
    for line in commands:
        typer.echo(f"  {line}")
    outs = " ".join(
        line.rsplit(" -o ", 1)[1]
        for line in commands
        if line.startswith("millsense identify")
    )
    typer.echo(
        f"then merge into a machine file:\n  millsense merge {machine} {outs} -o machine.toml"
    )
