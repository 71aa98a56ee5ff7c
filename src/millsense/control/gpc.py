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
    for the second-order plant.
    """
    av = np.asarray(a, dtype=float).ravel()
    bv = np.asarray(b, dtype=float).ravel()
    if n2 < 1:
        raise ConfigError(f"GPC: N2 must be ≥ 1, got {n2}")
    if bv.size == 0:
        raise ConfigError("GPC: B needs at least one coefficient")
    at = _delta_a(av)  # [1, ã1, ..., ã_{na+1}]
    na1 = at.size - 1  # deg(AΔ) = na + 1; F_j has na + 1 coefficients
    e = np.zeros((n2, n2))
    f = np.zeros((n2, na1))
    fj = -at[1:].copy()  # F_1 = z(1 − Ã)
    ej = np.zeros(n2)
    ej[0] = 1.0  # E_1 = 1
    for j in range(n2):
        e[j] = ej
        f[j] = fj
        if j + 1 < n2:
            lead = fj[0]  # e_{j+1}: the next coefficient of E
            ej = ej.copy()
            ej[j + 1] = lead
            fj = np.append(fj[1:], 0.0) - lead * at[1:]
    g = np.zeros((n2, n2 + bv.size - 1))
    for j in range(n2):
        gj = np.convolve(e[j, : j + 1], bv)
        g[j, : gj.size] = gj
    return Prediction(e, f, g)


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
        pred = diophantine(a, b, self.n2)
        y = np.asarray(y_past, dtype=float).ravel()
        du = np.asarray(du_past, dtype=float).ravel()
        nf = pred.f.shape[1]
        npast = pred.g.shape[1] - self.n2  # past increments each G_j reaches (nb − 1)
        if y.size < nf:
            raise ConfigError(f"GPC: needs {nf} past outputs, got {y.size}")
        if du.size < npast:
            raise ConfigError(f"GPC: needs {npast} past feed increments, got {du.size}")
        free = np.empty(self.n2)
        for j in range(self.n2):
            # G_j's coefficients beyond the future moves act on the past increments
            past = pred.g[j, j + 1 : j + 1 + npast]
            free[j] = past @ du[:npast] + pred.f[j] @ y[:nf]
        step = pred.step_response
        gm = np.zeros((self.n2, self.nu))
        for c in range(self.nu):
            gm[c:, c] = step[: self.n2 - c]
        r = np.broadcast_to(np.asarray(reference, dtype=float), (self.n2,))
        h = gm.T @ gm + self.lam * np.eye(self.nu)
        return float(np.linalg.solve(h, gm.T @ (r - free))[0])
