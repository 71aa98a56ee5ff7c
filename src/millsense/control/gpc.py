"""Generalized predictive control of the cutting force (Clarke et al.; Munasinghe Eq.
3.32–3.42; Aslan Eq. 6.8–6.14 and App. G).

Plant (CARIMA, one control interval = one spindle revolution)::

    A(z⁻¹)·F(t) = B(z⁻¹)·u(t−1) + ξ(t)/Δ,     Δ = 1 − z⁻¹

with A = 1 + a₁z⁻¹ + … (monic), B = b₀ + b₁z⁻¹ + …, F the peak force and u the feed (both
normalised by the controller). The j-step predictor uses the Diophantine identity

    1 = E_j(z⁻¹)·A(z⁻¹)·Δ + z⁻ʲ·F_j(z⁻¹),   deg E_j = j − 1, deg F_j = deg A     (6.9–6.10)

    F̂(t+j) = G_j·Δu(t+j−1) + F_j·F(t),      G_j = E_j·B                           (6.11)

:func:`diophantine` solves it by the recursion of Aslan App. G (with the digest's correction:
"f30 = f21 − e2·(a1 − 1)", a product, not a difference), written for any order;
:func:`diophantine_direct` solves it independently by long division of 1/(AΔ), and the tests
check one against the other and against App. G's printed coefficients.

The control law minimises J = Σ_{j=N1}^{N2} (F̂(t+j) − F_r)² + λ·Σ_{j=1}^{Nu} Δu(t+j−1)²
(Eq. 6.13 / 3.40) and applies the first move (receding horizon, Eq. 6.14 / 3.41)::

    Δu = (GᵀG + λI)⁻¹ Gᵀ (F_r − f)

with G the N2 × Nu lower-triangular Toeplitz matrix of the step response of z⁻¹B/A and f the
free response. Seed 000: N1 = 1, N2 = 4, Nu = 1, λ = 0.25 (seed 002 gives no λ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Prediction:
    """The j-step predictors of a CARIMA model, j = 1..N2.

    Attributes
    ----------
    e : (N2, N2) E_j coefficients (row j−1, first j entries used).
    f : (N2, na+1) F_j coefficients (of F(t), F(t−1), …).
    g : (N2, N2+nb) G_j = E_j·B coefficients (of Δu(t+j−1), Δu(t+j−2), …).
    """

    e: FloatArray
    f: FloatArray
    g: FloatArray

    @property
    def step_response(self) -> FloatArray:
        """g₀, g₁, …: the step response of z⁻¹B/A (coefficient of Δu(t) in F̂(t+j) is
        ``step_response[j−1]``)."""
        n2 = self.e.shape[0]
        return np.array([self.g[j, j] for j in range(n2)])


def _delta_a(a: FloatArray) -> FloatArray:
    """Coefficients of A·Δ (A monic, given without its leading 1)."""
    full = np.concatenate(([1.0], a))
    return np.convolve(full, [1.0, -1.0])


def diophantine(a: ArrayLike, b: ArrayLike, n2: int) -> Prediction:
    """E_j, F_j and G_j = E_j·B for j = 1..n2 by the recursion of Aslan App. G.

    ``a`` = [a₁, a₂, …] (A = 1 + a₁z⁻¹ + …), ``b`` = [b₀, b₁, …]. With à = AΔ =
    1 + ã₁z⁻¹ + … + ã_{na+1}z^{−na−1}: E₁ = 1, F₁ = z(1 − Ã); then e_j = f_{j,0},
    f_{j+1,i} = f_{j,i+1} − e_j·ã_{i+1} (f_{j,na+1} = 0) — App. G's
    f_{j+1,0} = f_{j,1} − e_j·ã₁, f_{j+1,1} = f_{j,2} − e_j·ã₂, f_{j+1,2} = −e_j·ã₃ = e_j·a₂
    for the second-order plant (compiled: :func:`_diophantine_into`).
    """
    at, bv = _model(a, b, n2)
    e, f, g = _prediction_arrays(at, bv, n2)
    _diophantine_into(at, bv, e, f, g)
    return Prediction(e, f, g)


def _model(a: ArrayLike, b: ArrayLike, n2: int) -> tuple[FloatArray, FloatArray]:
    """AΔ and B as contiguous float arrays, checked."""
    av = np.asarray(a, dtype=float).ravel()
    bv = np.ascontiguousarray(b, dtype=float).ravel()
    if n2 < 1:
        raise ConfigError(f"GPC: N2 must be ≥ 1, got {n2}")
    if bv.size == 0:
        raise ConfigError("GPC: B needs at least one coefficient")
    return _delta_a(av), bv


def _prediction_arrays(
    at: FloatArray, bv: FloatArray, n2: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Zeroed E (N2, N2), F (N2, na+1) and G (N2, N2+nb−1) for :func:`_diophantine_into`."""
    return np.zeros((n2, n2)), np.zeros((n2, at.size - 1)), np.zeros((n2, n2 + bv.size - 1))


@numba.njit(cache=True)
def _diophantine_into(
    at: FloatArray, b: FloatArray, e: FloatArray, f: FloatArray, g: FloatArray
) -> None:  # pragma: no cover - compiled
    """The recursion of :func:`diophantine` into the zeroed ``e``, ``f``, ``g`` (``at`` = AΔ
    with its leading 1); G_j = E_j·B is the convolution of E_j's first j coefficients with B.
    One compiled call: the adaptive feed decides once per revolution, and numpy's per-call
    overhead on these few coefficients was most of its decision time."""
    n2 = e.shape[0]
    na1 = at.shape[0] - 1  # deg(AΔ) = na + 1; F_j has na + 1 coefficients
    ej = np.zeros(n2)
    ej[0] = 1.0  # E_1 = 1
    fj = -at[1:]  # F_1 = z(1 − Ã)
    fn = np.empty(na1)
    for j in range(n2):
        e[j] = ej
        f[j] = fj
        if j + 1 < n2:
            lead = fj[0]  # e_{j+1}: the next coefficient of E
            ej[j + 1] = lead
            for i in range(na1):
                nxt = fj[i + 1] if i + 1 < na1 else 0.0
                fn[i] = nxt - lead * at[i + 1]
            fj, fn = fn, fj
    for j in range(n2):
        for p in range(j + 1):
            for q in range(b.shape[0]):
                g[j, p + q] += e[j, p] * b[q]


def diophantine_direct(a: ArrayLike, j: int) -> tuple[FloatArray, FloatArray]:
    """E_j and F_j of 1 = E_j·A·Δ + z⁻ʲF_j by long division (independent of the recursion):
    E_j is the first j terms of the power series of 1/(AΔ); F_j = zʲ(1 − E_j·A·Δ)."""
    at = _delta_a(np.asarray(a, dtype=float).ravel())
    series = np.zeros(j)
    rem = np.zeros(j + at.size)
    rem[0] = 1.0
    for k in range(j):  # synthetic division by the monic Ã
        series[k] = rem[k]
        rem[k : k + at.size] -= series[k] * at
    resid = np.r_[1.0, np.zeros(j + at.size - 2)] - np.convolve(series, at)
    return series, resid[j : j + at.size - 1]


@dataclass
class GPC:
    """Receding-horizon GPC of an identified CARIMA model (N1 = 1).

    Parameters
    ----------
    n2 : output horizon N2 (seed 000 and 002: 4).
    nu : control horizon Nu (1).
    lam : move weight λ (seed 000: 0.25).
    """

    n2: int = 4
    nu: int = 1
    lam: float = 0.25

    def __post_init__(self) -> None:
        if not (1 <= self.nu <= self.n2):
            raise ConfigError(f"GPC: need 1 ≤ Nu ≤ N2, got Nu={self.nu}, N2={self.n2}")
        if not self.lam >= 0:
            raise ConfigError(f"GPC: λ must be ≥ 0, got {self.lam!r}")

    def move(
        self,
        a: ArrayLike,
        b: ArrayLike,
        y_past: ArrayLike,
        du_past: ArrayLike,
        reference: float | ArrayLike,
    ) -> float:
        """The feed increment Δu(t) (Eq. 6.14 / 3.41).

        Parameters
        ----------
        a, b : the model A (without its leading 1) and B.
        y_past : F(t), F(t−1), …, at least na + 1 values, newest first.
        du_past : Δu(t−1), Δu(t−2), …, at least nb − 1 values, newest first.
        reference : F_r over the horizon (a scalar, or N2 values for a known future, e.g.
            the virtual plan's predicted force).
        """
        at, bv = _model(a, b, self.n2)
        y = np.ascontiguousarray(y_past, dtype=float).ravel()
        du = np.ascontiguousarray(du_past, dtype=float).ravel()
        nf = at.size - 1
        npast = bv.size - 1  # past increments each G_j reaches (nb − 1)
        if y.size < nf:
            raise ConfigError(f"GPC: needs {nf} past outputs, got {y.size}")
        if du.size < npast:
            raise ConfigError(f"GPC: needs {npast} past feed increments, got {du.size}")
        r = np.ascontiguousarray(np.broadcast_to(np.asarray(reference, dtype=float), (self.n2,)))
        e, f, g = _prediction_arrays(at, bv, self.n2)
        return float(_move(at, bv, y, du, r, self.nu, self.lam, e, f, g))


@numba.njit(cache=True)
def _move(
    at: FloatArray,
    b: FloatArray,
    y: FloatArray,
    du: FloatArray,
    r: FloatArray,
    nu: int,
    lam: float,
    e: FloatArray,
    f: FloatArray,
    g: FloatArray,
) -> float:  # pragma: no cover - compiled
    """:meth:`GPC.move` in one compiled call: the predictors (:func:`_diophantine_into`), the
    free response ``f_j = G_j's past part·Δu_past + F_j·y``, the step-response matrix G
    (``G[i, c] = g_{i−c}``) and the first entry of ``(GᵀG + λI)⁻¹ Gᵀ (r − f)``."""
    _diophantine_into(at, b, e, f, g)
    n2 = e.shape[0]
    nf = f.shape[1]
    npast = g.shape[1] - n2
    free = np.empty(n2)
    for j in range(n2):
        # G_j's coefficients beyond the future moves act on the past increments
        acc = 0.0
        for i in range(npast):
            acc += g[j, j + 1 + i] * du[i]
        acc_f = 0.0
        for i in range(nf):
            acc_f += f[j, i] * y[i]
        free[j] = acc + acc_f
    gm = np.zeros((n2, nu))
    for c in range(nu):
        for i in range(c, n2):
            gm[i, c] = g[i - c, i - c]  # the step response of z⁻¹B/A
    h = gm.T @ gm + lam * np.eye(nu)
    return np.linalg.solve(h, gm.T @ (r - free))[0]
