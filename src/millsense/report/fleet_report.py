"""The fleet view of a batch as one self-contained HTML page (``OUT/fleet.html``; issue 20
item 3): per tool and machine the wear monitor's VB against the tool's cutting time (the true VB
dashed where the runs are simulated) and the raw torque beside it, the per-tool table (runs,
last VB, wear rate, remaining cutting time, alarms) and the per-run table of the summary — the
same style and tables as the run report (:mod:`millsense.report.run_report`).
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

from millsense.report.fleet_plots import tool_runs, tool_table
from millsense.report.run_report import CSS, html_table

__all__ = ["RUN_COLUMNS", "fleet_html", "write_fleet_report"]

#: Columns of the per-run table: (summary column, heading).
RUN_COLUMNS = (
    ("run", "run"), ("status", "status"), ("machine", "machine"), ("tool_id", "tool"),
    ("program", "program"), ("duration_s", "duration [s]"), ("tool_cutting_time_s",
    "tool cutting time [s]"), ("alarms", "alarms"), ("raw_torque_nm", "raw torque [N·m]"),
    ("wear_vb_mm", "VB [mm]"), ("truth_wear_vb_mm", "true VB [mm]"),
    ("wear_remaining_min", "remaining [min]"), ("error", "error"),
)  # fmt: skip


def _figure(rows: Sequence[dict[str, Any]], limit_mm: float) -> go.Figure:
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
    fig.add_hline(y=limit_mm, line={"dash": "dot", "color": "black"}, row=1, col=1)
    fig.update_xaxes(title_text="tool cutting time [min]")
    fig.update_yaxes(title_text="flank wear VB [mm]", row=1, col=1)
    fig.update_yaxes(title_text="mean cutting torque [N·m]", row=1, col=2)
    fig.update_layout(height=460, margin={"l": 60, "r": 20, "t": 40, "b": 50})
    return fig


def fleet_html(rows: Sequence[dict[str, Any]], *, limit_mm: float, title: str = "") -> str:
    """The page (module docstring)."""
    tools = tool_table(rows)
    failed = sum(1 for r in rows if r.get("status") != "ok")
    title = title or f"millsense fleet: {len(rows)} runs, {len(tools)} tools"

    def num(v: Any) -> Any:
        return None if isinstance(v, float) and not math.isfinite(v) else v

    tool_rows = [[t["machine"], t["tool"], t["runs"], t["failed"], num(t["vb_mm"]),
                  num(t["rate_mm_min"]), num(t["remaining_min"]), t["alarms"]] for t in tools]
    run_rows = [[num(r.get(c)) for c, _ in RUN_COLUMNS] for r in rows]
    plot = _figure(rows, limit_mm).to_html(full_html=False, include_plotlyjs=False,
                                           div_id="plot-fleet")  # fmt: skip
    parts = [
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="note">{len(rows)} runs, {failed} failed; flank-wear limit VB = '
        f"{limit_mm:g} mm (ISO 8688-2).</p>",
        "<h2>Tools</h2>",
        html_table(["machine", "tool", "runs", "failed", "VB [mm]", "rate [mm/min]",
                    "remaining [min]", "alarms"], tool_rows, "tools"),
        "<h2>Wear over the tools' lives</h2>",
        plot,
        "<h2>Runs</h2>",
        html_table([h for _, h in RUN_COLUMNS], run_rows, "runs"),
    ]
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
