"""Compiled per-chunk steps of :class:`~millsense.estimation.feed.condition.
OperatingConditionFeedEstimator` (decisions 0106 and 0129).

At 10 ms chunks the block's cost was the Python/numpy call overhead of chains of small array
operations (diff, cumsum, concatenate on 100 samples); each chain here is one compiled call that
performs the same floating-point operations in the same order, so the outputs are unchanged
bit for bit (numpy's cumulative sum is sequential too).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.estimation.feed.commanded import difference_into


@numba.njit(cache=True)
def rest_weight_kernel(
    pos: NDArray[np.float64],
    state: NDArray[np.float64],
    drive: NDArray[np.float64],
    hist: NDArray[np.float64],
    width: int,
    out: NDArray[np.float64],
) -> bool:  # pragma: no cover - compiled
    """At-rest weight of one chunk's output samples (states updated in place); False, with
    nothing changed, if a command is not finite.

    ``state`` = [previous command, started]; ``drive`` = [f_s, r_g, rest speed]: the commanded
    motor speed is ``Δx_cmd·f_s/r_g`` (:func:`~millsense.estimation.feed.commanded.
    difference_into`, the first sample of a stream reading 0) and a sample is at rest
    when it is within ±rest speed. ``hist`` holds the last L + h rest flags (before the stream,
    the first command's condition); output j is the mean of the ``width`` = 2h + 1 flags from
    flag j of ``hist ++ this chunk's flags``: the centred window at the estimated sample j − L.
    The window sums are counts of ones, exact in any order.
    """
    n = pos.shape[0]
    for k in range(n):
        if not math.isfinite(pos[k]):
            return False
    fs, rg, rest_speed = drive[0], drive[1], drive[2]
    m = hist.shape[0]
    flags = np.empty(m + n)
    speed = np.empty(n)
    difference_into(pos, pos[0] if state[1] == 0.0 else state[0], fs, speed)
    for k in range(n):
        flags[m + k] = 1.0 if abs(speed[k] / rg) <= rest_speed else 0.0
    if state[1] == 0.0:
        flags[:m] = flags[m]
        state[1] = 1.0
    else:
        flags[:m] = hist
    state[0] = pos[n - 1]
    count = 0.0
    for k in range(width - 1):
        count += flags[k]
    for j in range(n):
        count += flags[j + width - 1]
        out[j] = count / width
        count -= flags[j]
    hist[:] = flags[n:]
    return True


@numba.njit(cache=True)
def highpass_blend(
    moving: NDArray[np.float64],
    at_rest: NDArray[np.float64],
    weight: NDArray[np.float64],
    recent: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``out = moving + w·(d − mean_N d)``, ``d = at_rest − moving`` (decision 0129), with the
    mean over the last N = len(recent) samples of d; ``recent`` (d's last N samples, carried
    across chunks) is updated in place. The mean is the difference of a running sum started at
    0 over ``recent ++ d``, as the numpy form ``cumsum`` it replaces."""
    n_win = recent.shape[0]
    n = moving.shape[0]
    x = np.empty(n_win + n)
    x[:n_win] = recent
    for k in range(n):
        x[n_win + k] = at_rest[k] - moving[k]
    csum = np.empty(n_win + n + 1)
    csum[0] = 0.0
    acc = 0.0
    for k in range(n_win + n):
        acc += x[k]
        csum[k + 1] = acc
    for j in range(n):
        mean = (csum[n_win + j + 1] - csum[j + 1]) / n_win
        out[j] = moving[j] + weight[j] * (x[n_win + j] - mean)
    recent[:] = x[n:]
