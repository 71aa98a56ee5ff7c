"""Robust noise scale from the differences of a signal's successive values.

A monitor or controller that must know how much of what it sees is noise estimates it from
|d| = |x(k) − x(k−lag)| at a lag where the process itself does not change (the same flute one
revolution apart, two control intervals at one override): for zero-mean normal noise the median
of |d| is 0.6745 σ_d, and σ_d = √2 σ for the difference of two independent values. The median
ignores the few differences a real change (a breakage, a step) makes (decisions 1548, 1550).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

#: Median |difference| of two independent values per σ of one: 0.6745 √2.
MEDIAN_ABS_DIFF_PER_SIGMA = 0.6744897501960817 * math.sqrt(2.0)
#: Its reciprocal, for compiled kernels that multiply.
SIGMA_PER_MEDIAN_ABS_DIFF = 1.0 / MEDIAN_ABS_DIFF_PER_SIGMA


def sigma_from_abs_differences(abs_diffs: ArrayLike) -> float:
    """σ of one value from |differences| of pairs of independent values (the module notes)."""
    return float(np.median(np.asarray(abs_diffs, dtype=np.float64))) / MEDIAN_ABS_DIFF_PER_SIGMA
