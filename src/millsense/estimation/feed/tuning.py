"""Automatic tuning of the disturbance Kalman filter (the thesis tuned Q by hand).

- R (Aslan §3.3: "RMS of the torque fluctuation in an air cut"): :func:`air_cut_variance`, the
  per-sample variance of the estimator's own torque measurement during an air cut, after the
  slow trend is removed
  (docs/decisions/0044-units-of-q-and-r-of-the-disturbance-kalman-filter-aslan-eq.md: R is a
  variance).
- Q (Aslan Eq. 3.30, hand-tuned): :func:`tune_q` maximises the ±3 dB bandwidth of the
  compensated FRF ``Φ_d·Φ_KF`` computed on the *identified* model (the estimator cannot see the
  true one), over log Q: a coarse grid (the bandwidth is piecewise smooth in Q, with jumps where
  a new deviation crosses ±3 dB) refined by a bounded scalar search
  (``scipy.optimize.minimize_scalar``). A noise constraint stops Q from growing without bound:
  the white-noise gain of the filter (RMS of the estimate per RMS of the measurement noise)
  must stay below ``max_noise_gain`` (default √10, i.e. the estimate's noise at most 10 dB above
  the measurement's — the thesis' "SNR > 10 dB" criterion of Ch. 5.3 read on the noise side).
  Robust option: the bandwidth is the smallest over the design model and variants of it
  (``plants``, e.g. the identified modes shifted by ±2 % for position dependence).
- Robust design for position-dependent modes (issue 7, :func:`tune_robust`): the estimator knows
  that its modes move by up to ±δ with the axis position but not where they are. The design
  maximises the smallest ±3 dB band over the family of plants with every mode frequency × κ,
  κ ∈ [1 − δ, 1 + δ] (:func:`mode_family`), over two variables: Q and an added damping γ of the
  estimator's own model (:func:`robust_fit`, every complex pole moved left by γ·|p|: the
  expected FRF when the relative mode frequency is Cauchy-distributed with scale γ, i.e. the
  mean plant of the family instead of its nominal member). :func:`flatness_bound` gives the
  limit no linear time-invariant estimator can beat on such a family
  (docs/decisions/0109-robust-feed-estimator-for-position-dependent-modes-issue-7.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, signal

from millsense.core.errors import InputDataError
from millsense.estimation.kalman.design import (
    KalmanDesign,
    StateSpaceModel,
    augment_disturbance,
    bandwidth_3db,
    compensated_frf,
    design_kalman,
)
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.estimation.kalman.smoother import fixed_lag_gains


def air_cut_variance(torque_nm: ArrayLike, trend_hz: float = 2.0, fs: float = 10_000.0) -> float:
    """Per-sample variance (N²·m²) of a measured torque during an air cut.

    Parameters
    ----------
    torque_nm : the estimator's torque measurement (e.g. the low-passed C3 torque) in air.
    trend_hz : fluctuations slower than this (friction level, gravity) are removed first by a
        zero-phase 2nd-order high-pass, Hz.
    fs : sample rate, Hz.
    """
    x = np.asarray(torque_nm, dtype=float)
    if len(x) < 100 or not np.all(np.isfinite(x)):
        raise InputDataError("air cut: need at least 100 finite torque samples")
    sos = signal.butter(2, trend_hz, btype="highpass", fs=fs, output="sos")
    y = signal.sosfiltfilt(sos, x - x.mean())
    trim = min(len(y) // 10, round(fs / trend_hz))
    return float(np.var(y[trim : len(y) - trim]))


def air_cut_r(
    current_a: ArrayLike,
    speed_rad_s: ArrayLike,
    drive: Any,
    lowpass: Any,
    fs: float,
    lugre: Any = None,
    skip_s: float = 0.2,
) -> float:
    """R of the feed estimator from an air cut (Aslan Eq. 3.28–3.30): the variance of the C3
    torque (:class:`~millsense.estimation.feed.estimator.C3Torque` of ``drive``, ``lowpass``,
    ``lugre``) after the first ``skip_s`` (the start of the move), by
    :func:`air_cut_variance`; the one computation of ``identify noise`` and the bench."""
    from millsense.estimation.feed.estimator import C3Torque

    tau = C3Torque(drive, lowpass, fs, lugre).process(
        np.asarray(current_a, dtype=float), np.asarray(speed_rad_s, dtype=float)
    )
    return air_cut_variance(tau[round(skip_s * fs) :], fs=fs)


def noise_gain(design: KalmanDesign) -> float:
    """RMS of the filtered disturbance estimate per unit RMS of white measurement noise.

    ``sqrt(Σ h_k²)`` of the impulse response of the frozen-gain filter ``y → τ̂_a(k|k)``,
    computed exactly from the discrete Lyapunov equation of the filter
    (:meth:`~millsense.estimation.kalman.lti_filter.LinearFilter.output_covariance`).
    """
    filt = design.filter("filtered")
    v = filt.output_covariance(np.eye(filt.n_inputs))
    return float(math.sqrt(max(float(v[0, 0]), 0.0)))


@dataclass(frozen=True)
class QTuning:
    """Result of :func:`tune_q`.

    Attributes
    ----------
    q : chosen spectral density of τ̇_a, (N·m)²/s.
    bandwidth_hz : ±3 dB band of the compensated FRF on the design model, Hz.
    noise_gain : white-noise gain of the filter at q.
    grid_q, grid_bandwidth_hz : the coarse search grid and its bandwidths.
    """

    q: float
    bandwidth_hz: float
    noise_gain: float
    grid_q: NDArray[np.float64]
    grid_bandwidth_hz: NDArray[np.float64]


def _design(model: StateSpaceModel, q: float, r: float) -> KalmanDesign:
    if model.dt is None:
        raise InputDataError("tuning needs a discrete model")
    return design_kalman(augment_disturbance(model), q * model.dt, r)


def tune_q(
    model: StateSpaceModel,
    r: float,
    *,
    bounds: tuple[float, float] = (1.0, 1e7),
    f_max_hz: float = 1000.0,
    n_freq: int = 2001,
    max_noise_gain: float = math.sqrt(10.0),
    n_grid: int = 29,
) -> QTuning:
    """Q maximising the compensated ±3 dB bandwidth on the (identified) design model.

    Parameters
    ----------
    model : discrete τ_a → measurement model the filter is designed on.
    r : per-sample measurement variance, N²·m².
    bounds : search range of Q, (N·m)²/s.
    f_max_hz : upper end of the frequency grid, Hz.
    n_freq : grid points.
    max_noise_gain : largest admissible white-noise gain (:func:`noise_gain`).
    n_grid : coarse log-spaced grid points.

    Notes
    -----
    Objective: ``−bandwidth_3db(f, Φ_d·Φ_KF(q))`` with Φ_d the design model itself; designs
    above the noise limit score 0 Hz. The best grid point is refined by a bounded Brent search on
    log₁₀ Q between its neighbours.
    """
    if not r > 0:
        raise InputDataError(f"tuning: R must be > 0, got {r}")
    f = np.linspace(0.0, f_max_hz, n_freq)
    plant = model.frf(f)  # Φ_d on the grid: the same for every Q tried

    def score(logq: float) -> float:
        d = _design(model, 10.0**logq, r)
        if noise_gain(d) > max_noise_gain:
            return 0.0
        return bandwidth_3db(f, compensated_frf(model, d, f, plant_frf=plant))

    grid = np.linspace(math.log10(bounds[0]), math.log10(bounds[1]), n_grid)
    bw = np.array([score(g) for g in grid])
    i = int(np.argmax(bw))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, n_grid - 1)]
    res = optimize.minimize_scalar(
        lambda x: -score(float(x)), bounds=(lo, hi), method="bounded", options={"xatol": 1e-3}
    )
    best_logq, best_bw = (float(res.x), -float(res.fun)) if -res.fun > bw[i] else (grid[i], bw[i])
    d = _design(model, 10.0**best_logq, r)
    return QTuning(10.0**best_logq, float(best_bw), noise_gain(d), 10.0**grid, bw)


#: Flatness the least-noise tuning keeps on the design model up to the requested band, dB
#: (decision "Least-noise Q for a requested band"): on the acceptance machine the measured
#: compensated FRF departs up to about 2 dB further than the design model's (identification
#: error, friction drift, the unmodelled 420 Hz mode), so ±1 dB on the model leaves ±3 dB.
BAND_FLATNESS_DB = 1.0


def least_noise_q(
    model: StateSpaceModel,
    r: float,
    band_hz: float,
    *,
    flatness_db: float = BAND_FLATNESS_DB,
    bounds: tuple[float, float] = (1.0, 1e7),
    f_max_hz: float = 1000.0,
    n_freq: int = 2001,
    max_noise_gain: float = math.sqrt(10.0),
    n_grid: int = 57,
) -> QTuning:
    """The least-noise Q whose compensated FRF on the design model is flat to ``band_hz``.

    The alternative to :func:`tune_q` (widest band under the noise limit) when the band needed
    is known, e.g. the highest tooth harmonic of interest: the white-noise gain of the filter
    grows with Q, so the least Q with ``|20·log₁₀|Φ_d·Φ_KF|| ≤ flatness_db`` on (0, band_hz]
    is the least noisy design that keeps the band (Aslan C6 tuned Q by hand for this trade).

    Parameters
    ----------
    model : discrete τ_a → measurement model the filter is designed on.
    r : per-sample measurement variance, N²·m².
    band_hz : band the compensated FRF must be flat in, Hz.
    flatness_db : largest |deviation| from 0 dB allowed in the band on the design model.
    bounds, f_max_hz, n_freq, max_noise_gain : as :func:`tune_q`.
    n_grid : log-spaced grid points over ``bounds`` (ascending; the first that is flat enough
        is refined by bisection on log₁₀ Q against its predecessor).

    Raises
    ------
    InputDataError
        When no Q within ``bounds`` and the noise limit keeps the band (one line with the band
        the widest-band tuning reaches).
    """
    if not r > 0:
        raise InputDataError(f"tuning: R must be > 0, got {r}")
    if not (0 < band_hz < f_max_hz and flatness_db > 0):
        raise InputDataError(
            f"tuning: band must be in (0, {f_max_hz:g}) Hz and flatness > 0 dB, got "
            f"{band_hz:g} Hz, {flatness_db:g} dB"
        )
    f = np.linspace(0.0, f_max_hz, n_freq)
    in_band = (f > 0) & (f <= band_hz)
    plant = model.frf(f)  # Φ_d on the grid: the same for every Q tried

    def evaluate(logq: float) -> tuple[bool, float]:
        d = _design(model, 10.0**logq, r)
        h = compensated_frf(model, d, f, plant_frf=plant)
        worst = float(np.max(deviation_db(h[in_band])))
        ok = worst <= flatness_db and noise_gain(d) <= max_noise_gain
        return ok, bandwidth_3db(f, h)

    grid = np.linspace(math.log10(bounds[0]), math.log10(bounds[1]), n_grid)
    bws: list[float] = []
    hit = None
    for i, g in enumerate(grid):
        ok, bw = evaluate(float(g))
        bws.append(bw)
        if ok:
            hit = i
            break
    if hit is None:
        widest = tune_q(model, r, bounds=bounds, f_max_hz=f_max_hz, max_noise_gain=max_noise_gain)
        raise InputDataError(
            f"tuning: no Q keeps the compensated FRF within ±{flatness_db:g} dB up to "
            f"{band_hz:g} Hz under the noise limit (the widest ±3 dB band is "
            f"{widest.bandwidth_hz:.0f} Hz at Q = {widest.q:.3g})"
        )
    lo, hi = (grid[hit - 1], grid[hit]) if hit > 0 else (grid[0], grid[0])
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        if evaluate(mid)[0]:
            hi = mid
        else:
            lo = mid
    d = _design(model, 10.0**hi, r)
    bw = bandwidth_3db(f, compensated_frf(model, d, f, plant_frf=plant))
    n = len(bws)
    return QTuning(10.0**hi, bw, noise_gain(d), 10.0 ** grid[:n], np.asarray(bws))


# ---------------------------------------------------------------------------------------------
# Robust design for position-dependent modes
# ---------------------------------------------------------------------------------------------

#: Relative mode-frequency uncertainty :func:`tune_robust` designs for when none is given (±2 %;
#: the feed estimators use it only with ``mode_shift_pct`` > 0, the default is nominal).
DEFAULT_MODE_SHIFT = 0.02
#: Added damping of the design model tried by :func:`tune_robust`, as fractions of the shift δ.
DAMPING_FRACTIONS = (0.0, 0.125, 0.25, 0.5, 1.0)


def mode_family(fit: RationalFit, shift: float, n: int = 9) -> list[RationalFit]:
    """The identified model with every mode frequency × κ, κ evenly in [1 − shift, 1 + shift].

    Parameters
    ----------
    fit : identified Φ_d (pole–residue form).
    shift : relative frequency uncertainty δ (0.02 = ±2 %), ≥ 0.
    n : members (odd n includes the nominal κ = 1); 1 gives the nominal model only.

    Notes
    -----
    Complex pole p → κ·p and residue ρ → κ·ρ (the term ρ/(s − p) + c.c. keeps its static gain,
    as ``ModalStateSpace.frequency_scaled`` keeps α/ω²); real poles (loop dynamics seen through the
    C3 torque, not structural modes) and the constant term are unchanged.
    """
    if not shift >= 0:
        raise InputDataError(f"mode family: shift must be >= 0, got {shift}")
    kappas = np.linspace(1.0 - shift, 1.0 + shift, n) if n > 1 else np.ones(1)
    return [fit.with_modes_scaled(float(k)) for k in kappas]


def robust_fit(fit: RationalFit, damping: float) -> RationalFit:
    """Design model with every complex pole moved left by ``damping·|p|`` (residues unchanged).

    Parameters
    ----------
    fit : identified Φ_d.
    damping : γ, dimensionless (added damping ratio, approximately: ζ → ζ + γ), ≥ 0.

    Notes
    -----
    If the relative frequency of a mode is uncertain, its pole moves along the imaginary axis,
    p → p + j|p|ε (≈ p·(1 + ε) for a lightly damped mode; the conjugate pole mirrored), and ε is
    Cauchy-distributed with scale γ, then for s on the imaginary axis (Re(s − p) > 0)
    ``E[ρ/(s − p − j|p|ε)] = ρ/(s − p + γ|p|)`` (close the contour in the half plane of the
    Cauchy pole ε = jγ): the mean FRF is the same mode with its pole moved left by γ|p|. The
    estimator inverting this mean plant does not trust the sharp resonance it cannot locate.
    Tested by quadrature in ``tests/test_robust_tuning.py``.
    """
    if not damping >= 0:
        raise InputDataError(f"robust model: damping must be >= 0, got {damping}")
    p = fit.complex_poles
    return replace(fit, complex_poles=p - damping * np.abs(p))


def _frf_eig(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    c: NDArray[np.float64],
    d: float,
    dt: float,
    f: NDArray[np.float64],
) -> NDArray[np.complex128]:
    """SISO discrete FRF ``c (zI − a)⁻¹ b + d`` on many frequencies via the eigenbasis of a."""
    lam, v = np.linalg.eig(a)
    vb = np.linalg.solve(v, b.reshape(-1))
    cv = c.reshape(-1) @ v
    z = np.exp(2j * np.pi * f * dt)
    return np.asarray((cv * vb) @ (1.0 / (z[None, :] - lam[:, None])) + d, dtype=complex)


def model_frf(model: StateSpaceModel, f_hz: ArrayLike) -> NDArray[np.complex128]:
    """FRF of a discrete SISO model (vectorised equivalent of ``model.frf(f)[:, 0, 0]``)."""
    if model.dt is None:
        raise InputDataError("model_frf needs a discrete model")
    f = np.asarray(f_hz, dtype=float)
    return _frf_eig(model.a, model.b, model.c, float(model.d[0, 0]), model.dt, f)


def estimator_frf(design: KalmanDesign, f_hz: ArrayLike, lag: int = 0) -> NDArray[np.complex128]:
    """FRF measured torque → τ̂_a of the filter (lag 0) or of the fixed-lag smoother, realigned.

    Parameters
    ----------
    design : steady-state Kalman design.
    f_hz : frequencies, Hz.
    lag : smoother lag L, samples (0: filtered estimate ``τ̂_a(k|k)``).

    Notes
    -----
    Smoother (:mod:`millsense.estimation.kalman.smoother`): ``τ̂(k−L|k) = S x̂(k−L|k−L−1) +
    Σ_j g_j e(k−L+j)``; advanced by L samples its FRF is ``S X̂_p(z) + Σ_j g_j z^j E(z)`` with
    ``X̂_p`` and ``E`` the predictor-state and innovation responses to the measurement.
    """
    f = np.asarray(f_hz, dtype=float)
    if lag == 0:
        filt = design.filter("filtered")
        return _frf_eig(filt.f, filt.g, filt.h, float(filt.j[0, 0]), design.dt, f)
    taps, _ = fixed_lag_gains(design, lag)
    acl, kp = design.closed_loop, design.k_predictor[:, 0]
    lam, v = np.linalg.eig(acl)
    vk = np.linalg.solve(v, kp)
    z = np.exp(2j * np.pi * f * design.dt)
    modal = vk[None, :] / (z[:, None] - lam[None, :])  # (nf, n): predicted state, eigenbasis
    e = 1.0 - modal @ (design.c[0] @ v)
    poly = np.polynomial.polynomial.polyval(z, taps[:, 0, 0])
    return np.asarray(modal @ (design.disturbance[0] @ v) + poly * e, dtype=complex)


def deviation_db(h: ArrayLike) -> NDArray[np.float64]:
    """``|20·log₁₀|H||``, dB (the deviation of a compensated FRF from 0 dB)."""
    return np.asarray(np.abs(20 * np.log10(np.maximum(np.abs(np.asarray(h)), 1e-300))))


def flatness_bound(
    plant_frfs: ArrayLike, f_hz: ArrayLike, f_max_hz: float, tol_db: float = 3.0
) -> tuple[float, float]:
    """Best worst-case flatness any LTI estimator can reach on a family of plants.

    Parameters
    ----------
    plant_frfs : (members, nf) FRFs of the family at ``f_hz``.
    f_hz : frequencies, Hz.
    f_max_hz : upper end of the flatness check, Hz (from 1 Hz).
    tol_db : band half-width, dB.

    Returns
    -------
    (worst_db, band_hz): the smallest achievable largest deviation over the family in
    1 Hz … ``f_max_hz``, dB; and the largest achievable common ±``tol_db`` band, Hz
    (``f_hz[-1]`` if never limited).

    Notes
    -----
    At each frequency an estimator is one complex gain C; the family's compensated values are
    ``Φ_κ·C``. ``max_κ |log|Φ_κ C||`` is smallest for ``|C| = (max|Φ_κ|·min|Φ_κ|)^(-1/2)`` and then
    equals ``½·20·log₁₀(max|Φ_κ| / min|Φ_κ|)``; no causal estimator does better.
    """
    mag = np.abs(np.atleast_2d(np.asarray(plant_frfs)))
    f = np.asarray(f_hz, dtype=float)
    half = 10.0 * np.log10(mag.max(axis=0) / np.maximum(mag.min(axis=0), 1e-300))
    sel = (f >= 1.0) & (f <= f_max_hz)
    worst = float(np.max(half[sel])) if np.any(sel) else 0.0
    out = np.nonzero((half >= tol_db) & (f >= 1.0))[0]
    return worst, float(f[out[0]]) if len(out) else float(f[-1])


@dataclass(frozen=True)
class RobustTuning:
    """Result of :func:`tune_robust`.

    Attributes
    ----------
    q : spectral density of τ̇_a, (N·m)²/s.
    damping : added damping γ of the design model (:func:`robust_fit`).
    shift : the relative mode-frequency uncertainty δ designed for.
    bandwidth_hz : smallest ±3 dB band over the family, Hz.
    nominal_bandwidth_hz : ±3 dB band on the identified model, Hz.
    worst_db : largest deviation over the family in 1 Hz … ``f_target_hz``, dB.
    nominal_worst_db : the same on the identified model, dB.
    nominal_error : RMS over 1 Hz … ``f_target_hz`` of ``|Φ_d·Φ_KF − 1|`` on the identified
        model (complex: magnitude and phase of the time-aligned estimate), dimensionless.
    bound_db, bound_band_hz : :func:`flatness_bound` of the family (no LTI estimator does better).
    noise_gain : white-noise gain of the filter.
    """

    q: float
    damping: float
    shift: float
    bandwidth_hz: float
    nominal_bandwidth_hz: float
    worst_db: float
    nominal_worst_db: float
    nominal_error: float
    bound_db: float
    bound_band_hz: float
    noise_gain: float


def tune_robust(
    fit: RationalFit,
    measurement: Callable[[RationalFit], StateSpaceModel],
    r: float,
    *,
    shift: float = DEFAULT_MODE_SHIFT,
    n_family: int = 9,
    damping_fractions: Sequence[float] = DAMPING_FRACTIONS,
    q: float | None = None,
    bounds: tuple[float, float] = (1.0, 1e7),
    q_per_decade: int = 4,
    f_max_hz: float = 1000.0,
    df_hz: float = 0.1,
    fine_to_hz: float = 300.0,
    f_target_hz: float = 180.0,
    lag: int = 0,
    max_noise_gain: float = math.sqrt(10.0),
    band_tolerance: float = 0.01,
) -> RobustTuning:
    """Q and design-model damping maximising the smallest ±3 dB band over a mode-shift family.

    Parameters
    ----------
    fit : identified Φ_d.
    measurement : builds the discrete τ_a → measurement model from a Φ_d (e.g.
        ``lambda m: feed_drive.measurement_model(m, lowpass_hz, dt)``).
    r : per-sample measurement variance, N²·m².
    shift : δ, relative mode-frequency uncertainty (0.02 = modes anywhere within ±2 %).
    n_family : members of :func:`mode_family`.
    damping_fractions : added damping γ tried, as fractions of δ (0 = the identified model).
    q : fixed Q, (N·m)²/s (only γ is chosen, the user's Q is not checked against the noise
        limit), or None to search Q too.
    bounds, q_per_decade : log grid of Q, (N·m)²/s.
    f_max_hz, df_hz, fine_to_hz : frequency grid 0 … f_max_hz, Hz, with step df_hz up to
        fine_to_hz (the lightly damped modes have half-power widths of about 1 Hz) and 1 Hz above.
    f_target_hz : target band of the axis, Hz: the tie-break between designs of equal family
        band is the nominal error over 1 Hz … f_target_hz.
    lag : smoother lag the estimator runs with (the criterion uses its FRF), samples.
    max_noise_gain : largest admissible white-noise gain (as :func:`tune_q`).
    band_tolerance : designs whose family band is within this fraction of the best are
        equivalent; among them the smallest RMS complex error ``|Φ_d·Φ_KF − 1|`` on the
        identified model over 1 Hz … f_target_hz wins (the family band is often capped by
        :func:`flatness_bound` for many designs, which then differ only in how well they
        compensate the identified model, in magnitude and phase: the smoothed estimate is time
        aligned), then the smallest Q.

    Notes
    -----
    Criterion: ``max_{γ,Q} min_κ bandwidth_3db(Φ_κ·Φ_KF(γ, Q))`` subject to the noise limit, with
    ``Φ_KF(γ, Q)`` the estimator designed on :func:`robust_fit` ``(fit, γ)``. With ``shift`` 0 the
    family is the nominal model alone and γ = 0 is chosen unless damping widens the band.
    """
    if not r > 0:
        raise InputDataError(f"tuning: R must be > 0, got {r}")
    fine = np.arange(0.0, min(fine_to_hz, f_max_hz), df_hz)
    f = np.concatenate([fine, np.arange(fine[-1] + 1.0, f_max_hz + 0.5, 1.0)])
    family = mode_family(fit, shift, n_family if shift > 0 else 1)
    plants = np.array([model_frf(measurement(m), f) for m in family])
    nominal = model_frf(measurement(fit), f)
    bound_db, bound_band = flatness_bound(plants, f, f_target_hz)
    tgt = (f >= 1.0) & (f <= f_target_hz)
    if q is None:
        lo, hi = math.log10(bounds[0]), math.log10(bounds[1])
        qs = 10.0 ** np.linspace(lo, hi, max(2, round((hi - lo) * q_per_decade) + 1))
    else:
        qs = np.array([float(q)])
    rows: list[tuple[float, float, float, float, float, float, float, float]] = []
    for frac in damping_fractions:
        gamma = float(frac) * shift
        model = measurement(robust_fit(fit, gamma))
        aug = augment_disturbance(model)
        for qi in qs:
            assert model.dt is not None
            d = design_kalman(aug, qi * model.dt, r)
            ng = noise_gain(d)
            if ng > max_noise_gain and q is None:
                continue
            est = estimator_frf(d, f, lag)
            band = min(bandwidth_3db(f, p * est) for p in plants)
            worst = max(float(np.max(deviation_db(p[tgt] * est[tgt]))) for p in plants)
            nom = nominal * est
            rows.append(
                (
                    band,
                    bandwidth_3db(f, nom),
                    float(np.max(deviation_db(nom[tgt]))),
                    float(np.sqrt(np.mean(np.abs(nom[tgt] - 1.0) ** 2))),
                    worst,
                    gamma,
                    float(qi),
                    ng,
                )
            )
    if not rows:
        raise InputDataError(
            f"robust tuning: no Q in {bounds} meets the noise gain limit {max_noise_gain:g}"
        )
    best_band = max(rw[0] for rw in rows)
    ok = [rw for rw in rows if rw[0] >= (1.0 - band_tolerance) * best_band]
    band, nom_band, nom_worst, nom_err, worst, gamma, qb, ng = min(
        ok, key=lambda rw: (rw[3], rw[6])
    )
    return RobustTuning(
        qb, gamma, shift, band, nom_band, worst, nom_worst, nom_err, bound_db, bound_band, ng
    )
