"""Plots of a virtual plan (PNG, matplotlib Agg): path coloured by force, states along it."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from millsense.plan.virtual_plan import VirtualPlan


def plot_plan(plan: VirtualPlan, path: str | Path, feed_mm_min: np.ndarray | None = None) -> None:
    """XY view coloured by the predicted peak resultant; force, torque (and feed) along s.

    Parameters
    ----------
    plan : VirtualPlan
        The plan.
    path : path
        PNG file, written atomically.
    feed_mm_min : (n,) float, optional
        A scheduled feed to draw with the programmed one [mm/min].
    """
    x, y, s = plan["x_mm"], plan["y_mm"], plan["s_mm"]
    f = plan["fres_peak_n"]
    rows = 3 if feed_mm_min is not None else 2
    fig = plt.figure(figsize=(11, 4.0 + 2.2 * rows))
    gs = fig.add_gridspec(rows, 2, width_ratios=(1.0, 1.6))
    ax0 = fig.add_subplot(gs[:, 0])
    pts = np.column_stack((x, y)).reshape(-1, 1, 2)
    segs = np.concatenate((pts[:-1], pts[1:]), axis=1)
    rapid = plan["rapid"][:-1].astype(bool)
    lc = LineCollection(list(segs[~rapid]), cmap="viridis", linewidths=1.6)
    lc.set_array(f[:-1][~rapid])
    ax0.add_collection(lc)
    # rapids: one thin dashed grey polyline per run of rapid steps (a dashed pattern per 0.4 mm
    # segment would look solid)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], rapid.astype(np.int8), [0]))))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax0.plot(x[a : b + 1], y[a : b + 1], "--", lw=0.7, color="0.6")
    ax0.set_xlim(float(x.min()) - 5, float(x.max()) + 5)
    ax0.set_ylim(float(y.min()) - 5, float(y.max()) + 5)
    ax0.set_aspect("equal")
    ax0.set_xlabel("X [mm]")
    ax0.set_ylabel("Y [mm]")
    fig.colorbar(lc, ax=ax0, label="peak resultant force [N]", shrink=0.8)
    ax1 = fig.add_subplot(gs[0, 1])
    ax1.plot(s, f, lw=0.8, label="peak F_res")
    ax1.plot(s, plan["fres_avg_n"], lw=0.8, label="|mean F_xy|")
    ax1.set_ylabel("force [N]")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.grid(alpha=0.3)
    ax2 = fig.add_subplot(gs[1, 1], sharex=ax1)
    ax2.plot(s, plan["torque_avg_nm"], lw=0.8, color="C2", label="mean torque")
    ax2.set_ylabel("torque [N·m]")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="upper right", fontsize=8)
    last = ax2
    if feed_mm_min is not None:
        ax3 = fig.add_subplot(gs[2, 1], sharex=ax1)
        cut = ~plan["rapid"].astype(bool)
        ax3.plot(s[cut], plan["feed_mm_min"][cut], ".", ms=1, color="0.5", label="programmed")
        ax3.plot(s[cut], feed_mm_min[cut], ".", ms=1, color="C3", label="scheduled")
        ax3.set_ylabel("feed [mm/min]")
        ax3.grid(alpha=0.3)
        ax3.legend(loc="upper right", fontsize=8)
        last = ax3
    last.set_xlabel("path length s [mm]")
    title = str(plan.metadata.get("program", ""))
    if "tool_number" in plan.metadata:  # one tool's plan of a program with several (1683)
        title += f": T{plan.metadata['tool_number']} ({plan.metadata.get('tool_name', '')})"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    from millsense.io.safe_output import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
