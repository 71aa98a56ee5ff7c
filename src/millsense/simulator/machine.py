"""The closed-loop virtual machine tool: a live :class:`~millsense.streaming.sources.Source`.

Composition, per block of one interpolation period (3 ms = 30 samples at 10 kHz):

1. :class:`~.interpolator.Interpolator` advances one period along the job's path at the
   programmed feed × the effective override (latency and quantisation of the configured
   :class:`~.interpolator.OverrideChannel`), :class:`~.interpolator.Upsampler` refines it to
   the drive rate (cubic Hermite by default: continuous velocity, no line at the 333 Hz
   interpolation rate in accelerations, decision 1682);
2. inverse kinematics (:mod:`.kinematics`; the trunnion table for 5-axis) gives the axis
   position references, their differences the velocity feed-forward;
3. the process (:mod:`.process_coupling`) evaluates the cutting forces at the *actual* tool
   motion, estimated for the block from the drives' state at the end of the previous block
   (``q_est = q_ref − (q_ref − q)|_prev``, the same for the velocity; spindle angle advanced
   at the last actual speed) — an explicit coupling with one block (3 ms) of lag, decision
   "Simulator process coupling";
4. the force on the tool becomes drive loads ``τ = Jᵀ·T·F`` (Aslan Eq. 3.49) resisting the
   axes, the cutting torque loads the spindle;
5. every feed drive (:class:`~.feed_drive.FeedDriveSim`) and the spindle
   (:class:`~.spindle.SpindleDriveSim`) advance the block; sensors and the realism layer
   follow.

Steps 1–2 (and the sensors and 333 Hz rows) are computed for all the blocks a read needs at
once; steps 3–5 run block by block (decision "Simulator block size"), in compiled kernels
(:mod:`.fast_block`, decision 1081; ``SimulatorOptions.reference_loop`` keeps the NumPy loop
for comparison). Blocks are fixed in
absolute sample index and every generator is drawn block by block, so the output does not
depend on how :meth:`MachineSimulator.read` cuts the stream. A command
(:meth:`MachineSimulator.command`) takes effect at ``t_cmd + latency`` where ``t_cmd`` is the
time of the next sample to be read; blocks already generated ahead of the reader (at most
one block) are not recomputed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.config import FeedAxisConfig, MachineConfig
from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.models.kinematics import Kinematics, TrunnionACMachine, kinematics_for
from millsense.models.modal_ss import ModalStateSpace
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.plan.path import cnc_line
from millsense.simulator.crash import CrashMonitor
from millsense.simulator.fast_block import (
    block_errors,
    drives_block,
    mean_abs_product,
    rotate_back,
    trunnion_block,
    trunnion_loads,
    trunnion_tip_error,
)
from millsense.simulator.feed_drive import N_OUT, OUT_NAMES, FeedDriveParams, FeedDriveSim
from millsense.simulator.interpolator import Interpolator, OverrideChannel, Upsampler
from millsense.simulator.process_coupling import ProcessCoupling
from millsense.simulator.realism import (
    AxisRealism,
    RealismOptions,
    friction_columns,
    high_modes,
    tool_mode_scale,
)
from millsense.simulator.sensors import SensorBank, SensorOptions
from millsense.simulator.spindle import SpindleDriveSim
from millsense.simulator.truth_machine import TRUTH_PRESETS, load_truth, truth_feed_params
from millsense.simulator.truth_spindle import TruthSpindleSim, load_truth_spindle
from millsense.stability.time_domain import DirectionModes
from millsense.streaming.block import Chunk, Event, EventKind
from millsense.streaming.sources import Source

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

AXES_3 = ("x", "y", "z")
AXES_5 = ("x", "y", "z", "a", "c")
AXES_1 = ("x",)


class _StageKinematics:
    """Kinematics of a 1-axis stage (``1-axis-stage``): the tool tip is ``[x, y₀, z₀]``.

    The job is a path in the workpiece frame whose y and z stay at ``y₀, z₀``; only x is a
    drive (decision "Simulator on a 1-axis stage").
    """

    n_axes = 1

    def __init__(self, y0_m: float, z0_m: float) -> None:
        self.y0_m = y0_m
        self.z0_m = z0_m

    def forward(self, q: FloatArray) -> FloatArray:
        """Tool tip (m), shape (N, 3), from the x positions (m), shape (N, 1)."""
        q2 = np.atleast_2d(np.asarray(q, dtype=np.float64))
        n = q2.shape[0]
        return np.column_stack([q2[:, 0], np.full(n, self.y0_m), np.full(n, self.z0_m)])


@dataclass(frozen=True)
class Job:
    """What the machine runs: a polyline with a feed, spindle speed and NC line per segment.

    Attributes
    ----------
    path : (N, 3) tool tip in the workpiece frame, m; or (N, 5) with the A and C axis
        angles, rad (5-axis trunnion).
    feed_m_s : (N−1,) programmed path feed per segment, m/s.
    spindle_rad_s : (N−1,) programmed spindle speed per segment, rad/s.
    nc_line : (N−1,) NC line (N number or source line) per segment.
    rapid : (N−1,) True on rapid (G0) segments, or None (none).
    """

    path: FloatArray
    feed_m_s: FloatArray
    spindle_rad_s: FloatArray
    nc_line: IntArray
    rapid: NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.path)
        if p.ndim != 2 or p.shape[1] not in (3, 5) or p.shape[0] < 2:
            raise InputDataError(f"job: path must be (N≥2, 3 or 5), got {p.shape}")
        n = p.shape[0] - 1
        for name in ("feed_m_s", "spindle_rad_s", "nc_line"):
            if np.asarray(getattr(self, name)).shape != (n,):
                raise InputDataError(f"job: {name} needs one value per segment ({n})")
        if not np.all(np.isfinite(p)):
            raise InputDataError("job: path has non-finite points")

    @classmethod
    def straight(
        cls,
        start_m: Sequence[float],
        end_m: Sequence[float],
        feed_m_s: float,
        spindle_rad_s: float,
        nc_line: int = 1,
    ) -> Job:
        """One straight move (3 or 5 coordinates) at a constant feed and spindle speed."""
        path = np.array([start_m, end_m], dtype=np.float64)
        return cls(path, np.array([feed_m_s]), np.array([spindle_rad_s]), np.array([nc_line]))

    @classmethod
    def from_sampled_path(cls, sp: object, five_axis: bool) -> Job:
        """From :class:`millsense.plan.path.SampledPath` (rapids keep their rapid rate).

        Samples that do not move (dwells, spindle changes) are merged; a segment takes the
        feed, spindle speed and NC line of the sample it moves to.
        """
        cols = [sp.x, sp.y, sp.z] + ([sp.a, sp.c] if five_axis else [])  # type: ignore[attr-defined]
        pts = np.column_stack(cols).astype(np.float64)
        if len(pts) < 2:
            raise InputDataError("job: the program has no motion")
        seg = np.diff(pts, axis=0)
        length = np.linalg.norm(seg[:, :3], axis=1)
        if five_axis:
            length = np.where(length > 1e-12, length, np.linalg.norm(seg[:, 3:], axis=1))
        keep = np.concatenate([[True], length > 1e-12])
        idx = np.nonzero(keep)[0]
        if len(idx) < 2:
            raise InputDataError("job: the program has no motion")
        nc = cnc_line(sp.nc_line, sp.source_line)  # type: ignore[attr-defined]
        return cls(
            pts[idx],
            np.maximum(np.asarray(sp.feed, dtype=np.float64)[idx[1:]], 1e-6),  # type: ignore[attr-defined]
            np.asarray(sp.spindle_speed, dtype=np.float64)[idx[1:]]  # type: ignore[attr-defined]
            * np.where(np.asarray(sp.spindle_dir)[idx[1:]] < 0, -1.0, 1.0),  # type: ignore[attr-defined]
            np.asarray(nc, dtype=np.int64)[idx[1:]],
            np.asarray(sp.rapid, dtype=np.bool_)[idx[1:]],  # type: ignore[attr-defined]
        )

    def arc_length(self) -> FloatArray:
        """Arc length at every path point (first three columns), m."""
        seg = np.linalg.norm(np.diff(self.path[:, :3], axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(seg)])


@dataclass(frozen=True)
class SimulatorOptions:
    """Settings of the virtual machine that the machine file does not hold.

    Attributes
    ----------
    feed_channel, spindle_channel : override latency/quantisation (open CNC by default).
    path_accel_m_s2 : interpolator path acceleration limit, m/s² (decision "Simulator
        defaults": 2 m/s², a UX600-class machine).
    spindle_accel_rad_s2 : spindle speed-reference ramp, rad/s² (2500: 0 → 24 000 rev/min in
        1 s).
    spindle_settle_s : feed hold after the start while the spindle runs up, s (added to the
        ramp time).
    drive_substeps : plant integration substeps per sample of the feed drives.
    fine_interpolation : how the 3 ms interpolator samples are refined to the drive rate
        (:class:`~.interpolator.Upsampler`): ``hermite`` (default) — the position between two
        samples is the integral of the velocity ramped linearly from one sample's path speed
        to the next (the interpolator's own trapezoid), so the velocity reference is
        continuous and its acceleration is the interpolator's, as the fine interpolation of a
        CNC's position controller; ``linear`` — straight lines between the samples, a
        velocity reference held over each period whose steps of a·T put a line at the
        interpolation rate (333 Hz) and its harmonics into the current in every
        acceleration; kept to produce such records (decision 1682).
    block_periods : interpolation periods per simulation block (the coupling lag and the
        largest extra command delay when reads are not aligned with blocks); 1 is the most
        faithful and the default, 4 saves some Python overhead at 9 ms more lag (decision
        "Simulator block size").
    seed : root seed of every generator (drives, sensors, realism).
    sensors : optional sensors.
    realism : the realism layer; None (default) = on, or off with ``ideal``.
    reference_loop : run the coupled part with the NumPy block loop of before the speed work
        (decision 1081) instead of the compiled one; the same recordings to float round-off,
        kept so that the benchmark measures the speed-up side by side and the golden tests
        compare the two. Default False.
    ideal : run the one-way model of the machine file (rigid body + printed disturbance
        modes Φ_d, Aslan Eq. 3.1/3.13) instead of the simulator's own truth (coupled lumped-mass
        drives of :mod:`~millsense.simulator.truth_machine`, for presets that have one) and
        Aslan's Ch. 5 spindle model (:mod:`~millsense.simulator.spindle`) instead of the truth
        spindle (:mod:`~millsense.simulator.truth_spindle`, decision 1210); with
        ``realism`` left None the realism layer is then off too. Default False: the truth
        with realism on, now that commissioning and identification run on it (decision 1062,
        superseding 1061); ``ideal=True`` is for debugging only.
    tool_modes_feed_frame : the tool modes of the process are along the feed (x) and its
        normal (y); the simulator maps their accelerations to machine x, y with the feed
        direction.
    """

    feed_channel: OverrideChannel = field(default_factory=OverrideChannel.open_cnc)
    spindle_channel: OverrideChannel = field(default_factory=OverrideChannel.open_cnc)
    path_accel_m_s2: float = 2.0
    spindle_accel_rad_s2: float = 2500.0
    spindle_settle_s: float = 0.05
    drive_substeps: int = 10
    fine_interpolation: str = "hermite"
    block_periods: int = 1
    seed: int = 0
    sensors: SensorOptions = field(default_factory=SensorOptions)
    realism: RealismOptions | None = None
    ideal: bool = False
    reference_loop: bool = False

    @property
    def realism_in_effect(self) -> RealismOptions:
        """The realism options that apply: as given, else on (off with ``ideal``)."""
        if self.realism is not None:
            return self.realism
        return RealismOptions(enabled=not self.ideal)

    def __post_init__(self) -> None:
        if not (self.path_accel_m_s2 > 0 and self.spindle_accel_rad_s2 > 0):
            raise ConfigError("simulator: acceleration limits must be > 0")
        if self.block_periods < 1:
            raise ConfigError(f"simulator: block_periods must be ≥ 1, got {self.block_periods}")
        if self.drive_substeps < 1:
            raise ConfigError(f"simulator: drive_substeps must be ≥ 1, got {self.drive_substeps}")
        if not self.spindle_settle_s >= 0:
            raise ConfigError("simulator: spindle_settle_s must be ≥ 0")
        if self.fine_interpolation not in ("hermite", "linear"):
            raise ConfigError(
                f"simulator: fine_interpolation '{self.fine_interpolation}' (hermite, linear)"
            )


#: Largest number of blocks generated at once (bounds the memory of one read), 1 s at 3 ms.
_MAX_BLOCKS = 334

_D_CUR_CMD, _D_CUR, _D_SPEED, _D_ANGLE = (OUT_NAMES.index(k) for k in OUT_NAMES[:4])
_D_SCALE = OUT_NAMES.index("scale")
_D_TRUE_SPEED = OUT_NAMES.index("true_speed")
_D_TRUE_POS = OUT_NAMES.index("true_position")
_D_TRUE_VEL = OUT_NAMES.index("true_velocity")
_D_TRUE_ACC = OUT_NAMES.index("true_acceleration")
_D_FRICTION = OUT_NAMES.index("friction_torque")


class _BlockArrays:
    """Per-sample outputs of the coupled part for a run of blocks (filled block by block)."""

    def __init__(self, n: int, n_axes: int) -> None:
        self.drive = np.empty((n_axes, n, N_OUT))
        self.loads = np.zeros((n, n_axes))
        self.force = np.zeros((n, 3))
        self.tool_acc = np.zeros((n, 2))
        self.tool_vib = np.zeros((n, 2))
        self.torque = np.zeros(n)
        # current_cmd, current, speed, true_speed (and the compiled loop's angle, speed range)
        self.spindle = np.empty((n, 6))
        self.chatter = np.zeros(n)
        self.broken = np.zeros(n)
        self.engagement = np.full(n, -1, dtype=np.int64)
        self.depth = np.zeros(n)
        self.feed_per_tooth = np.zeros(n)


@numba.njit(cache=True)
def _feed_frame(
    v_w: np.ndarray,
    axis: np.ndarray,
    last_dir: np.ndarray,
    speed: np.ndarray,
    x_p: np.ndarray,
    y_p: np.ndarray,
) -> None:
    """Feed frame of the process per sample: ``v⊥ = v − (v·a)·a``, speed ``|v⊥|``,
    ``x_p = v⊥/|v⊥|`` (the last direction held while ``|v⊥| ≤ 1e-9`` m/s, ``last_dir``
    updated in place), ``y_p = a × x_p`` (a the tool axis)."""
    for k in range(v_w.shape[0]):
        a0, a1, a2 = axis[k, 0], axis[k, 1], axis[k, 2]
        dot = v_w[k, 0] * a0 + v_w[k, 1] * a1 + v_w[k, 2] * a2
        p0 = v_w[k, 0] - dot * a0
        p1 = v_w[k, 1] - dot * a1
        p2 = v_w[k, 2] - dot * a2
        sp = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        speed[k] = sp
        if sp > 1e-9:
            last_dir[0] = p0 / sp
            last_dir[1] = p1 / sp
            last_dir[2] = p2 / sp
        x0, x1, x2 = last_dir[0], last_dir[1], last_dir[2]
        x_p[k, 0] = x0
        x_p[k, 1] = x1
        x_p[k, 2] = x2
        y_p[k, 0] = a1 * x2 - a2 * x1
        y_p[k, 1] = a2 * x0 - a0 * x2
        y_p[k, 2] = a0 * x1 - a1 * x0


@numba.njit(cache=True)
def _to_frame(
    f: np.ndarray, x_p: np.ndarray, y_p: np.ndarray, axis: np.ndarray, out: np.ndarray
) -> None:
    """``out = f_x·x_p + f_y·y_p + f_z·axis`` per sample (process frame → workpiece frame)."""
    for k in range(f.shape[0]):
        for i in range(3):
            out[k, i] = f[k, 0] * x_p[k, i] + f[k, 1] * y_p[k, i] + f[k, 2] * axis[k, i]


@numba.njit(cache=True)
def _window_mean(v: np.ndarray, ring: np.ndarray, count: int, win: int, out: np.ndarray) -> int:
    """Mean of the last ``win`` rows of the stream of ``v`` per row (fewer at its start).

    ``ring`` (L, 3) holds cumulative sums at absolute row index mod L (L > win); ``count``
    rows were added before this call; returns the new count.
    """
    n_ring = ring.shape[0]
    a = count
    for k in range(v.shape[0]):
        cur = a % n_ring
        prev = (a - 1) % n_ring
        for i in range(3):
            c_prev = ring[prev, i] if a > 0 else 0.0
            ring[cur, i] = c_prev + v[k, i]
        w = win if win <= a + 1 else a + 1
        j = a - w
        for i in range(3):
            base = ring[j % n_ring, i] if j >= 0 else 0.0
            out[k, i] = (ring[cur, i] - base) / w
        a += 1
    return a


@numba.njit(cache=True)
def _ramp(target: np.ndarray, last: float, step: float, out: np.ndarray) -> float:
    """Rate-limit ``target`` to ``step`` per sample starting from ``last``."""
    for k in range(target.shape[0]):
        d = target[k] - last
        if d > step:
            d = step
        elif d < -step:
            d = -step
        last += d
        out[k] = last
    return last


@numba.njit(cache=True)
def _pre_block(
    kind: int,
    q_ref: np.ndarray,
    v_ref: np.ndarray,
    err_q: np.ndarray,
    err_v: np.ndarray,
    q_ref_block: np.ndarray,
    a2: float,
    d4: float,
    theta0: float,
    omega0: float,
    steps: np.ndarray,
    fs: float,
    v_cum: np.ndarray,
    v_count: int,
    win: int,
    feed_dir: np.ndarray,
    s_tip: np.ndarray,
    theta: np.ndarray,
    omega: np.ndarray,
    v_w: np.ndarray,
    axis: np.ndarray,
    rot: np.ndarray,
    lm: np.ndarray,
    v_chip: np.ndarray,
    speed: np.ndarray,
    x_p: np.ndarray,
    y_p: np.ndarray,
    s_est: np.ndarray,
) -> int:
    """The process inputs of one block in one compiled call (decision 1081), the steps of
    :meth:`MachineSimulator._couple_block` before the process: the actual motion estimated
    from the last block's errors, the spindle angle advanced at the last speed, the tool-tip
    velocity and axis (``kind`` 0: 3-axis, 1: 1-axis stage, 2: trunnion, with its rotation and
    load matrix), the tooth-period velocity (returns the new history count), the feed frame
    (``feed_dir`` updated) and the arc length at the actual position."""
    n = q_ref.shape[0]
    na = q_ref.shape[1]
    q_est = np.empty((n, na))
    v_est = np.empty((n, na))
    for k in range(n):
        theta[k] = theta0 + omega0 * steps[k] / fs
        omega[k] = omega0
        for i in range(na):
            q_est[k, i] = q_ref[k, i] - err_q[i]
            v_est[k, i] = v_ref[k, i] - err_v[i]
    p_err = np.zeros(3)
    if kind == 2:
        trunnion_block(q_est, v_est, a2, d4, v_w, axis, rot, lm)
        trunnion_tip_error(q_ref_block, err_q, a2, d4, p_err)
    else:
        for k in range(n):
            if kind == 1:
                v_w[k, 0] = v_est[k, 0]
                v_w[k, 1] = 0.0
                v_w[k, 2] = 0.0
            else:
                for i in range(3):
                    v_w[k, i] = v_est[k, i]
            axis[k, 0] = 0.0
            axis[k, 1] = 0.0
            axis[k, 2] = 1.0
        if kind == 1:
            p_err[0] = err_q[0]
        else:
            for i in range(3):
                p_err[i] = err_q[i]
    count = _window_mean(v_w, v_cum, v_count, win, v_chip)
    _feed_frame(v_chip, axis, feed_dir, speed, x_p, y_p)
    lag = p_err[0] * feed_dir[0] + p_err[1] * feed_dir[1] + p_err[2] * feed_dir[2]
    for k in range(n):
        s = s_tip[k] - lag
        s_est[k] = s if s < s_tip[k] else s_tip[k]
    return count


class _OverrideSchedule:
    """Effective override versus time for one channel (latency and quantisation)."""

    def __init__(self, channel: OverrideChannel, initial: float = 1.0) -> None:
        self.channel = channel
        self.times = [-math.inf]
        self.values = [channel.quantise(initial)]

    def command(self, value: float, t_cmd: float) -> None:
        t_eff = t_cmd + self.channel.latency_s
        self.times.append(t_eff)
        self.values.append(self.channel.quantise(value))
        order = np.argsort(self.times, kind="stable")
        self.times = [self.times[i] for i in order]
        self.values = [self.values[i] for i in order]

    def at(self, t: FloatArray) -> FloatArray:
        idx = np.searchsorted(np.array(self.times), t, side="right") - 1
        return np.asarray(np.array(self.values)[idx], dtype=np.float64)


class MachineSimulator(Source):
    """Closed-loop virtual machine tool producing CNC channels and ``truth/`` channels.

    Parameters
    ----------
    machine : machine configuration (3-axis or 5-axis trunnion, with a spindle; or a
        1-axis stage: x only, force along x as its load, ideal spindle when the file has no
        [spindle] — decision "Simulator on a 1-axis stage").
    job : the path to run.
    process : the cutting process, or None for an air run.
    options : settings outside the machine file.
    duration_s : length of the stream, s; None: until the path end plus 0.2 s.

    Notes
    -----
    Channels (SI): per axis ``{ax}/current_cmd``, ``{ax}/current`` (A), ``{ax}/motor_speed``
    (rad/s, encoder difference), ``{ax}/motor_angle`` (rad, encoder), ``{ax}/position_cmd``
    (m or rad, fine interpolator), ``{ax}/scale`` (m, when the axis has a linear scale);
    ``spindle/speed``, ``spindle/speed_cmd`` (rad/s), ``spindle/current_cmd``,
    ``spindle/current`` (A); ``cnc/feed`` (m/s, interpolated path speed),
    ``cnc/feed_override``, ``cnc/spindle_override`` (fractions), ``cnc/nc_line``; optional
    ``accel/x``, ``accel/y``, ``mic/pressure``. Truth: ``truth/tool/force_{x,y,z}`` (N, on
    the tool, machine/tool frame), ``truth/tool/vibration_{x,y}`` (m, tool-mode displacement
    along machine x, y; 0 without tool modes), ``truth/{ax}/load`` (N or N·m, resisting the axis),
    ``truth/{ax}/position``, ``truth/{ax}/motor_speed``, ``truth/spindle/torque`` (N·m),
    ``truth/spindle/speed``, ``truth/process/chatter``, ``truth/process/broken``,
    ``truth/process/engagement``, ``truth/process/depth`` (m),
    ``truth/process/feed_per_tooth`` (m). The 333 Hz CNC stream (:meth:`take_stream_rows`)
    holds the tool-centre point (forward kinematics of the encoders), NC line, feed and
    overrides once per interpolation period.
    """

    name = "virtual machine"

    def __init__(
        self,
        machine: MachineConfig,
        job: Job,
        process: ProcessCoupling | None = None,
        options: SimulatorOptions | None = None,
        duration_s: float | None = None,
    ) -> None:
        self.machine = machine
        self.job = job
        self.process = process
        self.options = opts = options or SimulatorOptions()
        self.sample_rate_hz = fs = float(machine.sample_rate_hz)
        self.t0_s = 0.0
        period = machine.interpolator_period_ms * 1e-3
        ratio = period * fs
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError(
                f"machine {machine.name}: interpolator_period_ms {machine.interpolator_period_ms}"
                f" is not a whole number of samples at {fs} Hz"
            )
        self.per_period = round(ratio)
        self.ratio = self.per_period * opts.block_periods  # samples per block
        self.period_s = period
        self.stage = machine.kinematics == "1-axis-stage"
        self.kin: Kinematics | _StageKinematics
        self.axes: tuple[str, ...]
        if self.stage:
            # decision "Simulator on a 1-axis stage": x is the only drive, y and z fixed
            if job.path.shape[1] != 3:
                raise InputDataError(
                    f"job: path has {job.path.shape[1]} columns, machine {machine.name} "
                    "(1-axis-stage) needs 3 (x, y, z) with y and z constant"
                )
            yz = job.path[:, 1:3]
            if np.any(np.abs(yz - yz[0]) > 1e-9):
                raise InputDataError(
                    f"job: machine {machine.name} (1-axis-stage) moves x only; the path "
                    "moves y or z (program X words only)"
                )
            self.kin = _StageKinematics(float(yz[0, 0]), float(yz[0, 1]))
            self.axes = AXES_1
        else:
            self.kin = kinematics_for(machine.kinematics)
            self.axes = AXES_5 if machine.kinematics == "5-axis-trunnion-ac" else AXES_3
            if job.path.shape[1] != (5 if self.axes == AXES_5 else 3):
                raise InputDataError(
                    f"job: path has {job.path.shape[1]} columns, machine {machine.name} "
                    f"({machine.kinematics}) needs {len(self.axes)}"
                )
        missing = [a for a in self.axes if a not in machine.axes]
        if missing:
            raise ConfigError(f"machine {machine.name}: missing axis table [axes.{missing[0]}]")
        if machine.spindle is None and not self.stage:
            raise ConfigError(f"machine {machine.name}: missing [spindle] table")
        if duration_s is not None and not (duration_s > 0 and math.isfinite(duration_s)):
            raise InputDataError(f"simulator: duration_s must be > 0, got {duration_s!r}")
        seeds = np.random.SeedSequence(opts.seed).spawn(len(self.axes) + 2)
        real_rng = np.random.default_rng(seeds[-1])
        ro = opts.realism_in_effect
        self._realism = ro if ro.enabled else None
        truth = load_truth(machine.name) if not opts.ideal and machine.name in TRUTH_PRESETS else {}
        self.truth_axes = tuple(ax for ax in self.axes if ax in truth)

        # ---- interpolator and initial axis positions
        self._sovr = _OverrideSchedule(opts.spindle_channel, 1.0)
        self._held = False
        self._feed_value = 1.0
        self.interp = Interpolator(
            job.path,
            job.feed_m_s,
            opts.path_accel_m_s2,
            period_s=period,
            channel=OverrideChannel(0.0, opts.feed_channel.step, opts.feed_channel.max_override),
            initial_override=0.0,
            rapid=job.rapid,
        )
        # the spindle runs from the start at the first programmed speed (M3 before motion)
        spin = np.asarray(job.spindle_rad_s, dtype=np.float64).copy()
        nz = np.nonzero(spin)[0]
        if len(nz):
            spin[: nz[0]] = spin[nz[0]]
        self._spindle_target = spin
        spin0 = float(abs(spin[0]))
        # without a spindle drive the spindle turns at the programmed speed from the start (an
        # ideal reference, decision "Simulator on a 1-axis stage"): no run-up to wait for
        self.has_spindle = machine.spindle is not None
        ramp_s = spin0 / opts.spindle_accel_rad_s2 if self.has_spindle else 0.0
        self.start_s = ramp_s + opts.spindle_settle_s
        # the feed starts once the spindle is up to speed (applied without latency)
        self.interp.set_override(1.0, at_time_s=self.start_s)
        # the path columns and the path parameter s refined together (decision 1682)
        self.upsampler = Upsampler(
            self.per_period, np.append(job.path[0], 0.0), method=opts.fine_interpolation
        )
        q0 = self._axes_from_path(job.path[:1])[0]

        # ---- drives
        self.drives: list[FeedDriveSim] = []
        self.transmissions = np.zeros(len(self.axes))
        self._axis_real: list[AxisRealism | None] = []
        self._mode_tables: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
        self._fric_base: list[np.ndarray] = []
        self._fric_cols: list[list[int]] = []
        span = np.ptp(self._axes_from_path(job.path), axis=0)
        centre = 0.5 * (
            self._axes_from_path(job.path).max(axis=0) + self._axes_from_path(job.path).min(axis=0)
        )
        for i, ax in enumerate(self.axes):
            cfg = machine.axes[ax]
            if self._realism is not None and self._realism.high_modes:
                cfg = _with_high_modes(cfg, real_rng)
            if ax in truth:
                params = truth_feed_params(cfg, truth[ax])
            else:
                params = FeedDriveParams.from_config(cfg)
            rg = params.transmission
            self.transmissions[i] = rg
            drive = FeedDriveSim(
                params,
                fs,
                substeps=truth[ax].substeps if ax in truth else opts.drive_substeps,
                seed=int(seeds[i].generate_state(1)[0]),
                initial_angle_rad=float(q0[i] / rg),
            )
            self.drives.append(drive)
            self._fric_base.append(drive._fric.copy())
            self._fric_cols.append(friction_columns("lugre" if len(drive._fric) == 12 else "cv"))
            if self._realism is not None:
                ar = AxisRealism.seeded(real_rng, float(centre[i]), 0.5 * float(span[i]) + 0.05, rg)
                self._axis_real.append(ar)
                table = None
                # a machine file's own position profile (``mode_shift_pct_per_100mm``, applied by
                # the drive kernel every millisecond) takes precedence over the seeded one
                if (
                    self._realism.position_modes
                    and params.modes is not None
                    and params.mode_shift_per_m == 0.0
                ):
                    table = _mode_table(params.modes, ar, params, opts.drive_substeps, fs)
                self._mode_tables.append(table)
            else:
                self._axis_real.append(None)
                self._mode_tables.append(None)

        # ---- spindle, sensors
        self.spindle: SpindleDriveSim | TruthSpindleSim | None = None
        self._spindle_max = math.inf
        self.truth_spindle = False
        if machine.spindle is not None:
            if truth:  # the preset's truth spindle (decision 1210); --ideal: Aslan's Ch. 5 model
                self.spindle = TruthSpindleSim(load_truth_spindle(machine.name), fs)
                self.truth_spindle = True
            else:
                self.spindle = SpindleDriveSim(SpindleDriveParams.from_config(machine.spindle), fs)
            self._spindle_max = machine.spindle.max_rpm * 2 * math.pi / 60
        self.sensors = SensorBank(opts.sensors, fs, np.random.default_rng(seeds[-2]))
        self._tool_modes_base = (
            (process.modes.x, process.modes.y) if process and process.modes else None
        )
        self._tool_scale = 1.0

        # ---- coupling state (end of the previous block)
        n_ax = len(self.axes)
        self._q_ref_last = q0.copy()
        self._q_ref_block = q0.copy()  # reference at the end of the last coupled block
        self._err_q = np.zeros(n_ax)
        self._err_v = np.zeros(n_ax)
        self._theta = 0.0
        self._omega = 0.0
        self._omega_ref_last = 0.0
        self._feed_dir = np.array([1.0, 0.0, 0.0])
        # tool-centre velocity history for the tooth-period feed (decision "Simulator chip
        # from the tooth-period feed"), at most 0.1 s
        self._v_hist_max = max(round(0.1 * fs), 1)
        self._v_cum = np.zeros((self._v_hist_max + 1, 3))  # ring of cumulative sums
        self._v_count = 0
        self._torque_last = 0.0

        # ---- stream bookkeeping
        self._block = 0
        self.n_total: int | None = round(duration_s * fs) if duration_s is not None else None
        self._end_block: int | None = None
        self._pos = 0
        self._buf: dict[str, list[np.ndarray]] = {}
        self._buf_n = 0
        self._rows: list[dict[str, np.ndarray]] = []
        self._steps = np.arange(1, self.ratio + 1, dtype=np.float64)
        self._z_axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (self.ratio, 3))
        self._channels = self._declare()
        # crash events (decision 0942): engaged with the spindle stopped, beyond the limits
        self.crashes = CrashMonitor(machine, self.axes)
        # scratch of the compiled block loop (decision 1081)
        nb = self.ratio
        self._fb_vw = np.empty((nb, 3))
        self._fb_axis = np.empty((nb, 3))
        self._fb_rot = np.empty((nb, 3, 3))
        self._fb_lm = np.empty((nb, 5, 3))
        self._fb_speed = np.empty(nb)
        self._fb_xp = np.empty((nb, 3))
        self._fb_yp = np.empty((nb, 3))
        self._fb_fw = np.empty((nb, 3))
        self._fb_perr = np.empty(3)
        self._fb_omega = np.empty(nb)
        self._fb_theta = np.empty(nb)
        self._fb_sest = np.empty(nb)
        self._fb_vchip = np.empty((nb, 3))
        self._a2 = self.kin.a2_m if isinstance(self.kin, TrunnionACMachine) else 0.0
        self._d4 = self.kin.d4_m if isinstance(self.kin, TrunnionACMachine) else 0.0
        self._fric_slices = [slice(min(c), max(c) + 1) for c in self._fric_cols]
        if any(
            len(c) != sl.stop - sl.start
            for c, sl in zip(self._fric_cols, self._fric_slices, strict=True)
        ):
            raise ConfigError("simulator: friction drift columns must be contiguous")
        self._fb_states = self._drive_batch()

    def _drive_batch(self) -> object | None:
        """The drives' kernel states for :func:`~.fast_block.drives_block` (all axes in one
        compiled call per block), or None where that call does not apply — an axis whose
        realism rescales its modes from a table, or drives whose kernel arguments differ in
        type — and the loop over :meth:`FeedDriveSim.advance_block` runs instead."""
        if any(t is not None for t in self._mode_tables):
            return None
        # a tuple of the drives' states (numba: a UniTuple indexed in the kernel's loop) rather
        # than a numba typed List, whose methods numba compiles afresh in every process (4 s of
        # each `millsense run`'s start on this host); the states must share one numba type
        states = tuple(d.kernel_state(self.ratio) for d in self.drives)
        if len({numba.typeof(st) for st in states}) != 1:
            return None
        n_ax = len(self.drives)
        opts = self._realism
        width = max(len(f) for f in self._fric_base)
        self._fb_fric_base = np.zeros((n_ax, width))
        self._fb_real = np.zeros((n_ax, 6))
        self._fb_temp = np.zeros(n_ax)
        for i, ar in enumerate(self._axis_real):
            self._fb_fric_base[i, : len(self._fric_base[i])] = self._fric_base[i]
            if ar is not None and opts is not None and opts.friction_drift:
                sl = self._fric_slices[i]
                self._fb_real[i] = [
                    1.0,
                    ar.ripple,
                    ar.ripple_wavelength,
                    ar.ripple_phase,
                    sl.start,
                    sl.stop,
                ]
                self._fb_temp[i] = ar.temperature_k
        self._fb_thermal = np.array(
            [
                opts.thermal_resistance_k_w if opts else 0.0,
                opts.thermal_time_constant_s if opts else 1.0,
                opts.friction_temp_coeff_1_k if opts else 0.0,
                self.period_s,
            ]
        )
        self._fb_ndone = np.zeros(n_ax, dtype=np.int64)
        return states

    # ------------------------------------------------------------------ declarations
    def _declare(self) -> list[ChannelInfo]:
        ch: list[ChannelInfo] = []
        for ax in self.axes:
            unit = "rad" if self.machine.axes[ax].kind == "rotary" else "m"
            load_unit = "N*m" if unit == "rad" else "N"
            ch += [
                ChannelInfo(f"{ax}/current_cmd", "A", f"{ax.upper()} drive current command"),
                ChannelInfo(f"{ax}/current", "A", f"{ax.upper()} drive actual current"),
                ChannelInfo(f"{ax}/motor_speed", "rad/s", f"{ax.upper()} motor speed (encoder)"),
                ChannelInfo(f"{ax}/motor_angle", "rad", f"{ax.upper()} motor encoder angle"),
                ChannelInfo(f"{ax}/position_cmd", unit, f"{ax.upper()} axis position command"),
            ]
            if self.machine.axes[ax].scale_resolution_nm is not None:
                ch.append(ChannelInfo(f"{ax}/scale", unit, f"{ax.upper()} linear scale"))
            ch += [
                ChannelInfo(f"truth/{ax}/load", load_unit, f"{ax.upper()} cutting load"),
                ChannelInfo(f"truth/{ax}/position", unit, f"true {ax.upper()} axis position"),
                ChannelInfo(f"truth/{ax}/motor_speed", "rad/s", f"true {ax.upper()} motor speed"),
            ]
        ch += [
            ChannelInfo("spindle/speed", "rad/s", "spindle speed (measured)"),
            ChannelInfo("spindle/speed_cmd", "rad/s", "spindle speed reference"),
        ]
        if self.has_spindle:
            ch += [
                ChannelInfo("spindle/current_cmd", "A", "spindle current command"),
                ChannelInfo("spindle/current", "A", "spindle actual current"),
            ]
        ch += [
            ChannelInfo("cnc/feed", "m/s", "interpolated path feed"),
            ChannelInfo("cnc/feed_override", "1", "effective feed override (fraction)"),
            ChannelInfo("cnc/spindle_override", "1", "effective spindle override (fraction)"),
            ChannelInfo("cnc/nc_line", "1", "NC line being interpolated"),
        ]
        so = self.options.sensors
        if so.accelerometer:
            ch += [
                ChannelInfo("accel/x", "m/s^2", "accelerometer along machine x"),
                ChannelInfo("accel/y", "m/s^2", "accelerometer along machine y"),
            ]
        if so.microphone:
            ch.append(ChannelInfo("mic/pressure", "Pa", "microphone"))
        ch += [
            ChannelInfo("truth/tool/force_x", "N", "force on the tool, machine x"),
            ChannelInfo("truth/tool/force_y", "N", "force on the tool, machine y"),
            ChannelInfo("truth/tool/force_z", "N", "force on the tool, machine z"),
            ChannelInfo("truth/tool/vibration_x", "m", "tool vibration (tool modes), machine x"),
            ChannelInfo("truth/tool/vibration_y", "m", "tool vibration (tool modes), machine y"),
            ChannelInfo("truth/spindle/torque", "N*m", "cutting torque at the spindle"),
            ChannelInfo("truth/spindle/speed", "rad/s", "true spindle speed"),
            ChannelInfo("truth/process/chatter", "1", "1 while chatter (aperiodic vibration)"),
            ChannelInfo("truth/process/broken", "1", "1 after a tooth break or chip"),
            ChannelInfo("truth/process/engagement", "1", "engagement table index (-1 air)"),
            ChannelInfo("truth/process/depth", "m", "axial depth of cut"),
            ChannelInfo("truth/process/feed_per_tooth", "m", "feed per tooth"),
        ]
        return ch

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return list(self._channels)

    @staticmethod
    def stream_fields() -> list[ChannelInfo]:
        """Fields of the 333 Hz ``cnc`` stream (see :meth:`take_stream_rows`)."""
        return [
            ChannelInfo("tcp_x", "m", "tool-centre point x (encoders, forward kinematics)"),
            ChannelInfo("tcp_y", "m", "tool-centre point y"),
            ChannelInfo("tcp_z", "m", "tool-centre point z"),
            ChannelInfo("nc_line", "1", "NC line"),
            ChannelInfo("feed", "m/s", "interpolated path feed"),
            ChannelInfo("feed_override", "1", "effective feed override"),
            ChannelInfo("spindle_override", "1", "effective spindle override"),
        ]

    @property
    def metadata(self) -> dict[str, object]:
        """Run metadata (machine, seed, breakage time...)."""
        brk = self.process.breakage_time_s if self.process is not None else None
        return {
            "source": "millsense virtual machine",
            "machine": self.machine.name,
            "kinematics": self.machine.kinematics,
            "seed": self.options.seed,
            "breakage_time_s": brk if brk is not None else "none",
            "realism": self._realism is not None,
            "truth_plant": "coupled" if self.truth_axes else "ideal",
            "truth_spindle": "torsional" if self.truth_spindle else "ideal",
            "feed_latency_s": self.options.feed_channel.latency_s,
            "feed_override_step": self.options.feed_channel.step,
            "fine_interpolation": self.options.fine_interpolation,
        }

    # ------------------------------------------------------------------ commands
    def command(self, event: Event) -> None:
        """Apply ``feed_override`` / ``spindle_override`` (value in percent) or ``feed_hold``
        (value None or non-zero: hold; 0: release).

        The command is issued at ``event.time_s`` if that lies ahead of the reader (a
        schedule), else at the next unread sample; it takes effect one channel latency later,
        quantised by the channel.

        Raises
        ------
        InputDataError
            For an unknown override name or a missing/negative value.
        """
        if event.kind != EventKind.OVERRIDE:
            return
        # the command time: the event's own time if it lies ahead (a schedule), else the
        # next unread sample (the past cannot change)
        t_cmd = max(float(event.time_s), self._pos / self.sample_rate_hz)
        ch = self.options.feed_channel
        # the interpolator's own channel has no latency: it gets the effective time, never
        # before the end of the spindle run-up (the start hold)
        t_eff = max(t_cmd + ch.latency_s, self.start_s)
        if event.name == "feed_hold":
            self._held = event.value is None or event.value != 0
            self.interp.set_override(0.0 if self._held else self._feed_value, at_time_s=t_eff)
            return
        if event.value is None or not (event.value >= 0 and math.isfinite(event.value)):
            raise InputDataError(f"simulator: override '{event.name}' needs a value ≥ 0 %")
        if event.name == "feed_override":
            self._feed_value = event.value / 100.0
            if not self._held:
                self.interp.set_override(self._feed_value, at_time_s=t_eff)
        elif event.name == "spindle_override":
            self._sovr.command(event.value / 100.0, t_cmd)
        else:
            raise InputDataError(
                f"simulator: unknown override '{event.name}' "
                "(feed_override, spindle_override, feed_hold)"
            )

    # ------------------------------------------------------------------ kinematics helpers
    def _axes_from_path(self, pts: FloatArray) -> FloatArray:
        """Axis positions for path points (tip in the workpiece/G-code frame [+ A, C]).

        The programmed (unwrapped) rotary angles are kept as written and the linear axes
        solved for them, so the forward kinematics of the result is the programmed tip on
        any branch (decision "Trunnion frames: G-code and drives").
        """
        if isinstance(self.kin, TrunnionACMachine):
            return np.asarray(self.kin.inverse_at(pts[:, :3], pts[:, 3], pts[:, 4]))
        if self.stage:
            return np.asarray(pts[:, :1], dtype=np.float64).copy()
        return np.asarray(pts[:, :3], dtype=np.float64).copy()

    # ------------------------------------------------------------------ blocks
    def _generate(self, n_blocks: int) -> dict[str, np.ndarray]:
        """The next ``n_blocks`` blocks.

        Everything that does not depend on the drives' state (interpolator, fine
        interpolation, inverse kinematics, spindle reference, sensors, the 333 Hz rows) is
        computed for all blocks at once; the coupled part (process at the estimated actual
        motion → drive loads → drives and spindle) runs block by block in
        :meth:`_couple_block`, with the coupling of one block as before (decision "Simulator
        block size"). The result does not depend on ``n_blocks``.
        """
        fs = self.sample_rate_hz
        nb = self.ratio
        pp = self.per_period
        n_per = n_blocks * self.options.block_periods
        n = n_blocks * nb
        k0 = self._block
        t = (k0 * nb + np.arange(n)) / fs
        # 1. interpolator: the periods at the effective override, refined to the drive rate
        ipo = self.interp.advance(n_per)
        fine_s = self.upsampler(
            np.column_stack([ipo["position"], ipo["s"]]),
            np.column_stack([ipo["velocity"], ipo["v"]]),
            self.period_s,
        )
        fine, s_ref = fine_s[:, :-1], np.ascontiguousarray(fine_s[:, -1])
        feed_fine = np.repeat(ipo["v"], pp)
        ovr_fine = np.repeat(ipo["override"], pp)
        # 2. axis references
        q_ref = self._axes_from_path(fine)
        q_prev = np.vstack([self._q_ref_last[None, :], q_ref[:-1]])
        v_ref = (q_ref - q_prev) * fs
        self._q_ref_last = q_ref[-1].copy()
        pos_m = np.ascontiguousarray((q_ref / self.transmissions).T)
        vel_m = np.ascontiguousarray((v_ref / self.transmissions).T)
        # spindle reference with override and ramp
        seg = np.clip(
            np.searchsorted(self.interp.cum, s_ref, side="right") - 1, 0, len(self.job.nc_line) - 1
        )
        sovr = self._sovr.at(t)
        target = self._spindle_target[seg] * sovr
        spd_ref = np.empty(n)
        if self.has_spindle:
            self._omega_ref_last = _ramp(
                target, self._omega_ref_last, self.options.spindle_accel_rad_s2 / fs, spd_ref
            )
        else:  # an ideal spindle at the programmed speed (decision "Simulator on a 1-axis stage")
            spd_ref[:] = target
        # 3. the coupled blocks
        n_ax = len(self.axes)
        w = _BlockArrays(n, n_ax)
        if self.options.reference_loop:
            for b in range(n_blocks):
                self._couple_block(
                    slice(b * nb, (b + 1) * nb), t, s_ref, q_ref, v_ref, pos_m, vel_m, spd_ref, w
                )
        else:
            # what does not depend on the drives' state, for all blocks at once: the tip's arc
            # length of the reference and every drive's torque noise (the generators' next
            # draws, as block by block)
            s_tip = self.interp.tip_arc_length(s_ref) if self.process is not None else s_ref
            noise = np.empty((n_ax, n))
            for i, drive in enumerate(self.drives):
                noise[i] = drive.draw_noise(n)
            if self._fb_states is not None:
                for i, drive in enumerate(self.drives):
                    self._fb_ndone[i] = drive.samples_done
            for b in range(n_blocks):
                self._couple_block_fast(
                    b * nb, (b + 1) * nb, t, s_tip, q_ref, v_ref, pos_m, vel_m, spd_ref, noise, w
                )
            if self._fb_states is not None:  # the drives' counters and the axes' temperatures
                for i, drive in enumerate(self.drives):
                    drive.samples_done = int(self._fb_ndone[i])
                    ar = self._axis_real[i]
                    if ar is not None and self._fb_real[i, 0] != 0.0:
                        ar.temperature_k = float(self._fb_temp[i])
        # 4. channels
        d_out = w.drive
        data: dict[str, np.ndarray] = {}
        for i, ax in enumerate(self.axes):
            o = d_out[i]
            data[f"{ax}/current_cmd"] = o[:, _D_CUR_CMD]
            data[f"{ax}/current"] = o[:, _D_CUR]
            data[f"{ax}/motor_speed"] = o[:, _D_SPEED]
            data[f"{ax}/motor_angle"] = o[:, _D_ANGLE]
            data[f"{ax}/position_cmd"] = q_ref[:, i]
            if self.machine.axes[ax].scale_resolution_nm is not None:
                data[f"{ax}/scale"] = o[:, _D_SCALE]
            data[f"truth/{ax}/load"] = w.loads[:, i]
            data[f"truth/{ax}/position"] = o[:, _D_TRUE_POS]
            data[f"truth/{ax}/motor_speed"] = o[:, _D_TRUE_SPEED]
        table_acc = np.zeros((n, 2))
        for i in range(min(2, n_ax)):
            table_acc[:, i] = d_out[i][:, _D_TRUE_ACC]
        sp = w.spindle
        data["spindle/speed"] = sp[:, 2]
        data["spindle/speed_cmd"] = spd_ref
        sensed = self.sensors.measure(w.tool_acc, table_acc, (sp[:, 0], sp[:, 1]))
        if not self.has_spindle:
            del sensed["spindle/current_cmd"], sensed["spindle/current"]
        data.update(sensed)
        data["cnc/feed"] = feed_fine
        data["cnc/feed_override"] = ovr_fine
        data["cnc/spindle_override"] = sovr
        nc = self.job.nc_line[seg].astype(np.int64)
        data["cnc/nc_line"] = nc
        data["truth/tool/force_x"] = w.force[:, 0]
        data["truth/tool/force_y"] = w.force[:, 1]
        data["truth/tool/force_z"] = w.force[:, 2]
        data["truth/tool/vibration_x"] = w.tool_vib[:, 0]
        data["truth/tool/vibration_y"] = w.tool_vib[:, 1]
        data["truth/spindle/torque"] = w.torque
        data["truth/spindle/speed"] = sp[:, 3]
        data["truth/process/chatter"] = w.chatter
        data["truth/process/broken"] = w.broken
        data["truth/process/engagement"] = w.engagement
        data["truth/process/depth"] = w.depth
        data["truth/process/feed_per_tooth"] = w.feed_per_tooth
        # 5. the 333 Hz stream rows (one per period): encoders through forward kinematics
        ends = np.arange(pp - 1, n, pp)
        q_meas = np.column_stack(
            [d_out[i][ends, _D_ANGLE] * self.transmissions[i] for i in range(n_ax)]
        )
        tcp = np.atleast_2d(self.kin.forward(q_meas))
        self._rows.append(
            {
                "time_s": t[ends],
                "tcp_x": tcp[:, 0],
                "tcp_y": tcp[:, 1],
                "tcp_z": tcp[:, 2],
                "nc_line": nc[ends].astype(np.float64),
                "feed": ipo["v"],
                "feed_override": ipo["override"],
                "spindle_override": sovr[ends],
            }
        )
        # 6. the end of the stream: the first block whose last period has the path done
        if self._end_block is None and self.n_total is None:
            done = (ipo["s"] >= self.interp.cum[-1]) & (ipo["v"] == 0.0)
            last = done[self.options.block_periods - 1 :: self.options.block_periods]
            if last.any():
                k_end = k0 + int(np.argmax(last))
                self._end_block = k_end
                self.n_total = (k_end + 1) * nb + round(0.2 * fs)
        self._block += n_blocks
        return data

    def _couple_block(
        self,
        sl: slice,
        t_all: FloatArray,
        s_all: FloatArray,
        q_all: FloatArray,
        v_all: FloatArray,
        pos_m: FloatArray,
        vel_m: FloatArray,
        spd_all: FloatArray,
        w: _BlockArrays,
    ) -> None:
        """One block of the coupled part (decision "Simulator process coupling")."""
        n = sl.stop - sl.start
        fs = self.sample_rate_hz
        five = isinstance(self.kin, TrunnionACMachine)
        torque: FloatArray
        if self.process is not None:
            t = t_all[sl]
            q_ref = q_all[sl]
            # actual motion estimated for the block
            q_est = q_ref - self._err_q
            v_est = v_all[sl] - self._err_v
            theta = self._theta + self._omega * self._steps[:n] / fs
            omega = np.full(n, self._omega)
            if five:
                assert isinstance(self.kin, TrunnionACMachine)
                v_w = np.einsum("nij,nj->ni", self.kin.jacobian(q_est), v_est)
                axis = self.kin.orientation(q_est[:, 3], q_est[:, 4])
            elif self.stage:  # x only: y, z of the tool stand still
                v_w = np.zeros((n, 3))
                v_w[:, 0] = v_est[:, 0]
                axis = self._z_axis[:n]
            else:
                v_w = v_est
                axis = self._z_axis[:n]
            speed = np.empty(n)
            x_p = np.empty((n, 3))
            y_p = np.empty((n, 3))
            v_chip = self._tooth_period_velocity(v_w)
            _feed_frame(v_chip, axis, self._feed_dir, speed, x_p, y_p)  # updates _feed_dir
            # arc length at the actual position: the reference minus the lag along the feed
            p_err = self._tip_error()
            # the tip's arc length (rotary-only positioning does not advance it) less the
            # tracking lag along the feed; never ahead of the reference (decision "Path
            # parameter and tip arc length")
            s_tip = self.interp.tip_arc_length(s_all[sl])
            s_est = np.minimum(s_tip - float(p_err @ self._feed_dir), s_tip)
            po = self.process.evaluate(t, s_est, theta, omega, speed)
            f_w = np.empty((n, 3))
            _to_frame(po.force, x_p, y_p, axis, f_w)
            regen = self.process.modes is not None  # tool vibration exists
            if regen:
                acc_w = po.vibration_acc[:, :1] * x_p + po.vibration_acc[:, 1:2] * y_p
                vib_w = po.vibration_m[:, :1] * x_p + po.vibration_m[:, 1:2] * y_p
            if five:
                assert isinstance(self.kin, TrunnionACMachine)
                rot = self.kin.rotation(q_est[:, 3], q_est[:, 4])
                f_machine = np.einsum("nji,nj->ni", rot, f_w)  # Tᵀ·F_w: tool frame
                w.loads[sl] = -self.kin.drive_loads(q_est, f_machine)
                if regen:
                    acc_w = np.einsum("nji,nj->ni", rot, acc_w)
                    vib_w = np.einsum("nji,nj->ni", rot, vib_w)
            elif self.stage:
                # the stage feels the force along its axis; y and z are taken by its guides
                # (decision "Simulator on a 1-axis stage")
                f_machine = f_w
                w.loads[sl] = -f_w[:, :1]
            else:
                f_machine = f_w
                w.loads[sl] = -f_w
            w.force[sl] = f_machine
            if regen:  # else the preallocated zeros stand
                w.tool_acc[sl] = acc_w[:, :2]
                w.tool_vib[sl] = vib_w[:, :2]
            torque = po.torque
            w.torque[sl] = torque
            w.chatter[sl] = po.chatter
            w.broken[sl] = po.broken
            w.engagement[sl] = po.engagement_index
            w.depth[sl] = po.depth_m
            w.feed_per_tooth[sl] = po.feed_per_tooth_m
            self.crashes.check(
                t,
                (po.engagement_index >= 0) & (po.depth_m > 0),
                self._omega,
                w.loads[sl],
                torque,
            )
        else:
            torque = w.torque[sl]
        # drives and spindle
        loads = np.ascontiguousarray(w.loads[sl].T)
        for i in range(len(self.axes)):
            out = w.drive[i, sl]
            self.drives[i].advance_into(pos_m[i, sl], vel_m[i, sl], loads[i], out)
            if self._realism is not None:
                self._realism_axis(i, out, float(out[-1, _D_TRUE_POS]))
        blk = w.drive[:, sl]
        self._err_q = q_all[sl.stop - 1] - blk[:, -1, _D_TRUE_POS]
        # the velocity error averaged over the block: the chip is cut over a tooth period,
        # the sample-to-sample velocity noise of the drives does not thicken it
        self._err_v = (v_all[sl].sum(axis=0) - blk[:, :, _D_TRUE_VEL].sum(axis=1)) / n
        self._q_ref_block = q_all[sl.stop - 1].copy()
        if self.spindle is not None:
            sp = self.spindle.advance(spd_all[sl], torque)
            w.spindle[sl, 0] = sp["current_cmd"]
            w.spindle[sl, 1] = sp["current"]
            w.spindle[sl, 2] = sp["speed"]
            w.spindle[sl, 3] = sp["true_speed"]
            self._theta = float(sp["angle"][-1])
            self._omega = float(sp["true_speed"][-1])
        else:  # ideal spindle: the reference speed, its angle integrated (rectangle rule)
            spd = spd_all[sl]
            w.spindle[sl, 0] = 0.0
            w.spindle[sl, 1] = 0.0
            w.spindle[sl, 2] = spd
            w.spindle[sl, 3] = spd
            self._theta = float(self._theta + np.sum(spd) / fs)
            self._omega = float(spd[-1])
        self._torque_last = float(np.mean(torque))
        self._realism_tool()

    def _couple_block_fast(
        self,
        a: int,
        b: int,
        t_all: FloatArray,
        s_tip_all: FloatArray,
        q_all: FloatArray,
        v_all: FloatArray,
        pos_m: FloatArray,
        vel_m: FloatArray,
        spd_all: FloatArray,
        noise: FloatArray,
        w: _BlockArrays,
    ) -> None:
        """:meth:`_couple_block` with compiled kinematics, loads, errors and checks and the
        drives' noise drawn ahead (decision 1081): the same coupling and the same recordings
        to float round-off."""
        sl = slice(a, b)
        n = b - a
        fs = self.sample_rate_hz
        kin = self.kin
        five = isinstance(kin, TrunnionACMachine)
        torque: FloatArray
        if self.process is not None:
            t = t_all[sl]
            # the (nb, …) scratch arrays whole: every block is nb samples (_generate)
            assert n == self._fb_theta.shape[0]
            theta = self._fb_theta
            omega = self._fb_omega
            rot = self._fb_rot
            axis = self._fb_axis
            speed = self._fb_speed
            x_p = self._fb_xp
            y_p = self._fb_yp
            s_est = self._fb_sest
            self._v_count = _pre_block(
                2 if five else (1 if self.stage else 0),
                q_all[sl],
                v_all[sl],
                self._err_q,
                self._err_v,
                self._q_ref_block,
                self._a2,
                self._d4,
                self._theta,
                self._omega,
                self._steps,
                fs,
                self._v_cum,
                self._v_count,
                self._tooth_window(),
                self._feed_dir,
                s_tip_all[sl],
                theta,
                omega,
                self._fb_vw,
                axis,
                rot,
                self._fb_lm,
                self._fb_vchip,
                speed,
                x_p,
                y_p,
                s_est,
            )
            po = self.process.evaluate(t, s_est, theta, omega, speed)
            f_w = self._fb_fw
            _to_frame(po.force, x_p, y_p, axis, f_w)
            regen = self.process.modes is not None
            loads_blk = w.loads[sl]
            if five:
                trunnion_loads(rot, self._fb_lm, f_w, w.force[sl], loads_blk)
                if regen:
                    rotate_back(rot, x_p, y_p, po.vibration_acc, w.tool_acc[sl])
                    rotate_back(rot, x_p, y_p, po.vibration_m, w.tool_vib[sl])
            else:
                if self.stage:
                    np.negative(f_w[:, 0], out=loads_blk[:, 0])
                else:
                    np.negative(f_w, out=loads_blk)
                w.force[sl] = f_w
                if regen:
                    acc_w = po.vibration_acc[:, :1] * x_p + po.vibration_acc[:, 1:2] * y_p
                    vib_w = po.vibration_m[:, :1] * x_p + po.vibration_m[:, 1:2] * y_p
                    w.tool_acc[sl] = acc_w[:, :2]
                    w.tool_vib[sl] = vib_w[:, :2]
            torque = po.torque
            w.torque[sl] = torque
            w.chatter[sl] = po.chatter
            w.broken[sl] = po.broken
            w.engagement[sl] = po.engagement_index
            w.depth[sl] = po.depth_m
            w.feed_per_tooth[sl] = po.feed_per_tooth_m
            mean_torque = float(np.add.reduce(torque)) / n  # = np.mean
            self.crashes.check_block(
                t, po.engagement_index, po.depth_m, self._omega, loads_blk, torque, mean_torque
            )
        else:
            torque = w.torque[sl]
            mean_torque = float(np.mean(torque))
        # drives and spindle
        loads = np.ascontiguousarray(w.loads[sl].T)
        if self._fb_states is not None:
            drives_block(
                self._fb_states,
                self._fb_ndone,
                pos_m,
                vel_m,
                loads,
                noise,
                w.drive,
                a,
                b,
                self._fb_real,
                self._fb_temp,
                self._fb_fric_base,
                self._fb_thermal,
                _D_TRUE_POS,
                _D_FRICTION,
                _D_TRUE_SPEED,
                q_all[b - 1],
                v_all,
                _D_TRUE_VEL,
                self._err_q,
                self._err_v,
            )
        else:
            for i, drive in enumerate(self.drives):
                out = w.drive[i, sl]
                drive.advance_block(pos_m[i, sl], vel_m[i, sl], loads[i], noise[i, sl], out)
                if self._realism is not None:
                    self._realism_axis_fast(i, out)
            block_errors(
                q_all[b - 1],
                v_all,
                w.drive,
                a,
                b,
                _D_TRUE_POS,
                _D_TRUE_VEL,
                self._err_q,
                self._err_v,
            )
        # the tracking errors were written in place (read by the next block's _pre_block)
        self._q_ref_block[:] = q_all[b - 1]
        if self.spindle is not None:
            sp_out = w.spindle[sl]  # rows of a C array: C-contiguous
            self.spindle.advance_into(spd_all[sl], np.ascontiguousarray(torque), sp_out)
            self._theta = float(sp_out[n - 1, 4])
            self._omega = float(sp_out[n - 1, 3])
        else:
            spd = spd_all[sl]
            w.spindle[sl, 0] = 0.0
            w.spindle[sl, 1] = 0.0
            w.spindle[sl, 2] = spd
            w.spindle[sl, 3] = spd
            self._theta = float(self._theta + np.sum(spd) / fs)
            self._omega = float(spd[-1])
        self._torque_last = mean_torque
        self._realism_tool()

    def _realism_axis_fast(self, i: int, out: FloatArray) -> None:
        """:meth:`_realism_axis` with the friction power by a compiled mean and the friction
        columns as one slice."""
        ar = self._axis_real[i]
        opts = self._realism
        if ar is None or opts is None:
            return
        q = float(out[-1, _D_TRUE_POS])
        drive = self.drives[i]
        table = self._mode_tables[i]
        if table is not None:
            scales, mads, mbds = table
            j = int(np.argmin(np.abs(scales - ar.mode_scale(q))))
            drive._mad[:] = mads[j]
            drive._mbd[:] = mbds[j]
        if opts.friction_drift:
            power = mean_abs_product(out, _D_FRICTION, _D_TRUE_SPEED)
            sc = ar.friction_scale(q, power, self.period_s, opts)
            cols = self._fric_slices[i]
            drive._fric[cols] = self._fric_base[i][cols] * sc

    def _tooth_period_velocity(self, v_w: FloatArray) -> FloatArray:
        """Tool-centre velocity averaged over the last tooth period per sample, m/s.

        The chip a tooth cuts is the path travelled since the previous tooth passed
        (displacement over one tooth period T = 2π/(N Ω)), not the instantaneous velocity
        times T: a drive that oscillates at the tooth frequency under the cutting force
        would otherwise modulate the chip in phase with the force and bias the mean force
        (−6.5 % on F_x in a Ø20 mm slot at 1000 rev/min). Window: T at the spindle speed of
        the end of the last block, in whole samples, ≤ 0.1 s; the instantaneous velocity
        while the spindle stands (decision "Simulator chip from the tooth-period feed").
        """
        win = self._tooth_window()
        out = np.empty_like(v_w)
        self._v_count = _window_mean(
            np.ascontiguousarray(v_w), self._v_cum, self._v_count, win, out
        )
        return out

    def _tooth_window(self) -> int:
        """The window of :meth:`_tooth_period_velocity`, samples."""
        assert self.process is not None
        om = abs(self._omega)
        if om < 1e-3:
            return 1
        win = round(2 * math.pi / (self.process.tool.n_flutes * om) * self.sample_rate_hz)
        return int(min(max(win, 1), self._v_hist_max))

    def _tip_error(self) -> FloatArray:
        """Tracking error of the tool tip at the end of the last block (workpiece frame), m."""
        if isinstance(self.kin, TrunnionACMachine):
            q_ref = self._q_ref_block
            return np.asarray(self.kin.forward(q_ref) - self.kin.forward(q_ref - self._err_q))
        if self.stage:
            return np.array([self._err_q[0], 0.0, 0.0])
        return np.asarray(self._err_q[:3])

    # ------------------------------------------------------------------ realism per block
    def _realism_axis(self, i: int, out: FloatArray, q: float) -> None:
        ar = self._axis_real[i]
        opts = self._realism
        if ar is None or opts is None:
            return
        drive = self.drives[i]
        table = self._mode_tables[i]
        if table is not None:
            scales, mads, mbds = table
            j = int(np.argmin(np.abs(scales - ar.mode_scale(q))))
            drive._mad[:] = mads[j]
            drive._mbd[:] = mbds[j]
        if opts.friction_drift:
            power = float(np.mean(np.abs(out[:, _D_FRICTION] * out[:, _D_TRUE_SPEED])))
            sc = ar.friction_scale(q, power, self.period_s, opts)
            cols = self._fric_cols[i]
            drive._fric[cols] = self._fric_base[i][cols] * sc

    def _realism_tool(self) -> None:
        opts = self._realism
        if (
            opts is None
            or not opts.spindle_load
            or self._tool_modes_base is None
            or self.process is None
            or self.process._td is None
        ):
            return
        sc = tool_mode_scale(self._torque_last, self._omega, self._spindle_max, opts)
        if sc == self._tool_scale:
            return
        self._tool_scale = sc
        mx, my = self._tool_modes_base
        td = self.process._td
        td.modes_x = _scaled_modes(mx, sc)
        td.modes_y = _scaled_modes(my, sc)
        td.set_spindle_speed(td.spindle_speed_rad_s)  # re-discretises the modes

    # ------------------------------------------------------------------ Source
    def _fill(self, need: int) -> None:
        while self._buf_n < need:
            todo = self._block * self.ratio
            if self.n_total is not None and todo >= self.n_total:
                break
            # the blocks that cover the request (at most one block beyond it, as one block at
            # a time), at most _MAX_BLOCKS at once
            n_blocks = -(-(need - self._buf_n) // self.ratio)
            if self.n_total is not None:
                n_blocks = min(n_blocks, -(-(self.n_total - todo) // self.ratio))
            n_blocks = max(1, min(n_blocks, _MAX_BLOCKS))
            block = self._generate(n_blocks)
            for name, arr in block.items():
                self._buf.setdefault(name, []).append(arr)
            self._buf_n += n_blocks * self.ratio

    def read(self, max_samples: int) -> Chunk | None:
        """The next ``max_samples`` samples (fewer at the end), or None after the end."""
        if max_samples < 1:
            raise InputDataError(f"simulator: max_samples must be ≥ 1, got {max_samples}")
        if self.n_total is not None and self._pos >= self.n_total:
            return None
        self._fill(max_samples)
        m = min(max_samples, self._buf_n)
        if self.n_total is not None:
            m = min(m, self.n_total - self._pos)
        if m <= 0:
            return None
        data: dict[str, np.ndarray] = {}
        for name, parts in self._buf.items():
            arr = parts[0] if len(parts) == 1 else np.concatenate(parts)
            data[name] = arr[:m]
            self._buf[name] = [arr[m:]]
        self._buf_n -= m
        chunk = Chunk(self._pos, self.sample_rate_hz, self.t0_s, data)
        self._pos += m
        return chunk

    def take_stream_rows(self) -> dict[str, np.ndarray]:
        """The 333 Hz ``cnc`` stream rows up to the last sample read, removed from the queue.

        Returns a dict with ``time_s`` and the :meth:`stream_fields` as arrays.
        """
        t_read = self._pos / self.sample_rate_hz
        keys = ["time_s"] + [f.name for f in self.stream_fields()]
        if not self._rows:
            return {k: np.zeros(0) for k in keys}
        allr = {k: np.concatenate([r[k] for r in self._rows]) for k in keys}
        m = int(np.searchsorted(allr["time_s"], t_read, side="left"))
        self._rows = [{k: v[m:] for k, v in allr.items()}]
        return {k: np.asarray(v[:m], dtype=np.float64) for k, v in allr.items()}

    @property
    def samples_read(self) -> int:
        return self._pos

    def take_events(self) -> list[Event]:
        """Crash events (kind ``crash``) raised since the last call, removed from the queue.

        Events are raised as blocks are computed, so they may lead the samples read by up to
        one generated batch.
        """
        return self.crashes.take_events()


def _with_high_modes(cfg: FeedAxisConfig, rng: np.random.Generator) -> FeedAxisConfig:
    dm = cfg.disturbance_modes
    if dm is None:
        return cfg
    f, z, a, b = high_modes(cfg, rng)
    new = dm.model_copy(
        update={
            "natural_frequency_hz": [*dm.natural_frequency_hz, *f],
            "damping_ratio": [*dm.damping_ratio, *z],
            "alpha": [*dm.alpha, *a],
            "beta": [*dm.beta, *b],
        }
    )
    return cfg.model_copy(update={"disturbance_modes": new})


def _mode_table(
    modes: ModalStateSpace, ar: AxisRealism, params: FeedDriveParams, substeps: int, fs: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discretised disturbance modes at 9 frequency scales across the axis' travel."""
    d = abs(ar.mode_shift)
    scales = np.linspace(1.0 - d, 1.0 + d, 9)
    mads, mbds = [], []
    h = 1.0 / fs / substeps
    for s in scales:
        m = ModalStateSpace.from_modes(
            modes.frequency_hz * s, modes.damping_ratio, modes.alpha, modes.beta, modes.d
        )
        ad, bd = m.discretise(h)
        mads.append(ad)
        mbds.append(bd)
    return scales, np.stack(mads), np.stack(mbds)


def _scaled_modes(m: DirectionModes, scale: float) -> DirectionModes:
    if m.natural_hz.size == 0:
        return m
    return DirectionModes(m.natural_hz * scale, m.damping_ratio, m.stiffness_n_per_m)
