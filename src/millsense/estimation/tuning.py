"""Automatic tuning of the disturbance Kalman filter (the thesis tuned Q by hand).

- R (Aslan §3.3: "RMS of the torque fluctuation in an air cut"): :func:`air_cut_variance`, the
  per-sample variance of the estimator's own torque measurement during an air cut, after the
  slow trend is removed (docs/decisions.md, "Units of Q and R": R is a variance).
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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, signal

from millsense.core.errors import InputDataError
from millsense.estimation.kalman import (
    KalmanDesign,
    StateSpaceModel,
    augment_disturbance,
    bandwidth_3db,
    compensated_frf,
    design_kalman,
)


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


def noise_gain(design: KalmanDesign) -> float:
    """RMS of the filtered disturbance estimate per unit RMS of white measurement noise.

    ``sqrt(Σ h_k²)`` of the impulse response of the frozen-gain filter ``y → τ̂_a(k|k)``,
    computed exactly from the discrete Lyapunov equation of the filter
    (:meth:`~millsense.estimation.lti_filter.LinearFilter.output_covariance`).
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
    plants: Sequence[StateSpaceModel] = (),
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
    plants : further plants the design must compensate (robust tuning, e.g. the identified
        modes shifted by the expected position dependence); the score is the smallest bandwidth
        over ``model`` and these.

    Notes
    -----
    Objective: ``−bandwidth_3db(f, Φ_d·Φ_KF(q))`` with Φ_d the design model itself; designs
    above the noise limit score 0 Hz. The best grid point is refined by a bounded Brent search on
    log₁₀ Q between its neighbours.
    """
    if not r > 0:
        raise InputDataError(f"tuning: R must be > 0, got {r}")
    f = np.linspace(0.0, f_max_hz, n_freq)

    def score(logq: float) -> float:
        d = _design(model, 10.0**logq, r)
        if noise_gain(d) > max_noise_gain:
            return 0.0
        return min(bandwidth_3db(f, compensated_frf(pl, d, f)) for pl in (model, *plants))

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
