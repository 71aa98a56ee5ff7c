"""Steady-state fixed-lag Kalman smoother, streamed with exactly ``lag`` samples of delay.

Aslan Appendix B applies the Rauch–Tung–Striebel smoother (Eq. B.1–B.3) over a buffer of 60
samples (6 ms at 10 kHz) so that the compensated force of each axis follows the measurement
6 ms late but with the phase of the disturbance path corrected. Run over a sliding window whose
backward pass starts from the newest filtered estimate, RTS returns ``x̂(k−L | k)``: the
fixed-lag smoothed estimate. millsense computes that estimate directly, in steady state, from
the innovations (decision
docs/decisions/0048-fixed-lag-smoother-as-an-fir-on-the-innovations-aslan.md):

    x̂(k−L | k) = x̂(k−L | k−L−1) + Σ_{j=0..L} P (A_d − K_p C)ᵀʲ Cᵀ Σ⁻¹ · e(k−L+j),

where ``P`` is the steady prior covariance, ``Σ = C P Cᵀ + R`` and ``e`` the innovation
(Anderson & Moore, *Optimal Filtering*, §7.3, derived from the orthogonality of the
innovations). The gains are computed once; per chunk one numba kernel runs the Kalman filter,
a delay line and an FIR of L+1 taps on the innovation over the carried history, so the output
is chunk-size invariant and delayed by exactly ``lag`` samples.
The smoothed covariance ``P − Σ_j P_j Cᵀ Σ⁻¹ C P_jᵀ`` (``P_j = P (A_d − K_p C)ᵀʲ``) is the
steady value of Eq. B.3.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.estimation.kalman.design import KalmanDesign
from millsense.estimation.kalman.lti_filter import Realisation, StreamingFilter, run_lti

#: Aslan Appendix B: 60 samples at 10 kHz (6 ms).
ASLAN_LAG_SAMPLES = 60


def fixed_lag_gains(
    design: KalmanDesign, lag: int, rows: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Innovation gains and smoothed covariance of the steady-state fixed-lag smoother.

    Parameters
    ----------
    design : steady-state Kalman design.
    lag : L, samples (≥ 0; 0 gives the filtered estimate x̂(k|k)).
    rows : (d, n) selection S of the smoothed quantity; default the disturbance rows.

    Returns
    -------
    taps : (L+1, d, p) with ``taps[j] = S P_j Cᵀ Σ⁻¹``, the weight of ``e(k−L+j)``.
    cov : (d, d) smoothed error covariance ``S (P − Σ_j P_j Cᵀ Σ⁻¹ C P_jᵀ) Sᵀ``.
    """
    if lag < 0:
        raise ValueError(f"lag must be ≥ 0 samples, got {lag}")
    s = design.disturbance if rows is None else np.atleast_2d(np.asarray(rows, dtype=float))
    sig_inv = np.linalg.inv(design.innovation_covariance)
    acl_t = design.closed_loop.T
    pj = design.p_prior.copy()
    taps = np.empty((lag + 1, s.shape[0], design.c.shape[0]))
    cov = s @ design.p_prior @ s.T
    for j in range(lag + 1):
        spc = s @ pj @ design.c.T
        taps[j] = spc @ sig_inv
        cov = cov - spc @ sig_inv @ spc.T
        pj = pj @ acl_t
    return taps, 0.5 * (cov + cov.T)


@numba.njit(cache=True)
def _smooth(
    modal: bool,
    diag: NDArray[np.float64],
    off: NDArray[np.float64],
    n_pairs: int,
    f: NDArray[np.float64],
    g: NDArray[np.float64],
    h: NDArray[np.float64],
    j: NDArray[np.float64],
    u: NDArray[np.float64],
    z: NDArray[np.float64],
    taps_t: NDArray[np.float64],
    hist_pred: NDArray[np.float64],
    hist_innov: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    # Kalman filter with outputs [S x̂(k|k−1); e(k)], then out[k] = pred[k] + Σ_c Σ_j
    # taps_t[:, c, j]·e_c[k + j] over the history of L samples followed by the chunk: the
    # estimate of the sample L before the chunk's k-th. hist_* are updated in place.
    y = run_lti(modal, diag, off, n_pairs, f, g, h, j, u, z)
    return fixed_lag_output(y, taps_t, hist_pred, hist_innov)


@numba.njit(cache=True)
def fir_accumulate(
    w: NDArray[np.float64], e: NDArray[np.float64], acc: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """``acc[k] = Σ_i w[i]·e[k + i]`` for k < len(acc), each sum started at 0 and taken in the
    order i = 0 … len(w) − 1.

    The loop over k is innermost, so the samples run side by side (vectorised) instead of one
    sequential sum at a time; each pass adds four taps, ``acc[k] = acc[k] + w[i]·e[k+i] + … +
    w[i+3]·e[k+i+3]`` (evaluated left to right: the same additions in the same order as one
    tap a pass), so ``acc`` is loaded and stored a quarter as often."""
    n = acc.shape[0]
    n_taps = w.shape[0]
    acc[:] = 0.0
    i = 0
    while i + 4 <= n_taps:
        w0, w1, w2, w3 = w[i], w[i + 1], w[i + 2], w[i + 3]
        for k in range(n):
            j = k + i
            acc[k] = acc[k] + w0 * e[j] + w1 * e[j + 1] + w2 * e[j + 2] + w3 * e[j + 3]
        i += 4
    while i < n_taps:
        wi = w[i]
        for k in range(n):
            acc[k] += wi * e[k + i]
        i += 1


@numba.njit(cache=True)
def fixed_lag_output(
    y: NDArray[np.float64],
    taps_t: NDArray[np.float64],
    hist_pred: NDArray[np.float64],
    hist_innov: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """The smoother's output from the Kalman filter's ``y`` = [S x̂(k|k−1); e(k)] of a chunk:
    ``out[k] = pred[k] + Σ_c Σ_j taps_t[:, c, j]·e_c[k + j]`` over the history of L samples
    followed by the chunk (the estimate of the sample L before the chunk's k-th); ``hist_*``
    updated in place. One smoothed quantity from one innovation (d = p = 1, the feed
    estimators) is :func:`fixed_lag_series`."""
    d, p, n_taps = taps_t.shape
    lag = n_taps - 1
    n = y.shape[0]
    out = np.empty((n, d))
    if d == 1 and p == 1:
        fixed_lag_series(y[:, 0], y[:, 1], taps_t[0, 0], hist_pred[:, 0], hist_innov[0],
                         np.empty(lag + n), np.empty(n), out[:, 0])  # fmt: skip
        return out
    pred = np.empty((lag + n, d))
    innov = np.empty((p, lag + n))
    pred[:lag] = hist_pred
    innov[:, :lag] = hist_innov
    for k in range(n):
        for r in range(d):
            pred[lag + k, r] = y[k, r]
        for c in range(p):
            innov[c, lag + k] = y[k, d + c]
    acc = np.empty(n)
    for r in range(d):
        for k in range(n):
            out[k, r] = pred[k, r]
        for c in range(p):
            fir_accumulate(taps_t[r, c], innov[c], acc)
            for k in range(n):
                out[k, r] += acc[k]
    hist_pred[:] = pred[n:]
    hist_innov[:] = innov[:, n:]
    return out


@numba.njit(cache=True)
def fixed_lag_series(
    pred: NDArray[np.float64],
    innov: NDArray[np.float64],
    w: NDArray[np.float64],
    hist_pred: NDArray[np.float64],
    hist_innov: NDArray[np.float64],
    e: NDArray[np.float64],
    acc: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:func:`fixed_lag_output` for one smoothed quantity and one innovation, into ``out``
    (n,): ``out[k] = p[k] + Σ_j w[j]·e[k + j]`` with ``p`` = ``hist_pred ++ pred`` and ``e`` =
    ``hist_innov ++ innov`` (the L samples before the chunk, then the chunk's n), the sum by
    :func:`fir_accumulate`; the histories (L,) are updated in place. ``e`` (L + n) and ``acc``
    (n) are the caller's work buffers (none allocated here: at 10 ms chunks the allocations
    and copies cost more than the FIR)."""
    lag = hist_pred.shape[0]
    n = pred.shape[0]
    for k in range(lag):
        e[k] = hist_innov[k]
    for k in range(n):
        e[lag + k] = innov[k]
    fir_accumulate(w, e, acc)
    for k in range(n):
        out[k] = (hist_pred[k] if k < lag else pred[k - lag]) + acc[k]
    if n >= lag:
        for k in range(lag):
            hist_pred[k] = pred[n - lag + k]
    else:
        for k in range(lag - n):
            hist_pred[k] = hist_pred[k + n]
        for k in range(n):
            hist_pred[lag - n + k] = pred[k]
    for k in range(lag):
        hist_innov[k] = e[n + k]


class FixedLagSmoother:
    """Streaming fixed-lag smoother: emits ``S x̂(k−L | k)`` at sample k.

    Parameters
    ----------
    design : steady-state Kalman design (gains frozen).
    lag : L, samples; 60 (6 ms at 10 kHz) in Aslan Appendix B.
    rows : (d, n) selection S; default the disturbance rows (``τ̂_a``).
    realisation : kernel of the underlying Kalman filter (see
        :class:`~millsense.estimation.kalman.lti_filter.StreamingFilter`).

    Notes
    -----
    Start-up: before the stream starts the filter state is 0 and the innovations are taken as 0,
    so the first L outputs are the (partially smoothed) estimates of the samples "before" the
    stream, i.e. a transient of exactly L samples.
    """

    def __init__(
        self,
        design: KalmanDesign,
        lag: int = ASLAN_LAG_SAMPLES,
        rows: ArrayLike | None = None,
        realisation: Realisation = "auto",
    ) -> None:
        self.design = design
        self.lag = int(lag)
        s = design.disturbance if rows is None else np.atleast_2d(np.asarray(rows, dtype=float))
        self._d = s.shape[0]
        self._p = design.c.shape[0]
        self.taps, self.covariance = fixed_lag_gains(design, self.lag, s)
        self._kf = StreamingFilter(design.filter("predicted", s, innovation=True), realisation)
        self._taps_t = np.ascontiguousarray(self.taps.transpose(1, 2, 0))
        self.reset()

    @property
    def realisation(self) -> str:
        """Kernel of the underlying filter (``"modal"`` or ``"dense"``)."""
        return self._kf.realisation

    @property
    def delay_samples(self) -> int:
        """Delay of the output, samples (= lag)."""
        return self.lag

    @property
    def filtered_covariance(self) -> NDArray[np.float64]:
        """(d, d) error covariance of the filtered estimate ``S x̂(k|k)``, for comparison."""
        s = self._kf.filter.h[: self._d]
        return s @ self.design.p_filtered @ s.T

    def reset(self) -> None:
        """Forget the stream (zero filter state, zero delay line and FIR state)."""
        self._kf.reset()
        self._hist_pred = np.zeros((self.lag, self._d))
        self._hist_innov = np.zeros((self._p, self.lag))

    def process(self, y: ArrayLike) -> NDArray[np.float64]:
        """Smooth one chunk of measurements.

        Parameters
        ----------
        y : (N,) or (N, p) measurements.

        Returns
        -------
        (N, d): row k is the smoothed estimate of sample ``k − lag`` of the stream.
        """
        u = self._kf.as_input(y)
        return _smooth(
            *self._kf.kernel_args,
            u,
            self._kf.z,
            self._taps_t,
            self._hist_pred,
            self._hist_innov,
        )
