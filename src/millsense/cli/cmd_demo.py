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
    seed: int = typer.Option(0, help="Seed of the simulated noise."),
) -> None:
    """Simulate a slot cut on the X drive, estimate the force from the current command, report.

    Writes OUTPUT/demo.h5 (recording with truth/ channels and the estimate), OUT/demo_force.png
    (estimate against truth) and OUT/summary.json (errors computed from the recording).
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
