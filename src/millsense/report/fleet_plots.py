"""The fleet view of a batch (``millsense batch`` writes ``OUT/fleet.png``; issue 20 item 3).

Per tool (one colour each, per machine when several): the wear monitor's VB against the
tool's cutting time with the limit, the true VB dashed where the runs are simulated; beside it
the raw mean cutting torque of the same runs — what a monitor without the plan would have to
judge, which moves with every change of depth and width. A table below gives, per tool, the
runs, the last VB, the wear rate and the remaining cutting time, and the alarms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from millsense.report.plots import _save

__all__ = ["plot_fleet", "tool_key", "tool_runs", "tool_table"]


def tool_key(r: dict[str, Any]) -> tuple[str, str]:
    """(machine, tool id or name) of a summary row."""
    return (str(r.get("machine", "")), str(r.get("tool_id") or r.get("tool", "")))


def tool_runs(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    """The judged runs (status ok, with a wear estimate) per (machine, tool), sorted by tool,
    each tool's runs in order of its cutting time."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        if r.get("status") == "ok" and r.get("wear_vb_mm") is not None:
            groups.setdefault(tool_key(r), []).append(r)
    return {k: sorted(v, key=lambda r: float(r.get("tool_cutting_time_s") or 0.0))
            for k, v in sorted(groups.items())}  # fmt: skip


def tool_table(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One line per (machine, tool): runs, failed runs, last VB (mm), rate (mm/min),
    remaining cutting time (min), alarms."""
    out: dict[tuple[str, str], dict[str, Any]] = {}
    for r in rows:
        key = tool_key(r)
        fresh = {"machine": key[0], "tool": key[1], "runs": 0, "failed": 0, "vb_mm": math.nan,
                 "rate_mm_min": math.nan, "remaining_min": math.nan, "alarms": 0,
                 "_order": -1.0}  # fmt: skip
        t = out.setdefault(key, fresh)
        t["runs"] += 1
        if r.get("status") != "ok":
            t["failed"] += 1
            continue
        t["alarms"] += int(r.get("alarms") or 0)
        order = r.get("tool_cutting_time_s")
        if r.get("wear_vb_mm") is not None and order is not None and order >= t["_order"]:
            t.update(_order=float(order), vb_mm=float(r["wear_vb_mm"]),
                     rate_mm_min=r.get("wear_rate_mm_min"),
                     remaining_min=r.get("wear_remaining_min"))  # fmt: skip
    for t in out.values():
        t.pop("_order")
    return [out[k] for k in sorted(out)]


def plot_fleet(rows: Sequence[dict[str, Any]], path: str | Path, *, limit_mm: float) -> None:
    """Write the fleet PNG (module docstring)."""
    fig, (ax_vb, ax_tq) = plt.subplots(1, 2, figsize=(12, 4.8))
    groups = tool_runs(rows)
    several = len({k[0] for k in groups}) > 1
    for i, (key, members) in enumerate(groups.items()):
        t_min = [float(r.get("tool_cutting_time_s") or 0.0) / 60 for r in members]
        color = f"C{i % 10}"
        label = f"{key[0]} {key[1]}" if several else key[1]
        ax_vb.plot(t_min, [float(r["wear_vb_mm"]) for r in members], "o-", color=color,
                   label=label)  # fmt: skip
        truth = [r.get("truth_wear_vb_mm") for r in members]
        if any(v is not None for v in truth):
            ax_vb.plot(t_min, [float(v or 0.0) for v in truth], "--", color=color, lw=1,
                       alpha=0.7)  # fmt: skip
        ax_tq.plot(t_min, [float(r.get("raw_torque_nm") or math.nan) for r in members], "o-",
                   color=color, label=label)  # fmt: skip
    ax_vb.axhline(limit_mm, color="k", lw=1, ls=":", label=f"limit {limit_mm:g} mm")
    ax_vb.set(xlabel="tool cutting time [min]", ylabel="flank wear VB [mm]",
              title="wear monitor (matched engagement); dashed: true VB")  # fmt: skip
    ax_tq.set(xlabel="tool cutting time [min]", ylabel="mean cutting torque [N·m]",
              title="raw torque (no engagement normalisation)")  # fmt: skip
    for ax in (ax_vb, ax_tq):
        ax.grid(True, alpha=0.3)
    if groups:
        ax_vb.legend(fontsize=8, loc="upper left")
    else:
        ax_vb.text(0.5, 0.5, "no run with a wear estimate", ha="center", transform=ax_vb.transAxes)
    fig.tight_layout()
    _save(fig, path)
