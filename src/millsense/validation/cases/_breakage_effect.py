"""When a tool breakage shows, from the virtual machine's truth (decision 1731).

Issue 15 judges breakage detection from the breakage's *effect* to the event ("breakage effect
to event ≤ 3 tooth periods"; seed 000 V7: "within 3 tooth periods of its effect"). A flute that
breaks while it is out of the cut, or at the end of its arc, changes nothing until it cuts
again, up to a revolution later: no detector can see that time. The effect's onset is taken
where the quantity every seed's detector averages shows it: the tooth period's mean cutting
torque of the run with the break falls :data:`EFFECT_DROP` below that of the same run with the
tool intact (the simulator's ``truth/spindle/torque``, the same program, seed and session, so
the two are identical up to the break).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from millsense.streaming.block import Chunk

#: The shortfall of a tooth period's mean cutting torque, against the intact run's, that marks
#: the breakage's effect: 5 %, small against what a broken flute takes from the tooth periods
#: it cuts (20-100 % on the general cuts' truth) and far above the two runs' difference before
#: the break (exactly 0).
EFFECT_DROP = 0.05


def effect_onset_s(
    broken: np.ndarray, intact: np.ndarray, fs: float, tooth_s: float, break_s: float
) -> float:
    """The first time at or after ``break_s`` where the mean of ``broken`` over the tooth
    period ``tooth_s`` ending there is :data:`EFFECT_DROP` or more below that of ``intact``
    (both the truth's cutting torque at ``fs`` from time 0), s; inf if never."""
    n = min(len(broken), len(intact))
    if n == 0 or tooth_s <= 0.0:
        raise ValueError("effect_onset_s needs two torque records and a positive tooth period")
    width = tooth_s * fs
    k = np.arange(n + 1, dtype=float)

    def tooth_mean(x: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(x[:n])])
        return (c - np.interp(k - width, k, c)) / width  # mean over (k − width, k]

    mb, mi = tooth_mean(broken), tooth_mean(intact)
    start = max(math.ceil(break_s * fs), math.ceil(width))
    short = np.nonzero(mi[start:] - mb[start:] >= EFFECT_DROP * np.abs(mi[start:]))[0]
    return (start + short[0]) / fs if len(short) else math.inf


def latency_periods(alarms_s: Iterable[float], break_s: float, origin_s: float,
                    tooth_s: float) -> float:  # fmt: skip
    """The first of ``alarms_s`` at or after ``break_s``, in tooth periods ``tooth_s`` after
    ``origin_s`` (the effect's onset, or the break instant); inf where there is none or the
    origin is inf; negative for an alarm after the break but before the origin."""
    first = min((t for t in alarms_s if t >= break_s), default=math.inf)
    if math.isinf(first) or math.isinf(origin_s):
        return math.inf
    return (first - origin_s) / tooth_s


class TruthTorque:
    """A session observer (``run_session(observer=...)``) keeping the simulator's cutting
    torque, ``truth/spindle/torque``, chunk by chunk."""

    CHANNEL = "truth/spindle/torque"

    def __init__(self) -> None:
        self._parts: list[np.ndarray] = []
        self.sample_rate_hz = math.nan

    def __call__(self, chunk: Chunk, outputs: object = None, events: object = None) -> None:
        self.sample_rate_hz = chunk.sample_rate_hz
        self._parts.append(np.array(chunk.data[self.CHANNEL], dtype=float))

    @property
    def torque(self) -> np.ndarray:
        return np.concatenate(self._parts) if self._parts else np.zeros(0)
