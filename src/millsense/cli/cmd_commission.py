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
    it; the estimator's noise R (from the air cut) and its disturbance path need the C3 stage
    (friction, J_e), so a ``millsense merge`` of those two fragments into
    ``<axis>_stage1.toml`` comes first and the noise and path commands read it.
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
    # R of the feed estimator (rigid-body C3 stage; a ball screw's observers need none)
    noise = "air_cut" in files and "drive_sweep" not in files
    staged = f"{axis}_stage1.toml"
    if paths or noise:
        out.append(f"millsense merge {machine} {' '.join(stage1)} -o {staged}")
    if noise:
        out.append(
            f"millsense identify noise {files['air_cut']} --machine {staged} --axis {axis} "
            f"-o {axis}_noise.toml"
        )
    if paths:
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


def mergeable_fragments(commands: list[str]) -> list[str]:
    """The fragments of the identify commands that go into the machine file: all but the idle
    tables (``identify idle``: a position-indexed table with its CSV, not a machine-file key)."""
    return [
        ln.rsplit(" -o ", 1)[1]
        for ln in commands
        if ln.startswith("millsense identify") and not ln.startswith("millsense identify idle")
    ]


def run_identification(machine: str, out: Path, commands: list[str]) -> Path:
    """Run ``commands`` (the printed identify/merge lines, recordings given by absolute path)
    in ``out`` and merge every fragment into ``out/machine.toml``; its path."""
    import contextlib
    import shlex

    from millsense.cli.main import main

    def cli(line: str) -> None:
        typer.echo(f"$ {line}")
        try:
            main(shlex.split(line)[1:])
        except SystemExit as exc:
            if exc.code:
                msg = f"commission --identify: '{line}' failed (exit {exc.code})"
                raise ConfigError(msg) from None

    frags = mergeable_fragments(commands)
    with contextlib.chdir(out):
        for line in commands:
            cli(line)
        cli(f"millsense merge {machine} {' '.join(frags)} -o machine.toml")
    return out / "machine.toml"


@app.command()
def commission(
    machine: str = typer.Option(..., "--machine", help="Machine preset or .toml."),
    axis: str = typer.Option(
        "x", "--axis", help="Feed axis tested, or several separated by commas (x,y,z,a,c)."
    ),
    out: Path = typer.Option(..., "-o", "--output", help="Directory the recordings go to."),
    spindle: bool = typer.Option(True, "--spindle/--no-spindle", help="Also the spindle tests."),
    identify: bool = typer.Option(
        False,
        "--identify",
        help="Also run the printed identify and merge commands in the output directory: "
        "DIR/machine.toml is the commissioned machine file.",
    ),
    ideal: bool = typer.Option(
        False,
        "--ideal",
        help="Debugging only: test the machine file's model, not the simulator's truth.",
    ),
) -> None:
    """Simulate the commissioning tests of one or more axes (and the spindle), write the
    recordings and print (or, with --identify, run) the identification commands."""
    from millsense.io.safe_output import check_outputs
    from millsense.simulator.commissioning import write_commissioning_set
    from millsense.simulator.machine_file import simulator_machine

    check_outputs({"the machine file": machine}, {"-o": out})
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a directory")
    axes = [a.strip() for a in axis.split(",") if a.strip()]
    if not axes:
        raise ConfigError("--axis: give at least one axis")
    twice = next((a for i, a in enumerate(axes) if a in axes[:i]), None)
    if twice is not None:
        raise ConfigError(f"--axis {axis!r}: axis '{twice}' named twice")
    sim = simulator_machine(machine)
    for a in axes:
        sim.axis(a)  # one-line errors before anything is written
    where = out.resolve() if identify else out
    commands: list[str] = []
    for k, a in enumerate(axes):
        files = write_commissioning_set(machine, where, a, spindle=spindle and k == 0, ideal=ideal)
        for name, path in files.items():
            typer.echo(f"wrote {path} ({name})")
        commands += identify_commands(machine, a, files)
    if identify:
        merged = run_identification(machine, where, commands)
        typer.echo(f"commissioned machine file: {merged}")
        return
    typer.echo("identify with:")
    for line in commands:
        typer.echo(f"  {line}")
    outs = " ".join(mergeable_fragments(commands))
    typer.echo(
        f"then merge into a machine file:\n  millsense merge {machine} {outs} -o machine.toml"
    )
