"""``millsense report``: the HTML report of a run (:mod:`millsense.report.run_report`), also
written by ``run``, ``replay`` and ``demo``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from millsense.cli.main import app


@app.command()
def report(
    recording: Path = typer.Argument(..., help="Recording of a run (.h5)."),
    plan: Path | None = typer.Option(None, "--plan", help="Virtual plan of the program."),
    events: Path | None = typer.Option(
        None, "--events", help="Event log (.parquet; default: beside the recording if there)."
    ),
    machine_file: Path | None = typer.Option(
        None,
        "--machine-file",
        help="Machine file of the estimators (default: the one the recording names).",
    ),
    fleet: Path | None = typer.Option(
        None,
        "--fleet",
        help="Summary table of a batch (OUT/summary.parquet of `millsense batch`): adds the "
        "fleet view (tools, wear trend, this run marked).",
    ),
    wear_limit_mm: float = typer.Option(
        0.3, "--wear-limit-mm", help="Flank-wear limit VB of the fleet view [mm]."
    ),
    out: Path = typer.Option(..., "-o", "--output", help="Report to write (.html)."),
) -> None:
    """One self-contained HTML file of a run (plotly, opens offline): estimates against truth,
    tool path coloured by force with the events, breakage residual, adaptive control, spindle
    speed, the event table, the machine file and the validation status."""
    import math

    from millsense.core.errors import ConfigError
    from millsense.io.safe_output import check_outputs

    if not (math.isfinite(wear_limit_mm) and wear_limit_mm > 0):  # as batch --vb-limit-mm
        raise ConfigError(f"--wear-limit-mm: must be > 0, got {wear_limit_mm:g}")
    check_outputs(
        {"the recording": recording, "the plan": plan, "the event log": events,
         "the machine file": machine_file, "the summary table": fleet},
        {"-o": out}, suffixes={"-o": ".html"},
    )  # fmt: skip
    rows = None
    if fleet is not None:
        from millsense.cli.batch_run import read_summary

        rows = read_summary(fleet)
    rep = write_run_report(out, recording, plan=plan, events=events, machine_file=machine_file,
                           fleet=rows, fleet_where=str(fleet or ""),
                           wear_limit_mm=wear_limit_mm)  # fmt: skip
    typer.echo(report_line(rep, out))


def report_line(rep: Any, out: Path) -> str:
    """``wrote run.html (6.5 MB, 6 plots)``."""
    size = out.stat().st_size / 1e6
    return f"wrote {out} ({size:.1f} MB, {len(rep.figures)} plots)"


def report_path(recording: Path) -> Path:
    """``run.h5`` → ``run.html`` beside it."""
    return recording.with_suffix(".html")


def write_run_report(
    out: Path,
    recording: Path,
    *,
    plan: Any = None,
    events: Any = None,
    machine_file: Path | None = None,
    fleet: Any = None,
    fleet_where: str = "",
    wear_limit_mm: float = 0.3,
) -> Any:
    """Write the report of ``recording``: ``plan`` a path or a plan, ``events`` a path, a list
    of events or None (the event log beside the recording if there); the machine file is
    ``machine_file``, else the one the recording names (a file, or the commissioned file
    shipped for its machine); ``fleet`` the rows of a batch's summary table (from
    ``fleet_where``) for the fleet view, or None."""
    from millsense.io.recording_reader import opened_recording
    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.report.run_report import write_report
    from millsense.streaming.event_log import default_event_log_path, read_event_log
    from millsense.validation.status import prefixes_for, read_status

    if events is None:
        beside = default_event_log_path(recording)
        events = read_event_log(beside) if beside.is_file() else []
    elif isinstance(events, str | Path):
        events = read_event_log(events)
    plan_file = plan if isinstance(plan, str | Path) else None
    if plan_file is not None:
        plan = VirtualPlan.read(plan_file)
    with opened_recording(recording) as rec:
        meta = dict(rec.metadata)
        channels = list(rec.channel_names)
        if plan_file is not None:  # a plan given by the user: of this run's program?
            from millsense.cli.plan_match import check_plan_matches

            check_plan_matches(plan, Path(plan_file), rec, recording)
    machine, where = _machine(machine_file, meta)
    status = read_status(prefixes_for(channels))
    rows, status_where = status if status is not None else (None, "")
    return write_report(out, recording, events=events, plan=plan, machine=machine,
                        machine_where=where, validation=rows,
                        validation_where=status_where, fleet=fleet, fleet_where=fleet_where,
                        wear_limit_mm=wear_limit_mm)  # fmt: skip


def _machine(machine_file: Path | None, meta: dict[str, Any]) -> tuple[Any, str]:
    """The estimators' machine file of a run, or (None, what the recording says)."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import commissioned_machine, load_preset

    if machine_file is not None:
        return load_preset(MachineConfig, str(machine_file)), str(machine_file)
    named = str(meta.get("machine_file", ""))
    if named and Path(named).is_file():
        return load_preset(MachineConfig, named), named
    if named.startswith("commissioned "):
        shipped = commissioned_machine(str(meta.get("machine", "")))
        if shipped is not None:
            return shipped
    return None, named or "not recorded"
