"""Compiled forward kinematics, Jacobian and load matrix of the A/C trunnion table (Aslan
Eq. 3.38, 3.39/3.47, 3.49), for :mod:`millsense.models.kinematics`.

The on-line stack evaluates the tool-centre point of every sample (100 poses per 10 ms chunk)
and the load matrix ``Jᵀ·T`` of ten poses per chunk (the forces at the tool, Aslan Eq. 3.51):
on so few poses the numpy form's dozens of small-array calls (trigonometry, ``_matrix3``,
``einsum``, ``@ R0``) cost far more than the arithmetic. These loops perform the numpy form's
floating-point operations (the trigonometry is libm's, as numpy's on the hosts measured), the
rotation's zero entries multiplied in as numpy multiplies them, and each sum in the order
numpy's ``einsum`` adds its three products: ``(p0 + p2) + p1`` for the rotation times a vector
(its two-accumulator loop over a contiguous operand), ``(p0 + p1) + p2`` for ``Jᵀ·T`` (a
strided operand). The results equal the numpy form's bit for bit up to the sign of an exact
zero (the fixed permutation ``R0`` applied by negation instead of a product with ±1 and 0),
checked on 200 000 random poses; a numpy whose ``einsum`` summed otherwise would differ by
rounding (≤ 1 ulp of the largest product).

``machine`` selects the drives' frames (:class:`~millsense.models.kinematics.
TrunnionACMachine`: ``q`` is [X, Y, Z, A, C], mapped to Aslan's axes first, decision 0078)
or Aslan's (:class:`~millsense.models.kinematics.TrunnionACKinematics`, decision 0030).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

_HALF_PI = 0.5 * np.pi


@numba.njit(cache=True, inline="always")
def _aslan_axes(
    q: NDArray[np.float64], k: int, machine: bool, a2: float, d4: float
) -> tuple[float, float, float, float, float]:  # pragma: no cover - compiled
    """Aslan's ``[x, y, z − a2, θ_A, θ_C]`` of pose ``q[k]`` (``rel`` of Eq. 3.38): for the
    machine ``to_aslan`` (x = −X, y = −Z − d4, z = −Y + a2, θ_A = A − π/2) first."""
    if machine:
        x = -q[k, 0]
        y = -q[k, 2] - d4
        z = -q[k, 1] + a2
        ta = q[k, 3] - _HALF_PI
    else:
        x = q[k, 0]
        y = q[k, 1]
        z = q[k, 2]
        ta = q[k, 3]
    return x, y, z - a2, ta, q[k, 4]


@numba.njit(cache=True, inline="always")
def _cos_sin(
    angle: float, last: float, last_cos_sin: tuple[float, float]
) -> tuple[float, float]:  # pragma: no cover - compiled
    """(cos, sin) of ``angle``: ``last_cos_sin`` (those of ``last``) when ``angle`` is the same
    number (sign of zero included; a NaN is never), else evaluated. A rotary axis holds its
    angle over most samples, so the loops evaluate the trigonometry once per change."""
    if angle == last and math.copysign(1.0, angle) == math.copysign(1.0, last):
        return last_cos_sin
    return math.cos(angle), math.sin(angle)


@numba.njit(cache=True)
def trunnion_forward(
    q: NDArray[np.float64], machine: bool, a2: float, d4: float, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """Tool tips ``P = R·(p − a2·e_z) − d4·e_z`` (Aslan Eq. 3.38) of the poses ``q`` (N, 5)
    into ``out`` (N, 3) (any layout: the transpose of a (3, N) array gives rows of
    coordinates)."""
    last_a = last_c = math.nan
    ca = sa = cc = sc = math.nan
    for k in range(q.shape[0]):
        x, y, z, ta, tc = _aslan_axes(q, k, machine, a2, d4)
        ca, sa = _cos_sin(ta, last_a, (ca, sa))
        cc, sc = _cos_sin(tc, last_c, (cc, sc))
        last_a, last_c = ta, tc
        out[k, 0] = (-cc * x + sa * sc * z) + -ca * sc * y
        out[k, 1] = (sc * x + sa * cc * z) + -ca * cc * y
        out[k, 2] = ((0.0 * x + ca * z) + sa * y) - d4


@numba.njit(cache=True)
def trunnion_jacobian(
    q: NDArray[np.float64], machine: bool, a2: float, d4: float, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """Position Jacobians ``∂P/∂q`` (Aslan Eq. 3.39/3.47) of the poses ``q`` (N, 5) into
    ``out`` (N, 3, 5): columns 1–3 ``R`` (for the machine ``R·R0``: −R's first, third and
    second column), column 4 ``(∂R/∂θ_A)·rel``, column 5 ``(∂R/∂θ_C)·rel``."""
    last_a = last_c = math.nan
    ca = sa = cc = sc = math.nan
    for k in range(q.shape[0]):
        x, y, z, ta, tc = _aslan_axes(q, k, machine, a2, d4)
        ca, sa = _cos_sin(ta, last_a, (ca, sa))
        cc, sc = _cos_sin(tc, last_c, (cc, sc))
        last_a, last_c = ta, tc
        ca_sc, ca_cc, sa_sc, sa_cc = ca * sc, ca * cc, sa * sc, sa * cc
        j = out[k]
        if machine:
            j[0, 0], j[0, 1], j[0, 2] = cc, -sa_sc, ca_sc
            j[1, 0], j[1, 1], j[1, 2] = -sc, -sa_cc, ca_cc
            j[2, 0], j[2, 1], j[2, 2] = -0.0, -ca, -sa
        else:
            j[0, 0], j[0, 1], j[0, 2] = -cc, -ca_sc, sa_sc
            j[1, 0], j[1, 1], j[1, 2] = sc, -ca_cc, sa_cc
            j[2, 0], j[2, 1], j[2, 2] = 0.0, sa, ca
        j[0, 3] = (0.0 * x + ca_sc * z) + sa_sc * y
        j[1, 3] = (0.0 * x + ca_cc * z) + sa_cc * y
        j[2, 3] = (0.0 * x + -sa * z) + ca * y
        j[0, 4] = (sc * x + sa_cc * z) + -ca_cc * y
        j[1, 4] = (cc * x + -sa_sc * z) + ca_sc * y
        j[2, 4] = (0.0 * x + 0.0 * z) + 0.0 * y


@numba.njit(cache=True)
def trunnion_load_matrix(
    q: NDArray[np.float64], machine: bool, a2: float, d4: float, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """``Jᵀ·T`` (Aslan Eq. 3.49) of the poses ``q`` (N, 5) into ``out`` (N, 5, 3), with
    ``T`` the Jacobian's first three columns: ``out[i, c] = Σ_r J[r, i]·J[r, c]``."""
    j = np.empty((q.shape[0], 3, 5))
    trunnion_jacobian(q, machine, a2, d4, j)
    for k in range(q.shape[0]):
        jk = j[k]
        for i in range(5):
            for c in range(3):
                out[k, i, c] = jk[0, i] * jk[0, c] + jk[1, i] * jk[1, c] + jk[2, i] * jk[2, c]
