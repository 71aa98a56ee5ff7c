"""Φ_d = τ_c/τ_a of a table-load sweep through the estimator's own C3 stage (Aslan C5)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from millsense.estimation.feed.estimator import C3Torque
from millsense.estimation.feed.rigid_body import DriveModel
from millsense.estimation.kalman.rational_fit import RationalFit, fit_rational
from millsense.ident.frf import FrfEstimate, multisine_frf
from millsense.models.lugre import LuGre


@dataclass(frozen=True)
class SweepResult:
    """The simulated disturbance sweep: FRF τ_c/τ_a, its modal fit, the raw-current FRF."""

    frf: FrfEstimate
    fit: RationalFit


def fit_disturbance_path(
    load: NDArray[np.float64],
    current_a: NDArray[np.float64],
    speed_rad_s: NDArray[np.float64],
    drive: DriveModel,
    lowpass_hz: float,
    sample_rate_hz: float,
    *,
    period_samples: int | None = None,
    lugre: LuGre | None = None,
    fit_band_hz: tuple[float, float] = (3.0, 260.0),
    settle_samples: int = 0,
    history: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    welch_resolution_hz: float = 1.0,
) -> SweepResult:
    """Φ_d = τ_c/τ_a of a table-load sweep from the CNC's current and speed (Aslan C5).

    The response is the estimator's own C3 torque (:class:`C3Torque` of ``drive``, ``lugre``,
    ``lowpass_hz``), the input ``τ_a = (r_g/η)·F`` of the measured table load F; the FRF
    (multisine over whole periods, first discarded, when ``period_samples`` is given, Welch
    otherwise) is divided by the known low-pass response and fitted by
    :func:`~millsense.estimation.kalman.rational_fit.fit_rational` on the bilinear-warped axis of
    the
    sample rate (order automatic), so that the estimator's Tustin model reproduces the sampled
    relation (decision "Discretisation of the identified disturbance model").

    Parameters
    ----------
    load : applied table load, N (N·m rotary), aligned with ``current_a``/``speed_rad_s``.
    current_a, speed_rad_s : CNC current command, A, and motor speed, rad/s.
    drive, lowpass_hz, lugre : the estimator's C3 front end.
    sample_rate_hz : CNC rate, Hz.
    period_samples : multisine period, or None (Welch at ``welch_resolution_hz``).
    fit_band_hz : lines fitted, Hz.
    settle_samples : samples of ``history`` run through the C3 stage first (its filter state).
    history : (current, speed) before the record, or None.

    Raises
    ------
    InputDataError
        Records of different lengths, or fewer than 8 lines in ``fit_band_hz``.
    """
    from millsense.core.errors import InputDataError
    from millsense.ident.frf import welch_frf

    fs = sample_rate_hz
    if not len(load) == len(current_a) == len(speed_rad_s):
        raise InputDataError(
            f"disturbance path: load, current and speed differ in length "
            f"({len(load)}, {len(current_a)}, {len(speed_rad_s)})"
        )
    c3 = C3Torque(drive, lowpass_hz, fs, lugre)
    if history is not None and settle_samples > 0:
        c3.process(history[0][-settle_samples:], history[1][-settle_samples:])
    tau = c3.process(current_a, speed_rad_s)
    tau_a = drive.transmission / drive.efficiency * np.asarray(load, dtype=float)
    names = ("tau_a", "tau_c")
    if period_samples is not None:
        est = multisine_frf(tau_a, tau, fs, period_samples, skip_periods=1, names=names)
    else:
        est = welch_frf(tau_a, tau, fs, resolution_hz=welch_resolution_hz, names=names)
    _, lp = signal.sosfreqz(c3.sos, worN=est.freq_hz, fs=fs)
    est = replace(est, h1=est.h1 / lp, h2=est.h2 / lp)
    sel = (est.freq_hz >= fit_band_hz[0]) & (est.freq_hz <= fit_band_hz[1])
    fit = fit_rational(
        est.freq_hz[sel],
        est.h1[sel],
        coherence=est.coherence[sel],
        max_pairs=16,
        warped_fs_hz=fs,
    )
    return SweepResult(est, fit)
