"""Compiled linear algebra of :class:`~millsense.estimation.feed.estimator.ToolForceBlock`
(Aslan Eq. 3.51, ``F = −[Jᵀ·T]⁺·τ``, decision "Forces at the tool in estimate").

At 10 ms chunks the block evaluates ten poses: numpy's per-call overhead on 3×5 matrices
(a batched solve, fancy indexing) cost more than the arithmetic. The kinematics stay in
:mod:`millsense.models.kinematics` (the load matrix ``Jᵀ·T``); these kernels do the rest in
one call each. The 3×3 solves are LAPACK's, as numpy's; the forces agree with the numpy form
to rounding (decision 1651). The delay line of the poses and the hold of the pseudo-inverses
are loops performing the numpy form's operations, bit for bit (decision 1655);
:func:`tool_force_kernel` runs the whole chunk, kinematics included, in one call (the
trigonometry of the rotary angles once per change of an angle).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.models._kinematics_kernels import trunnion_load_matrix


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


@numba.njit(cache=True)
def tool_force_kernel(
    angles: NDArray[np.float64],
    loads: NDArray[np.float64],
    rg: NDArray[np.float64],
    offsets: NDArray[np.float64],
    hist: NDArray[np.float64],
    state: NDArray[np.float64],
    first: int,
    every: int,
    machine: bool,
    a2: float,
    d4: float,
    held_pinv: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """One chunk of :class:`~millsense.estimation.feed.estimator.ToolForceBlock` in one call:
    the delayed poses (:func:`delayed_poses`), their load matrices ``Jᵀ·T`` (the compiled
    trunnion kinematics, :func:`~millsense.models._kinematics_kernels.trunnion_load_matrix`),
    the pseudo-inverses (:func:`pseudo_inverses`) and the forces (:func:`apply_held_poses`)
    — the block's former sequence of calls, operation for operation. ``state`` = [started,
    held]: with held = 1, ``held_pinv`` (3, 5) is the pseudo-inverse held from the previous
    chunk; both updated in place."""
    n = angles.shape[1]
    n_poses = len(range(first, n, every))
    poses = np.empty((n_poses, 5))
    q0 = np.empty(5)
    delayed_poses(angles, rg, offsets, hist, state[0:1], first, every, poses, q0)
    held = state[1] != 0.0
    if n_poses == 0 and not held:
        poses = q0.reshape((1, 5))
    load = np.empty((poses.shape[0], 5, 3))
    trunnion_load_matrix(poses, machine, a2, d4, load)
    off = 1 if held else 0
    stack = np.empty((off + poses.shape[0], 3, 5))
    if held:
        stack[0] = held_pinv
    pseudo_inverses(load, stack[off:])
    apply_held_poses(stack, first, every, held, loads, out)
    held_pinv[:] = stack[-1]
    state[1] = 1.0
