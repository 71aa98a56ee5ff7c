"""Compiled linear algebra of :class:`~millsense.estimation.feed.estimator.ToolForceBlock`
(Aslan Eq. 3.51, ``F = −[Jᵀ·T]⁺·τ``, decision "Forces at the tool in estimate").

At 10 ms chunks the block evaluates ten poses: numpy's per-call overhead on 3×5 matrices
(a batched solve, fancy indexing) cost more than the arithmetic. The kinematics stay in
:mod:`millsense.models.kinematics` (the load matrix ``Jᵀ·T``); these kernels do the rest in
one call each. The 3×3 solves are LAPACK's, as numpy's; the forces agree with the numpy form
to rounding (decision 1651).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray


@numba.njit(cache=True)
def pseudo_inverses(load: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``M⁺ = (MᵀM)⁻¹Mᵀ`` of each load matrix ``M = Jᵀ·T`` of ``load`` (P, 5, 3), into ``out``
    (P, 3, 5) — the normal equations, M having full column rank away from singular poses."""
    a = np.empty((3, 3))
    mt = np.empty((3, 5))
    for p in range(load.shape[0]):
        for r in range(3):
            for i in range(5):
                mt[r, i] = load[p, i, r]
            for c in range(3):
                acc = 0.0
                for i in range(5):
                    acc += load[p, i, r] * load[p, i, c]
                a[r, c] = acc
        out[p] = np.linalg.solve(a, mt)


@numba.njit(cache=True)
def apply_held(
    stack: NDArray[np.float64],
    which: NDArray[np.int64],
    loads: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """``out[:, k] = stack[which[k]]·loads[k]``: each sample's loads (n, 5) through the
    pseudo-inverse of its pose (``stack`` (S, 3, 5)), into ``out`` (3, n)."""
    for k in range(loads.shape[0]):
        s = which[k]
        for i in range(3):
            acc = 0.0
            for j in range(5):
                acc += stack[s, i, j] * loads[k, j]
            out[i, k] = acc
