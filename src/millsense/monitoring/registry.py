"""Monitors by name: the ``--methods`` of ``millsense monitor``.

A monitor is registered as ``name → factory(context) → Block``; the CLI builds the
:class:`MonitorContext` from the recording, the plan and the options, and every factory takes
what it needs from it (raising a one-line :class:`~millsense.core.errors.InputDataError` when
something is missing). Registered: the chatter criteria (seeds 000, 001, 002), the breakage
detectors (seeds 000, 002), ``engagement`` (seed 004 ch. 2: depths, K_t, runout per revolution;
needs the tool geometry and the feed per tooth) and ``contact`` (seed 004 ch. 3: contact time
and position of one cut motion; needs an air-cut reference window). Further monitors are added
with :func:`register`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk

if TYPE_CHECKING:
    from millsense.monitoring.angle_origin import ToolAngle


@dataclass(frozen=True)
class MonitorContext:
    """What a monitor factory may use.

    Attributes
    ----------
    channels : channels of the recording (name → unit).
    sample_rate_hz : stream rate, Hz.
    signal : channel chosen with ``--channel`` (None: each monitor's default).
    speed_channel, speed_unit : spindle-speed channel and its unit (``rad/s``, ``rev/min``),
        or None.
    speed_rpm : constant spindle speed when there is no speed channel, rev/min.
    n_flutes : teeth of the tool.
    nc_line_channel : the CNC's NC-line channel, or None.
    locate : (time s, NC line) → (NC line, x, y, z mm) on the plan's path, or None.
    plan : the virtual plan (:class:`~millsense.plan.virtual_plan.VirtualPlan`), or None.
    source : name of the recording (for messages).
    options : further named settings for specific monitors (``engagement.feed_per_tooth_mm``,
        ``engagement.air_torque_nm``, ``engagement.response`` (the observer's
        :class:`~millsense.monitoring.engagement.TorqueResponse`),
        ``contact.air_s`` (start, end) s, ``contact.cut_s`` s, ``contact.position_channel``,
        ``breakage.expected_channel``, ``breakage.signal`` (what the breakage detectors average
        where it is not ``signal``: ``monitor --machine``'s spindle DOB, decision 1728),
        ``breakage.mean_resolution`` (that signal's resolution over a tooth period, its unit ×
        s: the DOB's encoder count, decision 1732), ``<chatter method>.threshold``,
        ``chatter.encoder_counts_rev`` (the machine file's spindle encoder, decision 1697)).
    tool : the tool (:class:`~millsense.core.config.ToolConfig`: ``--tool`` or the plan's), or
        None.
    read : reads samples ``[i0, i1)`` of a channel of the recording, or None (live).
    t0_s : time of the first sample, s.
    n_samples : samples in the recording (0: unknown).
    """

    channels: dict[str, str]
    sample_rate_hz: float
    signal: str | None = None
    speed_channel: str | None = None
    speed_unit: str = "rad/s"
    speed_rpm: float | None = None
    n_flutes: int = 2
    nc_line_channel: str | None = None
    locate: Callable[..., Any] | None = None
    plan: Any = None
    source: str = "recording"
    options: dict[str, Any] = field(default_factory=dict)
    tool: Any = None
    read: Callable[[str, int, int], np.ndarray] | None = None
    t0_s: float = 0.0
    n_samples: int = 0

    def require(self, names: Sequence[str], monitor: str) -> None:
        """One-line error if a channel ``monitor`` needs is not in the recording."""
        for c in names:
            if c not in self.channels:
                raise InputDataError(
                    f"{self.source}: monitor '{monitor}' needs channel '{c}', which the "
                    f"recording does not hold (it holds: {', '.join(sorted(self.channels))})"
                )


Factory = Callable[[MonitorContext], Block]
MONITORS: dict[str, Factory] = {}


def register(name: str, factory: Factory) -> None:
    """Add a monitor under ``name`` (a later registration replaces an earlier one)."""
    MONITORS[name] = factory


#: Signal channels a chatter monitor uses when none is chosen, best first: the compensated
#: spindle torque (seed 000), the raw spindle current, then external sensors.
CHATTER_SIGNALS = (
    "est/spindle/spindle/load",
    "spindle/torque_est",
    "spindle/current_cmd",
    "spindle/current",
    "accel/x",
    "accel/y",
    "mic/pressure",
)


#: Signals that carry the spindle drive's encoder quantisation lines (decision 1697): the
#: observer's compensated torque and the drive's current (command).
SPINDLE_DRIVE_SIGNALS = (
    "est/spindle/spindle/load",
    "plan/cutting_torque",
    "spindle/torque_est",
    "spindle/current_cmd",
    "spindle/current",
)


def _chatter_factory(method: str) -> Factory:
    def make(ctx: MonitorContext) -> Block:
        from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings

        signal = ctx.signal
        if signal is None:
            signal = next((c for c in CHATTER_SIGNALS if c in ctx.channels), None)
            if signal is None:
                raise InputDataError(
                    f"{ctx.source}: monitor '{method}' needs a signal channel (one of "
                    f"{', '.join(CHATTER_SIGNALS)}, or --channel); the recording holds: "
                    f"{', '.join(sorted(ctx.channels))}"
                )
        ctx.require([signal], method)
        if ctx.speed_channel is not None:
            ctx.require([ctx.speed_channel], method)
        elif not (ctx.speed_rpm and ctx.speed_rpm > 0):
            raise InputDataError(
                f"{ctx.source}: monitor '{method}' needs the spindle speed: no spindle-speed "
                "channel (spindle/speed, spindle/speed_cmd) and no spindle_rpm in its metadata; "
                "give --spindle-rpm"
            )
        return ChatterMonitor(
            ChatterSettings(
                method=method,
                signal=signal,
                n_flutes=ctx.n_flutes,
                speed_channel=ctx.speed_channel,
                speed_unit=ctx.speed_unit,
                speed_rpm=ctx.speed_rpm,
                nc_line_channel=ctx.nc_line_channel,
                threshold=ctx.options.get(f"{method}.threshold"),
                # the spindle encoder where the signal carries its quantisation lines (the
                # observer's torque or the drive's current, decision 1697)
                encoder_counts_rev=ctx.options.get("chatter.encoder_counts_rev")
                if signal in SPINDLE_DRIVE_SIGNALS
                else None,
            ),
            locate=ctx.locate,
        )

    return make


for _m in ("chatter-comb", "chatter-sdft", "chatter-threshold"):
    register(_m, _chatter_factory(_m))


#: Torque channels a breakage monitor uses when none is chosen, best first: the spindle
#: observer's compensated load (``monitor --machine``), an estimated spindle torque.
BREAKAGE_SIGNALS = ("est/spindle/spindle/load", "spindle/torque_est")
#: What the breakage monitors read when nothing is chosen: a session's (``millsense run``)
#: cutting torque, less its air-cut reference, first: its spindle DOB's (decision 1727), then its
#: LQE observer's.
BREAKAGE_SIGNALS_SESSION = ("plan/dob_cutting_torque", "plan/cutting_torque", *BREAKAGE_SIGNALS)
#: 1 where the spindle is settled at its commanded speed (a session's output, or made by
#: ``millsense monitor`` from spindle/speed and spindle/speed_cmd): breakage is judged only there
#: (decision 1550).
AT_SPEED = "spindle/at_speed"
#: ``millsense monitor``'s gate on a session recording: the spindle at speed and the plan's tool
#: in the cut; breakage is judged there when it is present.
BREAKAGE_GATE = "monitor/breakage_gate"
#: A session recording's expected torque where the calibrated plan judges the tool (steady
#: rows, spindle at speed; decisions 1622, 1550): the virtual threshold's reference.
SESSION_EXPECTED = "plan/judged_torque"
#: ``millsense monitor``'s gate of the plan-free breakage detectors (dual, constant) on a
#: session recording: the spindle at speed and the plan steady in the cut (``plan/judged_torque``
#: > 0), where their thresholds and reference are learnt and the cut judged (decision 1676).
BREAKAGE_STEADY_GATE = "monitor/breakage_steady_gate"
#: A session recording's lowest expected torque across the plan's transients in the material:
#: the virtual threshold judges a drop below it there (decision 1674).
SESSION_FLOOR = "plan/torque_floor"


def _breakage_factory(method: str) -> Factory:
    name = f"breakage-{method}"

    def make(ctx: MonitorContext) -> Block:
        from millsense.monitoring.breakage import BreakageBlock
        from millsense.monitoring.breakage_phased import PhasedBreakage

        # `monitor --machine` gives its spindle DOB's torque (decision 1728)
        signal = ctx.options.get("breakage.signal") or ctx.signal or next(
            (c for c in BREAKAGE_SIGNALS_SESSION if c in ctx.channels), None
        )
        if signal is None:
            raise InputDataError(
                f"{ctx.source}: monitor '{name}' needs a spindle torque channel (one of "
                f"{', '.join(BREAKAGE_SIGNALS_SESSION)}: give --machine for the spindle "
                "observer, or --channel)"
            )
        ctx.require([signal], name)
        if ctx.speed_channel is None or ctx.speed_unit != "rad/s":
            raise InputDataError(
                f"{ctx.source}: monitor '{name}' needs a spindle-speed channel in rad/s "
                "(spindle/speed) to cut the signal into tooth periods"
            )
        ctx.require([ctx.speed_channel], name)
        expected = ctx.options.get("breakage.expected_channel")
        if expected is None and SESSION_EXPECTED in ctx.channels:
            expected = SESSION_EXPECTED  # a recording of `millsense run`
        if method == "virtual":
            if expected is None:
                raise InputDataError(
                    f"{ctx.source}: monitor '{name}' needs the calibrated plan's expected "
                    f"torque per sample ('{SESSION_EXPECTED}' of a `millsense run` recording, "
                    "or option breakage.expected_channel; `millsense replay RUN.h5 --plan "
                    "PLAN.parquet` calibrates the plan on a recording and runs it); use "
                    "breakage-constant or "
                    "breakage-dual without it"
                )
            ctx.require([expected], name)
        # the plan-free detectors judge a session's plan-steady cut only (decision 1676)
        gates: tuple[str, ...] = (BREAKAGE_GATE, AT_SPEED)
        if method != "virtual":
            gates = (BREAKAGE_STEADY_GATE, *gates)
        options: dict[str, Any] = dict(
            signal_channels=(signal,),
            speed_channel=ctx.speed_channel,
            enable_channel=next((c for c in gates if c in ctx.channels), None),
            mean_resolution=float(ctx.options.get("breakage.mean_resolution", 0.0)),
            name=name,
        )
        if method == "virtual":  # at several phases of the tooth period (decision 1552)
            floor = SESSION_FLOOR if expected == SESSION_EXPECTED else None
            if floor not in ctx.channels:  # a recording of a session before decision 1674
                floor = None
            return PhasedBreakage(ctx.n_flutes, method="virtual", expected_channel=expected,
                                  floor_channel=floor, **options)  # fmt: skip
        # seed 002's detector and the constant reference on a shop's part: an alarm needs a
        # broken flute's drop and the next flute's rise (decisions 1707, 1724; the seeds'
        # cases run them bare)
        return BreakageBlock(ctx.n_flutes, method=method,  # type: ignore[arg-type]
                             flute_check=True, **options)

    return make


for _b in ("virtual", "constant", "dual"):
    register(f"breakage-{_b}", _breakage_factory(_b))


#: Torque channels the engagement monitor uses when none is chosen (N·m), best first.
ENGAGEMENT_SIGNALS = BREAKAGE_SIGNALS


#: The spindle observer's compensated torque (a session's, or the monitor's own observer).
OBSERVER_ESTIMATE = "est/spindle/spindle/load"
#: The CNC's interpolated path feed (m/s): the engagement monitor's feed per tooth where it is
#: recorded and no --feed-per-tooth-mm is given (overrides included).
PATH_FEED = "cnc/feed"


def _plan_feed_per_tooth_mm(plan: Any, flutes: int) -> float | None:
    """Median programmed feed per tooth of the plan's cutting steps, mm (None: none)."""
    try:
        feed = np.asarray(plan["feed_mm_min"], dtype=float)
        rpm = np.abs(np.asarray(plan["spindle_rpm"], dtype=float))
        cut = np.asarray(plan["in_cut"], dtype=bool)
    except (KeyError, TypeError):
        return None
    ok = cut & (rpm > 0) & (feed > 0)
    if not ok.any():
        return None
    return float(np.median(feed[ok] / (flutes * rpm[ok])))


#: The spindle's angle (rad), which the engagement monitor prefers to a speed (decision 1737).
SPINDLE_ANGLE = "spindle/angle"
#: A once-per-revolution index pulse, its next choice (decision 1737).
SPINDLE_INDEX = "spindle/index"


def _index_threshold(ctx: MonitorContext, index: str | None) -> float:
    """An index pulse's mark level: 0.5 on a 0/1 channel (unit 1), else half its largest
    value over the recording (a TTL pulse in volts), or 0.5 where it cannot be read."""
    if index is None or ctx.channels.get(index) == "1" or ctx.read is None or ctx.n_samples <= 0:
        return 0.5
    x = np.asarray(ctx.read(index, 0, ctx.n_samples), dtype=float)
    x = x[np.isfinite(x)]
    return 0.5 * float(x.max()) if x.size and x.max() > 0 else 0.5


def _angle_speeds_rpm(ctx: MonitorContext, channel: str, index: bool) -> np.ndarray:
    """The speeds (rev/min) of an angle channel's sample-to-sample steps, or of the angle an
    index pulse gives (``index``)."""
    from millsense.monitoring.index_pulse import index_angle, index_state

    assert ctx.read is not None
    a = np.ascontiguousarray(ctx.read(channel, 0, ctx.n_samples), dtype=np.float64)
    if index:
        pulse, a = a, np.empty(a.size)
        index_angle(pulse, _index_threshold(ctx, channel), index_state(), a)
    step = np.abs(np.diff(a[np.isfinite(a)]))
    step = np.minimum(step, 2.0 * np.pi - step)  # a wrapped angle's jump of 2π is no motion
    return np.asarray(step * ctx.sample_rate_hz * 60.0 / (2.0 * np.pi), dtype=np.float64)


def _spindle_speeds_rpm(
    ctx: MonitorContext, angle: str | None = None, index: str | None = None
) -> np.ndarray:
    """The recording's spindle speed samples (rev/min, finite, ≥ 0) from the engagement
    monitor's angle reference (an angle channel's or an index pulse's steps) or its speed
    channel, or the set speed alone; empty without the recording's samples and a set speed (a
    live stream with a speed channel)."""
    read = ctx.read if ctx.n_samples > 0 else None
    reference = angle or index
    if read is not None and reference is not None:
        return _angle_speeds_rpm(ctx, reference, index is not None)
    if read is None or ctx.speed_channel is None:
        # a set speed (decision 1737); none on a live stream with a speed channel
        return np.array([float(ctx.speed_rpm)]) if ctx.speed_rpm else np.zeros(0)
    speed = np.abs(np.asarray(read(ctx.speed_channel, 0, ctx.n_samples), dtype=float))
    per_unit = 60.0 / (2.0 * np.pi) if ctx.speed_unit == "rad/s" else 1.0
    return speed[np.isfinite(speed)] * per_unit


def _engagement_cycle(speeds_rpm: np.ndarray) -> int:
    """The engagement monitor's monitoring cycle (decision 1717): the revolutions nearest
    Lee's 50 ms at the recording's running speed (the median of its speeds above a tenth of
    the top: the spindle turning, not its run-up; an index pulse's first line is no running
    speed, 1.8× the 1000 rev/min of a test's), 1 without one."""
    from millsense.monitoring.engagement import cycle_revolutions

    top = float(speeds_rpm.max()) if speeds_rpm.size else 0.0
    if not top > 0:
        return 1
    return cycle_revolutions(float(np.median(speeds_rpm[speeds_rpm > 0.1 * top])))


def _engagement_harmonics(
    ctx: MonitorContext, n_flutes: int, name: str, speeds_rpm: np.ndarray
) -> int:
    """The tooth harmonics the engagement monitor fits: the default, or those below the
    Nyquist frequency at the recording's top spindle speed (of ``speeds_rpm``,
    :func:`_spindle_speeds_rpm`) where fewer (decision 1734); a one-line error where fewer than
    the fit needs lie below it. Without the recording's speed samples (a live stream): the
    default, and the block leaves a revolution whose harmonics reach the Nyquist frequency
    unevaluated."""
    from millsense.monitoring.engagement import (
        DEFAULT_HARMONICS,
        MIN_HARMONICS,
        harmonics_below_nyquist,
    )

    top_rpm = float(speeds_rpm.max()) if speeds_rpm.size else 0.0
    if not top_rpm > 0:
        return DEFAULT_HARMONICS
    k = harmonics_below_nyquist(n_flutes, top_rpm, ctx.sample_rate_hz)
    if k < MIN_HARMONICS:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs {MIN_HARMONICS} tooth-passing harmonics below "
            f"the Nyquist frequency ({0.5 * ctx.sample_rate_hz:g} Hz); at the recording's top "
            f"speed of {top_rpm:.0f} rev/min a {n_flutes}-flute tool's tooth-passing frequency "
            f"is {n_flutes * top_rpm / 60.0:.0f} Hz, which leaves {k}: record at a higher rate"
        )
    return k


def _engagement(ctx: MonitorContext) -> Block:
    """Seed 004 ch. 2 (Lee Fig. 2.9) from the registry: tool from ``--tool`` or the plan, feed
    per tooth from ``--feed-per-tooth-mm``, else the recorded path feed (``cnc/feed``: the feed
    the machine ran, overrides included), else the plan's programmed feed."""
    from millsense.monitoring.engagement import EngagementBlock

    name = "engagement"
    signal = ctx.signal or next((c for c in ENGAGEMENT_SIGNALS if c in ctx.channels), None)
    if signal is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs a spindle torque channel in N·m (one of "
            f"{', '.join(ENGAGEMENT_SIGNALS)}: give --machine for the spindle observer, or "
            "--channel)"
        )
    ctx.require([signal], name)
    angle = SPINDLE_ANGLE if ctx.channels.get(SPINDLE_ANGLE) == "rad" else None
    index = SPINDLE_INDEX if angle is None and SPINDLE_INDEX in ctx.channels else None
    if (angle is None and index is None and ctx.speed_channel is None
            and not (ctx.speed_rpm and ctx.speed_rpm > 0)):  # fmt: skip
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs the spindle angle: a spindle-angle channel "
            f"({SPINDLE_ANGLE}, rad), an index pulse ({SPINDLE_INDEX}), a spindle-speed "
            "channel (spindle/speed) or, for a cut at a set speed, --spindle-rpm"
        )
    if angle is None and index is None and ctx.speed_channel is not None:
        ctx.require([ctx.speed_channel], name)
    tool = ctx.tool
    if tool is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs the tool's diameter, flutes and helix: give "
            "--tool (preset or .toml) or a --plan built with the tool"
        )
    fz = ctx.options.get("engagement.feed_per_tooth_mm")
    # the feed the CNC ran (overrides and the adaptive feed included) before the programmed one
    feed = PATH_FEED if fz is None and PATH_FEED in ctx.channels else None
    if fz is None and feed is None and ctx.plan is not None:
        fz = _plan_feed_per_tooth_mm(ctx.plan, int(tool.flutes))
    if fz is None and feed is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs the feed per tooth: give --feed-per-tooth-mm "
            f"(mm), a --plan with the programmed feed, or record the path feed ({PATH_FEED}, "
            "m/s)"
        )
    # without a speed channel: the set speed, refined from the torque's own revolutions
    # (decision 1737)
    reference = angle or index  # a revolution reference beats a speed (decision 1737)
    set_rpm, speed_source = (None, "") if reference is not None else _set_speed(ctx, signal)
    speeds = _spindle_speeds_rpm(ctx, angle, index)
    settings: dict[str, Any] = dict(
        n_harmonics=_engagement_harmonics(ctx, int(tool.flutes), name, speeds),
        cycle_revolutions=_engagement_cycle(speeds),
        torque_channel=signal,
        speed_channel=ctx.speed_channel or "spindle/speed",
        speed_unit=ctx.speed_unit,
        speed_rpm=set_rpm,
        angle_channel=angle,
        index_channel=index,
        index_threshold=_index_threshold(ctx, index),
        feed_channel=feed,
        feed_per_tooth_mm=None if fz is None else float(fz),
        # the spindle observer's response, where the signal is its estimate (decision 1554)
        response=ctx.options.get("engagement.response") if signal == OBSERVER_ESTIMATE else None,
        air_torque_nm=ctx.options.get("engagement.air_torque_nm"),
        name=name,
    )
    shape = (int(tool.flutes), float(tool.diameter_mm), float(tool.helix_deg))
    given = ctx.options.get("engagement.flute0_deg")
    if given is not None:
        # flute 0's angle where the reference reads 0, known for the tool's clamping: no
        # search (decision 1694)
        if reference is None:
            raise InputDataError(
                f"{ctx.source}: --flute0-deg needs a spindle-angle reference ({SPINDLE_ANGLE} or "
                f"{SPINDLE_INDEX}): without one the record's zero is wherever the spindle was "
                "when it started"
            )
        block = EngagementBlock(*shape, **settings, angle_offset_rad=math.radians(given))
        block.offset_source = "given"
        block.speed_source = speed_source
        return block
    block = EngagementBlock(*shape, **settings)
    # the tool's angle at the record's zero, from its steady cut's harmonics (decision 1738)
    found = _tool_angle(ctx, block)
    if found is not None and found.misaligned and found.resolved(block.n_harmonics):
        block = EngagementBlock(*shape, **settings, angle_offset_rad=found.offset_rad)
        block.offset_source = "found"
    elif found is not None and found.misaligned:
        block.frame_unresolved = found  # (the pipeline resets the block before its run)
    block.speed_source = speed_source
    return block


def _tool_angle(ctx: MonitorContext, probe: Block) -> ToolAngle | None:
    """The tool's angle at the recording's first sample (decision 1738): ``probe`` (the
    engagement block, its angle from the record's zero) is run over the recording, and
    :func:`~millsense.monitoring.angle_origin.tool_angle_offset` searches the longest steady
    cut's averaged harmonics. None for a live stream or fewer than the averaged fit's
    revolutions in one steady cut."""
    from millsense.monitoring.angle_origin import tool_angle_offset
    from millsense.monitoring.engagement import EngagementBlock
    from millsense.monitoring.steady_cuts import steady_rows
    from millsense.monitoring.torque_spectrum import AVERAGED_MIN_REVS

    if ctx.read is None or ctx.n_samples <= 0 or not isinstance(probe, EngagementBlock):
        return None
    fs = ctx.sample_rate_hz
    probe.reset(fs)
    step = 1 << 16
    for a in range(0, ctx.n_samples, step):
        b = min(a + step, ctx.n_samples)
        data = {c: np.asarray(ctx.read(c, a, b), dtype=np.float64) for c in probe.inputs}
        probe.process(Chunk(a, fs, ctx.t0_s, data))
    harm = probe.revolution_harmonics
    rows = steady_rows([None if h is None else h[0] for h in harm])
    if len(rows) < AVERAGED_MIN_REVS:
        return None
    kept = [h for h in (harm[i] for i in rows) if h is not None]
    return tool_angle_offset(
        probe.geom, probe.n_harmonics, probe.edge, probe.max_depth_fraction, probe.orders,
        [h[0] for h in kept], [h[1] for h in kept], [h[2] for h in kept], [h[3] for h in kept],
    )  # fmt: skip


def _set_speed(ctx: MonitorContext, signal: str) -> tuple[float | None, str]:
    """Without a speed channel, the engagement monitor's constant speed (rev/min) and where
    it came from (decision 1737): the set speed refined from the torque record's own
    revolutions (:func:`~millsense.monitoring.revolution_period.refined_speed_rpm`), or the set
    speed as given where the record does not show it (a live stream, fewer than 4
    revolutions, no revolution in the torque). (None, "") with a speed channel."""
    from millsense.monitoring.revolution_period import MAX_SAMPLES, refined_speed_rpm

    if ctx.speed_channel is not None or not ctx.speed_rpm:
        return None, ""
    set_rpm = float(ctx.speed_rpm)
    if ctx.read is None or ctx.n_samples <= 0:
        return set_rpm, f"the set speed of {set_rpm:g} rev/min"
    x = np.asarray(ctx.read(signal, 0, min(ctx.n_samples, MAX_SAMPLES)), dtype=float)
    rpm = refined_speed_rpm(x, ctx.sample_rate_hz, set_rpm)
    if rpm is None:
        return set_rpm, (f"the set speed of {set_rpm:g} rev/min, which the torque's "
                         "revolutions did not refine")  # fmt: skip
    return rpm, (f"{rpm:.4f} rev/min, the set {set_rpm:g} rev/min refined from the torque's "
                 "own revolutions")  # fmt: skip


register("engagement", _engagement)

#: Torque channels of the contact detector, best first: the spindle torque command (Lee §3.2),
#: the observer's load, the current command (proportional to the torque command).
CONTACT_SIGNALS = ("spindle/torque_cmd", "est/spindle/spindle/load", "spindle/current_cmd")
#: Axis-position channels of the contact detector, best first (the X axis, Lee §3.2).
CONTACT_POSITIONS = ("x/scale", "x/position", "x/position_cmd")


class WindowedBlock(Block):
    """Runs ``block`` on the samples ``[start, stop)`` of the stream only, as a stream of its
    own (its sample 0 is ``start``): for detectors of one motion, as the contact detector of
    a cut motion that starts at the spindle start t₀ (Lee Fig. 3.6). Event times and samples
    are given on the outer stream."""

    def __init__(self, block: Block, start: int, stop: int) -> None:
        self.block = block
        self.start, self.stop = int(start), int(stop)
        self.name = getattr(block, "name", "windowed")
        self.inputs = tuple(block.inputs)

    def output_channels(self) -> list[ChannelInfo]:
        return []

    def reset(self, sample_rate_hz: float) -> None:
        self.block.reset(sample_rate_hz)

    def process(self, chunk: Chunk) -> BlockOutput:
        import dataclasses

        n = len(next(iter(chunk.data.values()))) if chunk.data else 0
        a = max(self.start, chunk.start)
        b = min(self.stop, chunk.start + n)
        if b <= a:
            return BlockOutput()
        data = {k: chunk.data[k][a - chunk.start : b - chunk.start] for k in self.inputs}
        t0 = chunk.t0_s + self.start / chunk.sample_rate_hz
        out = self.block.process(Chunk(a - self.start, chunk.sample_rate_hz, t0, data))
        events = [
            e if e.sample < 0 else dataclasses.replace(e, sample=e.sample + self.start)
            for e in out.events
        ]
        return BlockOutput({}, events)


def _contact(ctx: MonitorContext) -> Block:
    """Seed 004 ch. 3 (Lee Fig. 3.6) from the registry: the air-cut motion is the window
    ``--air-s A:B`` of the recording, the cut motion starts at ``--cut-s`` (default B) and is
    as long as the air-cut window."""
    from millsense.monitoring.contact import ContactBlock

    name = "contact"
    air = ctx.options.get("contact.air_s")
    if air is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs the air-cut reference: give --air-s A:B "
            "(the air-cut motion's time window, s; the cut motion follows at B or --cut-s)"
        )
    signal = ctx.signal or next((c for c in CONTACT_SIGNALS if c in ctx.channels), None)
    if signal is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs a spindle torque command (one of "
            f"{', '.join(CONTACT_SIGNALS)}, or --channel)"
        )
    pos = ctx.options.get("contact.position_channel") or next(
        (c for c in CONTACT_POSITIONS if c in ctx.channels), None
    )
    if pos is None:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs an axis-position channel (one of "
            f"{', '.join(CONTACT_POSITIONS)}, or --position)"
        )
    ctx.require([signal, pos], name)
    if ctx.read is None or ctx.n_samples <= 0:
        raise InputDataError(f"{ctx.source}: monitor '{name}' needs a recording (air-cut window)")
    fs = ctx.sample_rate_hz
    a_s, b_s = (float(v) for v in air)
    c_s = float(ctx.options.get("contact.cut_s") or b_s)
    i_a, i_b = round((a_s - ctx.t0_s) * fs), round((b_s - ctx.t0_s) * fs)
    i_c = round((c_s - ctx.t0_s) * fs)
    if not (0 <= i_a < i_b <= ctx.n_samples):
        end = ctx.t0_s + ctx.n_samples / fs
        raise InputDataError(
            f"{ctx.source}: --air-s {a_s:g}:{b_s:g} is not a window inside the recording "
            f"({ctx.t0_s:g}-{end:g} s)"
        )
    if not (0 <= i_c < ctx.n_samples):
        raise InputDataError(f"{ctx.source}: --cut-s {c_s:g} s is outside the recording")
    length = min(i_b - i_a, ctx.n_samples - i_c)
    if ctx.speed_channel is not None:
        spd = np.abs(ctx.read(ctx.speed_channel, i_a, i_b))
        rev_s = float(np.mean(spd)) * (1 / (2 * np.pi) if ctx.speed_unit == "rad/s" else 1 / 60)
    else:
        rev_s = (ctx.speed_rpm or 0.0) / 60.0
    if not rev_s > 0:
        raise InputDataError(
            f"{ctx.source}: monitor '{name}' needs the spindle turning in the air-cut window "
            "(its period T); give --spindle-rpm without a speed channel"
        )
    block = ContactBlock(
        ctx.read(signal, i_a, i_a + length),
        1.0 / rev_s,
        torque_channel=signal,
        position_channel=pos,
        name=name,
    )
    return WindowedBlock(block, i_c, i_c + length)


register("contact", _contact)
