"""The fleet view of a batch (issue 20 item 3): per tool and machine the wear monitor's VB
against the tool's cutting time (the true VB dashed where the runs are simulated) and the raw
torque beside it, the per-tool table (runs, last VB, wear rate, remaining cutting time, alarms)
and the per-run table of the summary.

Two places show it: the batch's own page (``OUT/fleet.html``, :func:`fleet_html`) and the run
report (``millsense report RUN.h5 --fleet OUT/summary.parquet``, :func:`fleet_sections` with
the run marked: its tool's line highlighted, the run starred on the wear trend, its own row of
the summary shown first). Same style and tables as the run report
(:mod:`millsense.report.html_parts`).
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import plotly.graph_objects as go
from plotly.offline import get_plotlyjs
from plotly.subplots import make_subplots

from millsense.report.fleet_plots import tool_key, tool_runs, tool_table
from millsense.report.html_parts import CSS, html_table

__all__ = ["RUN_COLUMNS", "find_run", "fleet_html", "fleet_sections", "write_fleet_report"]

#: Columns of the per-run table: (summary column, heading).
RUN_COLUMNS = (
    ("run", "run"), ("status", "status"), ("machine", "machine"), ("tool_id", "tool"),
    ("program", "program"), ("duration_s", "duration [s]"), ("tool_cutting_time_s",
    "tool cutting time [s]"), ("alarms", "alarms"), ("raw_torque_nm", "raw torque [N·m]"),
    ("wear_vb_mm", "VB [mm]"), ("truth_wear_vb_mm", "true VB [mm]"),
    ("wear_remaining_min", "remaining [min]"), ("error", "error"),
)  # fmt: skip


def _figure(rows: Sequence[dict[str, Any]], limit_mm: float,
            run: dict[str, Any] | None = None) -> go.Figure:  # fmt: skip
    fig = make_subplots(rows=1, cols=2, subplot_titles=(
        "wear monitor (matched engagement); dashed: true VB",
        "raw torque (no engagement normalisation)"))  # fmt: skip
    for i, (key, members) in enumerate(tool_runs(rows).items()):
        t = [float(r.get("tool_cutting_time_s") or 0.0) / 60 for r in members]
        color = f"hsl({(i * 67) % 360},65%,45%)"
        name = " ".join(k for k in key if k)
        fig.add_trace(go.Scatter(x=t, y=[r["wear_vb_mm"] for r in members], mode="lines+markers",
                                 name=name, line={"color": color},
                                 text=[r["run"] for r in members]), row=1, col=1)  # fmt: skip
        truth = [r.get("truth_wear_vb_mm") for r in members]
        if any(v is not None for v in truth):
            dashed = {"color": color, "dash": "dash"}
            fig.add_trace(go.Scatter(x=t, y=truth, mode="lines", name=f"{name} (true)",
                                     line=dashed), row=1, col=1)  # fmt: skip
        fig.add_trace(go.Scatter(x=t, y=[r.get("raw_torque_nm") for r in members],
                                 mode="lines+markers", name=f"{name} torque", showlegend=False,
                                 line={"color": color}), row=1, col=2)  # fmt: skip
    if run is not None and run.get("wear_vb_mm") is not None:
        t_run = [float(run.get("tool_cutting_time_s") or 0.0) / 60]
        star = {"symbol": "star", "size": 16, "color": "#ffb000",
                "line": {"color": "black", "width": 1}}  # fmt: skip
        fig.add_trace(go.Scatter(x=t_run, y=[run["wear_vb_mm"]], mode="markers", marker=star,
                                 name=f"this run ({run['run']})"), row=1, col=1)  # fmt: skip
        fig.add_trace(go.Scatter(x=t_run, y=[run.get("raw_torque_nm")], mode="markers",
                                 marker=star, showlegend=False), row=1, col=2)  # fmt: skip
    fig.add_hline(y=limit_mm, line={"dash": "dot", "color": "black"}, row=1, col=1)
    fig.update_xaxes(title_text="tool cutting time [min]")
    fig.update_yaxes(title_text="flank wear VB [mm]", row=1, col=1)
    fig.update_yaxes(title_text="mean cutting torque [N·m]", row=1, col=2)
    fig.update_layout(height=460, margin={"l": 60, "r": 20, "t": 40, "b": 50})
    return fig


def _num(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def find_run(rows: Sequence[dict[str, Any]], run: str) -> dict[str, Any] | None:
    """The summary row of ``run`` (its ``run`` name, or the file name of its ``path``)."""
    for r in rows:
        if str(r.get("run", "")) == run or Path(str(r.get("path", ""))).name == run:
            return r
    return None


def fleet_sections(
    rows: Sequence[dict[str, Any]], *, limit_mm: float, run: dict[str, Any] | None = None,
    level: int = 2,
) -> list[str]:  # fmt: skip
    """The fleet view's HTML parts (module docstring): the tool table, the wear trend and the
    per-run table; with ``run`` (one of the rows) its tool and its row are marked and its row
    is shown first. ``level``: the heading level of the parts."""
    tools = tool_table(rows)
    failed = sum(1 for r in rows if r.get("status") != "ok")
    mine = tool_key(run) if run is not None else None
    tool_rows = [[t["machine"], t["tool"], t["runs"], t["failed"], _num(t["vb_mm"]),
                  _num(t["rate_mm_min"]), _num(t["remaining_min"]), t["alarms"]]
                 for t in tools]  # fmt: skip
    marked_tools = [i for i, t in enumerate(tools) if (t["machine"], t["tool"]) == mine]
    run_rows = [[_num(r.get(c)) for c, _ in RUN_COLUMNS] for r in rows]
    marked_runs = [i for i, r in enumerate(rows) if r is run]
    plot = _figure(rows, limit_mm, run).to_html(full_html=False, include_plotlyjs=False,
                                                div_id="plot-fleet")  # fmt: skip
    h = f"h{level}"
    parts = [
        f'<p class="note">{len(rows)} runs, {failed} failed; flank-wear limit VB = '
        f"{limit_mm:g} mm (ISO 8688-2).</p>",
    ]
    if run is not None:
        parts += [f"<{h}>This run in the fleet</{h}>",
                  html_table([hd for _, hd in RUN_COLUMNS],
                             [run_rows[marked_runs[0]]], "fleet-this-run", [0])]  # fmt: skip
    parts += [
        f"<{h}>Tools</{h}>",
        html_table(["machine", "tool", "runs", "failed", "VB [mm]", "rate [mm/min]",
                    "remaining [min]", "alarms"], tool_rows, "tools", marked_tools),
        f"<{h}>Wear over the tools' lives</{h}>",
        plot,
        f"<{h}>Runs</{h}>",
        html_table([hd for _, hd in RUN_COLUMNS], run_rows, "runs", marked_runs),
    ]
    return parts


def fleet_html(rows: Sequence[dict[str, Any]], *, limit_mm: float, title: str = "") -> str:
    """The batch's page (module docstring)."""
    tools = tool_table(rows)
    title = title or f"millsense fleet: {len(rows)} runs, {len(tools)} tools"
    parts = [f"<h1>{html.escape(title)}</h1>", *fleet_sections(rows, limit_mm=limit_mm)]
    blob = json.dumps({"tools": tools}, default=float).replace("</", "<\\/")
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{CSS}</style>"
        f"<script type='text/javascript'>{get_plotlyjs()}</script></head><body>"
        + "\n".join(parts)
        + f"<script type='application/json' id='millsense-fleet-data'>{blob}</script>"
        "</body></html>"
    )


def write_fleet_report(rows: Sequence[dict[str, Any]], path: str | Path, *,
                       limit_mm: float) -> None:  # fmt: skip
    """Write :func:`fleet_html` atomically to ``path``."""
    from millsense.io.safe_output import write_text

    write_text(path, fleet_html(rows, limit_mm=limit_mm))
