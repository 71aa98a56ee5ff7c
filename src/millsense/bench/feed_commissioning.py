"""Feed-axis estimator model from simulated commissioning tests (Aslan C1, C2, C5).

:func:`identify_feed_axis` runs, on the drive simulator and reading only its CNC channels:
Coulomb + viscous friction from constant-velocity air moves (Aslan C1,
:mod:`millsense.ident.friction`) and the LuGre presliding stiffness and damping from an
open-loop rocking test (C2, :func:`identify_lugre`); the inertia by least squares on an
accelerating air move (:func:`identify_inertia`); Φ_d from a multisine table force applied
during a constant-velocity move or with the axis holding position (the thesis' hammer test, C5)
by :func:`millsense.ident.frf.multisine_frf` and
:func:`millsense.estimation.kalman.rational_fit.fit_rational` (:func:`disturbance_sweep`); R from an
air cut and Q by :mod:`millsense.estimation.feed.tuning`. The result is a
:class:`~millsense.estimation.feed.estimator.FeedAxisModel`.
K_t and η are the nameplate/catalogue values (the thesis takes K_t, J_e from TNCopt and η from
the catalogue for the linear axes): a current-only test cannot separate K_t from a load.

Issue 12 (docs/decisions/0992-bench-reads-the-nameplate.md): every value the estimator is
*given* — K_t, r_g, η, encoder counts — comes from the nameplate axis table (``nameplate``, a
:class:`~millsense.core.config.FeedAxisConfig` of ``millsense/data/machines/<name>.toml``), never
from the simulated drive; the simulated drive ``params`` is only the machine that is driven
(commands in, CNC channels out).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Literal

import numpy as np
from scipy import signal

from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError
from millsense.estimation.feed.estimator import (
    DEFAULT_FRICTION_SMOOTHING_RAD_S,
    DEFAULT_LOWPASS_HZ,
    ROBUST_SHIFT,
    C3Torque,
    FeedAxisModel,
    OperatingCondition,
)
from millsense.estimation.feed.path_fit import SweepResult, fit_disturbance_path
from millsense.estimation.feed.rigid_body import DriveModel
from millsense.ident.frf import multisine_signal
from millsense.ident.friction import coulomb_viscous_from_moves
from millsense.models.friction import CoulombViscous
from millsense.models.lugre import LuGre
from millsense.simulator.commissioning import ramp_move, run_table_load_sweep
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim, constant_velocity_sweep

#: Motor speed of the constant-velocity identification move (sweep), rad/s.
SWEEP_SPEED_RAD_S = 10.0
#: Motor speed of the air cut that gives R for a moving axis, rad/s.
AIR_CUT_SPEED_RAD_S = 5.0


def identify_friction(
    params: FeedDriveParams,
    sample_rate_hz: float,
    speeds_rad_s: Sequence[float],
    seed: int = 0,
    *,
    nameplate: FeedAxisConfig,
) -> CoulombViscous:
    """Coulomb + viscous friction from constant-velocity air moves in both directions (C1);
    torque = nameplate K_t × measured current."""
    sp = np.asarray(speeds_rad_s, dtype=float)
    sp = np.concatenate([sp, -sp])
    tau, _ = constant_velocity_sweep(
        params,
        sp,
        sample_rate_hz,
        duration_s=0.6,
        seed=seed,
        torque_constant=nameplate.torque_constant_nm_a,
    )
    fit = coulomb_viscous_from_moves(sp, tau)
    return replace(fit, smoothing_rad_s=DEFAULT_FRICTION_SMOOTHING_RAD_S)


def identify_lugre(
    params: FeedDriveParams,
    friction: CoulombViscous,
    inertia: float,
    sample_rate_hz: float,
    *,
    frequency_hz: float = 5.0,
    fraction: float = 0.2,
    min_counts: float = 20.0,
    seed: int = 4,
    nameplate: FeedAxisConfig,
) -> LuGre | None:
    """LuGre friction (Aslan C2, Eq. 3.2–3.8) from the line fit and a presliding test.

    Static part: τ_coul and σ2 from the constant-velocity line fit; τ_stat = τ_coul (no Stribeck
    rise identified; v_s is then irrelevant and set to 0.05 rad/s). Presliding: with the servo
    open, a sinusoidal current of ``fraction·τ_coul/K_t`` at ``frequency_hz`` rocks the motor on
    its bristles; from the complex ratio T/Θ at that frequency (Eq. 3.6:
    ``Jθ'' + (σ1+σ2)θ' + σ0θ = u``): ``σ0 = Re(T/Θ) + J ω²`` and ``σ1 = Im(T/Θ)/ω − σ2``
    (σ1 floored at 0). Returns None when the rocking amplitude is below ``min_counts`` encoder
    counts: the bristle stiffness is then not resolved by the encoder (the rotary axes, σ0 of
    2–3·10⁴ N·m/rad, rock by about 2 counts) and the static model is used instead.
    """
    fs = sample_rate_hz
    n = round(2.0 * fs)
    t = np.arange(n) / fs
    w = 2 * math.pi * frequency_hz
    tau_amp = fraction * min(friction.coulomb_pos, friction.coulomb_neg)
    kt = nameplate.torque_constant_nm_a
    inj = tau_amp / kt * np.sin(w * t)
    sim = FeedDriveSim(replace(params, closed_loop=False), fs, seed=seed)
    res = sim.advance(np.zeros(n), np.zeros(n), np.zeros(n), inj)
    sel = slice(n // 2, n)
    basis = np.column_stack([np.sin(w * t[sel]), np.cos(w * t[sel]), np.ones(n - n // 2)])
    ct = np.linalg.lstsq(basis, kt * res["current"][sel], rcond=None)[0]
    ca = np.linalg.lstsq(basis, res["angle"][sel], rcond=None)[0]
    counts = abs(complex(ca[0], ca[1])) / (2 * math.pi / nameplate.encoder_counts_rev)
    if counts < min_counts:
        return None
    ratio = complex(ct[0], ct[1]) / complex(ca[0], ca[1])
    s0 = max(ratio.real + inertia * w**2, 1e-6)
    s1p, s1n = (
        max(ratio.imag / w - friction.viscous_pos, 0.0),
        max(ratio.imag / w - friction.viscous_neg, 0.0),
    )
    return LuGre(
        sigma0=(s0, s0),
        sigma1=(s1p, s1n),
        sigma2=(friction.viscous_pos, friction.viscous_neg),
        static=(friction.coulomb_pos, friction.coulomb_neg),
        coulomb=(friction.coulomb_pos, friction.coulomb_neg),
        stribeck_velocity=(0.05, 0.05),
    )


def identify_inertia(
    params: FeedDriveParams,
    friction: CoulombViscous,
    sample_rate_hz: float,
    *,
    speed_rad_s: float = 20.0,
    seed: int = 1,
    nameplate: FeedAxisConfig,
) -> float:
    """J_e (kg·m²) by least squares on an air move with a sinusoidal speed (2 Hz, ±50 %).

    ``K_t·I_nom − τ_f(ω) = J_e·dω/dt`` (Eq. 3.1 in air); dω/dt from the encoder speed by a
    central difference of the 20 Hz low-passed speed (zero phase, offline).
    """
    fs = sample_rate_hz
    n = round(1.5 * fs)
    t = np.arange(n) / fs
    w = 2 * math.pi * 2.0
    ramp = np.minimum(t / 0.1, 1.0)
    vel = speed_rad_s * (ramp + 0.5 * np.sin(w * t) * ramp)
    pos = np.cumsum(vel) / fs
    sim = FeedDriveSim(params, fs, seed=seed)
    res = sim.advance(pos, vel, np.zeros(n))
    sos = signal.butter(2, 20.0, fs=fs, output="sos")
    spd = signal.sosfiltfilt(sos, res["speed"])
    acc = np.gradient(spd, 1.0 / fs)
    lhs = nameplate.torque_constant_nm_a * res["current_cmd"] - friction.torque(res["speed"])
    lhs = signal.sosfiltfilt(sos, lhs)
    sel = slice(round(0.3 * fs), n - round(0.1 * fs))
    a, y = acc[sel], lhs[sel]
    a0, y0 = a - a.mean(), y - y.mean()
    return float(np.dot(a0, y0) / np.dot(a0, a0))


def disturbance_sweep(
    params: FeedDriveParams,
    drive: DriveModel,
    sample_rate_hz: float,
    lowpass_hz: float,
    *,
    force_rms: float,
    band_hz: tuple[float, float] = (2.0, 300.0),
    fit_band_hz: tuple[float, float] = (3.0, 260.0),
    speed_rad_s: float = SWEEP_SPEED_RAD_S,
    period_s: float = 1.0,
    n_periods: int = 13,
    seed: int = 2,
    lugre: LuGre | None = None,
    start_position: float = 0.0,
) -> SweepResult:
    """Φ_d = τ_c/τ_a from a multisine table load during a constant-velocity move (C5).

    ``speed_rad_s`` = 0 runs the sweep with the servo on and the axis holding position (the
    thesis' impact tests, servo on, axis at rest; decision "Holding axis: Φ_d and R identified
    at rest"). The load (a shaker on the table standing in for the thesis' hammer) is known; τ_a is
    ``(r_g/η)·F`` with the estimator's r_g, η. The response is the C3 torque of the estimator's
    own front end, low-passed; the FRF is divided by the known low-pass response, averaged over
    whole periods (first discarded) and fitted with
    :func:`~millsense.estimation.kalman.rational_fit.fit_rational` (order automatic).

    ``start_position`` (m, rad rotary: load position) is where the move starts (identification
    at a position along the stroke, :mod:`millsense.estimation.feed.schedule`).
    """
    fs = sample_rate_hz
    per = round(period_s * fs)
    load, _ = multisine_signal(fs, per, band_hz[0], band_hz[1], n_periods, rms=force_rms)
    res, _, lead = run_table_load_sweep(
        params, fs, load, speed_rad_s=speed_rad_s, seed=seed, start_position=start_position
    )
    return fit_disturbance_path(
        load,
        res["current_cmd"][lead:],
        res["speed"][lead:],
        drive,
        lowpass_hz,
        fs,
        period_samples=per,
        lugre=lugre,
        fit_band_hz=fit_band_hz,
        settle_samples=lead,
        history=(res["current_cmd"][:lead], res["speed"][:lead]),
    )


def identify_feed_axis(
    params: FeedDriveParams,
    axis: str,
    kind: Literal["linear", "rotary"],
    *,
    sample_rate_hz: float = 10_000.0,
    lowpass_hz: float = DEFAULT_LOWPASS_HZ,
    sweep_force_rms: float | None = None,
    moment_arm_m: float | None = None,
    tune: bool = True,
    q_bounds: tuple[float, float] = (1.0, 1e7),
    robust_shift: float = ROBUST_SHIFT,
    use_lugre: bool = True,
    seed: int = 0,
    condition: OperatingCondition = "moving",
    start_position: float = 0.0,
    sweep_speed_rad_s: float = SWEEP_SPEED_RAD_S,
    nameplate: FeedAxisConfig,
) -> tuple[FeedAxisModel, SweepResult]:
    """Identify a feed axis's estimator model from simulated commissioning tests.

    Parameters
    ----------
    params : the simulated drive (the "machine"; only its CNC channels are used).
    axis, kind : axis name and ``linear``/``rotary``.
    nameplate : the axis table of the nameplate machine file: K_t, lead (r_g), η and the
        encoder counts the estimator is given (decision 0992).
    sample_rate_hz : CNC rate, Hz.
    lowpass_hz : C3 low-pass corner, Hz.
    sweep_force_rms : RMS of the sweep load (N, or N·m rotary); default the load giving 3 N·m
        RMS of τ_a at the motor.
    moment_arm_m : Eq. 3.12 arm for a rotary force output.
    tune : choose Q by :func:`millsense.estimation.feed.tuning.tune_q` (else Q = 1000 (N·m)²/s).
    q_bounds : search range of Q, (N·m)²/s.
    use_lugre : identify LuGre friction (:func:`identify_lugre`) for the C3 stage (C2);
        otherwise the static Coulomb + viscous line fit is used.
    robust_shift : δ, relative uncertainty of the mode frequencies (position dependence): Q and
        the design damping are chosen by :func:`millsense.estimation.feed.tuning.tune_robust` to
        maximise the smallest ±3 dB band over the modes × κ, κ ∈ [1 − δ, 1 + δ]; 0 for the
        nominal :func:`~millsense.estimation.feed.tuning.tune_q`.
    seed : base seed of the simulated tests.
    condition : ``moving`` — the sweep runs during a constant-velocity move at
        ``SWEEP_SPEED_RAD_S`` and R comes from an air cut at ``AIR_CUT_SPEED_RAD_S`` (an axis
        that feeds while cutting); ``at_rest`` — the sweep and the R record run with the servo
        on and the axis holding position (an axis that holds while the others cut). Friction,
        J_e and the LuGre presliding test are the same in both.
    start_position : load position (m, rad rotary) where the sweep and the R record start
        (identification at a position along the stroke; friction and J_e moves start at 0).
    sweep_speed_rad_s : motor speed of the moving sweep, rad/s (a slower sweep stays closer to
        ``start_position``: 13.3 s × speed × r_g of travel).

    Returns
    -------
    (model, sweep): the identified model and the sweep (FRF and modal fit) it came from.

    Notes
    -----
    Nameplate values (``nameplate``, not the simulated drive's): K_t (motor data), r_g (lead),
    η (catalogue), encoder counts.
    Identified: friction (C1), J_e, Φ_d (C5), R (air cut), Q (bandwidth optimisation).

    Operating condition (decision "Holding axis: Φ_d and R identified at rest"): the measured
    path is ``τ_c,C3/τ_a`` of the estimator's own C3 stage, i.e. Φ_d plus whatever the C3
    friction model leaves of the friction the motor feels. In a move that residue is the small
    sliding (viscous) error; at rest the bristles (LuGre σ0, σ1, Eq. 3.2–3.3) carry part of the
    load through the servo-held motor, and the identified σ0, σ1 are amplitude-dependent, so the
    residue is a different linear path. Aslan identified Φ_d from impact tests with the servo on
    and the axis at rest; the model used for an axis must come from the condition it runs in.
    """
    from millsense.estimation.feed import tuning

    if condition not in ("moving", "at_rest"):
        raise ConfigError(
            f"identify {axis}: condition must be 'moving' or 'at_rest', got {condition!r}"
        )
    fs = sample_rate_hz
    np_ = nameplate
    fric = identify_friction(params, fs, (2.0, 5.0, 10.0, 20.0, 40.0), seed=seed, nameplate=np_)
    inertia = identify_inertia(params, fric, fs, seed=seed + 1, nameplate=np_)
    rg = np_.transmission_m_rad
    drive = DriveModel(inertia, np_.torque_constant_nm_a, rg, np_.efficiency, fric)
    lg = rg / np_.efficiency
    f_rms = sweep_force_rms if sweep_force_rms is not None else 3.0 / lg
    lugre = (
        identify_lugre(params, fric, inertia, fs, seed=seed + 4, nameplate=np_)
        if use_lugre
        else None
    )
    move_speed = sweep_speed_rad_s if condition == "moving" else 0.0
    sweep = disturbance_sweep(
        params,
        drive,
        fs,
        lowpass_hz,
        force_rms=f_rms,
        seed=seed + 2,
        lugre=lugre,
        speed_rad_s=move_speed,
        start_position=start_position,
    )
    modes = sweep.fit
    # R: air cut at a cutting feed (constant speed, no load), or holding position at rest
    n = round(1.0 * fs)
    pos, vel = ramp_move(AIR_CUT_SPEED_RAD_S if condition == "moving" else 0.0, n, fs)
    q0 = start_position / rg
    res = FeedDriveSim(params, fs, seed=seed + 3, initial_angle_rad=q0).advance(
        pos + q0, vel, np.zeros(n)
    )
    c3 = C3Torque(drive, lowpass_hz, fs, lugre)
    tau_air = c3.process(res["current_cmd"], res["speed"])
    r = tuning.air_cut_variance(tau_air[round(0.2 * fs) :])
    model = FeedAxisModel(
        axis, kind, drive, modes, lowpass_hz, r, 1000.0, fs, moment_arm_m, lugre, condition
    )
    if tune:
        model = model.tuned(robust_shift, q_bounds=q_bounds)
    return model, sweep
