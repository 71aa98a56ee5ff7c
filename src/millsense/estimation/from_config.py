"""Estimator blocks built from a machine configuration (``millsense estimate``).

Every estimator is built from the machine file alone — the values a user merged into it from
``millsense identify`` fragments plus the nameplate data — never from the simulator. Each block's
outputs are renamed to ``est/{method}/{axis}/load`` (load resisting +motion: N on a linear
axis, N·m at the table on a rotary one; the sign and unit of the simulator's
``truth/{axis}/load``), so several methods can run side by side in one pipeline.

Methods
-------
``feed``  Kalman-compensated feed-drive estimator (Aslan C2–C7,
          :class:`~millsense.estimation.feed.estimator.FeedAxisEstimator`) from
          :meth:`~millsense.estimation.feed.estimator.FeedAxisModel.from_config`; with
          ``harmonic_teeth`` also the tooth harmonics of the commanded spindle speed.
``raw``   rigid-body inverse dynamics of the current (Aslan C3, Eq. 3.10–3.11,
          :class:`~millsense.estimation.feed.rigid_body.RigidBodyForceEstimator`).
``medob`` multi-encoder DOB of a ball-screw axis (Yamada,
          :class:`~millsense.estimation.dob.observers.MEDOBBlock`) from ``[axes.x.ball_screw]``,
          dead times and current-loop bandwidth.
``spindle`` spindle torque observer (Aslan C11, :class:`~millsense.estimation.spindle_observer.
          SpindleTorqueObserver`) on G_dτ (Eq. 5.12) modelled from ``[spindle]``
          (:func:`spindle_observer_from_config`); output ``est/spindle/spindle/load``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from millsense.core.config import MachineConfig
from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk

if TYPE_CHECKING:
    from millsense.estimation.spindle_dob import SpindleDobTorque
    from millsense.models.friction import CoulombViscous
    from millsense.models.spindle_plant import SpindleDriveParams

METHODS = ("feed", "raw", "medob", "spindle")


def load_channel(method: str, axis: str) -> str:
    """Name of the load estimate of ``method`` on ``axis``."""
    return f"est/{method}/{axis}/load"


class RenamedBlock(Block):
    """Wraps a block: its outputs renamed (and scaled) into the ``est/`` namespace.

    Parameters
    ----------
    inner : the wrapped block.
    mapping : inner output name → (new name, factor, unit).
    name : the wrapper's block name.
    delay_samples : samples by which the output lags the input (fixed-lag smoother), recorded
        for the comparison with truth.
    """

    def __init__(
        self,
        inner: Block,
        mapping: dict[str, tuple[str, float, str]],
        name: str,
        delay_samples: int = 0,
    ) -> None:
        self.inner = inner
        self.mapping = mapping
        self.name = name
        self.inputs = inner.inputs
        self.delay_samples = int(delay_samples)

    def output_channels(self) -> list[ChannelInfo]:
        infos = {c.name: c for c in self.inner.output_channels()}
        return [
            ChannelInfo(new, unit, infos[old].description)
            for old, (new, _, unit) in self.mapping.items()
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self.inner.reset(sample_rate_hz)

    def process(self, chunk: Chunk) -> BlockOutput:
        out = self.inner.process(chunk)
        ch = {}
        for old, (new, factor, _) in self.mapping.items():
            values = np.asarray(out.channels[old], dtype=float)
            # x·1 is x: the inner block's array is passed on, as the pipeline passes outputs
            ch[new] = values if factor == 1.0 else factor * values
        return BlockOutput(ch, out.events)


@dataclass(frozen=True)
class BuiltEstimators:
    """Blocks ready for :class:`~millsense.streaming.engine.Pipeline` and what they estimate.

    Attributes
    ----------
    blocks : the wrapped estimator blocks.
    estimates : (method, axis, channel, delay_samples) per load estimate.
    notes : one line per method skipped under ``all`` (why it could not be built).
    derived, derived_estimates : blocks that read the estimates above, run after them (the
        forces at the tool from the five feed loads, :func:`tool_force_block`), and what they
        estimate (``(method, "tool_x"|"tool_y"|"tool_z", channel, delay)``).
    """

    blocks: list[RenamedBlock]
    estimates: list[tuple[str, str, str, int]]
    notes: list[str]
    derived: list[RenamedBlock] = field(default_factory=list)
    derived_estimates: list[tuple[str, str, str, int]] = field(default_factory=list)


#: Keys of ``[spindle]`` the observer's G_dτ model needs (Aslan Eq. 5.3, 5.7, P7).
SPINDLE_MODEL_KEYS = (
    "velocity_kp_a_s_rev",
    "velocity_ki_a_rev",
    "velocity_loop_period_ms",
    "current_kp_v_a",
    "current_ki_v_a_s",
    "motor_a_v_s2_a",
    "motor_b_v_s_a",
    "motor_c_ohm",
    "back_emf_v_s_rad",
)

#: R of the spindle observer when ``[spindle] current_noise_a`` is 0, A (RMS of I_nom in air):
#: 0.02 A, the size of a 16-bit current command over ±600 A (decision
#: docs/decisions/0102-spindle-observer-from-the-machine-file-issue-7.md).
DEFAULT_SPINDLE_CURRENT_NOISE_A = 0.02


def spindle_unavailable_reason(machine: MachineConfig, where: str) -> str | None:
    """Why the spindle observer cannot be built from ``machine`` (one line), or None."""
    if machine.spindle is None:
        return f"{where}: missing table 'spindle' (the spindle observer needs it)"
    for key in SPINDLE_MODEL_KEYS:
        if getattr(machine.spindle, key) is None:
            return (
                f"{where}: missing key 'spindle.{key}' (the spindle observer's G_dτ, Aslan "
                "Eq. 5.12, needs it)"
            )
    return None


def spindle_observer_from_config(
    machine: MachineConfig, where: str, sample_rate_hz: float
) -> RenamedBlock:
    """Spindle torque observer built from ``[spindle]`` alone (Aslan C11, Eq. 5.12–5.21).

    Notes
    -----
    Per speed range: G_dτ by :func:`~millsense.estimation.spindle_observer.disturbance_model`
    from :meth:`SpindleDriveParams.from_config` with the residual modes of
    ``[spindle.residual_modes]`` (the same table in both ranges) or none (rigid-body G_dτ);
    R = ``current_noise_a``² (default :data:`DEFAULT_SPINDLE_CURRENT_NOISE_A`); Q_s by
    :func:`~millsense.estimation.spindle_observer.tune_spindle_q`. The configured friction
    ``τ_coul + B_eS·Ω`` is subtracted so the output is the cutting torque (the observer sees
    the steady friction current as disturbance).
    """
    from millsense.estimation.spindle_observer import (
        RangeSwitchedSpindleObserver,
        SpindleTorqueObserver,
    )

    params, ranges, _ = _spindle_designs(machine, where)
    friction = _spindle_friction(machine, params)
    obs = [SpindleTorqueObserver(design, sample_rate_hz, friction=friction)
           for _, design in ranges]  # fmt: skip
    block: Block = obs[0]
    if len(obs) == 2:
        block = RangeSwitchedSpindleObserver((obs[0], obs[1]), params.switch_rad_s)
    return RenamedBlock(
        block,
        {"spindle/torque_est": (load_channel("spindle", "spindle"), 1.0, "N*m")},
        "spindle",
    )


def spindle_dob_from_config(machine: MachineConfig, where: str) -> SpindleDobTorque:
    """The spindle's disturbance observer for tooth-period averages (seed 001 Eq. 2-15,
    decision 1726: :class:`~millsense.estimation.spindle_dob.SpindleDobTorque`) from
    ``[spindle]``: K_tS of both speed ranges, J_eS and the friction the LQE observer of
    :func:`spindle_observer_from_config` subtracts, and the encoder's counts (the resolution of
    its tooth-period means, decision 1732)."""
    from millsense.estimation.spindle_dob import SpindleDobTorque

    params = _spindle_params(machine, where)
    r1, r2 = params.ranges
    assert machine.spindle is not None
    return SpindleDobTorque((r1.torque_constant, r2.torque_constant), params.switch_rad_s,
                            params.inertia, _spindle_friction(machine, params),
                            encoder_counts_rev=machine.spindle.encoder_counts_rev)  # fmt: skip


def _spindle_params(machine: MachineConfig, where: str) -> SpindleDriveParams:
    """The ``[spindle]`` drive's parameters (``SpindleDriveParams``), or the one-line error
    naming what the file lacks."""
    from millsense.models.spindle_plant import SpindleDriveParams

    reason = spindle_unavailable_reason(machine, where)
    if reason is not None:
        raise ConfigError(reason)
    assert machine.spindle is not None
    return SpindleDriveParams.from_config(machine.spindle)


def _spindle_friction(machine: MachineConfig, params: SpindleDriveParams) -> CoulombViscous:
    """The configured spindle friction τ_coul + B_eS·Ω (one value for both directions), with
    the drive's smoothing of sgn(Ω): what the LQE observer and the DOB subtract."""
    from millsense.models.friction import CoulombViscous

    cfg = machine.spindle
    assert cfg is not None
    return CoulombViscous(cfg.coulomb_nm, cfg.coulomb_nm, cfg.viscous_nm_s_rad,
                          cfg.viscous_nm_s_rad, params.friction_smoothing_rad_s)  # fmt: skip


def _spindle_designs(
    machine: MachineConfig, where: str
) -> tuple[Any, list[tuple[Any, Any]], float]:
    """The drive parameters, per speed range G_dτ (Eq. 5.12) for a torque that changes every
    CNC sample as a cut's does, fitted as the identification fits it (decisions 1696, 1699:
    :func:`~millsense.estimation.spindle_observer.disturbance_model_per_sample`), and the
    tuned observer design of :func:`spindle_observer_from_config`, and the residual R's
    feedthrough.

    The observer is designed on the loop with the speed at the instant even where the file
    says the drive's speed is its encoder's difference over the velocity period (decision
    1708): the 6-state fit of that loop's per-sample response misses it by up to 6 % at low
    frequency (0.97 dB at 2.5 kHz), a bias of the mean torque the observer would keep, where
    the fit of the loop at the instant is within 3 % (the same as before the key). The
    returned parameters keep the key: :func:`spindle_estimate_response` takes the drive's
    exact response with it."""
    from millsense.estimation.spindle_observer import disturbance_model_per_sample, tune_spindle_q

    base = _spindle_params(machine, where)
    cfg = machine.spindle
    assert cfg is not None
    modes = np.zeros((0, 4))
    feedthrough = 0.0
    if cfg.residual_modes is not None:
        rm = cfg.residual_modes
        modes = np.column_stack([rm.natural_frequency_hz, rm.damping_ratio, rm.alpha, rm.beta])
        feedthrough = rm.feedthrough
    params = replace(base, ranges=tuple(replace(r, modes=modes) for r in base.ranges))  # type: ignore[arg-type]
    noise = cfg.current_noise_a or DEFAULT_SPINDLE_CURRENT_NOISE_A
    design = replace(params, speed_from_encoder_difference=False)
    out = []
    for r in range(2 if math.isfinite(params.switch_rad_s) else 1):
        model, _ = disturbance_model_per_sample(design, r, machine.sample_rate_hz, feedthrough)
        out.append((model, tune_spindle_q(model, noise**2).design))
    return params, out, feedthrough


def spindle_estimate_response(
    machine: MachineConfig, where: str
) -> tuple[Callable[[np.ndarray, int], np.ndarray], float]:
    """The spindle observer's estimate against the cutting torque, as the machine file models
    it: ``H(f, range) = G_cτ(f)`` (Aslan Eq. 5.23: the loop's G_dτ for a torque that changes
    every CNC sample, :func:`~millsense.estimation.spindle_observer.per_sample_disturbance_frf`,
    times the observer's filter; decision 1699) times the hold of the observer's output over
    the CNC samples of its period (decision 1708), and the range-switch speed (rad/s; inf for
    one range).
    Decision 1554: the engagement monitor divides the torque's harmonics by it."""
    from millsense.estimation.spindle_observer import compensated, per_sample_disturbance_frf

    params, ranges, feedthrough = _spindle_designs(machine, where)
    fs = machine.sample_rate_hz

    def response(f_hz: np.ndarray, r: int) -> np.ndarray:
        r = min(r, len(ranges) - 1)
        _, design = ranges[r]
        f = np.asarray(f_hz, dtype=np.float64)
        g = per_sample_disturbance_frf(params, r, f, fs, feedthrough)
        # each estimate is held over the m CNC samples of its period: on the stream a line is
        # multiplied by the mean of e^{−iωjT_s}, j < m (a lag of (m − 1)T_s/2, 50 µs at 10 kHz;
        # a continuous hold over T_v, 100 µs, is not what the stream holds; decision 1708)
        m = max(round(design.dt * fs), 1)
        hold = np.exp(-2j * np.pi * np.outer(f, np.arange(m)) / fs).mean(axis=1)
        return np.asarray(compensated(g, design, f) * hold, dtype=np.complex128)

    return response, float(params.switch_rad_s)


def _feed(
    axis: str, machine: MachineConfig, where: str, fs: float, teeth: int | None = None
) -> RenamedBlock:
    from millsense.estimation.feed.estimator import FeedAxisEstimator, FeedAxisModel

    cfg = machine.axis(axis)
    unit = "N" if cfg.kind == "linear" else "N*m"
    if cfg.disturbance_modes_at:
        return _scheduled_feed(axis, machine, where, fs, teeth)
    model = FeedAxisModel.from_config(axis, cfg, sample_rate_hz=fs, where=where)
    moving = FeedAxisEstimator(model, teeth=teeth)
    block: Block = moving
    est = cfg.estimator
    if est is not None and est.disturbance_path_at_rest is not None:
        from millsense.estimation.feed.condition import OperatingConditionFeedEstimator

        rest_cfg = cfg.model_copy(
            update={
                "estimator": est.model_copy(
                    update={"disturbance_path": est.disturbance_path_at_rest}
                )
            }
        )
        rest = replace(
            FeedAxisModel.from_config(
                axis, rest_cfg, sample_rate_hz=fs, where=f"{where} (at rest)"
            ),
            condition="at_rest",
        )
        block = OperatingConditionFeedEstimator(
            moving, FeedAxisEstimator(rest, teeth=teeth), cfg.transmission_m_rad
        )
    return RenamedBlock(
        block,
        {f"{axis}/load_est": (load_channel("feed", axis), 1.0, unit)},
        f"feed_{axis}",
        moving.lag,
    )


def _scheduled_feed(
    axis: str, machine: MachineConfig, where: str, fs: float, teeth: int | None
) -> RenamedBlock:
    """The position-scheduled feed estimator of an axis with ``disturbance_modes_at``: one
    :class:`~millsense.estimation.feed.estimator.FeedAxisModel` per identified position (each tuned
    as ``FeedAxisModel.from_config`` tunes one), interpolated linearly by the commanded position
    (:class:`~millsense.estimation.feed.schedule.ScheduledFeedEstimator`)."""
    from millsense.core import units
    from millsense.core.config import DisturbanceModesConfig
    from millsense.estimation.feed.estimator import FeedAxisModel
    from millsense.estimation.feed.schedule import FeedModelBank, ScheduledFeedEstimator

    cfg = machine.axis(axis)
    if teeth is not None:
        raise ConfigError(
            f"{where}: axes.{axis}.disturbance_modes_at: the position-scheduled estimator has no "
            "tooth-harmonic option (--harmonics)"
        )
    models = []
    for i, at in enumerate(cfg.disturbance_modes_at):
        modes = DisturbanceModesConfig.model_validate(at.model_dump(exclude={"position_mm"}))
        member = cfg.model_copy(update={"disturbance_modes": modes, "disturbance_modes_at": []})
        models.append(
            FeedAxisModel.from_config(
                axis, member, sample_rate_hz=fs, where=f"{where} disturbance_modes_at[{i}]"
            )
        )
    positions = tuple(at.position_mm * units.MM for at in cfg.disturbance_modes_at)
    bank = FeedModelBank(positions, tuple(models), tuple(0.0 for _ in models))
    block = ScheduledFeedEstimator(bank)
    return RenamedBlock(
        block,
        {f"{axis}/load_est": (load_channel("feed", axis), 1.0, "N")},
        f"feed_{axis}",
        block.lag,
    )


def raw_estimator(axis: str, machine: MachineConfig, cutoff_hz: float) -> RenamedBlock:
    """The raw C3 estimate of ``axis`` (Aslan Eq. 3.10–3.11, :func:`rigid_limit` drive),
    output ``est/raw/{axis}/load`` low-passed at ``cutoff_hz`` (2nd-order Butterworth)."""
    from millsense.estimation.feed.estimator import DEFAULT_FRICTION_SMOOTHING_RAD_S
    from millsense.estimation.feed.rigid_body import DriveModel, RigidBodyForceEstimator

    cfg = machine.axis(axis)
    drive = DriveModel.from_config(
        cfg, DEFAULT_FRICTION_SMOOTHING_RAD_S, where=f"machine {machine.name}", axis=axis
    )
    unit = "N" if cfg.kind == "linear" else "N*m"
    # the block gives the force on the table along +axis; the load resisting motion is −force
    return RenamedBlock(
        RigidBodyForceEstimator(axis, drive, cutoff_hz),
        {f"{axis}/force_est": (load_channel("raw", axis), -1.0, unit)},
        f"raw_{axis}",
    )


def _medob(axis: str, machine: MachineConfig, where: str) -> RenamedBlock:
    from millsense.estimation.dob.observers import DriveParameters, MEDOBBlock

    cfg = machine.axis(axis)
    if cfg.ball_screw is None or cfg.kind != "linear":
        raise ConfigError(
            f"{where}: missing key 'axes.{axis}.ball_screw' (the MEDOB needs a ball-screw axis)"
        )
    ms = 1e-3
    block = MEDOBBlock(
        axis,
        DriveParameters.from_axis_config(cfg),
        kind="medob",
        delays_s=(
            cfg.dead_time_amplifier_ms * ms,
            cfg.dead_time_motor_encoder_ms * ms,
            cfg.dead_time_scale_ms * ms,
        ),
        current_loop_hz=cfg.current_bandwidth_hz,
    )
    return RenamedBlock(
        block, {f"{axis}/force_medob": (load_channel("medob", axis), 1.0, "N")}, f"medob_{axis}"
    )


#: The axes whose feed loads give the forces at the tool (Aslan Eq. 3.51), in the order of q.
TOOL_FORCE_AXES = ("x", "y", "z", "a", "c")


def tool_axis(component: str) -> str:
    """Name of a tool-force estimate in ``BuiltEstimators`` (``tool_x``, …)."""
    return f"tool_{component}"


def truth_channel(axis: str) -> str:
    """Ground-truth channel an estimate of ``axis`` is compared with (``tool_x`` →
    ``truth/tool/force_x``, else ``truth/{axis}/load``)."""
    if axis.startswith("tool_"):
        return f"truth/tool/force_{axis.removeprefix('tool_')}"
    return f"truth/{axis}/load"


def tool_force_block(
    machine: MachineConfig, method: str, delay_samples: int
) -> tuple[RenamedBlock, list[tuple[str, str, str, int]]]:
    """Forces on the tool from the five feed loads of ``method`` (Aslan Eq. 3.51).

    :class:`~millsense.estimation.feed.estimator.ToolForceBlock` on the machine's trunnion
    kinematics in the drives' frames, reading ``est/{method}/{axis}/load`` and the encoders
    ``{axis}/motor_angle`` (positions ``r_g·angle``, delayed by ``delay_samples`` to meet the
    smoothed loads); outputs ``est/{method}/tool/force_{x,y,z}`` (N, drive frame).

    Raises
    ------
    ConfigError
        The machine is not a 5-axis trunnion.
    """
    from millsense.estimation.feed.estimator import ToolForceBlock
    from millsense.models.kinematics import kinematics_for

    if machine.kinematics != "5-axis-trunnion-ac":
        raise ConfigError(
            f"forces at the tool: machine '{machine.name}' is {machine.kinematics}, "
            "Eq. 3.51 needs the 5-axis trunnion"
        )
    block = ToolForceBlock(
        kinematics_for(machine.kinematics),
        TOOL_FORCE_AXES,
        [machine.axis(a).transmission_m_rad for a in TOOL_FORCE_AXES],
        lag=delay_samples,
        load_channels=[load_channel(method, a) for a in TOOL_FORCE_AXES],
    )
    mapping = {f"tool/force_{c}_est": (f"est/{method}/tool/force_{c}", 1.0, "N") for c in "xyz"}
    est = [(method, tool_axis(c), f"est/{method}/tool/force_{c}", delay_samples) for c in "xyz"]
    return RenamedBlock(block, mapping, f"{method}_tool_force", delay_samples), est


def with_feed_band(machine: MachineConfig, axes: Sequence[str], band_hz: float) -> MachineConfig:
    """The machine with the feed estimators of ``axes`` tuned for ``band_hz`` (Hz).

    Sets ``[axes.<a>.estimator] band_hz`` (the least-noise Q flat within ±1 dB to the band,
    :func:`millsense.estimation.feed.tuning.least_noise_q`) and clears what it replaces (a fixed
    ``q_nm2_s``, a ``mode_shift_pct`` margin): the command-line choice wins over the file's.

    Raises
    ------
    ConfigError
        ``band_hz`` not in (0, 1000) Hz.
    """
    from millsense.core.config import FeedEstimatorConfig

    if not 0 < band_hz < 1000:
        raise ConfigError(f"--band-hz: must be in (0, 1000) Hz, got {band_hz:g}")
    axes_cfg = dict(machine.axes)
    for a in axes:
        cfg = machine.axis(a)
        est = (cfg.estimator or FeedEstimatorConfig()).model_copy(
            update={"band_hz": float(band_hz), "q_nm2_s": None, "mode_shift_pct": 0.0}
        )
        axes_cfg[a] = cfg.model_copy(update={"estimator": est})
    return machine.model_copy(update={"axes": axes_cfg})


def build_estimators(
    machine: MachineConfig,
    methods: Sequence[str],
    axes: Sequence[str],
    sample_rate_hz: float,
    *,
    where: str = "machine",
    raw_cutoff_hz: float = 300.0,
    skip_unavailable: bool = False,
    harmonic_teeth: int | None = None,
) -> BuiltEstimators:
    """Estimator blocks of ``methods`` on ``axes`` from a machine configuration.

    Parameters
    ----------
    machine : the machine configuration (identified values merged in).
    methods : subset of :data:`METHODS`.
    axes : axis names.
    sample_rate_hz : stream rate, Hz (must equal the machine's CNC rate).
    where : configuration name for error messages (file or preset).
    raw_cutoff_hz : low-pass corner of the raw C3 estimate, Hz.
    skip_unavailable : under ``all``: a method that cannot be built on an axis is skipped with a
        note instead of raising.
    harmonic_teeth : cutter teeth; given, the ``feed`` estimators add the tooth harmonics from
        the commanded spindle speed ``spindle/speed_cmd`` (Aslan Eq. 3.16–3.20,
        :class:`~millsense.estimation.feed.estimator.FeedAxisEstimator` ``teeth``); None: the
        random-walk design.

    Raises
    ------
    ConfigError
        One line: unknown method, unknown axis, or the configuration key a method misses.
    """
    for m in methods:
        if m not in METHODS:
            raise ConfigError(f"--method: unknown method '{m}' (one of {', '.join(METHODS)}, all)")
    for a in axes:
        machine.axis(a)
    blocks: list[RenamedBlock] = []
    est: list[tuple[str, str, str, int]] = []
    notes: list[str] = []
    for m in methods:
        if m == "spindle":
            try:
                b = spindle_observer_from_config(machine, where, sample_rate_hz)
            except ConfigError as exc:
                if not skip_unavailable:
                    raise
                notes.append(str(exc))
                continue
            blocks.append(b)
            est.append((m, "spindle", load_channel(m, "spindle"), b.delay_samples))
            continue
        for a in axes:
            try:
                if m == "feed":
                    b = _feed(a, machine, where, sample_rate_hz, harmonic_teeth)
                elif m == "raw":
                    b = raw_estimator(a, machine, raw_cutoff_hz)
                else:
                    b = _medob(a, machine, where)
            except ConfigError as exc:
                if not skip_unavailable:
                    raise
                notes.append(str(exc))
                continue
            blocks.append(b)
            est.append((m, a, load_channel(m, a), b.delay_samples))
    if not blocks:
        raise ConfigError(f"{where}: no estimator could be built ({'; '.join(notes)})")
    derived: list[RenamedBlock] = []
    derived_est: list[tuple[str, str, str, int]] = []
    feed_delay = {a: d for m, a, _, d in est if m == "feed"}
    if machine.kinematics == "5-axis-trunnion-ac" and all(a in feed_delay for a in TOOL_FORCE_AXES):
        delays = {feed_delay[a] for a in TOOL_FORCE_AXES}
        if len(delays) == 1:
            b, e = tool_force_block(machine, "feed", delays.pop())
            derived.append(b)
            derived_est += e
        else:
            notes.append("forces at the tool: the five feed estimates lag differently; skipped")
    return BuiltEstimators(blocks, est, notes, derived, derived_est)
