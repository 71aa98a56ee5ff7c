"""Static plots (PNG) of recordings and estimates. Uses matplotlib's Agg backend (no screen)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from millsense.core.errors import RecordingError
from millsense.core.recording import Recording


def _save(fig: plt.Figure, path: str | Path) -> None:
    """Write atomically: a failed save leaves no half-written PNG (decision 0921)."""
    from millsense.io.safe_output import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    finally:
        plt.close(fig)


@dataclass(frozen=True)
class Series:
    """One line of :func:`plot_channels`: a channel, or a field of a slower stream."""

    label: str
    time_s: np.ndarray
    values: np.ndarray
    unit: str
    stream: str | None = None


def _listed(names: Sequence[str], most: int = 12) -> str:
    shown = ", ".join(names[:most]) or "(none)"
    return shown + (f" … ({len(names)} in all)" if len(names) > most else "")


def recording_series(
    rec: Recording, names: Sequence[str], t_range_s: tuple[float, float] | None = None
) -> list[Series]:
    """The named lines of a recording within ``[t0, t1)`` (s): a channel (``x/current_cmd``),
    a stream's field as ``STREAM/FIELD`` (``dynamometer/x/force`` of a slower file imported as
    the stream ``dynamometer/x``: the name its map gave it), or a stream (all its fields).

    Raises
    ------
    RecordingError
        One line naming what is unknown, with the channels and stream fields there are.
    """
    out: list[Series] = []
    if t_range_s is None:
        lo, hi = 0, rec.n_samples
    else:
        lo = int(np.searchsorted(rec.time_s, t_range_s[0], side="left"))
        hi = max(int(np.searchsorted(rec.time_s, t_range_s[1], side="left")), lo)
    for name in names:
        if name in rec.channel_names:
            out.append(
                Series(name, rec.time_s[lo:hi], rec.channel(name)[lo:hi], rec.info(name).unit)
            )
            continue
        sname, _, field = name.rpartition("/")
        if name in rec.stream_names:
            sname, fields = name, None
        elif sname in rec.stream_names and field in rec.stream(sname).fields:
            fields = [field]
        else:
            streams = [f"{s}/{f}" for s in rec.stream_names for f in rec.stream(s).fields]
            raise RecordingError(
                f"{rec.source}: unknown channel '{name}' (nor a stream or STREAM/FIELD); "
                f"channels: {_listed(rec.channel_names)}; stream fields: {_listed(streams)}"
            )
        st = rec.stream(sname)
        if t_range_s is not None:
            st = st.slice_time(*t_range_s)
        for f in fields or list(st.fields):
            label = f"{sname}/{f}"
            out.append(Series(label, st.time_s, st[f], st.info[f].unit, sname))
    return out


def plot_channels(
    rec: Recording,
    names: Sequence[str],
    path: str | Path,
    t_range_s: tuple[float, float] | None = None,
) -> None:
    """One panel per unit: the named channels and stream fields (:func:`recording_series`)
    against time; a stream's rows are marked (they are slower than the channels)."""
    series = recording_series(rec, names, t_range_s)
    by_unit: dict[str, list[Series]] = {}
    for sr in series:
        by_unit.setdefault(sr.unit, []).append(sr)
    fig, axes = plt.subplots(
        len(by_unit), 1, sharex=True, figsize=(10, 2.6 * len(by_unit) + 0.6), squeeze=False
    )
    for ax, (unit, lines) in zip(axes[:, 0], by_unit.items(), strict=True):
        for sr in lines:
            style = {"marker": ".", "ms": 3} if sr.stream is not None else {}
            ax.plot(sr.time_s, sr.values, lw=0.8, label=sr.label, **style)
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
