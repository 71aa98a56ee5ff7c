"""Compiled first-order recursions for streaming blocks (no per-sample Python loop, and no
scipy.signal import — ≈ 0.8 s — in a process that only needs this)."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["exponential_average", "exponential_average_kernel"]


@numba.njit(cache=True)
def exponential_average_kernel(
    x: NDArray[np.float64], alpha: float, y0: float
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`exponential_average` for compiled callers (a contiguous float64 ``x``)."""
    y = np.empty_like(x)
    prev = y0
    keep = 1.0 - alpha
    for i in range(x.size):
        prev = alpha * x[i] + keep * prev
        y[i] = prev
    return y


def exponential_average(x: NDArray[np.float64], alpha: float, y0: float) -> NDArray[np.float64]:
    """``y[k] = α·x[k] + (1 − α)·y[k−1]`` from ``y[−1] = y0`` (the first-order average
    ``lfilter([α], [1, α − 1], x, zi=[(1 − α)·y0])``)."""
    return exponential_average_kernel(np.ascontiguousarray(x, dtype=np.float64), float(alpha),
                                      float(y0))  # fmt: skip
