"""The virtual plan beside the machine: synchronisation by tool-centre position and the K_tc
calibration of the predicted torque (seed 000 C15, C16; issue 16 item 5).

:class:`PlanSync` matches the measured tool-centre point to the plan's rows (±10 µm per axis,
:meth:`~millsense.plan.virtual_plan.VirtualPlan.match`, seed 000 C15) at the CNC's 333 Hz
(every ``decimate``-th absolute sample, so the chunking cannot move a match) and gives every
sample the plan's row, NC line, in-cut flag and the **expected cutting torque**

    T_exp = T_edge + s · u · T_shear,

with T_edge and T_shear the plan's predicted mean torque split into its edge and shear parts
(columns ``torque_avg_nm`` and ``torque_avg_shear_nm``), u the effective feed override (the
shear part is linear in the chip thickness) and s = K_tc,new / K_tc,plan the calibration:
over the first ``calibration_revs`` revolutions in cut where the plan is steady
(:func:`steady_rows`; decision 1556: not in a plunge, an entry or a step) with an expected
torque of at least :data:`MIN_CALIBRATION` of the largest of the plan's steady rows (seed 000
C16: 10; the first ``settle_revs`` skipped) the mean measured torque T̄ gives
s = (T̄ − T̄_edge)/T̄_shear (:mod:`millsense.plan.calibration`, decision 0064). The breakage
monitor's virtual threshold (seed 000 §2.9: 40 % of the expected torque) reads T_exp where the
plan is steady and 0 (not judged) in its transients — entries, steps, ramps, exits
(:func:`steady_rows`, decision 1622) — as ``judged_torque``; in the transients
``torque_floor`` gives the lowest torque the plan expects over the same window (0 where that
window reaches air), against which the monitor judges a drop (decision 1674).

:class:`TcpFromAxes` gives the tool-centre point from the axis position commands by the
machine's forward kinematics (a CNC's TCP), for machines whose axes are not the part frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.models.kinematics import Kinematics
from millsense.online._sync_kernels import (
    OVERRIDE_STATE,
    calibration_kernel,
    expected_kernel,
    override_transient_kernel,
    plan_rows_kernel,
)
from millsense.online.gates import AirReference
from millsense.plan.path import cnc_line
from millsense.plan.virtual_plan import VirtualPlan
from millsense.streaming.block import (
    Block,
    BlockOutput,
    Chunk,
    Event,
    EventKind,
    HeldViews,
    Severity,
    held_views,
)

if TYPE_CHECKING:
    from millsense.core.config import MachineConfig

#: Range of the calibration ratio K_tc,new/K_tc,plan accepted; outside it the plan is kept and a
#: warning says the measurement does not describe the plan (a wrong tool, material or signal).
SCALE_RANGE = (0.33, 3.0)
#: Fraction of the plan's largest mean torque below which a revolution is not calibrated on.
MIN_CALIBRATION = 0.3
#: Decision 1714: a feed-override change is a transient of the expected torque while the
#: override and the feed the axes follow (its first-order lag) differ by more than this share:
#: half the flute pattern's size bound (0.2 of the expected torque, decision 1684), so a
#: change the plant has not followed yet cannot read as a flute's drop and rise.
OVERRIDE_TRANSIENT_TOL = 0.1
#: The lag's time constant where the machine's is not given (s): twice 1/K_v at K_v = 50/s.
DEFAULT_FEED_TIME_CONSTANT_S = 0.04


def feed_time_constant_s(machine: MachineConfig | None) -> float:
    """How long the feed takes to follow an override change (decision 1714): 2/K_v of the
    linear axes' slowest position loop (1/K_v is the loop's time constant; the factor 2 covers
    the velocity loop, the interpolator's ramp and the CNC's latency, which a position loop
    alone leaves out), or :data:`DEFAULT_FEED_TIME_CONSTANT_S` without a machine or linear
    axes."""
    if machine is None:
        return DEFAULT_FEED_TIME_CONSTANT_S
    gains = [a.position_gain() for a in machine.axes.values() if a.kind == "linear"]
    return 2.0 / min(gains) if gains else DEFAULT_FEED_TIME_CONSTANT_S


#: The spindle gate of a plan sync without one (:func:`~millsense.online._sync_kernels.
#: expected_kernel`: no sample closed).
_NO_GATE = np.empty(0)


def _window_rows(plan: VirtualPlan, revs: float, max_override: float) -> int:
    """Rows travelled in ``revs`` revolutions (≥ 1) at up to ``max_override`` of the programmed
    feed, the largest over the plan's cutting rows."""
    step = float(plan.metadata.get("step_mm", 0.4))
    feed = np.asarray(plan["feed_mm_min"], dtype=np.float64)
    rpm = np.abs(np.asarray(plan["spindle_rpm"], dtype=np.float64))
    cut = np.asarray(plan["in_cut"], dtype=bool) & ~np.asarray(plan["rapid"], dtype=bool)
    travel = np.where(cut & (rpm > 0), feed / np.maximum(rpm, 1e-9), 0.0) * revs * max_override
    w = int(np.ceil(np.nanmax(travel, initial=0.0) / step)) if feed.size else 0
    return max(w, 1)


def _window_extremes(values: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest of ``values`` over rows ±``w`` (the ends repeated beyond the plan)."""
    n = values.size
    pad = np.concatenate(
        [np.full(w, values[0] if n else 0.0), values, np.full(w, values[-1] if n else 0.0)]
    )
    win = np.lib.stride_tricks.sliding_window_view(pad, 2 * w + 1)
    return win.min(axis=1), win.max(axis=1)


def steady_rows(plan: VirtualPlan, revs: float, max_override: float = 1.5) -> np.ndarray:
    """Rows whose predicted mean torque varies by at most 20 % of its largest value over the
    rows travelled in ``revs`` revolutions either side (at up to ``max_override`` of the
    programmed feed): entries, steps, ramps and exits are transients where the measured torque
    and the plan's may disagree by their timing alone, so a breakage threshold would judge the
    plan's timing, not the tool (decision 1622)."""
    tq = np.nan_to_num(np.asarray(plan["torque_avg_nm"], dtype=np.float64))
    lo, hi = _window_extremes(tq, _window_rows(plan, revs, max_override))
    return np.asarray(hi - lo <= 0.2 * np.maximum(hi, 1e-12), dtype=bool)


def transient_floor(
    plan: VirtualPlan, revs: float, max_override: float = 1.5, steady: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the lowest edge and shear parts of the plan's mean torque over the window of
    :func:`steady_rows` (each part's own lowest: their sum is at most the lowest torque there),
    0 where the row is steady (decision 1674). Where the window reaches air the floor is 0: an
    entry or an exit is judged by nothing; across a step, a ramp or a cavity wall with the
    tool in the material throughout, a tooth period far below the lower level is a lost flute
    whatever the plan's timing. ``steady``: :func:`steady_rows` of the same window where the
    caller has it."""
    tq = np.nan_to_num(np.asarray(plan["torque_avg_nm"], dtype=np.float64))
    sh = np.nan_to_num(np.asarray(plan["torque_avg_shear_nm"], dtype=np.float64))
    cut = np.asarray(plan["in_cut"], dtype=bool) & ~np.asarray(plan["rapid"], dtype=bool)
    w = _window_rows(plan, revs, max_override)
    if steady is None:
        steady = steady_rows(plan, revs, max_override)
    floors = []
    for part in (np.where(cut, tq - sh, 0.0), np.where(cut, sh, 0.0)):
        lo, _ = _window_extremes(part, w)
        floors.append(np.where(steady, 0.0, np.maximum(lo, 0.0)))
    return floors[0], floors[1]


class TcpFromAxes(Block):
    """``tcp/x``, ``tcp/y``, ``tcp/z`` (m) from axis position channels by forward kinematics."""

    def __init__(self, kinematics: Kinematics, position_channels: Sequence[str]) -> None:
        self.kin = kinematics
        self.inputs = tuple(position_channels)
        self.name = "tcp"

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(f"tcp/{a}", "m", f"tool-centre point {a}") for a in "xyz"]

    def reset(self, sample_rate_hz: float) -> None:
        pass

    def process(self, chunk: Chunk) -> BlockOutput:
        if chunk.n == 0:
            return BlockOutput({f"tcp/{a}": np.zeros(0) for a in "xyz"})
        q = np.array([chunk.data[c] for c in self.inputs], dtype=np.float64)  # (axes, n)
        rows = np.empty((3, chunk.n))
        self.kin.forward_rows(q, rows)  # straight into the output rows
        return BlockOutput({f"tcp/{a}": rows[i] for i, a in enumerate("xyz")})


class PlanSync(Block):
    """Plan row, NC line, in-cut flag and calibrated expected torque per sample (module).

    Parameters
    ----------
    plan : the virtual plan of the program being run.
    tcp_channels : measured tool-centre point (m).
    torque_channel : measured or estimated spindle cutting torque (N·m) for the calibration,
        or None (no calibration: s = 1).
    speed_channel : spindle speed (rad/s), to count revolutions.
    override_channel : effective feed override (fraction), or None (1).
    feed_channel : the CNC's path feed (m/s), where it reports it: the feed ratio u is then the
        path feed over the matched row's programmed feed (the override and the path's own
        accelerations and decelerations; a move that stops in the material thins the chip to
        nothing over its last fraction of a millimetre, decision 1733), the override where the
        row has no programmed feed; None: the override alone.
    at_speed_channel : 1/0 "spindle settled at speed" (:class:`~millsense.online.gates.
        SpindleAtSpeed`); given with ``torque_channel``, the air-cut reference of the torque is
        learned where the plan says air (:class:`~millsense.online.gates.AirReference`) and
        ``{name}/cutting_torque`` = torque − reference is what the calibration uses; samples
        where the spindle is not at speed are neither calibrated on nor judged
        (``judged_torque`` 0; decision 1550).
    decimate : samples between matches (30: the CNC's 333 Hz at 10 kHz).
    calibration_revs, settle_revs : revolutions averaged, and skipped after the entry.
    transient_revs : revolutions of travel either side of a row over which the plan's torque
        must be steady for the row to be judged (``judged_torque``).
    feed_time_constant_s : the feed's lag behind an override change (s,
        :func:`feed_time_constant_s`): while the override and that lag differ by more than
        :data:`OVERRIDE_TRANSIENT_TOL`, the samples are in a transient like the plan's
        (decision 1714).
    name : channel prefix ``plan``.
    """

    def __init__(
        self,
        plan: VirtualPlan,
        tcp_channels: tuple[str, str, str] = ("tcp/x", "tcp/y", "tcp/z"),
        torque_channel: str | None = "est/spindle/spindle/load",
        speed_channel: str = "spindle/speed",
        override_channel: str | None = "cnc/feed_override",
        feed_channel: str | None = None,
        at_speed_channel: str | None = None,
        decimate: int = 30,
        calibration_revs: float = 10.0,
        settle_revs: float = 1.0,
        transient_revs: float = 3.0,
        feed_time_constant_s: float = DEFAULT_FEED_TIME_CONSTANT_S,
        name: str = "plan",
    ) -> None:
        if len(plan) < 2:
            raise ConfigError("plan sync: the plan has fewer than 2 rows")
        if decimate < 1 or not (calibration_revs > 0 and settle_revs >= 0):
            raise ConfigError("plan sync: decimate ≥ 1, calibration_revs > 0, settle_revs ≥ 0")
        if not (math.isfinite(feed_time_constant_s) and feed_time_constant_s > 0):
            raise ConfigError(
                f"plan sync: feed_time_constant_s {feed_time_constant_s!r}: must be > 0 (s)"
            )
        self.feed_tau_s = float(feed_time_constant_s)
        self.plan = plan
        self.tcp_channels = tcp_channels
        self.torque_channel = torque_channel
        self.speed_channel = speed_channel
        self.override_channel = override_channel
        self.feed_channel = feed_channel
        self.decimate = int(decimate)
        self.cal_revs = float(calibration_revs)
        self.settle_revs = float(settle_revs)
        self.name = name
        ins = [*tcp_channels, speed_channel]
        if torque_channel is not None:
            ins.append(torque_channel)
        if override_channel is not None:
            ins.append(override_channel)
        if feed_channel is not None:
            ins.append(feed_channel)
        self.air: AirReference | None = None
        self.at_speed_channel: str | None = None
        if at_speed_channel is not None and torque_channel is not None:
            ins.append(at_speed_channel)
            self.at_speed_channel = at_speed_channel
            self.air = AirReference(torque_channel, f"{name}/in_cut", at_speed_channel,
                                    out=f"{name}/cutting_torque", name=f"{name}/air")  # fmt: skip
        self.inputs = tuple(ins)
        tq = np.asarray(plan["torque_avg_nm"], dtype=np.float64)
        sh = np.asarray(plan["torque_avg_shear_nm"], dtype=np.float64)
        # the per-row tables end with the value of "no row yet", which row −1 indexes
        self._shear = np.append(np.nan_to_num(sh), 0.0)
        self._edge = np.append(np.nan_to_num(tq - sh), 0.0)
        self._in_cut = np.append(np.asarray(plan["in_cut"], dtype=bool), False)
        # the programmed path feed of each row, m/s (0: a rapid, or none: the override alone)
        prog = np.nan_to_num(np.asarray(plan["feed_mm_min"], dtype=np.float64)) / 60e3
        rapid = np.asarray(plan["rapid"], dtype=bool)
        self._feed = np.append(np.where(rapid | (prog <= 0.0), 0.0, prog), 0.0)
        steady = steady_rows(plan, transient_revs)
        self._steady = np.append(steady, False)
        floor_edge, floor_shear = transient_floor(plan, transient_revs, steady=steady)
        self._floor_edge = np.append(floor_edge, 0.0)
        self._floor_shear = np.append(floor_shear, 0.0)
        depth = np.nan_to_num(np.asarray(plan["axial_depth_mm"], dtype=np.float64)) * 1e-3
        self._depth = np.append(depth, 0.0)
        #: only revolutions whose expected torque is at least this are calibrated on: at a
        #: light load an observer's offset and noise would set the ratio (decision 1622); of
        #: the largest where the plan is steady, the rows calibrated on (decision 1556: a
        #: plunge's or an entry's peak would otherwise leave no steady row heavy enough)
        steady_cut = self._steady[:-1] & self._in_cut[:-1]
        self._min_cal = MIN_CALIBRATION * float(
            np.nanmax(np.abs(tq[steady_cut] if steady_cut.any() else tq), initial=0.0)
        )
        self._nc = np.append(cnc_line(plan["nc_line"], plan["source_line"]), -1)
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        n = self.name
        return [
            ChannelInfo(f"{n}/row", "1", "matched plan row (-1 before the first match)"),
            ChannelInfo(f"{n}/nc_line", "1", "NC line of the matched row"),
            ChannelInfo(f"{n}/in_cut", "1", "1 where the plan says the tool is in cut"),
            ChannelInfo(f"{n}/expected_torque", "N*m", "expected mean cutting torque (calibrated)"),
            ChannelInfo(
                f"{n}/judged_torque", "N*m", "expected torque where the plan is steady, else 0"
            ),
            ChannelInfo(
                f"{n}/torque_floor", "N*m", "lowest expected torque over a transient of the "
                "plan in the material (a drop below it is judged), else 0"
            ),
            ChannelInfo(f"{n}/ktc_scale", "1", "K_tc calibration ratio (1 until calibrated)"),
            ChannelInfo(f"{n}/axial_depth", "m", "axial depth of cut of the matched row"),
        ] + (self.air.output_channels() if self.air is not None else [])

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        self.row = -1
        self.scale = 1.0
        self.calibrated = False
        self._revs_in_cut = 0.0
        self._acc = np.zeros(4)  # Σ measured, Σ edge, Σ u·shear, samples
        self._scale_name = (f"{self.name}/ktc_scale",)
        self._scale_views: HeldViews | None = None  # once the ratio no longer changes
        self._ovr_state = np.zeros(OVERRIDE_STATE)
        self._ovr_alpha = -math.expm1(-1.0 / (self.fs * self.feed_tau_s))
        if self.air is not None:
            self.air.reset(sample_rate_hz)

    @property
    def metres_per_row(self) -> float:
        return float(self.plan.metadata.get("step_mm", 0.4)) * 1e-3

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        n = chunk.n
        first = -chunk.start % self.decimate
        at = np.arange(first, n, self.decimate)
        # (3, m): the rows of the transpose handed to match are contiguous (no copies there)
        tcp = np.array(
            [np.asarray(d[c])[first :: self.decimate] for c in self.tcp_channels],
            dtype=np.float64,
        )
        if at.size and np.count_nonzero(np.isfinite(tcp)) == tcp.size:
            matched = self.plan.match(tcp.T, from_row=max(self.row, 0))
        else:  # a pose not finite: matched where it is, −1 (no match) where not
            matched = np.full(at.size, -1, dtype=np.int64)
            ok = np.all(np.isfinite(tcp), axis=0)
            if ok.any():
                matched[ok] = self.plan.match(tcp[:, ok].T, from_row=max(self.row, 0))
        u = (  # a copy: the kernel may write the path's ratio into it (and a recording's
            # channel can be read-only, which the compiled kernel cannot take for a written array)
            np.array(d[self.override_channel], dtype=np.float64)
            if self.override_channel is not None
            else np.ones(n)
        )
        feed = (
            np.ascontiguousarray(d[self.feed_channel], dtype=np.float64)
            if self.feed_channel is not None
            else _NO_GATE
        )
        # each sample holds the last match at or before it (through unmatched ones), and
        # reads the per-row tables there (row −1: their last entry, "no row yet"); one
        # compiled loop (decision 1653)
        rows = np.empty(n, dtype=np.int64)
        values = np.empty((11, n))
        flags = np.empty((2, n), dtype=bool)
        in_cut, steady = flags[0], flags[1]
        plan_rows_kernel(at, matched, self.row, u, feed, self._feed, self._in_cut, self._edge,
                         self._shear, self._nc, self._steady, self._depth, self._floor_edge,
                         self._floor_shear, rows, values, in_cut, steady)  # fmt: skip
        # the plan's own steadiness, where the K_tc calibration averages (decision 1714: an
        # override change is a transient of the judging only)
        plan_steady = steady
        if self.override_channel is not None or self.feed_channel is not None:
            # an override change, or the path's own deceleration, is a transient too
            plan_steady = steady.copy()
            override_transient_kernel(u, self._ovr_alpha, OVERRIDE_TRANSIENT_TOL,
                                      self._ovr_state, steady, values)  # fmt: skip
        if n and rows[-1] >= 0:
            self.row = int(rows[-1])
        in_cut_f, edge, shear = values[2], values[3], values[4]
        calibrating = not self.calibrated and self.torque_channel is not None and n > 0
        if calibrating:
            scale = np.full(n, self.scale)
        else:  # the ratio held: views of one array never written again
            if self._scale_views is None or self._scale_views[0] != n:
                self._scale_views = held_views(self._scale_name, np.array([self.scale]), None, n)[0]
            scale = self._scale_views[1][self._scale_name[0]]
        events: list[Event] = []
        extra: dict[str, np.ndarray] = {}
        torque = None
        if self.air is not None:
            assert self.torque_channel is not None and self.at_speed_channel is not None
            extra = self.air.run(d[self.torque_channel], in_cut_f, d[self.at_speed_channel])
            torque = extra[f"{self.name}/cutting_torque"]
        gate = (
            np.ascontiguousarray(d[self.at_speed_channel], dtype=np.float64)
            if self.at_speed_channel is not None
            else _NO_GATE
        )
        k_cal = 0
        if calibrating:
            k_done = self._calibrate(chunk, in_cut & plan_steady, edge, shear, gate, events,
                                     torque)  # fmt: skip
            if k_done >= 0:
                scale[k_done:] = self.scale
            k_cal = k_done if k_done >= 0 else n
        # the virtual threshold judges the tool once the plan is calibrated to it (a plan
        # whose K_tc is 40 % off would otherwise read as a broken tool, decision 1622); while
        # the spindle changes speed the observer's torque holds the acceleration torque (tens
        # of N·m on a 1000 rev/min step): nothing is judged on it (decision 1550)
        ready_from = 0
        if self.torque_channel is not None:
            ready_from = max(k_cal, 0) if self.calibrated else n
        expected, judged, floor = values[6], values[7], values[10]
        expected_kernel(edge, shear, values[8], values[9], scale, steady, ready_from, gate,
                        expected, judged, floor)  # fmt: skip
        name = self.name
        return BlockOutput(
            {
                f"{name}/row": values[0],
                f"{name}/nc_line": values[1],
                f"{name}/in_cut": in_cut_f,
                f"{name}/expected_torque": expected,
                f"{name}/judged_torque": judged,
                f"{name}/torque_floor": floor,
                f"{name}/ktc_scale": scale,
                f"{name}/axial_depth": values[5],
                **extra,
            },
            events,
        )

    def _calibrate(
        self,
        chunk: Chunk,
        in_cut: np.ndarray,
        edge: np.ndarray,
        shear: np.ndarray,
        gate: np.ndarray,
        events: list[Event],
        torque: np.ndarray | None = None,
    ) -> int:
        """Accumulate the window; the sample where the calibration completes (−1: not yet).

        ``in_cut``: the samples that may be calibrated on, in cut where the plan is steady
        (decision 1556: a plunge, an entry or a step is a transient where measurement and plan
        differ by their timing and by what the side-milling model leaves out). ``gate``: the
        spindle's at-speed channel (1/0, float64; empty: none), samples below 0.5 left out
        (decision 1550: the acceleration torque). The count and the samples come from
        :func:`~millsense.online._sync_kernels.calibration_kernel`.
        ``torque``: the cutting torque with the air-cut reference subtracted (decision 1622:
        the reference is subtracted before the torque is calibrated on); None without an air
        reference (the torque channel as it is)."""
        assert self.torque_channel is not None
        d = chunk.data
        speed = np.ascontiguousarray(d[self.speed_channel], dtype=np.float64)
        tq = np.ascontiguousarray(d[self.torque_channel] if torque is None else torque,
                                  dtype=np.float64)  # fmt: skip
        # the window's count of revolutions and the samples it averages, in one compiled pass;
        # the spindle gate: no acceleration torque
        use = np.empty(chunk.n, dtype=np.bool_)
        k_done, revs = calibration_kernel(
            speed, tq, in_cut, edge, shear, self._min_cal, 2 * math.pi * self.fs,
            self._revs_in_cut, self.settle_revs, self.settle_revs + self.cal_revs, gate, use,
        )  # fmt: skip
        # (the sums as ndarray.sum takes them, without its Python layer)
        add = np.add.reduce
        self._acc += [add(tq[use]), add(edge[use]), add(shear[use]), np.count_nonzero(use)]
        self._revs_in_cut = revs
        if k_done < 0:
            return -1
        m, e, s, cnt = self._acc
        self.calibrated = True
        t = chunk.t0_s + (chunk.start + k_done) / chunk.sample_rate_hz
        ktc_plan = float(np.nanmax(np.asarray(self.plan["ktc_n_mm2"], dtype=np.float64)))
        ratio = (m - e) / s if s > 0 and cnt > 0 else math.nan
        if not math.isfinite(ratio):
            # no sample to calibrate on: the spindle off speed through the window, or the plan's
            # rows there without a shear part (a plunge's)
            why = ("the spindle was not at speed" if cnt == 0
                   else "the plan has no shear torque there (a plunge)")  # fmt: skip
            reason = f"no sample of its {self.cal_revs:g} revolutions to calibrate on ({why})"
        elif not (SCALE_RANGE[0] <= ratio <= SCALE_RANGE[1]):
            reason = (f"measured/plan shear torque {ratio:.3g} outside {SCALE_RANGE[0]}–"
                      f"{SCALE_RANGE[1]} (mean measured {m / max(cnt, 1):.3g} N·m against "
                      f"{(e + s) / max(cnt, 1):.3g} N·m planned)")  # fmt: skip
        else:
            reason = ""
        if reason:
            events.append(Event(t, EventKind.ALARM, self.name,
                                f"K_tc calibration refused: {reason}: the plan is kept",
                                name="ktc_calibration_refused", value=ratio,
                                sample=chunk.start + k_done,
                                severity=Severity.WARNING))  # fmt: skip
            return -1
        self.scale = float(ratio)
        events.append(Event(t, EventKind.NOTE, self.name,
                            f"K_tc calibrated over {self.cal_revs:g} revolutions: "
                            f"{ktc_plan * ratio:.0f} N/mm² (plan {ktc_plan:.0f}, × {ratio:.3f})",
                            name="ktc_calibrated", value=ktc_plan * ratio,
                            sample=chunk.start + k_done, severity=Severity.INFO,
                            values={"ktc_plan_n_mm2": ktc_plan, "scale": ratio,
                                    "torque_meas_nm": m / cnt,
                                    "torque_pred_nm": (e + s) / cnt}))  # fmt: skip
        return k_done
