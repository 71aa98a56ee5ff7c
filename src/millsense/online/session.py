"""The integrated on-line session: estimators, the virtual plan, monitors and controllers
side by side on one stream (seed 000 ch. 6, Fig. 6.16; seed 002 ch. 4–5; issue 16 item 5).

:func:`session_blocks` builds the blocks in the order the data flows:

1. the estimators of a commissioned machine file (the spindle torque observer; for force
   regulation the five feed-drive estimators and the forces at the tool, Aslan Eq. 3.51), or
   a table dynamometer on the virtual machine (``force_from="dynamometer"``, a sensor);
2. the tool-centre point from the axis positions and :class:`~millsense.online.plan_sync.
   PlanSync` (plan row, NC line, in cut, K_tc-calibrated expected torque);
3. the :class:`~millsense.control.arbitration.Supervisor` with its children: chatter
   avoidance around a chatter monitor on the compensated spindle torque (seed 000 §2.7),
   the breakage monitor with the virtual threshold (seed 000 §2.9), and the adaptive feed
   control with the virtual look-ahead (seed 000 §2.10) — the only block whose OVERRIDE
   events reach the machine.

:func:`run_session` runs them on any source (the virtual machine in closed loop, a
recording in replay, a CNC link), behind the :class:`~millsense.online.guard.GuardedSource`,
writes the recording chunk by chunk (crash-safe) with the event log beside it, and returns a
summary. Nothing recorded is lost when the source fails: the writer is closed in every case.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from millsense.control.adaptive_feed import (
    REPORTED_OVERRIDE,
    AdaptiveFeedBlock,
    AdaptiveFeedOptions,
)
from millsense.control.arbitration import Supervisor, SupervisorOptions
from millsense.core.config import MachineConfig
from millsense.core.errors import ConfigError
from millsense.core.recording import COMPUTED_CHANNELS
from millsense.monitoring.breakage_phased import PhasedBreakage
from millsense.online.gates import AirReference, SpindleAtSpeed
from millsense.online.guard import FAULT_CHANNEL, GuardedSource
from millsense.online.plan_sync import PlanSync, TcpFromAxes, feed_time_constant_s
from millsense.plan.virtual_plan import VirtualPlan
from millsense.streaming.block import Block, Chunk, Event
from millsense.streaming.engine import Pipeline, run
from millsense.streaming.sources import Source, SourceWrapper

#: The compensated spindle torque of the machine file's observer (chatter, breakage, K_tc).
TORQUE_CHANNEL = "est/spindle/spindle/load"
#: The same less its air-cut reference (:class:`~millsense.online.gates.AirReference`).
CUTTING_TORQUE = "plan/cutting_torque"
#: The spindle's disturbance observer for tooth-period averages (decision 1726) less its own
#: air-cut reference: what the breakage monitor averages by default (``breakage_torque="dob"``,
#: decision 1727).
DOB_CUTTING_TORQUE = "plan/dob_cutting_torque"
#: The CNC's interpolated path feed (m/s): the plan's expected torque follows it (decision
#: 1733).
PATH_FEED = "cnc/feed"
#: What the breakage monitor may average (:attr:`SessionOptions.breakage_torque`).
BREAKAGE_TORQUES = ("dob", "observer")
FORCE_SOURCES = ("estimate", "dynamometer")
#: Expected torques below this fraction of the plan's largest are not judged for breakage: the
#: tooth-period average of an observer's estimate is too noisy there (decision 1622).
MIN_JUDGED = 0.3
#: Revolutions of travel either side over which the plan's torque must be steady for breakage
#: to be judged (decision 1627: the plan is synchronised on the commanded path, whose lead on
#: the tool is the servo lag v/K_v, 0.16 mm at 150 % of 400 mm/min with K_v = 62.8 1/s, under
#: the 0.6 mm a revolution travels there).
TRANSIENT_REVS = 1.0


@dataclass(frozen=True)
class SessionOptions:
    """What runs in a session (field units in the names).

    Attributes
    ----------
    adaptive : run the adaptive feed control.
    quantity : regulated quantity (``force``, ``torque``, ``power``); by default the spindle
        power from the spindle torque observer (what Heidenhain AFC regulates; decision 1622).
    reference : its set point (N, N·m, W); None: 90 % of the plan's largest predicted
        per-revolution value in cut (peak force, mean torque or power).
    force_from : ``estimate`` (the feed-drive estimators, sensorless) or ``dynamometer``
        (the virtual machine's table dynamometer, a sensor).
    look_ahead : the virtual look-ahead of seed 000.
    chatter : run the chatter monitor; ``chatter_method`` which one; ``avoid_chatter``: act
        (spindle override) rather than recommend.
    breakage : run the breakage monitor (virtual threshold); ``hold_on_breakage``: feed hold.
    breakage_torque : what the breakage monitor averages per tooth period: ``dob`` (the
        spindle's disturbance observer, seed 001 Eq. 2-15: a multi-flute tool's break found in
        its first revolution; decisions 1726, 1727) or ``observer`` (the machine file's LQE
        observer, Aslan Eq. 5.17-5.21, as chatter and the adaptive feed read it).
    period_s : control period of the supervisor, s.
    stability_case : the lobes' case (:class:`~millsense.stability.cases.
        MillingStabilityCase`: tool modes, flutes, coefficients, immersion) the chatter
        avoidance checks its speeds on, at the plan's axial depth where it chatters; None: the
        nearest faster lobe, unchecked (Smith–Tlusty).
    """

    adaptive: bool = True
    quantity: str = "power"
    reference: float | None = None
    force_from: str = "estimate"
    look_ahead: bool = True
    chatter: bool = True
    chatter_method: str = "chatter-comb"
    avoid_chatter: bool = True
    breakage: bool = True
    hold_on_breakage: bool = True
    breakage_torque: str = "dob"
    period_s: float = 0.01
    stability_case: Any = None

    def __post_init__(self) -> None:
        if self.breakage_torque not in BREAKAGE_TORQUES:
            raise ConfigError(f"--breakage-torque: one of {', '.join(BREAKAGE_TORQUES)}, got "
                              f"{self.breakage_torque!r}")  # fmt: skip
        if self.force_from not in FORCE_SOURCES:
            raise ConfigError(
                f"--force-from: one of {', '.join(FORCE_SOURCES)}, got {self.force_from!r}"
            )


@dataclass
class SessionBlocks:
    """The blocks of a session and what the summary reads of them."""

    blocks: list[Block]
    supervisor: Supervisor
    notes: list[str] = field(default_factory=list)


def default_reference(plan: VirtualPlan, quantity: str, statistic: str) -> float:
    """90 % of the plan's largest predicted per-revolution value in cut (the controller then
    works where the program is heaviest and leaves the lighter cuts to the override limit)."""
    cut = np.asarray(plan["in_cut"], dtype=bool)
    if not cut.any():
        raise ConfigError("run: the plan never cuts; give --reference explicitly")
    if quantity == "force":
        col = "fres_peak_n" if statistic == "peak" else "fres_avg_n"
        v = np.asarray(plan[col], dtype=np.float64)
    else:
        v = np.abs(np.asarray(plan["torque_avg_nm"], dtype=np.float64))
        if quantity == "power":
            v = v * np.abs(np.asarray(plan["spindle_rpm"], dtype=np.float64)) * 2 * np.pi / 60
    return 0.9 * float(np.nanmax(v[cut]))


def session_blocks(
    plan: VirtualPlan,
    machine: MachineConfig,
    sample_rate_hz: float,
    options: SessionOptions,
    *,
    where: str = "machine file",
    channels: Sequence[str] = (),
) -> SessionBlocks:
    """The blocks of a session on ``machine`` (the estimators' machine file) running ``plan``.

    ``channels``: what the source provides (to choose the spindle torque signal and check
    that the dynamometer is there).
    """
    from millsense.estimation.feed.bank import bank_or_blocks
    from millsense.estimation.from_config import build_estimators
    from millsense.models.kinematics import kinematics_for

    o = options
    notes: list[str] = []
    have = set(channels)
    blocks: list[Block] = []
    built = build_estimators(machine, ["spindle"], [], sample_rate_hz, where=where)
    blocks += built.blocks
    force_ch: tuple[str, str] = ("force_x", "force_y")
    if o.adaptive and o.quantity == "force":
        if o.force_from == "dynamometer":
            from millsense.control.closed_loop import DYNAMOMETER_NOISE_N, Dynamometer

            if "truth/tool/force_x" not in have:
                raise ConfigError("--force-from dynamometer: only on the virtual machine")
            blocks.append(Dynamometer(noise_n=DYNAMOMETER_NOISE_N))
        else:
            axes = list(machine.axes)
            feed = build_estimators(machine, ["feed"], axes, sample_rate_hz, where=where)
            # the five axes' estimators in one compiled call per chunk (decision 1652)
            blocks += bank_or_blocks(feed.blocks)
            blocks += feed.derived
            names = [c for _, a, c, _ in feed.derived_estimates]
            if machine.kinematics == "5-axis-trunnion-ac" and len(names) == 3:
                force_ch = (names[0], names[1])
            elif machine.kinematics == "3-axis":
                force_ch = ("est/feed/x/load", "est/feed/y/load")
            else:
                raise ConfigError(
                    f"{where}: forces at the tool from the feed estimators need a 3-axis or a "
                    f"5-axis trunnion machine ({'; '.join(feed.notes) or machine.kinematics})"
                )
    # the gate also closes on the guard's faults (decision 1559; run_session guards every source)
    blocks.append(SpindleAtSpeed(fault_channel=FAULT_CHANNEL))
    axes_pos = [f"{a}/position_cmd" for a in machine.axes]
    blocks.append(TcpFromAxes(kinematics_for(machine.kinematics), axes_pos))
    # the CNC's path feed, where it reports it: a move's deceleration thins the chip as an
    # override cut does (decision 1733)
    sync = PlanSync(plan, torque_channel=TORQUE_CHANNEL, at_speed_channel="spindle/at_speed",
                    transient_revs=TRANSIENT_REVS,
                    feed_channel=PATH_FEED if PATH_FEED in have else None,
                    feed_time_constant_s=feed_time_constant_s(machine))  # fmt: skip
    blocks.append(sync)
    flutes = int(plan.metadata.get("tool", {}).get("flutes", 2))
    children: list[Block] = []
    if o.chatter:
        counts = machine.spindle.encoder_counts_rev if machine.spindle is not None else None
        children.append(_chatter_child(o, flutes, have, counts))
    # a plan that never has the tool in the material (a program run in air, a tool above the
    # stock): nothing to judge for breakage and no reference to regulate to (decision 1678)
    in_cut = bool(np.asarray(plan["in_cut"], dtype=bool).any())
    cuts = in_cut and _largest(plan, "torque_avg_nm") > 0
    if not cuts and o.breakage:
        notes.append("breakage monitor off: the plan never has the tool in the material")
    if not cuts and o.adaptive and o.reference is None:
        notes.append("adaptive feed off: the plan never has the tool in the material (nothing "
                     "to regulate; give --reference for a set point)")  # fmt: skip
    if o.breakage and cuts:
        breakage_signal = CUTTING_TORQUE
        # the LQE observer's step is not derived (its gain spreads a count over the filter's
        # dynamics): none (decision 1732)
        resolution = 0.0
        if o.breakage_torque == "dob":
            from millsense.estimation.from_config import spindle_dob_from_config
            from millsense.estimation.spindle_dob import DOB_TORQUE

            # the tooth periods' mean torque with the encoder's quantisation of the inertial
            # term divided by the speed window, less its air as the observer's (decision 1726)
            dob = spindle_dob_from_config(machine, where)
            blocks.append(dob)
            # the encoder's count at a period's end, held while the speed holds (decision 1732)
            resolution = dob.mean_resolution_nms(sample_rate_hz)
            blocks.append(AirReference(DOB_TORQUE, "plan/in_cut", "spindle/at_speed",
                                       out=DOB_CUTTING_TORQUE, name="plan/dob_air"))  # fmt: skip
            breakage_signal = DOB_CUTTING_TORQUE
        children.append(
            PhasedBreakage(
                flutes,
                method="virtual",
                signal_channels=(breakage_signal,),
                expected_channel="plan/judged_torque",
                # a drop below the plan's lowest torque across its transients (decision 1674)
                floor_channel="plan/torque_floor",
                min_expected_nm=MIN_JUDGED * _largest(plan, "torque_avg_nm"),
                # a tooth period with a sample off the gate is not judged (decision 1559)
                enable_channel="spindle/at_speed",
                mean_resolution=resolution,
                name="breakage",
            )
        )
    if o.adaptive and (cuts or o.reference is not None):
        stat = "peak" if o.quantity == "force" else "mean"
        ref = o.reference if o.reference is not None else default_reference(plan, o.quantity, stat)
        if o.reference is None:
            notes.append(f"adaptive feed: reference {ref:.4g} (90 % of the plan's largest)")
        children.append(
            AdaptiveFeedBlock(
                AdaptiveFeedOptions(reference=ref, quantity=o.quantity, look_ahead=o.look_ahead),
                plan,
                force_channels=force_ch,
                torque_channel=CUTTING_TORQUE,
                tcp_channels=("tcp/x", "tcp/y", "tcp/z"),
                enable_channel="spindle/at_speed",
                # the override the CNC reports in effect, where it does (decision 1666)
                override_channel=REPORTED_OVERRIDE if REPORTED_OVERRIDE in have else None,
            )
        )
    sup = Supervisor(
        children,
        SupervisorOptions(period_s=o.period_s, hold_on_breakage=o.hold_on_breakage),
        fault_channel=FAULT_CHANNEL,
        in_cut_channel="plan/in_cut",
        location_channels=("plan/nc_line", "tcp/x", "tcp/y", "tcp/z"),
    )
    blocks.append(sup)
    return SessionBlocks(blocks, sup, notes)


def _largest(plan: VirtualPlan, column: str) -> float:
    return float(np.nanmax(np.abs(np.asarray(plan[column], dtype=np.float64)), initial=0.0))


def _chatter_child(
    o: SessionOptions, flutes: int, have: set[str], encoder_counts_rev: int | None = None
) -> Block:
    """The chatter monitor on the compensated spindle torque inside the chatter avoidance
    (seed 000 §2.7; the new speed by :func:`~millsense.control.chatter_avoidance.
    choose_spindle_speed`, commanded or only recommended); ``encoder_counts_rev``: the
    machine file's spindle encoder, which tells where its quantisation lines can stand in
    that torque (decision 1697)."""
    from millsense.control.chatter_avoidance import (
        AvoidanceSettings,
        ChatterAvoidanceBlock,
        StabilityModel,
    )
    from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings

    monitor = ChatterMonitor(
        ChatterSettings(
            method=o.chatter_method,
            signal=TORQUE_CHANNEL,
            n_flutes=flutes,
            speed_channel="spindle/speed",
            speed_unit="rad/s",
            encoder_counts_rev=encoder_counts_rev,
        )
    )
    ovr = "cnc/spindle_override" if "cnc/spindle_override" in have else None
    model = None
    depth = None
    if o.stability_case is not None:
        model = StabilityModel(o.stability_case, 1.0)  # judged at the plan's depth
        depth = "plan/axial_depth"
    settings = AvoidanceSettings(act=o.avoid_chatter, override_channel=ovr, depth_channel=depth)
    return ChatterAvoidanceBlock(monitor, settings, model)


class StopAfterHold(SourceWrapper):
    """Ends a live stream ``after_s`` after a feed hold was sent to it: the machine is
    stopped and waits for the operator, so the session records the stop and closes (a
    replay ends with its recording anyway)."""

    def __init__(self, inner: Source, after_s: float = 0.5) -> None:
        super().__init__(inner)
        self.after = max(1, round(after_s * inner.sample_rate_hz))
        self.stop_at: int | None = None
        self._pos = 0

    def command(self, event: Event) -> None:
        self.inner.command(event)
        if event.name == "feed_hold" and (event.value is None or event.value != 0):
            if self.stop_at is None:
                self.stop_at = self._pos + self.after

    def read(self, max_samples: int) -> Chunk | None:
        if self.stop_at is not None:
            max_samples = min(max_samples, self.stop_at - self._pos)
            if max_samples <= 0:
                return None
        c = self.inner.read(max_samples)
        if c is not None:
            self._pos = c.start + c.n
        return c


@dataclass
class SessionResult:
    """What a session did: samples, events (blocks' and the guard's), wall time."""

    samples: int
    sample_rate_hz: float
    events: list[Event]
    wall_s: float

    @property
    def seconds(self) -> float:
        return self.samples / self.sample_rate_hz


def run_session(
    source: Source,
    blocks: Sequence[Block],
    *,
    out: Path | None = None,
    events_out: Path | None = None,
    metadata: dict[str, Any] | None = None,
    chunk_samples: int = 100,
    keep: Sequence[str] | None = None,
    on_progress: Callable[[int], None] | None = None,
    guard: bool = True,
    stop_after_hold_s: float | None = 0.5,
    observer: Callable[[Chunk, dict[str, np.ndarray], list[Event]], None] | None = None,
) -> SessionResult:
    """Run ``blocks`` on ``source`` (override events fed back), recording as it goes.

    ``out``: the recording (the source's channels named in ``keep``, all when None, and every
    block output), appended chunk by chunk and closed whatever happens; ``events_out``: the
    event log (Parquet) written at the end, also after a failure of the source;
    ``stop_after_hold_s``: a live run ends this long after a feed hold (None: runs on);
    ``observer``: called with every chunk, the blocks' outputs and events (the live
    dashboard, :mod:`millsense.dashboard`).
    """
    from millsense.io import RecordingWriter
    from millsense.streaming.event_log import write_event_log

    src: Source = GuardedSource(source) if guard else source
    if stop_after_hold_s is not None:
        src = StopAfterHold(src, stop_after_hold_s)
    pipe = Pipeline(blocks)
    infos = src.channel_info
    # a channel no block and no source provides: one line naming it, before anything is written
    pipe.check_inputs([c.name for c in infos], str(getattr(source, "name", "the source")))
    kept = [c for c in infos if keep is None or c.name in keep or c.name == FAULT_CHANNEL]
    writer = None
    if out is not None:
        computed = pipe.output_channels()
        writer = RecordingWriter(
            out,
            src.sample_rate_hz,
            kept + computed,
            # the blocks' outputs, apart from what the source measured: `check` judges the
            # data, not what millsense computed from it (decision 1745)
            metadata={**(metadata or {}), COMPUTED_CHANNELS: [
                *(c.name for c in kept if c.name == FAULT_CHANNEL), *(c.name for c in computed)
            ]},
            flush_every_s=0.5,
        )
    names = [c.name for c in kept]

    count = [0]
    # the blocks' events as they come: what the event log keeps of a run that ends early (an
    # operator's Ctrl-C, a failing source), with the recording up to the same sample
    emitted: list[Event] = []

    def sink(chunk: Chunk, outputs: dict[str, np.ndarray], events: list[Event]) -> None:
        count[0] += chunk.n
        emitted.extend(events)
        if writer is not None:
            data = {k: chunk.data[k] for k in names}
            data.update(outputs)
            writer.append(data)
        if observer is not None:
            observer(chunk, outputs, events)

    t0 = time.perf_counter()
    events: list[Event] = emitted
    try:
        res = run(src, pipe, chunk_samples, sink=sink, on_progress=on_progress, collect=False)
        events = list(res.events)
    finally:
        guarded = src.inner if isinstance(src, StopAfterHold) else src
        if isinstance(guarded, GuardedSource):
            events += guarded.events
        take = getattr(source, "take_events", None)
        if callable(take):
            events += list(take())  # the simulator's crashes, a link's losses and gaps
        events.sort(key=lambda e: (e.time_s, e.sample))
        if writer is not None:
            writer.update_metadata({"events": len(events)})
            writer.close()
        if events_out is not None:
            write_event_log(events_out, events, recording=out)
    return SessionResult(count[0], src.sample_rate_hz, events, time.perf_counter() - t0)
