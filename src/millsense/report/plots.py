"""Static plots (PNG) of recordings and estimates. Uses matplotlib's Agg backend (no screen)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from millsense.core.recording import Recording


def _save(fig: plt.Figure, path: str | Path) -> None:
    """Write atomically: a failed save leaves no half-written PNG (decision 0921)."""
    from millsense.io.safe_output import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    finally:
        plt.close(fig)


def plot_channels(
    rec: Recording,
    names: Sequence[str],
    path: str | Path,
    t_range_s: tuple[float, float] | None = None,
) -> None:
    """One panel per unit, the named (sample-rate) channels against time."""
    if t_range_s is not None:
        rec = rec.slice_time(*t_range_s)
    by_unit: dict[str, list[str]] = {}
    for n in names:
        by_unit.setdefault(rec.info(n).unit, []).append(n)
    fig, axes = plt.subplots(
        len(by_unit), 1, sharex=True, figsize=(10, 2.6 * len(by_unit) + 0.6), squeeze=False
    )
    t = rec.time_s
    for ax, (unit, chans) in zip(axes[:, 0], by_unit.items(), strict=True):
        for n in chans:
            ax.plot(t, rec.channel(n), lw=0.8, label=n)
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    title = rec.metadata.get("source", "")
    fig.suptitle(str(title), fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def plot_estimate_vs_truth(
    t: np.ndarray,
    truth: np.ndarray,
    estimate: np.ndarray,
    path: str | Path,
    *,
    truth_filtered: np.ndarray | None = None,
    title: str = "",
    zoom_s: tuple[float, float] | None = None,
    unit: str = "N",
) -> None:
    """Estimate against truth: whole record, a zoom on a few tooth periods, and the error."""
    rows = 3 if zoom_s is not None else 2
    fig, axes = plt.subplots(rows, 1, figsize=(10, 3.0 * rows))
    ax = axes[0]
    ax.plot(t, truth, color="0.7", lw=0.6, label="truth")
    if truth_filtered is not None:
        ax.plot(t, truth_filtered, color="C0", lw=0.8, label="truth, same low-pass")
    ax.plot(t, estimate, color="C3", lw=0.8, label="estimate")
    ax.set_ylabel(unit)
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)
    if zoom_s is not None:
        ax = axes[1]
        sel = (t >= zoom_s[0]) & (t <= zoom_s[1])
        ax.plot(t[sel], truth[sel], color="0.6", lw=1.0, label="truth")
        if truth_filtered is not None:
            ax.plot(t[sel], truth_filtered[sel], color="C0", lw=1.0, label="truth, same low-pass")
        ax.plot(t[sel], estimate[sel], color="C3", lw=1.0, label="estimate")
        ax.set_ylabel(unit)
        ax.set_title(f"zoom {zoom_s[0]:g}-{zoom_s[1]:g} s", fontsize=9)
        ax.grid(alpha=0.3)
    ax = axes[-1]
    ref = truth_filtered if truth_filtered is not None else truth
    ax.plot(t, estimate - ref, color="C2", lw=0.6)
    ax.set_ylabel(f"error [{unit}]")
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
