"""The plot of an on-line run (``millsense run --plot``): what the controllers did and why.

Four panels over time: the feed override (commanded by the supervisor and in effect on the
machine), the regulated quantity against its reference (and the true resultant force on the
virtual machine), the spindle speed, and the spindle cutting torque (estimated, less the
air-cut reference, while the spindle is at speed; expected from the calibrated plan; true); the
events are marked (chatter, breakage, feed hold, faults).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from millsense.report.labels import regulated_label
from millsense.report.plots import _save
from millsense.streaming.block import Event

#: Points drawn per line at most (the recording is decimated by a stride).
MAX_POINTS = 20000
_MARKS = {
    "chatter": ("tab:red", "chatter"),
    "breakage": ("black", "breakage"),
    "feed_hold": ("tab:purple", "feed hold"),
    "spindle_override": ("tab:orange", "spindle change"),
    "input_fault": ("tab:brown", "input fault"),
    "source_lost": ("tab:brown", "source lost"),
}




def plot_run(recording: str | Path, events: Sequence[Event], path: str | Path) -> None:
    """Write the PNG of a run's recording and events."""
    _save(run_figure(recording, events), path)


def run_figure(recording: str | Path, events: Sequence[Event]) -> Any:
    """The figure of :func:`plot_run` (four panels, every axis labelled with its unit; the
    true resultant force on its own axis where the regulated quantity is not a force)."""
    from millsense.io.recording_reader import opened_recording

    with opened_recording(recording) as rec:
        names = set(rec.channel_names)
        n = rec.n_samples
        stride = max(1, n // MAX_POINTS)

        def get(name: str) -> np.ndarray | None:
            if name not in names:
                return None
            return np.asarray(rec.channel(name))[::stride]

        t = np.arange(0, n, stride) / rec.sample_rate_hz
        fig, ax = plt.subplots(4, 1, figsize=(11, 10), sharex=True)
        _line(ax[0], t, get("supervisor/feed_override"), "commanded", 100.0)
        _line(ax[0], t, get("cnc/feed_override"), "in effect", 100.0)
        ax[0].set_ylabel("feed override [%]")
        _line(ax[1], t, get("adaptive_feed/peak"), "regulated (per control interval)")
        _line(ax[1], t, get("adaptive_feed/reference"), "reference")
        unit = rec.info("adaptive_feed/peak").unit if "adaptive_feed/peak" in names else ""
        ax[1].set_ylabel(regulated_label(unit))
        fx, fy = get("truth/tool/force_x"), get("truth/tool/force_y")
        if fx is not None and fy is not None:
            # the force in N on the panel's own axis only where the regulated quantity is one
            fax = ax[1] if unit == "N" else ax[1].twinx()
            fax.plot(t, np.hypot(fx, fy), lw=0.3, alpha=0.4, color="grey", label="true |F_xy|")
            if fax is not ax[1]:
                fax.set_ylabel("true |F_xy| [N]", color="grey")
                fax.legend(loc="upper left", fontsize=7)
        sp = get("spindle/speed")
        if sp is not None:
            ax[2].plot(t, sp * 60 / (2 * np.pi), lw=0.8, label="spindle speed")
        ax[2].set_ylabel("spindle [rev/min]")
        est = get("plan/cutting_torque")  # less the air-cut reference
        if est is None:
            est = get("est/spindle/spindle/load")
        gate = get("spindle/at_speed")
        if est is not None and gate is not None:
            # off speed the observer's torque is the acceleration torque (tens of N·m on a
            # run-up), which would set the panel's scale: not drawn
            est = np.where(gate > 0.5, est, np.nan)
        _line(ax[3], t, est, "estimated (spindle at speed)", alpha=0.3)
        tooth = get("breakage/tooth_avg")
        if tooth is not None:
            if gate is not None:
                tooth = np.where(gate > 0.5, tooth, np.nan)
            _line(ax[3], t, tooth, "estimated, tooth-period average")
        _line(ax[3], t, get("plan/expected_torque"), "expected (plan, calibrated)")
        _line(ax[3], t, get("truth/spindle/torque"), "true", alpha=0.5)
        ax[3].set_ylabel("cutting torque [N·m]")
        ax[3].set_xlabel("time [s]")
        seen: set[str] = set()
        for e in events:
            mark = _MARKS.get(e.name)
            if mark is None:
                continue
            for a in ax:
                a.axvline(e.time_s, color=mark[0], lw=1.0, ls="--",
                          label=mark[1] if a is ax[0] and mark[1] not in seen else None)
            seen.add(mark[1])
        for a in ax:
            if a.get_legend_handles_labels()[0]:
                a.legend(loc="upper right", fontsize=7)
            a.grid(alpha=0.3)
        ax[0].set_title(f"{Path(recording).name}: on-line run")
        fig.tight_layout()
        return fig


def _line(
    ax: plt.Axes,
    t: np.ndarray,
    v: np.ndarray | None,
    label: str,
    scale: float = 1.0,
    alpha: float = 1.0,
) -> None:
    if v is not None:
        ax.plot(t[: len(v)], v[: len(t)] * scale, lw=0.8, alpha=alpha, label=label)


#: Colours of the runs side by side.
_RUN_COLOURS = {"controlled": "tab:blue", "open": "tab:grey"}


def _time_axis(n: int, sample_rate_hz: float) -> tuple[np.ndarray, int]:
    """Times of ``n`` samples, s, and the stride that keeps a line within MAX_POINTS."""
    return np.arange(n) / sample_rate_hz, max(1, n // MAX_POINTS)


def _mark_runs(ax: Sequence[Any], events: Sequence[Event], dashed: str, solid: str,
               colour: str | None) -> None:  # fmt: skip
    """A run's ``dashed`` and ``solid`` events as vertical lines on every panel."""
    for e in events:
        if e.name in (dashed, solid):
            for a in ax:
                a.axvline(e.time_s, color=colour, ls="--" if e.name == dashed else "-", lw=0.9,
                          alpha=0.8)  # fmt: skip


def _finish(fig: Any, ax: Sequence[Any], ylabels: Sequence[str], xlabel: str, title: str,
            path: str | Path) -> None:  # fmt: skip
    """Labels, grids, legends and the title of a comparison; saved to ``path``."""
    for a, label in zip(ax, ylabels, strict=True):
        a.set_ylabel(label)
        a.grid(alpha=0.3)
        a.legend(loc="upper right", fontsize=8)
    ax[-1].set_xlabel(xlabel)
    ax[0].set_title(title)
    fig.tight_layout()
    _save(fig, path)


def plot_comparison(
    data: dict[str, dict[str, np.ndarray]],
    events: dict[str, Sequence[Event]],
    path: str | Path,
    title: str,
    sample_rate_hz: float = 10000.0,
) -> None:
    """Runs side by side (e.g. ``controlled`` and ``open``): the feed override in effect, the
    regulated spindle power per revolution against its reference, and the true resultant force
    (per-revolution maximum), with each run's breakage alarm and feed hold marked."""
    fig, ax = plt.subplots(3, 1, figsize=(11, 8.5), sharex=True)
    for key, d in data.items():
        col = _RUN_COLOURS.get(key)
        n = len(d["cnc/feed_override"])
        t, stride = _time_axis(n, sample_rate_hz)
        ax[0].plot(t[::stride], 100 * d["cnc/feed_override"][::stride], color=col, lw=1.0,
                   label=key)  # fmt: skip
        ax[1].plot(t[::stride], d["adaptive_feed/peak"][::stride], color=col, lw=1.0, label=key)
        f = np.hypot(d["truth/tool/force_x"], d["truth/tool/force_y"])
        rev = int(sample_rate_hz * 0.06)  # one revolution at 1000 rev/min
        m = (n // rev) * rev
        fmax = f[:m].reshape(-1, rev).max(axis=1)
        ax[2].plot(t[:m:rev], fmax, color=col, lw=1.0, label=key)
        _mark_runs(ax, events.get(key, ()), "breakage", "feed_hold", col)
    ref = next(iter(data.values()))["adaptive_feed/reference"]
    if len(ref):
        ax[1].axhline(float(ref[-1]), color="tab:orange", lw=1.0, label="reference")
    _finish(fig, ax, ("feed override in effect [%]", "spindle power per rev. [W]",
                      "true |F_xy| per rev. [N]"),
            "time [s]  (dashed: breakage alarm, solid: feed hold)", title, path)  # fmt: skip


def plot_chatter_comparison(
    data: dict[str, dict[str, np.ndarray]],
    events: dict[str, Sequence[Event]],
    path: str | Path,
    title: str,
    sample_rate_hz: float = 10000.0,
) -> None:
    """A chatter-prone pass run side by side (``controlled``, ``open``): the spindle speed
    (``spindle/speed``, rad/s), the chatter monitor's ratio against the chatter-comb threshold
    (``chatter/energy_ratio``, when recorded) and the share of each 0.1 s in which the
    simulator's truth chatters (``truth/process/chatter``), with each run's chatter alarms and
    speed commands marked."""
    from millsense.monitoring.chatter import METHODS

    fig, ax = plt.subplots(3, 1, figsize=(11, 8.5), sharex=True)
    for key, d in data.items():
        col = _RUN_COLOURS.get(key)
        n = len(d["spindle/speed"])
        t, stride = _time_axis(n, sample_rate_hz)
        rpm = d["spindle/speed"] * 60.0 / (2 * np.pi)
        ax[0].plot(t[::stride], rpm[::stride], color=col, lw=1.0, label=key)
        if "chatter/energy_ratio" in d:
            ax[1].plot(t[::stride], d["chatter/energy_ratio"][::stride], color=col, lw=1.0,
                       label=key)  # fmt: skip
        step = max(1, round(0.1 * sample_rate_hz))
        m = (n // step) * step
        share = (d["truth/process/chatter"][:m] > 0.5).reshape(-1, step).mean(axis=1)
        ax[2].step(t[:m:step], 100 * share, where="post", color=col, lw=1.0, label=key)
        _mark_runs(ax, events.get(key, ()), "chatter", "spindle_override", col)
    ax[1].axhline(METHODS["chatter-comb"].threshold, color="tab:red", lw=1.0, label="threshold")
    _finish(fig, ax, ("spindle speed [rev/min]", "chatter ratio [-]",
                      "truth chatters [% of 0.1 s]"),
            "time [s]  (dashed: chatter alarm; solid: spindle-speed command, in the open run "
            "recommended and not sent)", title, path)  # fmt: skip
