"""Kalman filter with a time-varying measurement matrix, for parameter-type estimators.

İlme (seed 003, Eq. 3.6–3.14) estimates constant cutting coefficients ``q = [K_t, K_r, K_te,
K_re]`` from acceleration with ``q(k+1) = Φ q(k) + w`` (Φ = I: a random walk) and the
measurement ``z(k) = H(φ_k) q(k) + v`` whose matrix is rebuilt from the spindle angle at every
sample. The gain cannot be frozen, so the filter runs the full covariance recursion per sample
in a numba kernel; the state (estimate and covariance) is carried across chunks.

Per sample (İlme Eq. 3.10–3.14, predict then update):
``q⁻ = Φ q``, ``P⁻ = Φ P Φᵀ + Q``, ``S = H P⁻ Hᵀ + R``, ``K = P⁻ Hᵀ S⁻¹``,
``q = q⁻ + K (z − H q⁻)``, and the covariance in Joseph form
``P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ`` (decision
docs/decisions/0049-joseph-form-and-missing-samples-in-the-time-varying-kalman.md: algebraically
equal to İlme's Eq. 3.14 ``(I − K H) P⁻`` but it stays symmetric positive semi-definite in floating
point over millions of samples). A sample whose measurement is NaN is a prediction only (no update).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray


@numba.njit(cache=True)
def _spd_inverse(s: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover - compiled
    # Gauss-Jordan on a small symmetric positive-definite matrix (no pivoting needed)
    m = s.shape[0]
    a = s.copy()
    inv = np.eye(m)
    for i in range(m):
        piv = a[i, i]
        for c in range(m):
            a[i, c] /= piv
            inv[i, c] /= piv
        for r in range(m):
            if r != i:
                fac = a[r, i]
                if fac != 0.0:
                    for c in range(m):
                        a[r, c] -= fac * a[i, c]
                        inv[r, c] -= fac * inv[i, c]
    return inv


@numba.njit(cache=True)
def _tv_kalman_state(
    phi: NDArray[np.float64],
    q: NDArray[np.float64],
    r: NDArray[np.float64],
    z: NDArray[np.float64],
    h: NDArray[np.float64],
    x0: NDArray[np.float64],
    p0: NDArray[np.float64],
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]:  # pragma: no cover - compiled
    n_samples, m = z.shape
    n = x0.shape[0]
    x = x0.copy()
    p = p0.copy()
    x_out = np.empty((n_samples, n))
    z_out = np.empty((n_samples, m))
    p_diag = np.empty((n_samples, n))
    xm = np.empty(n)
    pm = np.empty((n, n))
    tmp = np.empty((n, n))
    ph = np.empty((n, m))
    s = np.empty((m, m))
    kg = np.empty((n, m))
    innov = np.empty(m)
    ikh = np.empty((n, n))
    for k in range(n_samples):
        # predict: x⁻ = Φ x, P⁻ = Φ P Φᵀ + Q
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += phi[i, j] * x[j]
            xm[i] = acc
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for l in range(n):
                    acc += phi[i, l] * p[l, j]
                tmp[i, j] = acc
        for i in range(n):
            for j in range(n):
                acc = q[i, j]
                for l in range(n):
                    acc += tmp[i, l] * phi[j, l]
                pm[i, j] = acc
        finite = True
        for c in range(m):
            if not np.isfinite(z[k, c]):
                finite = False
        if finite:
            # P⁻Hᵀ, S = H P⁻ Hᵀ + R, K = P⁻Hᵀ S⁻¹
            for i in range(n):
                for c in range(m):
                    acc = 0.0
                    for l in range(n):
                        acc += pm[i, l] * h[k, c, l]
                    ph[i, c] = acc
            for a in range(m):
                for c in range(m):
                    acc = r[a, c]
                    for l in range(n):
                        acc += h[k, a, l] * ph[l, c]
                    s[a, c] = acc
            sinv = _spd_inverse(s)
            for i in range(n):
                for c in range(m):
                    acc = 0.0
                    for a in range(m):
                        acc += ph[i, a] * sinv[a, c]
                    kg[i, c] = acc
            for c in range(m):
                acc = z[k, c]
                for l in range(n):
                    acc -= h[k, c, l] * xm[l]
                innov[c] = acc
            for i in range(n):
                acc = xm[i]
                for c in range(m):
                    acc += kg[i, c] * innov[c]
                x[i] = acc
            # Joseph form: P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ
            for i in range(n):
                for j in range(n):
                    acc = 1.0 if i == j else 0.0
                    for c in range(m):
                        acc -= kg[i, c] * h[k, c, j]
                    ikh[i, j] = acc
            for i in range(n):
                for j in range(n):
                    acc = 0.0
                    for l in range(n):
                        acc += ikh[i, l] * pm[l, j]
                    tmp[i, j] = acc
            for i in range(n):
                for j in range(i, n):
                    acc = 0.0
                    for l in range(n):
                        acc += tmp[i, l] * ikh[j, l]
                    for a in range(m):
                        for c in range(m):
                            acc += kg[i, a] * r[a, c] * kg[j, c]
                    p[i, j] = acc
                    p[j, i] = acc
        else:
            for i in range(n):
                x[i] = xm[i]
                for j in range(n):
                    p[i, j] = pm[i, j]
        for i in range(n):
            x_out[k, i] = x[i]
            p_diag[k, i] = p[i, i]
        for c in range(m):
            acc = 0.0
            for l in range(n):
                acc += h[k, c, l] * x[l]
            z_out[k, c] = acc
    return x_out, z_out, p_diag, x, p


@dataclass(frozen=True)
class TVKalmanOutput:
    """Per-sample outputs of :class:`TimeVaryingKalman`.

    Attributes
    ----------
    x : (N, n) posterior estimates ``x̂(k|k)``.
    z_est : (N, m) ``H_k x̂(k|k)`` (İlme's estimated acceleration).
    p_diag : (N, n) diagonal of the posterior covariance.
    """

    x: NDArray[np.float64]
    z_est: NDArray[np.float64]
    p_diag: NDArray[np.float64]


class TimeVaryingKalman:
    """Linear Kalman filter ``x⁺ = Φ x + w``, ``z_k = H_k x + v`` with H_k given per sample.

    Parameters
    ----------
    n_states : n.
    q : process noise covariance per sample (scalar → q·I, or (n, n)), units of x².
    r : measurement noise covariance (scalar → r·I, or (m, m)), units of z².
    x0 : initial estimate (default zeros).
    p0 : initial covariance (scalar → p0·I, or (n, n)); default 1e6·I (uninformative).
    transition : Φ (default I: constant parameters as a random walk, İlme Eq. 3.6).
    n_measurements : m (default 1).
    """

    def __init__(
        self,
        n_states: int,
        q: ArrayLike,
        r: ArrayLike,
        *,
        x0: ArrayLike | None = None,
        p0: ArrayLike = 1e6,
        transition: ArrayLike | None = None,
        n_measurements: int = 1,
    ) -> None:
        self.n = int(n_states)
        self.m = int(n_measurements)
        self.q = self._square(q, self.n, "q")
        self.r = self._square(r, self.m, "r")
        self.phi = (
            np.eye(self.n) if transition is None else self._square(transition, self.n, "transition")
        )
        self._x0 = np.zeros(self.n) if x0 is None else np.asarray(x0, dtype=float).reshape(self.n)
        self._p0 = self._square(p0, self.n, "p0")
        self.reset()

    @staticmethod
    def _square(v: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
        a = np.atleast_2d(np.asarray(v, dtype=float))
        if a.shape == (1, 1):
            return a[0, 0] * np.eye(n)
        if a.shape != (n, n):
            raise ValueError(f"{name} must be a scalar or {n}×{n}, got shape {a.shape}")
        return np.ascontiguousarray(a)

    def reset(self) -> None:
        """Back to the initial estimate and covariance."""
        self.x = self._x0.copy()
        self.p = self._p0.copy()

    def process(self, z: ArrayLike, h: ArrayLike) -> TVKalmanOutput:
        """Filter one chunk.

        Parameters
        ----------
        z : (N,) or (N, m) measurements (NaN: no measurement at that sample).
        h : (N, n) for m = 1, or (N, m, n): the measurement matrix of each sample.

        Returns
        -------
        TVKalmanOutput for the chunk; the state carries over to the next call.
        """
        za = np.asarray(z, dtype=float)
        za = za.reshape(-1, self.m) if za.ndim == 1 else za
        ha = np.asarray(h, dtype=float)
        if ha.ndim == 2:
            ha = ha[:, None, :]
        if za.shape[1] != self.m or ha.shape != (za.shape[0], self.m, self.n):
            raise ValueError(
                f"z has shape {np.shape(z)} and h {np.shape(h)}; expected (N, {self.m}) and "
                f"(N, {self.m}, {self.n})"
            )
        x, zs, pd, self.x, self.p = _tv_kalman_state(
            self.phi,
            self.q,
            self.r,
            np.ascontiguousarray(za),
            np.ascontiguousarray(ha),
            self.x,
            self.p,
        )
        return TVKalmanOutput(x, zs, pd)
