"""One pass over a run's recording for its report: display envelopes and the run's figures.

A run of an hour at 10 kHz is 36 million samples per channel; the report reads each channel it
shows once, in blocks of :data:`READ_BLOCK` samples, and keeps per channel only the min/max
envelope of :class:`~millsense.report.estimate_stream.Envelope` (every bin drawn from its
minimum to its maximum: no peak is dropped at any zoom-out), the sample at each bin's start
(for the tool path) and the accumulators of :class:`RunFigures` (the numbers the demo's summary
prints: peak force, mean power in cut, time cut with a broken tool, from the same code).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from millsense.io.recording_reader import channel_window
from millsense.report.estimate_stream import Envelope
from millsense.streaming.block import Event

#: Samples read at once per channel (2 MiB of float64).
READ_BLOCK = 1 << 18
#: Envelope bins of every whole-record trace (two points each, minimum and maximum).
DISPLAY_BINS = 5000
#: Resultant force above which the tool counts as cutting for the figures, N (the demo's).
CUTTING_FORCE_N = 50.0
#: Derived channels (computed per block from recorded ones).
FXY_TRUE = "truth/tool/force_xy"
POWER = "plan/cutting_power"


@dataclass
class RunFigures:
    """What one run did: the figures of the demo's summary, from a recording and its events.

    Attributes
    ----------
    seconds : signal recorded, s.
    program_end_s : when the program ended (None: stopped by a feed hold).
    peak_force_n : largest true resultant force |F_xy|, N (0 without truth).
    peak_force_intact_n : the same while the true tool is intact (``truth/process/broken``
        off; all of the run without that channel), N: what the controller did, apart from
        what a broken tooth does before the feed hold.
    mean_power_w : mean spindle cutting power (the compensated torque less its air reference
        × speed) while the true |F_xy| exceeds :data:`CUTTING_FORCE_N`, W.
    breakage_alarm_s, feed_hold_s : first breakage alarm and feed hold, s, or None.
    cut_with_broken_tool_s : time cut with a broken tooth (truth), s.
    events : count of events per name.
    """

    seconds: float
    program_end_s: float | None
    peak_force_n: float
    peak_force_intact_n: float
    mean_power_w: float
    breakage_alarm_s: float | None
    feed_hold_s: float | None
    cut_with_broken_tool_s: float
    events: dict[str, int]


@dataclass
class RunScan:
    """The envelopes, bin-start samples and figures of one pass (see :func:`scan_run`)."""

    n: int
    fs: float
    envelopes: dict[str, Envelope]
    starts: dict[str, NDArray[np.float64]]
    figures: RunFigures
    width: int = 1
    present: set[str] = field(default_factory=set)
    truth: bool = True
    """The recording has the true tool forces (a simulation): the figures of them hold."""
    power: bool = True
    """The recording has the plan's cutting torque and the spindle speed (a session)."""


def scan_run(
    rec: Any,
    events: Sequence[Event],
    channels: Sequence[str],
    *,
    bins: int = DISPLAY_BINS,
    block: int = READ_BLOCK,
) -> RunScan:
    """Read ``channels`` of ``rec`` (those present) once, block by block: their min/max
    envelopes in ``bins`` bins, each bin's first sample, and the :class:`RunFigures`.

    The derived channels :data:`FXY_TRUE` (``hypot(truth/tool/force_x, force_y)``) and
    :data:`POWER` (``plan/cutting_torque × spindle/speed``) may be asked for like recorded ones.
    """
    names = set(rec.channel_names)
    n, fs = int(rec.n_samples), float(rec.sample_rate_hz)
    fx, fy = "truth/tool/force_x", "truth/tool/force_y"
    derived = {FXY_TRUE: (fx, fy), POWER: ("plan/cutting_torque", "spindle/speed")}
    want = [c for c in channels if c in names or (c in derived and set(derived[c]) <= names)]
    figs = [FXY_TRUE, POWER, "truth/process/broken"]
    reads = sorted(
        {c for c in want if c in names}
        | {s for c in (*want, *figs) if c in derived and set(derived[c]) <= names
           for s in derived[c]}
        | ({"truth/process/broken"} & names)
    )  # fmt: skip
    envs = {c: Envelope(n, bins) for c in want}
    width = next(iter(envs.values())).width if envs else max(1, -(-n // bins))
    nb = max(1, -(-n // width))
    starts = {c: np.full(nb, np.nan) for c in want}
    peak, intact, p_sum, p_cnt, broken_cnt = 0.0, 0.0, 0.0, 0, 0
    have_fxy = {fx, fy} <= names
    for a in range(0, n, block):
        b = min(n, a + block)
        data = {c: np.asarray(channel_window(rec, c, a, b), dtype=np.float64) for c in reads}
        if have_fxy:
            data[FXY_TRUE] = np.hypot(data[fx], data[fy])
        if {"plan/cutting_torque", "spindle/speed"} <= names:
            data[POWER] = data["plan/cutting_torque"] * data["spindle/speed"]
        for c in want:
            v = data[c]
            envs[c].add(a, v)
            first = -(-a // width) * width  # first bin start at or after a
            idx = np.arange(first, b, width)
            starts[c][idx // width] = v[idx - a]
        if have_fxy:
            f = data[FXY_TRUE]
            peak = max(peak, float(f.max(initial=0.0)))
            ok = f if "truth/process/broken" not in data else f[data["truth/process/broken"] < 0.5]
            intact = max(intact, float(ok.max(initial=0.0)))
            cutting = f > CUTTING_FORCE_N
            if POWER in data:
                p_sum += float(np.sum(data[POWER][cutting]))
                p_cnt += int(np.count_nonzero(cutting))
            if "truth/process/broken" in data:
                broken_cnt += int(np.count_nonzero((data["truth/process/broken"] > 0.5) & cutting))
    figures = run_figures_from(events, n / fs, peak, p_sum / p_cnt if p_cnt else 0.0,
                               broken_cnt / fs, intact)  # fmt: skip
    power = {"plan/cutting_torque", "spindle/speed"} <= names
    return RunScan(n, fs, envs, starts, figures, width, set(want), have_fxy, power)


def run_figures_from(
    events: Sequence[Event],
    seconds: float,
    peak_force_n: float,
    mean_power_w: float,
    cut_with_broken_tool_s: float,
    peak_force_intact_n: float | None = None,
) -> RunFigures:
    """The :class:`RunFigures` of a run from its events and the recorded figures
    (``peak_force_intact_n`` None: the run's peak)."""
    brk = next((e.time_s for e in events if e.name == "breakage"), None)
    hold = next((e.time_s for e in events if e.name == "feed_hold"), None)
    return RunFigures(
        seconds=seconds,
        program_end_s=None if hold is not None else seconds,
        peak_force_n=peak_force_n,
        peak_force_intact_n=peak_force_n if peak_force_intact_n is None else peak_force_intact_n,
        mean_power_w=mean_power_w,
        breakage_alarm_s=brk,
        feed_hold_s=hold,
        cut_with_broken_tool_s=cut_with_broken_tool_s,
        events=dict(Counter(e.name for e in events)),
    )


def run_figures(rec: Any, events: Sequence[Event]) -> RunFigures:
    """The :class:`RunFigures` of a recording (``rec`` open) and its events."""
    return scan_run(rec, events, ()).figures
