"""``millsense batch``: many recordings through the pipeline on Dask, one summary table."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from millsense.cli.main import allow_fast_exit, app


@app.command()
def batch(
    recordings: str = typer.Argument(..., help="Folder (searched recursively) or glob of .h5."),
    out: Path = typer.Option(..., "-o", "--output", help="Results folder."),
    do: str = typer.Option(
        "estimate,monitor,wear,summary",
        "--do",
        help="Steps per recording: estimate, monitor, wear, summary (comma-separated).",
    ),
    machine: str | None = typer.Option(
        None,
        "--machine",
        help="Identified machine file for every recording (default: the commissioned file "
        "shipped for each recording's machine).",
    ),
    plan: str | None = typer.Option(
        None, "--plan", help="Virtual plan for every recording (default: each one's own)."
    ),
    workers: int = typer.Option(2, "--workers", help="Local worker processes."),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="Address of a running Dask scheduler (tcp://HOST:PORT) instead of a local cluster.",
    ),
    method: str = typer.Option("spindle", "--method", help="estimate: the estimators' method."),
    monitors: str = typer.Option("chatter-comb", "--monitors", help="monitor: the methods."),
    vb_limit_mm: float = typer.Option(
        0.3, "--vb-limit-mm", help="Flank-wear limit VB [mm] (ISO 8688-2: 0.3)."
    ),
    segment_s: float = typer.Option(
        600.0,
        "--segment-s",
        help="Recordings longer than 1.5 x this [s] run as segments of about this length, in "
        "parallel (the wear sums over the whole recording as one more task); 0: never split.",
    ),
) -> None:
    """Run the pipeline over many recordings (a task per recording on Dask; a failed or
    corrupt recording is a row of the table, never the end of the batch) and write
    OUT/summary.parquet: one row per run with its statistics, events and tool wear.
    Recordings finished by an earlier batch into the same OUT are not run again."""
    from millsense.cli.batch_run import (
        assess_wear,
        batch_inputs,
        parse_steps,
        run_batch,
        write_summary,
    )
    from millsense.cli.progress import progress_bar
    from millsense.core.errors import ConfigError

    parse_steps(do)
    if not (math.isfinite(vb_limit_mm) and vb_limit_mm > 0):
        raise ConfigError(f"--vb-limit-mm: must be > 0, got {vb_limit_mm:g}")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a folder")
    found, skipped = batch_inputs(recordings, out)
    if not found:
        raise ConfigError(
            f"batch: {recordings} holds no recording outside -o {out} and earlier batch outputs"
        )
    if skipped:
        typer.echo(f"batch: {skipped} file(s) of batch outputs (runs/ beside a summary.parquet) "
                   "inside the input are not taken as recordings")  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    # the wear assessment and the fleet view's libraries load while the local cluster starts:
    # its workers wait for their fork server's imports then and this process's core is idle
    # (during the tasks, with a worker per core, they would take the workers' CPU; decision
    # 2008)
    import threading

    preload = threading.Thread(target=_import_reports, daemon=True)

    def progress(done: float, _total: int) -> None:
        update(float(done))

    with progress_bar("batch", float(len(found))) as update:
        res = run_batch(found, out, do=do, machine=machine, plan=plan, workers=workers,
                        scheduler=scheduler, estimate_method=method, monitor_methods=monitors,
                        segment_s=segment_s if segment_s != 0 else None,
                        on_progress=progress, on_waiting=preload.start)  # fmt: skip
    if preload.ident is None:
        preload.start()
    preload.join()
    rows = assess_wear(res.rows, limit_mm=vb_limit_mm)
    target = write_summary(rows, out)
    from millsense.report.fleet_plots import plot_fleet, tool_table
    from millsense.report.fleet_report import write_fleet_report

    plot_fleet(rows, out / "fleet.png", limit_mm=vb_limit_mm)
    write_fleet_report(rows, out / "fleet.html", limit_mm=vb_limit_mm)
    _print_tools(tool_table(rows))
    if res.closing is not None:
        res.closing.join()
    failed = [r for r in rows if r.get("status") != "ok"]
    for r in failed:
        error = str(r.get("error", ""))
        # the reason names the recording already where it comes from a check of its data
        where = "" if error.startswith(str(r["path"])) else f"{r['path']}: "
        typer.echo(f"millsense: warning: {where}{error}", err=True)
    worn = [r for r in rows if r.get("wear_worn")]
    where = f"{res.workers} worker(s), {res.scheduler}" if res.ran else "nothing to run"
    typer.echo(
        f"wrote {target}: {len(rows)} runs ({res.ran} run on {where}, {res.reused} from an "
        f"earlier batch), {len(failed)} failed, {len(worn)} with VB ≥ {vb_limit_mm:g} mm; "
        f"fleet view {out / 'fleet.html'} and {out / 'fleet.png'}"
    )
    # everything is written and closed, the cluster's closing thread joined
    allow_fast_exit()


def _import_reports() -> None:
    """What the client needs once the workers are done (wear assessment, summary table, the
    fleet view)."""
    import pyarrow.parquet  # noqa: F401

    import millsense.monitoring.wear
    import millsense.report.fleet_plots
    import millsense.report.fleet_report  # noqa: F401


def _print_tools(tools: list[dict[str, object]]) -> None:
    """Per tool: runs, failed, last VB, rate, remaining cutting time, alarms."""
    from rich.console import Console
    from rich.table import Table

    def num(v: object, fmt: str) -> str:
        return "-" if not isinstance(v, int | float) or not math.isfinite(v) else format(v, fmt)

    table = Table("machine", "tool", "runs", "failed", "VB [mm]", "rate [mm/min]",
                  "remaining [min]", "alarms")  # fmt: skip
    for t in tools:
        table.add_row(str(t["machine"]), str(t["tool"]), str(t["runs"]), str(t["failed"]),
                      num(t["vb_mm"], ".3f"), num(t["rate_mm_min"], ".4f"),
                      num(t["remaining_min"], ".0f"), str(t["alarms"]))  # fmt: skip
    con = Console()
    if not con.is_terminal:
        con = Console(width=140)
    con.print(table)
