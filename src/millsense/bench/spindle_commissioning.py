"""Spindle observer identification from simulated commissioning tests (Aslan C10, Ch. 5)."""

from __future__ import annotations

import math

import numpy as np

from millsense.estimation.kalman.design import KalmanDesign
from millsense.estimation.kalman.rational_fit import fit_rational
from millsense.estimation.spindle_observer import (
    SpindleIdentification,
    SpindleTorqueObserver,
    torque_lag_s,
)
from millsense.ident.frf import multisine_frf, multisine_signal
from millsense.ident.friction import fit_line
from millsense.models.friction import CoulombViscous
from millsense.models.spindle_plant import SpindleDriveParams, velocity_decimation
from millsense.simulator.commissioning import spindle_sim
from millsense.simulator.truth_spindle import TruthSpindle
from millsense.streaming.block import Chunk


def identify_spindle(
    params: SpindleDriveParams | TruthSpindle,
    *,
    velocity_period_s: float,
    speed_rpm: float = 0.0,
    sample_rate_hz: float = 10_000.0,
    torque_rms_nm: float = 5.0,
    current_noise_a: float = 0.0,
    n_pairs: int = 10,
    period_s: float = 0.5,
    n_periods: int = 13,
    seed: int = 0,
) -> SpindleIdentification:
    """Identify ``G_dτ = I_nom/τ_d`` from a simulated multisine torque test (Aslan C10).

    Parameters
    ----------
    params : the simulated spindle drive — the truth (:mod:`millsense.simulator.truth_spindle`)
        or Aslan's Ch. 5 model; only I_nom is read from it.
    velocity_period_s : the CNC's velocity-loop period, s: the rate I_nom is held at, from the
        drive's data (the nameplate machine file's ``velocity_loop_period_ms``), never from the
        simulated drive (issue 12).
    speed_rpm : spindle speed during the test, rev/min (selects the speed range).
    sample_rate_hz : CNC sample rate, Hz (a multiple of the velocity-loop rate).
    torque_rms_nm : RMS of the multisine disturbance torque, N·m (lines 2 Hz … Nyquist).
    current_noise_a : white noise added to the recorded I_nom, A (the measurement noise of the
        test; also the noise of the air run that gives R).
    n_pairs : starting complex pairs of the rational fit.
    period_s, n_periods : multisine period, s, and periods (the first is discarded).
    seed : noise seed.
    """
    m = velocity_decimation(velocity_period_s, sample_rate_hz, "spindle")
    fv = sample_rate_hz / m
    per = round(period_s * fv)
    # the torque changes every CNC sample, as a cut's does (a tap's force is continuous): the
    # multisine's lines (2 Hz … 0.4996·fv) at the CNC rate, read at the velocity-loop instants.
    # Held over the velocity period instead, it gives the loop's response to a held torque:
    # on the truth 3.3 dB above its response to a cut's torque at 1.94 kHz, 4.3 dB at 2.28 kHz
    # (decision 1696)
    u_fast, _ = multisine_signal(sample_rate_hz, per * m, 2.0, 0.4996 * fv, n_periods,
                                 rms=torque_rms_nm)  # fmt: skip
    u = u_fast[::m]
    rng = np.random.default_rng(seed)
    lead = round((0.8 if speed_rpm == 0 else 2.0) * fv)
    w = speed_rpm * 2 * math.pi / 60
    sim = spindle_sim(params, sample_rate_hz)
    n = (lead + len(u)) * m
    ramp = np.minimum(np.arange(n) / (0.3 * sample_rate_hz), 1.0) * w
    tau = np.concatenate([np.zeros(lead * m), u_fast])
    out = sim.advance(ramp, tau)
    inom = out["current_cmd"][::m] + rng.normal(0.0, current_noise_a, n // m)
    air = inom[lead - round(0.4 * fv) : lead]  # at speed, before the excitation: R
    r = float(np.var(air - air.mean()))
    est = multisine_frf(u, inom[lead:], fv, per, skip_periods=1, names=("tau_d", "I_nom"))
    lag = torque_lag_s(est.freq_hz, est.h1)
    fit = fit_rational(
        est.freq_hz,
        est.h1 * np.exp(2j * np.pi * est.freq_hz * lag),
        n_pairs=n_pairs,
        coherence=est.coherence,
        warped_fs_hz=fv,
    )
    return SpindleIdentification(est, fit, fit.discrete_model(1.0 / fv), max(r, 1e-12), speed_rpm,
                                 lag)  # fmt: skip


def identify_spindle_friction(
    params: SpindleDriveParams | TruthSpindle,
    designs: dict[int, KalmanDesign],
    *,
    range_switch_rpm: float | None,
    speeds_rpm: tuple[float, ...] = (500.0, 1500.0, 2500.0, 3000.0, 4000.0, 5000.0, 6000.0),
    sample_rate_hz: float = 10_000.0,
    current_noise_a: float = 0.0,
    seed: int = 5,
) -> CoulombViscous:
    """Spindle friction seen by the observer, from air runs at constant speed (Eq. 5.2).

    At constant speed in air the observer's torque estimate is the friction torque
    ``τ_coul,S + B_eS·Ω`` (it enters the loop exactly like τ_d); the mean estimate over the
    steady half of each run, per speed, is fitted by :func:`millsense.ident.friction.fit_line`
    (one direction; the same values are used for both). The observer subtracts it so that
    τ̂_d is the cutting torque (C14 needs the cutting part only).
    """
    speeds, torques = [], []
    rng = np.random.default_rng(seed)
    for rpm in speeds_rpm:
        w = rpm * 2 * math.pi / 60
        n = round(1.2 * sample_rate_hz)
        ref = np.minimum(np.arange(n) / (0.3 * sample_rate_hz), 1.0) * w
        out = spindle_sim(params, sample_rate_hz).advance(ref, np.zeros(n))
        inom = out["current_cmd"] + rng.normal(0.0, current_noise_a, n)
        design = designs[speed_range(rpm, range_switch_rpm)]
        obs = SpindleTorqueObserver(design, sample_rate_hz)
        obs.reset(sample_rate_hz)
        data = {"spindle/current_cmd": inom}
        tau = obs.process(Chunk(0, sample_rate_hz, 0.0, data)).channels["spindle/torque_est"]
        speeds.append(float(np.mean(out["speed"][n // 2 :])))
        torques.append(float(np.mean(tau[n // 2 :])))
    line = fit_line(np.asarray(speeds), np.asarray(torques))
    return CoulombViscous(line.intercept, line.intercept, line.slope, line.slope, 1.0)


def speed_range(rpm: float, range_switch_rpm: float | None) -> int:
    """The spindle's speed range at ``rpm`` (0: range 1, 1: range 2 from ``range_switch_rpm``
    on; None: one range), as the drive's data give it."""
    return 1 if range_switch_rpm is not None and abs(rpm) >= range_switch_rpm else 0
