"""Constant-trace recursive least squares with a dead zone (Munasinghe Eq. 3.27–3.31; Aslan
App. F, Eq. F.1–F.6).

The adaptive force controllers re-identify their plant every control interval (one spindle
revolution): ``y(t) = φ(t)ᵀ θ + noise``. The estimator is

- θ̂(t) = θ̂(t−1) + α(t)·k(t)·(y(t) − φᵀ(t)θ̂(t−1))              (3.27)
- k(t) = P(t−1)φ(t) / (1 + φᵀ(t)P(t−1)φ(t))                      (3.28)
- P̄(t) = P(t−1) − α(t)·k(t)·φᵀ(t)·P(t−1)                        (3.29)
- P(t) = c₁·P̄(t)/tr(P̄(t)) + c₂·I                                (3.30)
- α(t) = 1 if |y(t) − φᵀ(t)θ̂(t−1)| > 2δ, else 0                   (3.31)

The constant trace keeps the estimator alert (no covariance wind-down) without the wind-up of
exponential forgetting when the signals are not exciting; the dead zone freezes θ̂ and P while
the prediction error is within the noise band δ.

Seed 002 prints its constants illegibly (``a=0.5, c1 =5•o/4Tq andcl/c2 iO``; the digest reads
δ = 0.5 N, c₁ "5/(φᵀφ)", c₁/c₂ = 10 with a probably lost exponent) and seed 000 gives none.
Decision 1601: the controllers run the RLS on normalised signals (force / reference force,
feed / programmed feed, so φ is O(1)); P₀ = 10·I as seed 002, c₁ = tr(P₀) (the trace is held
at its initial value, the literal "constant trace"), c₂ = 10⁻⁴·c₁ (the textbook ratio of 10⁴),
and δ is the force noise band divided by the reference. A trace of 1 (c₁ = 1) was measured to
need 3000 revolutions to identify the test plant that c₁ = tr(P₀) = 50 identifies in 600.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError

FloatArray = NDArray[np.float64]


@dataclass
class ConstantTraceRLS:
    """Constant-trace RLS with dead zone (Munasinghe Eq. 3.27–3.31).

    Parameters
    ----------
    theta0 : initial parameter estimate θ̂₀.
    c1 : trace of P after each normalisation (> 0); None: tr(P₀) = n·p0 (decision 1601).
    c2 : added to the diagonal of P after each normalisation (≥ 0), keeps P from
        becoming singular in directions that are not excited; None: 10⁻⁴·c₁.
    delta : dead-zone half-width δ: no update while |prediction error| ≤ 2δ.
    p0 : initial covariance scale, P₀ = p0·I (seed 002: 10).
    """

    theta0: ArrayLike
    c1: float | None = None
    c2: float | None = None
    delta: float = 0.0
    p0: float = 10.0
    theta: FloatArray = field(init=False)
    P: FloatArray = field(init=False)
    updates: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        n = np.asarray(self.theta0, dtype=float).size
        if self.c1 is None:
            self.c1 = n * float(self.p0)
        if self.c2 is None:
            self.c2 = 1e-4 * self.c1
        if not self.c1 > 0:
            raise ConfigError(f"RLS: c1 must be > 0, got {self.c1!r}")
        if not self.c2 >= 0:
            raise ConfigError(f"RLS: c2 must be ≥ 0, got {self.c2!r}")
        if not self.delta >= 0:
            raise ConfigError(f"RLS: delta must be ≥ 0, got {self.delta!r}")
        if not self.p0 > 0:
            raise ConfigError(f"RLS: p0 must be > 0, got {self.p0!r}")
        self.reset()

    @property
    def n(self) -> int:
        return int(self.theta.size)

    def reset(self) -> None:
        """Back to θ̂₀ and P₀."""
        self.theta = np.array(self.theta0, dtype=float).ravel().copy()
        self.P = self.p0 * np.eye(self.theta.size)
        self.updates = 0

    def predict(self, phi: ArrayLike) -> float:
        """φᵀθ̂ with the current estimate."""
        return float(np.dot(np.asarray(phi, dtype=float), self.theta))

    def update(self, phi: ArrayLike, y: float) -> float:
        """One step of Eq. 3.27–3.31 with regressor ``phi`` and output ``y``; returns the a
        priori prediction error y − φᵀθ̂(t−1)."""
        ph = np.asarray(phi, dtype=float).ravel()
        if ph.size != self.theta.size:
            raise ConfigError(f"RLS: regressor has {ph.size} entries, θ has {self.theta.size}")
        if not (np.all(np.isfinite(ph)) and np.isfinite(y)):
            return float("nan")  # a corrupt sample never enters the estimate
        err, theta, cov, moved = _update(
            np.ascontiguousarray(ph), float(y), self.theta, self.P, float(self.delta),
            float(self.c1 or 0.0), float(self.c2 or 0.0),
        )  # fmt: skip
        if moved:
            self.theta, self.P = theta, cov
            self.updates += 1
        return float(err)


@numba.njit(cache=True)
def _update(
    ph: FloatArray,
    y: float,
    theta: FloatArray,
    p: FloatArray,
    delta: float,
    c1: float,
    c2: float,
) -> tuple[float, FloatArray, FloatArray, bool]:  # pragma: no cover - compiled
    """One step of Eq. 3.27–3.31 in one compiled call (the adaptive feed runs it once per
    revolution; numpy's per-call overhead on 5×5 matrices was most of it): the a priori error,
    the new θ̂ and P (new arrays) and whether they moved (α = 1)."""
    n = ph.shape[0]
    pred = 0.0
    for i in range(n):
        pred += ph[i] * theta[i]
    err = y - pred
    if abs(err) <= 2.0 * delta:  # Eq. 3.31: α = 0
        return err, theta, p, False
    p_phi = np.zeros(n)
    for i in range(n):
        for j in range(n):
            p_phi[i] += p[i, j] * ph[j]
    den = 0.0
    for i in range(n):
        den += ph[i] * p_phi[i]
    k = p_phi / (1.0 + den)  # Eq. 3.28
    new_theta = theta + k * err  # Eq. 3.27
    p_bar = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            p_bar[i, j] = p[i, j] - k[i] * p_phi[j]  # Eq. 3.29 (P symmetric: φᵀP = (Pφ)ᵀ)
    p_bar = 0.5 * (p_bar + p_bar.T)
    tr = 0.0
    for i in range(n):
        tr += p_bar[i, i]
    if not tr > 0:  # numerically exhausted: restart the covariance (Aslan App. F reset)
        p_bar = np.eye(n)
        tr = float(n)
    return err, new_theta, c1 * p_bar / tr + c2 * np.eye(n), True  # Eq. 3.30
