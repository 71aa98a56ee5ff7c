"""Compiled linear algebra of :class:`~millsense.estimation.feed.estimator.ToolForceBlock`
(Aslan Eq. 3.51, ``F = −[Jᵀ·T]⁺·τ``, decision "Forces at the tool in estimate").

At 10 ms chunks the block evaluates ten poses: numpy's per-call overhead on 3×5 matrices
(a batched solve, fancy indexing) cost more than the arithmetic. The kinematics stay in
:mod:`millsense.models.kinematics` (the load matrix ``Jᵀ·T``); these kernels do the rest in
one call each. The 3×3 solves are LAPACK's, as numpy's; the forces agree with the numpy form
to rounding (decision 1651). The delay line of the poses and the hold of the pseudo-inverses
are loops performing the numpy form's operations, bit for bit (decision 1655).
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
def delayed_poses(
    angles: NDArray[np.float64],
    rg: NDArray[np.float64],
    offsets: NDArray[np.float64],
    hist: NDArray[np.float64],
    state: NDArray[np.float64],
    first: int,
    every: int,
    poses: NDArray[np.float64],
    q0: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The poses ``q = r_g·θ + offset`` (5 axes) delayed by the lag L = len(hist): ``poses``
    (P, 5) at the chunk's samples ``first``, ``first + every``, … and ``q0`` at its first
    sample. ``hist`` (L, 5) holds the last L poses (before the stream: the first one, when
    ``state[0]`` is 0), updated in place; ``angles`` (5, n)."""
    n = angles.shape[1]
    lag = hist.shape[0]
    allq = np.empty((lag + n, 5))
    for k in range(n):
        for a in range(5):
            allq[lag + k, a] = angles[a, k] * rg[a] + offsets[a]
    if state[0] == 0.0:
        for i in range(lag):
            allq[i] = allq[lag]
        state[0] = 1.0
    else:
        allq[:lag] = hist
    for j in range(poses.shape[0]):
        poses[j] = allq[first + j * every]
    q0[:] = allq[0]
    hist[:] = allq[n:]


@numba.njit(cache=True)
def apply_held_poses(
    stack: NDArray[np.float64],
    first: int,
    every: int,
    held: bool,
    loads: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``out[:, k] = stack[s(k)]·(−loads[:, k])`` (``loads`` (5, n), the axis loads resisting
    motion): sample k takes the newest pose at or before it — with a held pose (``stack[0]``)
    entry ``(k − first + every) // every``, else the chunk's first pose up to there."""
    for k in range(loads.shape[1]):
        s = (k - first + every) // every
        if not held:
            s = max(s - 1, 0)
        for i in range(3):
            acc = 0.0
            for j in range(5):
                acc += stack[s, i, j] * -loads[j, k]
            out[i, k] = acc
