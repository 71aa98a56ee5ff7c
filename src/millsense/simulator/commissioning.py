"""Simulated commissioning tests: the standard identification runs on a machine preset.

Each function runs :class:`~millsense.simulator.feed_drive.FeedDriveSim` or
:class:`~millsense.simulator.spindle.SpindleDriveSim` through one test and returns a
:class:`~millsense.core.recording.Recording` with the channels a CNC trace would give
(``<axis>/current_cmd``, ``<axis>/current``, ``<axis>/speed``, ``<axis>/angle``,
``<axis>/scale``, the commanded ``<axis>/velocity_ref`` and, for sweeps, the injected
``<axis>/injection``) plus ground truth under ``truth/``. ``metadata['test']`` names the test;
``metadata`` also carries what the identification needs to know about the test (the sweep
period in samples, the axis' transmission).

Tests (seed 000 C1/Ch. 3.2.1 and Ch. 5; seed 001 C8, C11):

- :func:`friction_test` — constant-velocity moves at several speeds, both directions;
- :func:`presliding_test` — current steps below breakaway with the loops open;
- :func:`acceleration_test` — back-and-forth trapezoidal moves;
- :func:`drive_sweep` — a periodic current injection (multisine) on a constant-velocity move;
- :func:`table_load_sweep` — a multisine table load (shaker) on a move or at rest, for Φ_d
  (:func:`run_table_load_sweep`, which the acceptance identification runs too);
- :func:`spindle_sweep` and :func:`spindle_friction_test` — velocity-loop sweep and
  constant-speed runs of the spindle;
- :func:`idle_runs` — repeated air cuts with the same trajectory and feed.

Every feed-axis test drives the plant ``millsense simulate`` runs: for a preset with a truth
(:data:`~millsense.simulator.truth_machine.TRUTH_PRESETS`) the coupled truth axis of
:func:`~millsense.simulator.truth_machine.truth_feed_params` with its substeps, else (or with
``ideal=True``, debugging only) the machine file's one-way model. The drive sweep's injection
amplitude is designed from the nameplate's J and K_t (:func:`nameplate_axis`, what a user
commissioning a real machine knows; decision 1790), the table-load sweep's level from its
efficiency and lead, the presliding steps from the breakaway the friction moves measured
(:func:`breakaway_from_friction_test`; decision 1799); the recordings' metadata carries the
transmission (the lead, a nameplate value); the identification then learns the truth from the
CNC channels. The realism layer's thermal friction drift
(time constant 600 s) is not applied to these runs of a few seconds each.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from millsense.core.config import FeedAxisConfig, MachineConfig
from millsense.core.errors import InputDataError
from millsense.core.recording import Recording
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.spindle import SpindleDriveSim
from millsense.simulator.truth_machine import TRUTH_PRESETS, load_truth, truth_feed_params
from millsense.simulator.truth_spindle import (
    TruthSpindle,
    TruthSpindleSim,
    has_truth_spindle,
    load_truth_spindle,
)

_CHANNELS = (
    ("current_cmd", "current_cmd", "A"),
    ("current", "current", "A"),
    ("speed", "speed", "rad/s"),
    ("angle", "angle", "rad"),
    ("scale", "scale", "m"),
)
_TRUTH = (
    ("true_speed", "rad/s"),
    ("true_position", "m"),
    ("friction_torque", "N*m"),
)


def _recording(
    fs: float,
    axis_name: str,
    res: dict[str, np.ndarray],
    test: str,
    params: FeedDriveParams,
    extra: dict[str, np.ndarray],
    metadata: dict[str, object] | None = None,
    extra_units: dict[str, str] | None = None,
) -> Recording:
    meta: dict[str, object] = {
        "test": test,
        "axis": axis_name,
        "source": f"simulated {test} ({axis_name})",
        "transmission_m_rad": params.transmission,
    }
    meta.update(metadata or {})
    rec = Recording(fs, metadata=meta)
    for key, name, unit in _CHANNELS:
        rec.add_channel(f"{axis_name}/{name}", res[key], unit)
    for name, arr in extra.items():
        unit = (extra_units or {}).get(name, "A" if name == "injection" else "rad/s")
        rec.add_channel(f"{axis_name}/{name}", arr, unit)
    for key, unit in _TRUTH:
        rec.add_channel(f"truth/{axis_name}/{key}", res[key], unit)
    return rec


def _params(cfg: MachineConfig, axis_name: str, **kw: object) -> FeedDriveParams:
    """The simulator's machine-file model of the axis (test design and metadata)."""
    return FeedDriveParams.from_config(cfg.axis(axis_name), **kw)  # type: ignore[arg-type]


def nameplate_axis(cfg: MachineConfig, axis_name: str) -> FeedAxisConfig:
    """The axis as a commissioning engineer knows it before any test: the nameplate machine
    file of the same name (``millsense/data/machines/<name>.toml``, loaded as the estimators
    load it: catalogue K_t, J, η, lead, CNC settings), else, for a machine without a separate
    nameplate (a user's own file), ``cfg`` itself (decision 1790)."""
    from millsense.core.errors import ConfigError
    from millsense.core.presets import load_preset

    try:
        return load_preset(MachineConfig, cfg.name).axis(axis_name)
    except ConfigError:
        return cfg.axis(axis_name)


def plant_params(
    cfg: MachineConfig,
    axis_name: str,
    *,
    ideal: bool = False,
    drive: FeedDriveParams | None = None,
    **kw: object,
) -> tuple[FeedDriveParams, int]:
    """The plant the tests drive and its kernel substeps: ``drive`` when given (a drive the
    bench built, e.g. with an unmodelled mode), else the simulator's truth of the axis when the
    preset has one and not ``ideal`` (as :class:`~.machine.MachineSimulator` builds it), else
    the simulator's machine-file model (``kw`` go to ``FeedDriveParams.from_config``)."""
    if drive is not None:
        return drive, 10
    if not ideal and cfg.name in TRUTH_PRESETS:
        truth = load_truth(cfg.name)
        if axis_name in truth:
            return truth_feed_params(cfg.axis(axis_name), truth[axis_name]), truth[
                axis_name
            ].substeps
    return _params(cfg, axis_name, **kw), 10


def _profile(vel: np.ndarray, fs: float, start_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    pos = start_rad + np.concatenate([[0.0], np.cumsum(vel[:-1])]) / fs
    return pos, vel


def friction_test(
    cfg: MachineConfig,
    axis_name: str,
    speeds_rad_s: np.ndarray,
    *,
    hold_s: float = 1.0,
    ramp_s: float = 0.1,
    seed: int = 0,
    drive: FeedDriveParams | None = None,
    friction: str = "auto",
    ideal: bool = False,
) -> Recording:
    """Constant-velocity moves at each speed (motor rad/s, signed), one after the other.

    Between plateaus the velocity ramps linearly over ``ramp_s``; ``velocity_ref`` records the
    command (the identification finds the plateaus from it).
    """
    fs = cfg.sample_rate_hz
    p = _params(cfg, axis_name, friction=friction)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal, drive=drive, friction=friction)
    n_hold, n_ramp = round(hold_s * fs), round(ramp_s * fs)
    pieces = []
    prev = 0.0
    for v in np.asarray(speeds_rad_s, dtype=float):
        pieces.append(np.linspace(prev, v, n_ramp, endpoint=False))
        pieces.append(np.full(n_hold, v))
        prev = v
    pieces.append(np.linspace(prev, 0.0, n_ramp))
    vel = np.concatenate(pieces)
    pos, vel = _profile(vel, fs)
    sim = FeedDriveSim(plant, fs, substeps=sub, seed=seed)
    res = sim.advance(pos, vel, np.zeros(len(vel)))
    return _recording(fs, axis_name, res, "friction", p, {"velocity_ref": vel})


def breakaway_from_friction_test(
    rec: Recording, axis_name: str, torque_constant_nm_a: float
) -> float:
    """The breakaway torque a commissioning engineer reads off the friction moves
    (:func:`friction_test`), N·m: the mean motor torque (``torque_constant_nm_a`` × the current
    command) over the second half of the slowest plateau, the smaller of its two directions
    (the Coulomb level past the Stribeck hump, what ``identify friction`` checks the presliding
    steps against; decision 1041)."""
    vel = np.asarray(rec[f"{axis_name}/velocity_ref"], dtype=np.float64)
    cur = np.asarray(rec[f"{axis_name}/current_cmd"], dtype=np.float64)
    # plateaus: runs of one non-zero command at least 0.2 s long (the ramps between them change
    # every sample)
    edges = np.flatnonzero(np.diff(vel) != 0.0) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(vel)]])
    long_ = (stops - starts >= 0.2 * rec.sample_rate_hz) & (vel[starts] != 0.0)
    if not long_.any():
        raise ValueError(f"friction test of {axis_name}: no plateau of 0.2 s")
    slowest = float(np.min(np.abs(vel[starts[long_]])))
    levels = []
    for a, b in zip(starts[long_], stops[long_], strict=True):
        if abs(vel[a]) == slowest:
            levels.append(abs(float(np.mean(cur[(a + b) // 2 : b]))) * torque_constant_nm_a)
    return min(levels)


def presliding_test(
    cfg: MachineConfig,
    axis_name: str,
    *,
    breakaway_nm: float,
    fraction: float = 0.5,
    step_s: float = 0.05,
    seed: int = 0,
    drive: FeedDriveParams | None = None,
    ideal: bool = False,
) -> Recording:
    """Current steps of ±``fraction``·breakaway and back to zero, position/velocity loops open.

    Pattern (in units of the step): +1, 0, −1, 0, +0.6, −0.6, +0.3, 0, each ``step_s`` long.
    ``breakaway_nm`` is the breakaway torque measured in the friction moves
    (:func:`breakaway_from_friction_test`: ``identify friction`` checks the steps against it,
    so a level above the Coulomb torque would be refused, decision 1041); it becomes a current
    with the nameplate's K_t (:func:`nameplate_axis`): the test is designed from what the
    engineer has measured and knows, never from the simulator's friction table (decision 1799).
    """
    fs = cfg.sample_rate_hz
    p = _params(cfg, axis_name)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal, drive=drive)
    plant = replace(plant, closed_loop=False)
    if not (breakaway_nm > 0 and math.isfinite(breakaway_nm)):
        raise ValueError(f"presliding test of {axis_name}: breakaway {breakaway_nm} N·m")
    level = fraction * breakaway_nm / nameplate_axis(cfg, axis_name).torque_constant_nm_a
    n = round(step_s * fs)
    inj = np.repeat(np.array([1.0, 0.0, -1.0, 0.0, 0.6, -0.6, 0.3, 0.0]), n) * level
    z = np.zeros(len(inj))
    res = FeedDriveSim(plant, fs, substeps=sub, seed=seed).advance(z, z, z, inj)
    return _recording(fs, axis_name, res, "presliding", p, {"injection": inj}, {"step_samples": n})


def acceleration_test(
    cfg: MachineConfig,
    axis_name: str,
    *,
    speeds_rad_s: tuple[float, ...] = (10.0, 20.0, 40.0),
    accel_rad_s2: float = 600.0,
    cruise_s: float = 0.05,
    seed: int = 0,
    drive: FeedDriveParams | None = None,
    ideal: bool = False,
) -> Recording:
    """Back-and-forth trapezoidal moves (accelerate, cruise, decelerate, reverse) per speed.

    Several cruise speeds separate Coulomb from viscous friction in the regression.
    """
    fs = cfg.sample_rate_hz
    p = _params(cfg, axis_name)
    pieces = []
    for v in speeds_rad_s:
        n_acc = max(2, round(v / accel_rad_s2 * fs))
        ramp = np.arange(n_acc) / n_acc * v
        one = np.concatenate(
            [ramp, np.full(round(cruise_s * fs), v), ramp[::-1], np.zeros(round(0.02 * fs))]
        )
        pieces += [one, -one]
    vel = np.concatenate(pieces)
    pos, vel = _profile(vel, fs)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal, drive=drive)
    res = FeedDriveSim(plant, fs, substeps=sub, seed=seed).advance(pos, vel, np.zeros(len(vel)))
    return _recording(fs, axis_name, res, "acceleration", p, {"velocity_ref": vel})


def shaped_multisine(
    sample_rate_hz: float,
    period_samples: int,
    f_lo_hz: float,
    f_hi_hz: float,
    corner_hz: float,
    amplitude: float,
    n_periods: int,
    exponent: float = 1.0,
) -> np.ndarray:
    """Schroeder-phase multisine whose line amplitudes rise as ``min(1, f/corner)^exponent``.

    The peak of one period is scaled to ``amplitude``. A rising spectrum keeps the velocity
    response of a current injection small at low frequencies (no reversal on a slow move).
    """
    df = sample_rate_hz / period_samples
    k = np.arange(max(1, math.ceil(f_lo_hz / df)), math.floor(f_hi_hz / df) + 1)
    idx = np.arange(len(k))
    spec = np.zeros(period_samples // 2 + 1, dtype=complex)
    spec[k] = np.minimum(1.0, k * df / corner_hz) ** exponent * np.exp(
        -1j * np.pi * idx * (idx - 1) / len(k)
    )
    x = np.fft.irfft(spec, n=period_samples)
    x *= amplitude / float(np.max(np.abs(x)))
    return np.tile(x, n_periods)


def drive_sweep(
    cfg: MachineConfig,
    axis_name: str,
    *,
    feed_rad_s: float = 40.0,
    period_s: float = 0.5,
    n_periods: int = 8,
    f_lo_hz: float = 2.0,
    f_hi_hz: float = 1000.0,
    amplitude_a: float | None = None,
    seed: int = 0,
    ideal: bool = False,
) -> Recording:
    """Periodic current injection (shaped multisine) during a constant-velocity move.

    ``amplitude_a`` defaults to the current that drives the rigid axis at 16 000 rad/s² (less
    below 150 Hz, :func:`shaped_multisine`), reduced until the rigid-body speed excursion is
    half the feed, both with the nameplate's J and K_t (:func:`nameplate_axis`). The first
    period is a run-in.
    """
    fs = cfg.sample_rate_hz
    axis = cfg.axis(axis_name)
    p = _params(cfg, axis_name)
    # designed from the nameplate's J and K_t (what the engineer knows), not the simulator's
    name = nameplate_axis(cfg, axis_name)
    j_n, kt_n = name.inertia_kg_m2, name.torque_constant_nm_a
    per = round(period_s * fs)
    amp = amplitude_a if amplitude_a is not None else 16000.0 * j_n / kt_n
    inj = shaped_multisine(fs, per, f_lo_hz, f_hi_hz, 150.0, amp, n_periods, 1.5)
    # keep the rigid-body speed excursion K_t/J·∫i below half the feed: the velocity must not
    # reverse, or Coulomb friction distorts the low-frequency FRF
    dev = np.cumsum(inj[:per]) / fs * kt_n / j_n
    inj *= min(1.0, 0.5 * abs(feed_rad_s) / max(float(np.ptp(dev)) / 2.0, 1e-300))
    vel = np.full(len(inj), feed_rad_s)
    pos, vel = _profile(vel, fs)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal)
    res = FeedDriveSim(plant, fs, substeps=sub, seed=seed).advance(
        pos, vel, np.zeros(len(inj)), inj
    )
    return _recording(
        fs,
        axis_name,
        res,
        "drive_sweep",
        p,
        {"injection": inj, "velocity_ref": vel},
        {
            "period_samples": per,
            "lead_m": (axis.lead_mm_rev or 0.0) * 1e-3,
            "current_bandwidth_hz": axis.current_bandwidth_hz,
        },
    )


def ramp_move(
    v: float, n: int, fs: float, accel_time_s: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a move from rest to ``v`` (constant acceleration over
    ``accel_time_s``, then constant speed), ``n`` samples at ``fs`` (units of ``v``·s)."""
    t = np.arange(n) / fs
    vel = np.where(t < accel_time_s, v * t / accel_time_s, v)
    pos = np.where(
        t < accel_time_s,
        0.5 * v * t**2 / accel_time_s,
        0.5 * v * accel_time_s + v * (t - accel_time_s),
    )
    return pos, vel


def run_table_load_sweep(
    params: FeedDriveParams,
    sample_rate_hz: float,
    load: np.ndarray,
    *,
    speed_rad_s: float,
    lead_s: float = 0.3,
    seed: int = 2,
    start_position: float = 0.0,
    substeps: int = 10,
) -> tuple[dict[str, np.ndarray], np.ndarray, int]:
    """The drive under a known table load (a shaker on the table) while it moves or holds.

    The axis starts at ``start_position`` (load position, m; rad rotary), ramps to
    ``speed_rad_s`` (motor; 0 holds position) by :func:`ramp_move`, and ``load`` (table load,
    N or N·m, positive resisting +motion) is applied after ``lead_s`` of run-in.

    Returns
    -------
    (simulator result over run-in + load, commanded motor speed, run-in samples).
    """
    fs = sample_rate_hz
    lead = round(lead_s * fs)
    pos, vel = ramp_move(speed_rad_s, len(load) + lead, fs)
    q0 = start_position / params.transmission
    sim = FeedDriveSim(params, fs, substeps=substeps, seed=seed, initial_angle_rad=q0)
    res = sim.advance(pos + q0, vel, np.concatenate([np.zeros(lead), load]))
    return res, vel, lead


def table_load_sweep(
    cfg: MachineConfig,
    axis_name: str,
    *,
    speed_rad_s: float = 10.0,
    torque_rms_nm: float = 3.0,
    period_s: float = 1.0,
    n_periods: int = 13,
    f_lo_hz: float = 2.0,
    f_hi_hz: float = 300.0,
    lead_s: float = 0.3,
    seed: int = 2,
    drive: FeedDriveParams | None = None,
    ideal: bool = False,
) -> Recording:
    """Multisine table load (a shaker on the table, its force measured) during a move (C5).

    The disturbance path Φ_d = τ_c/τ_a of the feed estimator is identified from this test
    (``millsense identify path``; Aslan measured it with impact tests, servo on). The load
    (channel ``<axis>/load``, N or N·m at the table, positive resisting +motion) has
    ``torque_rms_nm`` RMS at the motor, equal lines over ``f_lo_hz``–``f_hi_hz``, Schroeder
    phases (:func:`shaped_multisine`, flat); the axis moves at ``speed_rad_s`` (motor; 0 holds
    position, the condition of an axis that holds while the others cut) by
    :func:`run_table_load_sweep`. The record starts after ``lead_s`` of run-in; the first
    period is a run-in of the multisine as well.
    """
    fs = cfg.sample_rate_hz
    axis = cfg.axis(axis_name)
    p = _params(cfg, axis_name)
    per = round(period_s * fs)
    load = shaped_multisine(fs, per, f_lo_hz, f_hi_hz, 1.0, 1.0, n_periods, 0.0)
    # the load's level from the nameplate's efficiency and transmission (decision 1799)
    name = nameplate_axis(cfg, axis_name)
    load *= torque_rms_nm * name.efficiency / name.transmission_m_rad / float(np.std(load[:per]))
    plant, sub = plant_params(cfg, axis_name, ideal=ideal, drive=drive)
    res, vel, lead = run_table_load_sweep(
        plant, fs, load, speed_rad_s=speed_rad_s, lead_s=lead_s, seed=seed, substeps=sub
    )
    res = {k: v[lead:] for k, v in res.items()}
    return _recording(
        fs,
        axis_name,
        res,
        "table_load_sweep",
        p,
        {"load": load, "velocity_ref": vel[lead:]},
        {
            "period_samples": per,
            "lead_m": (axis.lead_mm_rev or 0.0) * 1e-3,
            "speed_rad_s": speed_rad_s,
        },
        {"load": "N" if axis.kind == "linear" else "N*m"},
    )


def air_cut_test(
    cfg: MachineConfig,
    axis_name: str,
    *,
    speed_rad_s: float = 5.0,
    duration_s: float = 1.0,
    start_position: float = 0.0,
    seed: int = 3,
    drive: FeedDriveParams | None = None,
    ideal: bool = False,
) -> Recording:
    """An air cut: a move from rest to ``speed_rad_s`` (motor; 0 holds position) without load,
    from ``start_position`` (load position, m; rad rotary). The estimator's R comes from it
    (Aslan Eq. 3.28–3.30: the variance of the torque measurement in air)."""
    fs = cfg.sample_rate_hz
    p = _params(cfg, axis_name)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal, drive=drive)
    n = round(duration_s * fs)
    pos, vel = ramp_move(speed_rad_s, n, fs)
    q0 = start_position / p.transmission
    sim = FeedDriveSim(plant, fs, substeps=sub, seed=seed, initial_angle_rad=q0)
    res = sim.advance(pos + q0, vel, np.zeros(n))
    return _recording(
        fs, axis_name, res, "air_cut", p, {"velocity_ref": vel}, {"speed_rad_s": speed_rad_s}
    )


def idle_runs(
    cfg: MachineConfig,
    axis_name: str,
    *,
    feed_mm_min: float,
    travel_mm: float,
    n_runs: int = 3,
    load_n: float = 0.0,
    seed: int = 0,
    ideal: bool = False,
) -> list[Recording]:
    """Repeated moves over the same travel at the same feed (air cuts when ``load_n`` is 0).

    Each run starts at rest at position 0, accelerates over 0.05 s, cruises and stops at
    ``travel_mm``; ``load_n`` is a constant table load (a cut) during the whole run.
    """
    fs = cfg.sample_rate_hz
    p = _params(cfg, axis_name)
    r = p.transmission
    v = feed_mm_min * 1e-3 / 60.0 / r
    n_acc = round(0.05 * fs)
    n_cru = round((travel_mm * 1e-3 / r / v - 0.05) * fs)
    vel = np.concatenate([np.arange(n_acc) / n_acc * v, np.full(n_cru, v), np.zeros(n_acc)])
    pos, vel = _profile(vel, fs)
    plant, sub = plant_params(cfg, axis_name, ideal=ideal)
    out = []
    for k in range(n_runs):
        sim = FeedDriveSim(plant, fs, substeps=sub, seed=seed + k)
        res = sim.advance(pos, vel, np.full(len(vel), load_n))
        out.append(
            _recording(
                fs,
                axis_name,
                res,
                "idle" if load_n == 0.0 else "cut",
                p,
                {"velocity_ref": vel},
                {"feed_mm_min": feed_mm_min, "load_n": load_n},
            )
        )
    return out


def spindle_sim(
    params: SpindleDriveParams | TruthSpindle, sample_rate_hz: float = 10000.0
) -> SpindleDriveSim | TruthSpindleSim:
    """The simulated spindle drive: the truth (:mod:`.truth_spindle`) or Aslan's Ch. 5 model."""
    if isinstance(params, TruthSpindle):
        return TruthSpindleSim(params, sample_rate_hz)
    return SpindleDriveSim(params, sample_rate_hz)


def _drive_gains(params: SpindleDriveParams | TruthSpindle) -> dict[str, object]:
    """The velocity PI as the drive shows it (per rev/s of speed error, decision 0032)."""
    if isinstance(params, TruthSpindle):
        two_pi = 2 * math.pi
        kp, ki, unit = params.velocity_kp * two_pi, params.velocity_ki * two_pi, "rev/s"
    else:
        kp, ki, unit = params.velocity_kp, params.velocity_ki, params.velocity_error_unit
    return {
        "velocity_kp": kp,
        "velocity_ki": ki,
        "velocity_error_unit": unit,
        "velocity_period_s": params.velocity_period_s,
    }


def spindle_sweep(
    params: SpindleDriveParams | TruthSpindle,
    *,
    sample_rate_hz: float = 10000.0,
    speed_rad_s: float = 100.0,
    period_s: float = 0.5,
    n_periods: int = 6,
    f_lo_hz: float = 2.0,
    f_hi_hz: float = 2500.0,
    amplitude_rad_s: float = 5.0,
) -> Recording:
    """Multisine on the velocity reference around a constant speed (velocity loop closed).

    Channels ``spindle/speed_ref`` (rad/s), ``spindle/speed`` (measured, rad/s),
    ``spindle/current_cmd`` (I_nom, A), ``spindle/current`` (A); the multisine starts after a
    1 s run-up that is cut off.
    """
    fs = sample_rate_hz
    per = round(period_s * fs)
    ms = shaped_multisine(fs, per, f_lo_hz, f_hi_hz, 1e-9, amplitude_rad_s, n_periods)
    n_up = round(1.0 * fs)
    ref = np.concatenate([np.linspace(0.0, speed_rad_s, n_up), speed_rad_s + ms])
    res = spindle_sim(params, fs).advance(ref, np.zeros(len(ref)))
    rec = Recording(
        fs,
        metadata={
            "test": "spindle_sweep",
            "source": "simulated spindle sweep",
            "period_samples": per,
            **_drive_gains(params),
        },
    )
    cut = slice(n_up, None)
    rec.add_channel("spindle/speed_ref", ref[cut], "rad/s")
    rec.add_channel("spindle/speed", res["speed"][cut], "rad/s")
    rec.add_channel("spindle/current_cmd", res["current_cmd"][cut], "A")
    rec.add_channel("spindle/current", res["current"][cut], "A")
    return rec


def spindle_friction_test(
    params: SpindleDriveParams | TruthSpindle,
    speeds_rad_s: np.ndarray,
    *,
    sample_rate_hz: float = 10000.0,
    hold_s: float = 1.5,
    drive_torque_constants: tuple[float, float] | None = None,
) -> Recording:
    """Constant-speed runs of the spindle (ramps of 0.5 s between them).

    The channel ``spindle/torque_constant`` is the K_t the drive uses per speed range: the
    given ``drive_torque_constants`` (the drive's parameter, not the truth's K_t), else the
    model's own (Aslan's Ch. 5 model only; a truth needs them given).
    """
    fs = sample_rate_hz
    n_hold, n_ramp = round(hold_s * fs), round(0.5 * fs)
    pieces, prev = [], 0.0
    for v in np.asarray(speeds_rad_s, dtype=float):
        pieces += [np.linspace(prev, v, n_ramp, endpoint=False), np.full(n_hold, v)]
        prev = v
    ref = np.concatenate(pieces)
    res = spindle_sim(params, fs).advance(ref, np.zeros(len(ref)))
    if drive_torque_constants is None:
        if isinstance(params, TruthSpindle):
            raise InputDataError("spindle friction test: give the drive's torque constants")
        r1, r2 = params.ranges
        drive_torque_constants = (r1.torque_constant, r2.torque_constant)
    kt = np.asarray(drive_torque_constants, dtype=float)[res["speed_range"]]
    rec = Recording(
        fs, metadata={"test": "spindle_friction", "source": "simulated spindle friction test"}
    )
    rec.add_channel("spindle/speed_ref", ref, "rad/s")
    rec.add_channel("spindle/speed", res["speed"], "rad/s")
    rec.add_channel("spindle/current", res["current"], "A")
    rec.add_channel("spindle/torque_constant", kt, "N*m/A")
    return rec


def write_commissioning_set(
    machine: str,
    out_dir: str | Path,
    axis_name: str = "x",
    *,
    spindle: bool = True,
    ideal: bool = False,
) -> dict[str, Path]:
    """Run the standard tests on a machine preset and write each recording (HDF5).

    Parameters
    ----------
    machine : preset name (the simulator's own description of it,
        :func:`millsense.simulator.machine_file.simulator_machine`) or machine TOML path.
    out_dir : directory for the files (created).
    axis_name : the feed axis tested.
    spindle : also run the spindle tests when the machine has a spindle.
    ideal : debugging only — drive the machine file's model instead of the simulator's truth.

    Returns
    -------
    {test name: file path}. Friction moves use 16 speeds per direction from 0.1 to 30 rad/s
    (2 s each); the presliding test only runs for an axis with LuGre friction, the drive sweep
    for a ball-screw axis, the table-load sweeps (moving, at rest) for a rigid axis with
    disturbance modes, the
    idle runs (3 air cuts at 600 mm/min over 20 mm) for an axis with position-periodic
    disturbances.
    """
    from millsense.io.recording_file import write_recording
    from millsense.simulator.machine_file import simulator_machine

    cfg = simulator_machine(machine)
    axis = cfg.axis(axis_name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    speeds = np.geomspace(0.1, 30.0, 16)
    order = np.ravel(np.column_stack([speeds, -speeds]))
    recs: dict[str, Recording] = {
        "friction": friction_test(cfg, axis_name, order, hold_s=2.0, ideal=ideal),
        "acceleration": acceleration_test(cfg, axis_name, ideal=ideal),
    }
    if axis.friction is not None and axis.friction.sigma0_nm_rad is not None:
        # the steps' level from the breakaway the friction moves measured (decision 1799)
        kt = nameplate_axis(cfg, axis_name).torque_constant_nm_a
        brk = breakaway_from_friction_test(recs["friction"], axis_name, kt)
        recs["presliding"] = presliding_test(cfg, axis_name, breakaway_nm=brk, ideal=ideal)
    # an air cut at a cutting speed: the estimator's R (`identify noise`, Aslan Eq. 3.28-3.30)
    recs["air_cut"] = air_cut_test(cfg, axis_name, speed_rad_s=10.0, duration_s=1.5, ideal=ideal)
    if axis.ball_screw is not None:
        recs["drive_sweep"] = drive_sweep(cfg, axis_name, ideal=ideal)
    elif axis.disturbance_modes is not None:
        recs["table_load_sweep"] = table_load_sweep(cfg, axis_name, ideal=ideal)
        recs["table_load_sweep_at_rest"] = table_load_sweep(
            cfg, axis_name, speed_rad_s=0.0, ideal=ideal
        )
    if axis.periodic_disturbances:
        idle = idle_runs(cfg, axis_name, feed_mm_min=600.0, travel_mm=20.0, ideal=ideal)
        for k, rec in enumerate(idle):
            recs[f"idle_{k + 1}"] = rec
    if spindle and cfg.spindle is not None:
        # the truth spindle (decision 1210) unless ideal; the friction test's K_t is the drive's
        # parameter (the simulator machine file's [spindle]), never the truth's
        ideal_sp = SpindleDriveParams.from_config(cfg.spindle)
        sp: SpindleDriveParams | TruthSpindle = ideal_sp
        if not ideal and has_truth_spindle(cfg.name):
            sp = load_truth_spindle(cfg.name)
        recs["spindle_sweep"] = spindle_sweep(sp)
        recs["spindle_friction"] = spindle_friction_test(
            sp,
            np.array([50.0, 100.0, 150.0, 200.0, 250.0]),
            drive_torque_constants=(
                ideal_sp.ranges[0].torque_constant,
                ideal_sp.ranges[1].torque_constant,
            ),
        )
    paths = {}
    for name, rec in recs.items():
        p = out / f"{cfg.name}-{axis_name}-{name}.h5"
        write_recording(p, rec)
        paths[name] = p
    return paths
