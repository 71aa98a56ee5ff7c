"""The spindle angle from a once-per-revolution index pulse (decision 1737).

Lee recorded his dynamometer with a revolution reference, "the spindle angle or an index
pulse" (seed 004 digest, A3). A pulse channel (a keyphasor, a laser tachometer, an encoder's
zero mark) marks the same angle once a revolution. Sampled at 10 kHz, a revolution of 600
samples puts each mark up to a sample late, which is 0.6° at the fundamental and 14° at the
24th order, where a reset at each mark would carry it. The angle is therefore the
least-squares line of the mark count against the marks' sample positions over the last
:data:`FIT_MARKS` marks: the sample quantisation averages out, and a change of speed is
followed within those revolutions. This is causal, sample by sample, so any chunking gives the
same angle:

- a mark is the first sample of a rising crossing of ``threshold``;
- the angle is NaN until two marks have been seen;
- after that it is 2π × the line's turn count at the sample, and it never runs backwards (a
  new mark's line may start a little behind the old one's).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

#: Marks the angle's line is fitted over (the last ones).
FIT_MARKS = 8
#: State of :func:`index_angle`: [previous sample, samples seen, marks seen, the line's mean
#: position, mean turn, slope (turns a sample), the last angle given], then the ring of the
#: last :data:`FIT_MARKS` marks' sample positions.
IDX_PREV, IDX_SAMPLE, IDX_MARKS, IDX_PBAR, IDX_NBAR, IDX_SLOPE, IDX_LAST = range(7)
IDX_RING = 7
INDEX_STATE = IDX_RING + FIT_MARKS


def index_state() -> NDArray[np.float64]:
    """A fresh state for :func:`index_angle` (no sample seen: the first can be no mark)."""
    state = np.zeros(INDEX_STATE)
    state[IDX_PREV] = math.inf
    state[IDX_LAST] = -math.inf
    return state


@numba.njit(cache=True)
def _fit(state: NDArray[np.float64]) -> None:  # pragma: no cover - compiled
    """The line of the mark count against the positions of the last marks in the ring."""
    marks = int(state[IDX_MARKS])
    m = min(marks, FIT_MARKS)
    pbar = 0.0
    nbar = 0.0
    for i in range(m):
        n = marks - 1 - i
        pbar += state[IDX_RING + n % FIT_MARKS]
        nbar += n
    pbar /= m
    nbar /= m
    sxy = 0.0
    sxx = 0.0
    for i in range(m):
        n = marks - 1 - i
        dp = state[IDX_RING + n % FIT_MARKS] - pbar
        sxy += dp * (n - nbar)
        sxx += dp * dp
    state[IDX_PBAR] = pbar
    state[IDX_NBAR] = nbar
    state[IDX_SLOPE] = sxy / sxx if sxx > 0.0 else 0.0


@numba.njit(cache=True)
def index_angle(
    pulse: NDArray[np.float64], threshold: float, state: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # fmt: skip  # pragma: no cover - compiled
    """The spindle angle (rad, unwrapped) of each sample of ``pulse`` into ``out`` (module
    notes); ``state`` (:func:`index_state`) carries it across chunks."""
    prev = state[IDX_PREV]
    for k in range(pulse.shape[0]):
        x = pulse[k]
        t = state[IDX_SAMPLE]
        if x >= threshold and prev < threshold:
            marks = int(state[IDX_MARKS])
            state[IDX_RING + marks % FIT_MARKS] = t
            state[IDX_MARKS] = marks + 1
            if marks + 1 >= 2:
                _fit(state)
        if x == x:
            prev = x
        state[IDX_SAMPLE] = t + 1.0
        if state[IDX_MARKS] < 2.0 or not state[IDX_SLOPE] > 0.0:
            out[k] = math.nan
            continue
        turns = state[IDX_NBAR] + state[IDX_SLOPE] * (t - state[IDX_PBAR])
        a = max(2.0 * math.pi * turns, state[IDX_LAST])
        state[IDX_LAST] = a
        out[k] = a
    state[IDX_PREV] = prev
