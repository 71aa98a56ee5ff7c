"""``millsense demo``: the end-to-end path on the embedded default machine."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from millsense.cli.main import app
from millsense.cli.progress import progress_bar


@app.command()
def demo(
    out: Path = typer.Option(Path("demo-output"), "-o", "--output", help="Output folder."),
    seed: int = typer.Option(
        0, min=0, help="Seed of the virtual machine (noise, realism) in every part of the demo."
    ),
) -> None:
    """The two halves of millsense on the virtual machine: force from a drive's current, then
    the integrated on-line system on the demo part, with and without control.

    Part 1 writes OUTPUT/demo.h5 (a slot on the X drive with truth/ channels and the force
    estimated from the current command), demo_force.png and summary.json. Part 2 plans a short
    program on the demo stock (a cavity, an entry, a depth step, an exit; a tooth breaks late)
    and runs it in closed loop with the estimators, the plan, the monitors and the controllers,
    and once more without sending their commands: online.h5, online.events.parquet,
    online_open.events.parquet, online_demo.nc, online_demo.png, online.html (the report of
    the controlled run) and online_summary.json. Part 3 runs a chatter-prone pass (seed 000's
    T1 face mill slotting between two lobes, on a bar of its own) with and without the chatter
    avoidance: online_chatter.nc, online_chatter.h5, online_chatter.events.parquet,
    online_chatter_open.events.parquet, online_chatter.png and online_chatter_summary.json.
    """
    from millsense.core.errors import ConfigError
    from millsense.demo import run_demo

    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a folder")
    console = Console()
    with progress_bar("simulating and estimating", 1) as update:
        summary = run_demo(out, seed=seed, on_progress=lambda n, total: update(n / total))
    table = Table(title="Slot cut on X: mean cutting force per depth, from the current command")
    for col in ("depth [mm]", "window [s]", "truth [N]", "estimate [N]", "error [%]"):
        table.add_column(col, justify="right")
    for s in summary.segments:
        table.add_row(
            f"{s.depth_mm:g}",
            f"{s.start_s:.2f}-{s.end_s:.2f}",
            f"{s.truth_mean_n:.1f}",
            f"{s.estimate_mean_n:.1f}",
            f"{s.error_percent:+.2f}",
        )
    console.print(table)
    console.print(
        f"RMS error in the cut: {summary.rms_error_lowpassed_n:.2f} N against the truth through "
        f"the estimator's {summary.estimator_cutoff_hz:g} Hz low-pass "
        f"(RMS of that truth {summary.rms_truth_lowpassed_n:.1f} N); "
        f"{summary.rms_error_raw_n:.1f} N against the unfiltered truth "
        f"(peak {summary.peak_truth_n:.0f} N)."
    )
    console.print(f"wrote {summary.recording}, {summary.plot}, {out / 'summary.json'}")
    _online(out, console, seed)
    _chatter(out, console, seed)


def _online(out: Path, console: Console, seed: int) -> None:
    """Part 2: the on-line system with and without control (:mod:`millsense.demo_online`)."""
    from millsense.demo_online import run_online_demo
    from millsense.validation.status import SESSION_PREFIXES, read_status

    status = read_status(SESSION_PREFIXES)
    with progress_bar("on-line system: controlled, then open", 1) as update:
        summary = run_online_demo(out, on_progress=update, validation=status, seed=seed)
    table = Table(title="On-line system on the demo part (a tooth breaks at "
                  f"{summary['break_s']:g} s)")  # fmt: skip
    table.add_column("run", no_wrap=True)
    for col in ("signal [s]", "power in cut [W]", "peak |F| intact [N]", "peak |F| [N]",
                "breakage alarm [s]", "feed hold [s]", "cut broken [s]"):  # fmt: skip
        table.add_column(col, justify="right")
    for key, r in summary["runs"].items():
        hold = "-" if key == "open" else _s(r["feed_hold_s"])
        table.add_row(key, f"{r['seconds']:.1f}", f"{r['mean_power_w']:.0f}",
                      f"{r['peak_force_intact_n']:.0f}", f"{r['peak_force_n']:.0f}",
                      _s(r["breakage_alarm_s"]), hold,
                      f"{r['cut_with_broken_tool_s']:.2f}")  # fmt: skip
    console.print(table)
    console.print(f"wrote {summary['recording']}, {summary['plot']}, {summary['report']}, "
                  f"{out / 'online_summary.json'}")


def _chatter(out: Path, console: Console, seed: int) -> None:
    """Part 3: the chatter-prone pass with and without avoidance (:mod:`millsense.demo_chatter`)."""
    from millsense.demo_chatter import run_chatter_demo

    with progress_bar("chatter-prone pass: controlled, then open", 1) as update:
        summary = run_chatter_demo(out, on_progress=update, seed=seed)
    table = Table(title=f"Chatter-prone pass (Aslan T1, {summary['spindle_rpm']:.0f} rev/min, "
                  f"{summary['depth_mm']:g} mm slot, programmed feed)")  # fmt: skip
    table.add_column("run", no_wrap=True)
    # alarm and its frequency; speed commands; the last speed; share of the cut the truth
    # chatters; from the last command to the first second without chatter in the truth
    for col in ("alarm [s]", "[Hz]", "speed cmds", "last [rev/min]", "truth chatter [%]",
                "quiet after [s]"):  # fmt: skip
        table.add_column(col, justify="right")
    for key, r in summary["runs"].items():
        hz = "-" if r["alarm_hz"] is None else f"{r['alarm_hz']:.0f}"
        cmds = f"{r['speed_commands']}" if key != "open" else f"{r['speed_commands']} unsent"
        quiet = "never" if r["stopped"] is False else _s(r["quiet_after_command_s"])
        table.add_row(key, _s(r["alarm_s"]), hz, cmds, f"{r['last_rpm']:.0f}",
                      f"{100 * r['truth_chatter_share']:.0f}", quiet)  # fmt: skip
    console.print(table)
    console.print(f"wrote {summary['recording']}, {summary['plot']}, {summary['summary']}")


def _s(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"
