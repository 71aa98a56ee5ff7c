"""Compiled per-chunk check of the pipeline (:class:`~millsense.streaming.engine.Pipeline`).

Imported when a pipeline is built, not with :mod:`millsense.streaming`: reading an event log or
a recording does not load numba.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def all_finite_kernel(channels: tuple[np.ndarray, ...]) -> bool:  # pragma: no cover - compiled
    """True when no sample of ``channels`` (a tuple of 1-D arrays of one type) is NaN or ±inf.

    One pass over all of them in a single call (at 10 ms chunks a numpy reduction per channel,
    or one over their concatenation, costs more in call overhead and copying than the
    comparisons); ``|x| < inf`` is false exactly for NaN and ±inf, with no overflow to clear."""
    for values in channels:
        bad = False
        for k in range(values.shape[0]):
            bad |= not (abs(values[k]) < np.inf)  # no early exit: the loop vectorises
        if bad:
            return False
    return True


def all_finite(channels: tuple[np.ndarray, ...]) -> bool | None:
    """:func:`all_finite_kernel` of ``channels``; None where it cannot take them (channels of
    several dtypes or layouts, 2-D or object arrays: the caller checks them otherwise)."""
    try:
        return bool(all_finite_kernel(channels))
    except Exception:  # numba's typing errors, and its assertion on an object array
        return None
