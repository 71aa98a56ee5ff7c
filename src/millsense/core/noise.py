"""Robust noise scale from the differences of a signal's successive values.

A monitor or controller that must know how much of what it sees is noise estimates it from
|d| = |x(k) − x(k−lag)| at a lag where the process itself does not change (the same flute one
revolution apart, two control intervals at one override): for zero-mean normal noise the median
of |d| is 0.6745 σ_d, and σ_d = √2 σ for the difference of two independent values. The median
ignores the few differences a real change (a breakage, a step) makes (decisions 1548, 1550).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

#: Median |difference| of two independent values per σ of one: 0.6745 √2.
MEDIAN_ABS_DIFF_PER_SIGMA = 0.6744897501960817 * math.sqrt(2.0)
#: Its reciprocal, for compiled kernels that multiply.
SIGMA_PER_MEDIAN_ABS_DIFF = 1.0 / MEDIAN_ABS_DIFF_PER_SIGMA


def sigma_from_abs_differences(abs_diffs: Iterable[float]) -> float:
    """σ of one value from |differences| of pairs of independent values (the module notes)."""
    return window_median(abs_diffs) / MEDIAN_ABS_DIFF_PER_SIGMA


def window_median(values: Iterable[float]) -> float:
    """The median of a short window of numbers as ``np.median`` gives it (the middle value, or
    the mean of the two middle values), from the sorted numbers: ≈ 4 µs for the 32 values the
    adaptive feed keeps once a revolution, where ``np.median`` takes ≈ 20 µs. With a NaN or both
    infinities, none, or a zero in the middle (the sign of a zero is that of numpy's sum, which
    starts from +0), ``np.median`` itself."""
    v = sorted(map(float, values))
    n = len(v)
    if n and not math.isnan(sum(v)):
        h = n // 2
        lo, hi = v[h - 1 + n % 2], v[h]  # the same value for an odd count
        if lo != 0.0 and hi != 0.0:
            return hi if n % 2 else (lo + hi) / 2
    return float(np.median(np.asarray(v, dtype=np.float64)))
