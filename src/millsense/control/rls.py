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

Parameter projection (decision 1657; Goodwin & Sin, *Adaptive Filtering, Prediction and
Control*: least squares with projection in the metric of P⁻¹; Åström & Wittenmark, *Adaptive
Control*: projection onto a set known to hold the true parameters, among the safeguards of a
practical estimator): with ``constraints`` (G, h) an update that leaves the convex set
{θ : Gθ ≤ h} is replaced by the point of the set nearest to it in the norm ‖·‖_{P⁻¹}, so the
estimate never leaves the set of physically possible models, and (the set being convex) the
projection never moves it farther, in that norm, from a true θ inside the set. P is not changed.
:func:`force_model_constraints` is the set of the adaptive force controllers.
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
    constraints : (G, h): the estimate is kept in the convex set Gθ ≤ h by projection in the
        P⁻¹ metric after each update (decision 1657); None: unconstrained.
    """

    theta0: ArrayLike
    c1: float | None = None
    c2: float | None = None
    delta: float = 0.0
    p0: float = 10.0
    constraints: tuple[ArrayLike, ArrayLike] | None = None
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
        self._g: FloatArray | None = None
        self._h: FloatArray | None = None
        if self.constraints is not None:
            g = np.ascontiguousarray(self.constraints[0], dtype=float)
            h = np.ascontiguousarray(self.constraints[1], dtype=float).ravel()
            if g.ndim != 2 or g.shape != (h.size, n) or h.size > 20:
                raise ConfigError(
                    f"RLS: constraints need G of shape (m, {n}) and h of m ≤ 20 entries"
                )
            self._g, self._h = g, h
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
            if self._g is not None and self._h is not None:
                theta = project(theta, cov, self._g, self._h)
            self.theta, self.P = theta, cov
            self.updates += 1
        return float(err)


def force_model_constraints(na: int = 2, nb: int = 3) -> tuple[FloatArray, FloatArray]:
    """(G, h) of the physically possible per-revolution force models A·F = z⁻¹B·f
    (θ = [a₁ … a_na, b₀ … b_{nb−1}], Munasinghe Eq. 3.23, Aslan Eq. 6.7; decision 1657).

    Seed 002 derives the plant from its parts: the cutting process with the tool's deflection,
    F(j) = p/(1+p)·F(j−1) + k_s·p/(1+p)·f(j−1) with p = K·a·b/k_s > 0 (Eq. 3.10–3.12): one
    real pole p/(1+p) in [0, 1) and a positive gain; and the feed drive, whose pole at a
    revolution's sampling is negligible (App. B: a₁ = −5.6·10⁻⁴, a₂ = 1.1·10⁻⁸, neglected in
    Eq. B.8, the drive left as z⁻¹(b₁ + b₂z⁻¹)); seed 000 §6.4: the drive "tuned to be
    overdamped with no overshoot". So:

    - a₁ ∈ [−1, 0] (the process pole −a₁ real, in [0, 1]) and a₂ … a_na = 0;
    - every b ≥ 0 (the chip, h = f_t·sin φ, and the force grow with the feed, and an
      overdamped drive's response does not overshoot).

    The second pole of Eq. 3.23 is kept in the regressor (seed 000 App. F, Eq. F.2) and pinned
    at 0 by the projection. (The convex hull of two real poles in [0, 1] was measured first: it
    admits damped complex poles, and on V8's engagement jump such a model raised the override
    from 20 to 96 % at 2.8 × the reference; decision 1657.)"""
    if na < 0 or nb < 1:
        raise ConfigError(f"RLS constraints: need na ≥ 0 and nb ≥ 1, got {na}, {nb}")
    n = na + nb
    rows: list[list[float]] = []
    h: list[float] = []

    def row(i: int, sign: float, bound: float) -> None:
        r = [0.0] * n
        r[i] = sign
        rows.append(r)
        h.append(bound)

    if na >= 1:
        row(0, 1.0, 0.0)  # a₁ ≤ 0
        row(0, -1.0, 1.0)  # a₁ ≥ −1
    for i in range(1, na):
        row(i, 1.0, 0.0)  # a_i = 0
        row(i, -1.0, 0.0)
    for i in range(nb):
        row(na + i, -1.0, 0.0)  # b_i ≥ 0
    return np.array(rows), np.array(h)


def project(theta: FloatArray, p: FloatArray, g: FloatArray, h: FloatArray) -> FloatArray:
    """The point of {θ : Gθ ≤ h} nearest to ``theta`` in the norm ‖·‖_{P⁻¹} (P symmetric
    positive definite; decision 1657): ``theta`` itself when it is inside, else the solution
    of min ½(θ − θ̂)ᵀP⁻¹(θ − θ̂) s.t. Gθ ≤ h by its KKT conditions over the active sets,
    smallest first (θ = θ̂ − P·G_Sᵀλ, λ ≥ 0, the others satisfied); the optimum of a strictly
    convex problem is unique, so the first set that passes is it (compiled:
    :func:`_project`)."""
    return _project(
        np.ascontiguousarray(theta, dtype=float), np.ascontiguousarray(p, dtype=float),
        np.ascontiguousarray(g, dtype=float), np.ascontiguousarray(h, dtype=float),
    )  # fmt: skip


@numba.njit(cache=True)
def _project(
    theta: FloatArray, p: FloatArray, g: FloatArray, h: FloatArray
) -> FloatArray:  # pragma: no cover - compiled
    """:func:`project`: the active sets enumerated by bit mask in order of size."""
    m = h.shape[0]
    tol = 1e-12 * (1.0 + np.max(np.abs(theta)))
    if np.all(g @ theta <= h + tol):
        return theta.copy()
    pg = p @ g.T  # (n, m)
    best = theta.copy()
    for size in range(1, m + 1):
        for mask in range(1, 1 << m):
            # the active set S of this mask, if it has ``size`` members
            cnt = 0
            for i in range(m):
                if (mask >> i) & 1:
                    cnt += 1
            if cnt != size:
                continue
            idx = np.empty(size, dtype=np.int64)
            k = 0
            for i in range(m):
                if (mask >> i) & 1:
                    idx[k] = i
                    k += 1
            gs = g[idx]
            mat = gs @ pg[:, idx]
            if abs(np.linalg.det(mat)) <= 1e-14 * (1.0 + np.max(np.abs(mat))) ** size:
                continue
            lam = np.linalg.solve(mat, gs @ theta - h[idx])
            if np.any(lam < -1e-12):
                continue
            x = theta - pg[:, idx] @ lam
            if np.all(g @ x <= h + 1e-9):
                return x
    return best  # unreachable for a non-empty set and P positive definite


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
