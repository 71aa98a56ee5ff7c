"""Adaptive feed control per spindle revolution with the virtual look-ahead (seed 000 §2.10,
Ch. 6.4; seed 002 §2.2–2.4, M4).

Once per control interval — one spindle revolution (seeds 000 and 002), or at high speed the
fewest whole revolutions that last ``min_interval_s`` = 40 ms (decision 1548) — the block
takes the peak (or, for torque and power, the mean: decision 1619) of the regulated quantity
over the interval — the resultant XY force (seed 000 and 002), the spindle torque, or the
spindle power (what Heidenhain AFC regulates) —
identifies the plant z⁻¹B/A (Aslan Eq. 6.7, Munasinghe Eq. 3.23) with
:class:`~millsense.control.rls.ConstantTraceRLS` on normalised signals (y = peak / reference,
u = feed override as a fraction of the programmed feed, decision 1601), its estimate projected
onto the physical models (one real pole in [0, 1], every b ≥ 0: decision 1657), and computes
the new override with :class:`~millsense.control.gpc.GPC` (N1/N2/Nu = 1/4/1, λ = 0.25,
Eq. 6.14). Around it (decisions 1611–1616, 1619):

- limits 20–150 % (seed 000), dead band ±5 % of the reference (no move while the peak is in
  the band, seed 000 §2.10);
- seed 002's air-cut rule: peak ≤ the air threshold (80 N) → V_max (150 %); on re-entry V_max/3
  for 3 revolutions (Munasinghe per-revolution wrapper, steps 4–5); with a plan, in air with
  the cut within the look-ahead horizon (at V_max), V_max/3 already before the contact
  (decision 1626); where the plan has the tool in the material an air reading is a light cut:
  not above 100 % (decision 1663), and it does not restart the re-entry (decision 1675);
- the virtual look-ahead of seed 000 (:meth:`~millsense.plan.virtual_plan.VirtualPlan.look_ahead`,
  0.5 s at the current override): flag 1 (engagement or chip load rising ≥ 15 %) → the plan's
  predicted peak force over the next revolutions (edge and shear parts, the shear part scaled
  by the override, calibrated to the measurement over the first 10 revolutions in steady cut:
  one common factor, or each part its own factor when the window's overrides separate them,
  decision 1656) sets a ceiling on the override so the predicted force does not exceed the reference
  (feed-forward, decision 1613); flag 2 (cavity or exit) → the override is held at its value
  when the flag rose or lower, never raised, and the air rule is suspended (decision 1614);
- safety: a revolution with a non-finite sample, a signal frozen at a non-zero value for
  ``stall_s``, or no revolution completing within ``stall_s`` after the expected end → the
  safe action min(override, 100 %) and an ALARM; the override is never raised by a fault
  (decision 1615).

Chunk-size invariance: the spindle angle is accumulated as an integer (2⁻³² revolution units),
so revolution ends fall on the same samples however the stream is cut; peaks are running maxima
carried between chunks; the watchdog and the frozen-signal detector are per-sample with carried
state, and a fault inside a revolution takes effect at its own sample. The per-sample pass is
one compiled loop (:func:`_scan`); only the per-revolution decisions run in Python (≈ 17 per
second at 1000 rev/min).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.control.gpc import GPC
from millsense.control.rls import ConstantTraceRLS, force_model_constraints
from millsense.core.errors import ConfigError
from millsense.core.noise import sigma_from_abs_differences, window_median
from millsense.core.recording import ChannelInfo
from millsense.plan.path import cnc_line
from millsense.plan.virtual_plan import LOOK_AHEAD_S, RISE_FRACTION, VirtualPlan
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

#: The channel of the feed override in effect as a CNC reports it (fraction; the virtual
#: machine's and an OPC UA recording's), read where present (decision 1666).
REPORTED_OVERRIDE = "cnc/feed_override"

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

QUANTITIES = ("force", "torque", "power")
#: Intervals over which the noise of the regulated value is judged, and the fewest needed
#: (decision 1548).
NOISE_INTERVALS = 32
NOISE_MIN_INTERVALS = 8
#: Decision 1548: with a plan, the regulated value in air (the plan's tool out of the material,
#: no cut ahead, spindle at speed) over the last AIR_INTERVALS intervals; from AIR_MIN of them
#: on, a median at or above AIR_LIMIT × the reference means the signal cannot show the cut
#: (the feed is then held at the programmed 100 %), and below AIR_CLEAR × it that it can again.
#: Decision 1667: the GPC's move is at most this multiple of the proportional-cut move.
MOVE_LIMIT = 2.0
AIR_INTERVALS = 16
AIR_MIN = 8
AIR_LIMIT = 0.5
AIR_CLEAR = 0.25
_UNITS = {"force": "N", "torque": "N*m", "power": "W"}
#: Spindle angle resolution of the integer revolution counter (2⁻³² rev).
_ANGLE_BITS = 32
_ANGLE_ONE = 1 << _ANGLE_BITS


@dataclass(frozen=True)
class AdaptiveFeedOptions:
    """Settings of :class:`AdaptiveFeedBlock` (field units in the names).

    Attributes
    ----------
    reference : set point of the per-revolution peak, in the quantity's unit (N, N·m, W);
        seed 000 V8: 325 N.
    quantity : ``force`` (peak resultant of the two force channels), ``torque`` or ``power``
        (torque × |spindle speed|).
    statistic : what is taken of each revolution, ``peak`` or ``mean``; None: the peak for
        force (seed 000 and 002), the mean for torque and power (decision 1619: the spindle
        power AFC regulates is a mean, and the peak of an observer's broadband estimate is
        its noise).
    min_override_pct, max_override_pct : override limits (seed 000: 20–150 %).
    dead_band : relative band around the reference without a move (seed 000: ±5 %).
    air_threshold : peak at or below which the tool is in air, quantity's unit; None: 80 N
        for force (seed 002), 80/325 of the reference for a torque or power peak (decision
        1612), a tenth of it for their per-revolution mean (decision 1624).
    reentry_revs : revolutions at V_max/3 after an air cut (seed 002: 3).
    lam, n2 : GPC move weight and output horizon (seed 000: 0.25, 4).
    rls_delta : RLS dead zone on the normalised peak (0.005 = 0.5 % of the reference); it
        widens to twice the measured noise of the peak when that is larger (decision 1548).
    look_ahead : use the plan's look-ahead (flags 1/2) when a plan is given.
    look_ahead_s, rise : look-ahead horizon and rise threshold (seed 000: 0.5 s, 15 %).
    feedforward_revs : revolutions of travel whose predicted force the flag-1 ceiling covers.
    calibration_revs : revolutions in steady cut (flag 0, the override unchanged since the
        revolution before) over which the plan's force is calibrated to the measurement (seed
        000 C16: the first 10; one factor, or the edge and shear parts apart, decision 1656).
    stall_s : frozen-signal and missing-revolution timeout, s.
    min_change_pct : smallest override change that is sent as an event.
    min_interval_s : the control interval is the fewest whole revolutions that last at least
        this long (decision 1548; seed 002's 40 ms, the spindle period at 1500 rev/min: one
        revolution up to 1500 rev/min, five at 7500); the regulated value is the peak (or the
        mean) over the interval. 0: every revolution.
    """

    reference: float = 325.0
    quantity: str = "force"
    statistic: str | None = None
    min_override_pct: float = 20.0
    max_override_pct: float = 150.0
    dead_band: float = 0.05
    air_threshold: float | None = None
    reentry_revs: int = 3
    lam: float = 0.25
    n2: int = 4
    rls_delta: float = 0.005
    look_ahead: bool = True
    look_ahead_s: float = LOOK_AHEAD_S
    rise: float = RISE_FRACTION
    feedforward_revs: float = 2.0
    calibration_revs: int = 10
    stall_s: float = 0.1
    min_change_pct: float = 0.5
    min_interval_s: float = 0.04

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ConfigError(
                f"adaptive feed: quantity must be one of {', '.join(QUANTITIES)}, "
                f"got {self.quantity!r}"
            )
        if self.statistic not in (None, "peak", "mean"):
            raise ConfigError(
                f"adaptive feed: statistic must be peak or mean, got {self.statistic!r}"
            )
        if not (self.reference > 0 and math.isfinite(self.reference)):
            raise ConfigError(f"adaptive feed: reference must be > 0, got {self.reference!r}")
        if not (0 < self.min_override_pct < self.max_override_pct):
            raise ConfigError(
                "adaptive feed: need 0 < min_override_pct < max_override_pct, got "
                f"{self.min_override_pct!r}, {self.max_override_pct!r}"
            )
        if not (0 <= self.dead_band < 1):
            raise ConfigError(f"adaptive feed: dead_band must be in [0, 1), got {self.dead_band}")
        if self.reentry_revs < 0 or self.calibration_revs < 1:
            raise ConfigError("adaptive feed: reentry_revs ≥ 0 and calibration_revs ≥ 1 needed")
        if not (self.min_interval_s >= 0 and math.isfinite(self.min_interval_s)):
            raise ConfigError(
                f"adaptive feed: min_interval_s must be ≥ 0, got {self.min_interval_s!r}"
            )
        if not (self.stall_s > 0 and self.look_ahead_s >= 0 and self.feedforward_revs > 0):
            raise ConfigError(
                "adaptive feed: stall_s > 0, look_ahead_s ≥ 0, feedforward_revs > 0 needed"
            )

    @property
    def per_revolution(self) -> str:
        """``peak`` or ``mean`` (the default of the quantity when ``statistic`` is None)."""
        if self.statistic is not None:
            return self.statistic
        return "peak" if self.quantity == "force" else "mean"

    @property
    def air(self) -> float:
        if self.air_threshold is not None:
            return float(self.air_threshold)
        if self.quantity == "force":
            return 80.0
        # a per-revolution mean of a signed estimate is near 0 in air: a tenth of the reference
        # separates air from light cuts; a peak needs seed 002's 80/325 (decision 1624)
        return (0.1 if self.per_revolution == "mean" else 80.0 / 325.0) * self.reference


@dataclass
class _Loop:
    """Controller state between revolutions (normalised signals)."""

    u: float = 1.0  #: commanded override (fraction) now in force
    y_hist: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # y(k), y(k-1), y(k-2)
    u_hist: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])  # u(k-1), u(k-2), u(k-3)
    du_hist: list[float] = field(default_factory=lambda: [0.0, 0.0])  # Δu(k-1), Δu(k-2)
    air: bool = False  #: seed 002's fflag: the tool was in air (a stream starts as if cutting)
    reentry: int = 0  #: revolutions done at V_max/3
    engaged: bool = False  #: a revolution in cut has been seen (watchdog armed)
    identified: bool = False  #: RLS initialised from a revolution in cut
    hold: float | None = None  #: flag-2 ceiling (override at the flag's rise)
    fault: bool = False
    kappa_sum: float = 0.0
    kappa_n: int = 0
    #: calibration revolutions: (edge part, shear part, measured) of each (decision 1656)
    cal: list[tuple[float, float, float]] = field(default_factory=list)
    #: (α_E, α_S) of the two-part calibration once fitted; None: the common factor κ
    parts: tuple[float, float] | None = None
    row: int = 0
    flag: int = 0
    ff_until: int = -1  #: the flag-1 ceiling holds until the tool passes this plan row
    entering: bool = False  #: out of the material with the cut ahead (latched, decision 1626)
    #: revolutions the latched entry has read air with the plan's tool in the material
    #: (decision 1669)
    plan_entry: int = 0
    matched: bool = False  #: the plan matched the tool at the last decision


class AdaptiveFeedBlock(Block):
    """Per-revolution adaptive feed control (RLS + GPC) with the virtual look-ahead.

    Parameters
    ----------
    options : :class:`AdaptiveFeedOptions`.
    plan : the virtual plan (look-ahead, NC line and position of the events); None: the
        conventional adaptive control of seed 002 (no look-ahead).
    force_channels : the two XY force channels (N) for ``quantity = "force"``.
    torque_channel : spindle torque channel (N·m) for ``torque`` and ``power``.
    speed_channel : spindle speed (rad/s): revolutions are counted on it.
    tcp_channels : tool-centre position channels (m) matched to the plan.
    enable_channel : optional 1/0 channel; a revolution during which or at whose end it is 0
        makes no decision (the override is held: e.g. while the spindle runs up, when a torque
        observer's estimate holds the acceleration torque, and in the revolution the gate opens
        in, decision 1555), or None.
    override_channel : optional channel of the feed override in effect as the CNC reports it
        (fraction, ``cnc/feed_override``), or None. With it the RLS learns from the override
        the machine ran each control interval with (its mean over the interval), and the GPC
        moves from the override in effect: a closed CNC's 10 % steps and 120 ms, and a replay
        whose recorded overrides are not this block's, are modelled as they are (decision 1666).
    name : block name (channel prefix).

    Outputs: ``{name}/override`` (commanded override, fraction), ``{name}/peak`` (last
    control interval's peak or mean, quantity's unit; NaN while not enabled),
    ``{name}/reference``, ``{name}/flag`` (look-ahead flag 0/1/2, 3 while a fault holds the safe
    action). Events: OVERRIDE ``feed_override``
    (value in percent) when the commanded override changes by ≥ ``min_change_pct``; ALARM
    ``adaptive_feed_fault`` when an input fault forces the safe action.
    """

    reads_truth = False

    def __init__(
        self,
        options: AdaptiveFeedOptions | None = None,
        plan: VirtualPlan | None = None,
        *,
        force_channels: tuple[str, str] = ("force_x", "force_y"),
        torque_channel: str = "spindle/torque_est",
        speed_channel: str = "spindle/speed",
        tcp_channels: tuple[str, str, str] = ("x/position_cmd", "y/position_cmd", "z/position_cmd"),
        enable_channel: str | None = None,
        override_channel: str | None = None,
        name: str = "adaptive_feed",
    ) -> None:
        self.opts = opts = options or AdaptiveFeedOptions()
        self.plan = plan
        self.name = name
        self.force_channels = force_channels
        self.torque_channel = torque_channel
        self.speed_channel = speed_channel
        self.tcp_channels = tcp_channels
        if opts.quantity == "force":
            ins: list[str] = list(force_channels)
        else:
            ins = [torque_channel]
        ins.append(speed_channel)
        self.enable_channel = enable_channel
        if enable_channel is not None:
            ins.append(enable_channel)
        self.override_channel = override_channel
        if override_channel is not None:
            ins.append(override_channel)
        if plan is not None:
            if len(plan) < 2:
                raise ConfigError("adaptive feed: the plan has fewer than 2 rows")
            ins.extend(tcp_channels)
            self._plan_cols = _plan_force_columns(plan, opts.quantity, opts.per_revolution)
            self._in_cut = np.asarray(plan["in_cut"], dtype=bool)
        self.inputs = tuple(dict.fromkeys(ins))
        self.reads_truth = any(c.startswith("truth/") for c in self.inputs)
        self.gpc = GPC(n2=opts.n2, nu=1, lam=opts.lam)
        self._use_mean = opts.per_revolution == "mean"
        self.reset(10000.0)

    # ------------------------------------------------------------------ contract
    def output_channels(self) -> list[ChannelInfo]:
        unit = _UNITS[self.opts.quantity]
        st = self.opts.per_revolution
        n = self.name
        return [
            ChannelInfo(f"{n}/override", "1", "commanded feed override (fraction)"),
            ChannelInfo(
                f"{n}/peak",
                unit,
                f"{st} {self.opts.quantity} of the last control interval (NaN while not enabled)",
            ),
            ChannelInfo(f"{n}/reference", unit, f"reference {st} {self.opts.quantity}"),
            ChannelInfo(f"{n}/flag", "1", "look-ahead flag 0/1/2 (3: fault, safe action)"),
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        o = self.opts
        self.u_min = o.min_override_pct / 100.0
        self.u_max = o.max_override_pct / 100.0
        # the estimate kept among the physical models: one real pole in [0, 1], b ≥ 0
        # (decision 1657)
        self.rls = ConstantTraceRLS(
            theta0=[0.0, 0.0, 1.0, 0.0, 0.0], delta=o.rls_delta,
            constraints=force_model_constraints(2, 3),
        )  # fmt: skip
        self.loop = _Loop()
        # |y(k) − y(k−1)| of intervals at one override: the noise of the regulated value
        self._dy: deque[float] = deque(maxlen=NOISE_INTERVALS)
        # the regulated value in air (with a plan), and whether it drowns the set point
        self._air_vals: deque[float] = deque(maxlen=AIR_INTERVALS)
        self._drowned = False
        # scan state: [integer spindle angle (2⁻³² rev), frozen run length],
        # [running peak, last sample, running revolution holds a bad sample]
        self._st_i = np.zeros(3, dtype=np.int64)
        self._st_f = np.array([-np.inf, np.nan, 0.0, 0.0])
        self._scale = _ANGLE_ONE / (2 * math.pi * self.fs)
        self._rev_start = 0  # sample index where the running revolution began
        # Σ of the reported override over the running revolution's samples, and over the
        # control interval's revolutions; the last reported value (decision 1666)
        self._rev_ovr = 0.0
        self._ovr_now = math.nan
        self._off_at = -1  # last sample before this chunk where the enable channel was 0
        self._off = np.empty(0, dtype=np.int64)  # this chunk's samples where it is 0
        self._last_rev_len = 0
        # the control interval being gathered: [revolutions, samples, Σ value·samples or max,
        # Σ reported override over its samples]
        self._acc = [0, 0, 0.0, 0.0]
        self._min_interval = round(o.min_interval_s * self.fs)
        self._last_interval_len = 0
        self._watch_fired = False
        self._why = ""
        self._peak = 0.0
        self._n_stall = max(round(o.stall_s * self.fs), 1)
        self._ceiling_ext: float | None = None
        # the override the machine was last sent as far as this block knows: its own last
        # OVERRIDE event, or the arbiter's command when it told it another (decision 1671)
        self._sent = 1.0
        self._scratch: tuple[np.ndarray, ...] = (np.empty(0, dtype=np.int64),)
        self._ref_name = (f"{self.name}/reference",)
        self._ref_value = np.array([o.reference], dtype=np.float64)
        self._ref_views: HeldViews | None = None

    def set_ceiling(self, ceiling: float | None, commanded: float) -> None:
        """From an arbiter (:class:`~millsense.control.arbitration.Supervisor`): the largest
        override this block may propose from now on (None: its own limits only), and the
        override the machine was actually sent (the block's state follows it when the arbiter
        did not pass a proposal, so the next GPC move starts from what the plant saw).

        With no ceiling and the machine sent this block's own last proposal, nothing changes:
        the state is the block's own, including the override the CNC reports (decision 1666),
        which it does not overwrite with the command between two decisions (decision 1671: so
        an arbiter that passes every proposal does not act on the block, and may run it over
        several of its control periods at once)."""
        self._ceiling_ext = ceiling
        if ceiling is None and abs(commanded - self._sent) <= 1e-12:
            return
        self._sent = commanded  # what the machine was sent, now known to this block
        if abs(commanded - self.loop.u) > 1e-12:
            self.loop.u = commanded
            self.loop.u_hist[0] = commanded

    # ------------------------------------------------------------------ streaming
    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        n = chunk.n
        q = np.ascontiguousarray(self._quantity(d), dtype=np.float64)
        speed = np.ascontiguousarray(d[self.speed_channel], dtype=np.float64)
        # the scan's scratch arrays, kept from chunk to chunk (read only up to its counts)
        if self._scratch[0].shape[0] < n + 1:
            m = 2 * n + 1
            self._scratch = (np.empty(m, dtype=np.int64), np.empty(m),
                             np.empty(m, dtype=np.bool_), np.empty(m, dtype=np.int64),
                             np.empty(m, dtype=np.int64))  # fmt: skip
        ends, peaks, bads, frozen_end, hits = self._scratch
        n_end, n_hit = _scan(
            q, speed, self._scale, self._n_stall, self._st_i, self._st_f, self._use_mean,
            ends, peaks, bads, frozen_end, hits,
        )  # fmt: skip
        if self.enable_channel is not None:
            self._off = (np.asarray(d[self.enable_channel]) < 0.5).nonzero()[0]
        # the reported override's running sum (decision 1666)
        ovr = ovr_cs = None
        if self.override_channel is not None and n:
            ovr = np.asarray(d[self.override_channel], dtype=np.float64)
            ovr_cs = np.empty(n + 1)
            ovr_cs[0] = 0.0
            ovr.cumsum(out=ovr_cs[1:])
        events: list[Event] = []
        ov = np.empty(n)
        pk = np.empty(n)
        fl = np.empty(n)
        hit_list = hits[:n_hit].tolist()
        pos = 0
        for j in range(n_end + 1):
            e = int(ends[j]) if j < n_end else n
            # safety checks inside the running revolution (a fault splits the fill)
            at = self._check_faults(chunk, pos, e, hit_list, events) if e > pos else -1
            if at > pos:
                self._fill(ov, pk, fl, slice(pos, at))
                self._apply_fault(chunk, at, events)
                self._fill(ov, pk, fl, slice(at, e))
            else:
                if at == pos:
                    self._apply_fault(chunk, at, events)
                self._fill(ov, pk, fl, slice(pos, e))
            if ovr is not None and ovr_cs is not None:
                self._rev_ovr += float(ovr_cs[e] - ovr_cs[pos])
                if e > 0:
                    self._ovr_now = float(ovr[e - 1])
            if j == n_end:
                break
            self._revolution_end(
                chunk, e, float(peaks[j]), bool(bads[j]), int(frozen_end[j]), events
            )
            pos = e
        if self._off.size:
            self._off_at = chunk.start + int(self._off[-1])
        # the reference, constant: views of one array never written again
        self._ref_views, ref = held_views(self._ref_name, self._ref_value, self._ref_views, n)
        return BlockOutput(
            {
                f"{self.name}/override": ov,
                f"{self.name}/peak": pk,
                f"{self.name}/reference": ref[self._ref_name[0]],
                f"{self.name}/flag": fl,
            },
            events,
        )

    def _fill(self, ov: FloatArray, pk: FloatArray, fl: FloatArray, seg: slice) -> None:
        ov[seg] = self.loop.u
        pk[seg] = self._peak
        fl[seg] = 3 if self.loop.fault else self.loop.flag

    # ------------------------------------------------------------------ signal
    def _quantity(self, d: Any) -> FloatArray:
        if self.opts.quantity == "force":
            fx = np.asarray(d[self.force_channels[0]], dtype=np.float64)
            fy = np.asarray(d[self.force_channels[1]], dtype=np.float64)
            return np.asarray(np.hypot(fx, fy))
        tq = np.asarray(d[self.torque_channel], dtype=np.float64)
        speed = np.asarray(d[self.speed_channel], dtype=np.float64)
        if self._use_mean:
            # signed, so that the noise of an estimate averages out over the revolution; the
            # revolution's |mean| is taken in _scan (decision 1624)
            return tq if self.opts.quantity == "torque" else tq * np.abs(speed)
        if self.opts.quantity == "torque":
            return np.abs(tq)
        return np.abs(tq * speed)

    # ------------------------------------------------------------------ safety
    def _check_faults(
        self, chunk: Chunk, a: int, b: int, hits: list[int], events: list[Event]
    ) -> int:
        """First sample in [a, b) where a fault starts (−1: none); notes its reason."""
        lp = self.loop
        if lp.fault or not lp.engaged:
            return -1
        at = -1
        why = ""
        for h in hits:
            if a <= h < b:
                at, why = h, "signal frozen"
                break
        if self._last_rev_len > 0 and not self._watch_fired:
            deadline = self._rev_start + self._last_rev_len + self._n_stall - chunk.start
            if a <= deadline < b and (at < 0 or deadline < at):
                at, why = deadline, "no spindle revolution"
        self._why = why
        return at

    def _apply_fault(self, chunk: Chunk, at: int, events: list[Event]) -> None:
        if self._why == "no spindle revolution":
            self._watch_fired = True
            if self._out_of_material():
                self._safe(chunk, at, self._why, events, paused=True)
                return
        self._safe(chunk, at, self._why, events)

    def _out_of_material(self) -> bool:
        """The tool was out of the material at the last decision: the plan's row (with the
        look-ahead) is not in cut, or, without it, the last revolution read air."""
        in_cut = self._plan_row_in_cut()
        return not in_cut if in_cut is not None else self.loop.air

    def _safe(
        self, chunk: Chunk, at: int, why: str, events: list[Event], paused: bool = False
    ) -> None:
        """The safe action: min(override, 100 %) and an alarm (decision 1615); ``paused``: no
        spindle revolution with the tool out of the material (decision 1686), a spindle stopped
        by the program (M5 after the last cut, before a tool change), which is no fault: the
        same override (nothing enters the material faster than programmed if the spindle
        signal, not the spindle, was lost), said as a NOTE. Control resumes at the next clean
        revolution."""
        lp = self.loop
        lp.fault = True
        t = chunk.t0_s + (chunk.start + at) / chunk.sample_rate_hz
        signal = self._signal_name()
        events.append(
            Event(
                t,
                EventKind.NOTE if paused else EventKind.ALARM,
                self.name,
                f"adaptive feed paused: {why} on '{signal}' with the tool out of the material "
                "(a spindle stop); feed held at 100 % at most"
                if paused
                else f"adaptive feed: {why} on '{signal}'; safe feed held",
                name="adaptive_feed_paused" if paused else "adaptive_feed_fault",
                value=None,
                sample=chunk.start + at,
                severity=Severity.INFO if paused else Severity.WARNING,
            )
        )
        if paused:
            self._command(chunk, at, min(lp.u, 1.0), events, Severity.INFO,
                          why="paused: spindle stopped out of the material")  # fmt: skip
        else:
            self._command(chunk, at, min(lp.u, 1.0), events, Severity.WARNING, force=True,
                          why=f"safe action: {why}")  # fmt: skip

    def _signal_name(self) -> str:
        if self.opts.quantity == "force":
            return ", ".join(self.force_channels)
        return self.torque_channel

    # ------------------------------------------------------------------ control
    def _revolution_end(
        self, chunk: Chunk, e: int, peak: float, was_bad: bool, frozen: int, events: list[Event]
    ) -> None:
        """Revolution complete at sample ``e`` (first sample of the next): one decision.

        ``peak``: its largest sample; ``was_bad``: it held a non-finite sample; ``frozen``:
        how long the signal had been frozen at its last sample."""
        o = self.opts
        lp = self.loop
        start = self._rev_start
        self._last_rev_len = chunk.start + e - start
        self._rev_start = chunk.start + e
        self._watch_fired = False
        rev_ovr, self._rev_ovr = self._rev_ovr, 0.0
        if was_bad or not math.isfinite(peak):
            self._acc = [0, 0, 0.0, 0.0]
            if lp.engaged and not lp.fault:
                self._safe(chunk, e, "non-finite samples", events)
            return
        if self.enable_channel is not None:
            i = int(np.searchsorted(self._off, e, "right"))
            last_off = chunk.start + int(self._off[i - 1]) if i else self._off_at
            if last_off >= start:
                # not enabled during this revolution or at its end: no decision, override
                # held, and no value shown (a run-up's acceleration torque is not the process,
                # nor is the torque of the samples before the gate opened: decision 1555)
                self._peak = math.nan
                self._acc = [0, 0, 0.0, 0.0]
                return
        if frozen >= self._n_stall:
            self._acc = [0, 0, 0.0, 0.0]
            if lp.engaged and not lp.fault:
                self._safe(chunk, e, "signal frozen", events)
            return
        # the control interval: whole revolutions lasting at least min_interval_s (decision
        # 1548); the decision comes at the end of its last revolution
        acc = self._acc
        length = self._last_rev_len
        acc[0] += 1
        acc[1] += length
        acc[2] = acc[2] + peak * length if self._use_mean else max(acc[2], peak)
        acc[3] += rev_ovr
        if acc[1] < self._min_interval:
            return
        ovr_mean = acc[3] / acc[1]
        if acc[0] > 1:  # one revolution: its own value, as it is
            peak = acc[2] / acc[1] if self._use_mean else acc[2]
        self._last_interval_len = int(acc[1])
        self._acc = [0, 0, 0.0, 0.0]
        self._peak = peak
        if lp.fault:
            lp.fault = False  # a clean revolution: resume from the held (safe) override
        y = peak / o.reference
        lp.y_hist = [y, lp.y_hist[0], lp.y_hist[1]]
        if self.override_channel is not None:
            self._use_reported_override(ovr_mean)
        flag, cap, entering = self._look(chunk, e)
        # the loudest of the signal's recent air readings (decision 1679), before this one joins
        air_loud = max(self._air_vals) if len(self._air_vals) >= AIR_MIN else 0.0
        if self._watch_air(chunk, e, peak, entering, events):
            # the signal cannot show the cut: the programmed feed, no regulation (decision 1548)
            lp.flag = flag
            u = 1.0 if self._ceiling_ext is None else min(1.0, self._ceiling_ext)
            u = min(max(u, self.u_min), self.u_max)
            self._command(chunk, e, u, events, Severity.WARNING, why="signal drowned in air")
            return
        plan_air = self._plan_air()
        in_air = peak <= o.air or plan_air
        if not in_air and lp.air and peak <= air_loud and not self._plan_in_cut():
            # out of the plan's material, a reading over the air threshold but within what the
            # air itself has read is the noise, not a re-entry: around the threshold seed 002's
            # rules alternated 150 % / 50 % every revolution (decision 1679)
            in_air = True
        if in_air and flag == 2 and lp.engaged:
            u, why = lp.u, "exit hold"  # leaving the cut: the air rule would speed up
        elif in_air:
            if entering and not plan_air and self._plan_in_cut():
                # the plan has counted the re-entry revolutions in the material and the signal
                # still reads air: a cut too light to show (a helix, a ramp); the latch's
                # purpose is served, and it no longer holds the whole light cut at V_max/3;
                # seed 002's re-entry is done too, so the first revolution loaded enough to
                # show does not start it again (decision 1669)
                lp.plan_entry += 1
                if lp.plan_entry > o.reentry_revs:
                    lp.entering = entering = False
                    lp.air = False
            # seed 002's air rule, but where the plan sees the cut resume within the horizon
            # the tool meets the material at the re-entry feed, not at V_max (decision 1626)
            u = self.u_max / 3.0 if entering else self.u_max
            why = ("air by the plan" if plan_air else "air") + (", cut ahead" if entering else "")
            if not plan_air and self._plan_in_cut():
                # the plan has the tool in the material (a plunge, the light start of an
                # entry, a light cut): the signal's air is a light cut, and the air rule does
                # not go faster than programmed there (decision 1663); nor is it an air cut
                # whose re-entry restarts: on a cut reading air at V_max/3 and not at the
                # programmed feed the two alternated every revolution (decision 1675)
                if u > 1.0:
                    u, why = 1.0, f"{why}, the plan in cut"
            else:
                lp.air, lp.reentry = True, 0
        elif lp.air and lp.reentry < o.reentry_revs:
            lp.engaged = True
            lp.reentry += 1
            u, why = self.u_max / 3.0, f"re-entry {lp.reentry}/{o.reentry_revs}"
            if lp.reentry >= o.reentry_revs:
                lp.air = False
        else:
            lp.air = False
            lp.engaged = True
            u, why = self._gpc(y), "regulation"
        if not in_air:
            lp.entering = False
            self._calibrate(y, flag)
        limits: list[tuple[float, str]] = []  # what may lower u, with its name for the event
        if flag == 2:
            if lp.hold is None:
                lp.hold = lp.u
            limits.append((lp.hold, "flag-2 hold"))
        elif lp.hold is not None and not in_air and not self._in_cut[lp.row]:
            # the plan's tool has left the material but the machine still cuts (a plan's rows
            # and z-map are coarser than the machine's edge; runout; servo lag): the exit hold
            # stands until a revolution reads as air (decision 1741)
            limits.append((lp.hold, "exit hold"))
        else:
            lp.hold = None
        if flag == 1 and (not in_air or self._plan_in_cut()):
            # never faster into a rising engagement, nor where the signal reads air but the
            # plan has the tool in the material (decision 1663)
            limits.append((lp.u, "flag 1: no rise"))
        if cap is not None:
            limits.append((cap, "look-ahead ceiling"))
        if self._ceiling_ext is not None:
            limits.append((self._ceiling_ext, "supervisor ceiling"))
        for limit, name in limits:
            if limit < u:
                u, why = limit, f"{why}; {name}"
        u = min(max(u, self.u_min), self.u_max)
        lp.flag = flag
        sev = Severity.WARNING if flag else Severity.INFO
        self._command(chunk, e, u, events, sev, why=why)

    def _use_reported_override(self, interval_mean: float) -> None:
        """Decision 1666: the control interval's input is the override the CNC reported over
        it (its mean), and the next move starts from the override it reports now, instead of
        what this block commanded. They differ where the CNC quantises and delays the command
        (a closed CNC's 10 % steps and 120 ms), where an operator or an arbiter set another
        value, and in a replay, whose recorded overrides were another controller's. A reported
        0 (a feed hold) or a non-finite value is not a feed the cut answered: the commanded
        values stay."""
        lp = self.loop
        if math.isfinite(interval_mean) and interval_mean > 0.0:
            lp.u_hist[0] = interval_mean
            lp.du_hist[0] = lp.u_hist[0] - lp.u_hist[1]
        now = self._ovr_now
        if math.isfinite(now) and now > 0.0:
            lp.u = now

    def _plan_row_in_cut(self) -> bool | None:
        """Whether the plan row the look-ahead matched the tool to at this decision is in the
        material; None without that information (no plan, no look-ahead: the conventional
        controller; no match)."""
        lp = self.loop
        if self.plan is None or not self.opts.look_ahead or not lp.matched:
            return None
        return bool(self._in_cut[lp.row])

    def _plan_in_cut(self) -> bool:
        """The plan has the tool in the material at this decision (decision 1663)."""
        return self._plan_row_in_cut() is True

    def _plan_air(self) -> bool:
        """The plan puts the tool in air before its first engagement: the look-ahead matched
        the tool at this decision to a row out of the material, and no revolution has been
        in cut yet. The regulated value is then not a cut whatever it reads (a spindle run-up,
        an air reference still settling, an estimate's air error: decision 1555); after the
        first engagement the machine, not the plan, confirms an exit (decision 1741)."""
        return self._plan_row_in_cut() is False and not self.loop.engaged

    def _seed_model(self, y: float, u: float) -> None:
        """The RLS restarted from the static gain y/u (θ̂₀ = [0, 0, y/u, 0, 0], P₀;
        decisions 1611, 1661)."""
        self.rls.theta0 = [0.0, 0.0, y / max(u, 1e-6), 0.0, 0.0]
        self.rls.reset()

    def _gpc(self, y: float) -> float:
        """RLS update and the GPC move (Munasinghe 3.27–3.31, 3.41; Aslan 6.14)."""
        o = self.opts
        lp = self.loop
        y0, y1, y2 = lp.y_hist
        u1, u2, u3 = lp.u_hist
        if not lp.identified:
            # decision 1611: θ̂₀ from the first revolution in cut (static gain y/u)
            self._seed_model(y0, u1)
            lp.identified = True
        else:
            self.rls.delta = self._dead_zone(y0, y1, u1, u2)
            self.rls.update([-y1, -y2, u1, u2, u3], y0)
        th = self.rls.theta
        a, b = th[:2], th[2:]
        if abs(y0 - 1.0) <= o.dead_band:
            return lp.u
        if float(np.sum(b)) <= 1e-6 * (1.0 + abs(float(np.sum(a)))):
            # a non-physical model (force falling with feed): learned while the force moved at a
            # constant feed (chatter, a spindle-speed change), where nothing excites the RLS
            # again, so waiting for it to recover held the feed for good (decision 1661). The
            # model restarts from this revolution's static gain, as at the first revolution in
            # cut (decision 1611), and the move is taken on it.
            self._seed_model(y0, u1)
            th = self.rls.theta
            a, b = th[:2], th[2:]
        du = self.gpc.move(a, b, [y0, y1, y2], lp.du_hist, 1.0)
        if not math.isfinite(du):
            return lp.u
        return lp.u + self._bounded_move(du, y0, u1)

    def _bounded_move(self, du: float, y0: float, u1: float) -> float:
        """Decision 1667: the GPC's move, kept between 0 and MOVE_LIMIT × the move a cut whose
        force is proportional to the feed needs (to u₁/y₀, the interval's override over its
        normalised value). The RLS of a steady cut at one override is not excited; it drifts to
        a near-integrator with a small gain (a pole at 0.97, b₀ 0.05 against a static gain of
        3.4 on V8's slot with the machine's seed 1), on which an 18 % shortfall asked for +134 %
        (20 → 150 %) and the next revolution's force reached 2.8 × the reference; a force above
        the reference was met with a cut to 20 % where 32 % was needed. A move in the wrong
        direction is never taken (0), one larger than MOVE_LIMIT × the proportional move is
        that limit: the edge force makes the cut less sensitive than proportional, which
        MOVE_LIMIT = 2 leaves room for (an edge part up to the shear part)."""
        if not y0 > 0.0:
            return du
        need = u1 / y0 - self.loop.u
        lo, hi = (MOVE_LIMIT * need, 0.0) if need < 0.0 else (0.0, MOVE_LIMIT * need)
        return min(max(du, lo), hi)

    def _watch_air(
        self, chunk: Chunk, e: int, value: float, entering: bool, events: list[Event]
    ) -> bool:
        """Whether the regulated signal is drowned in its own air reading (decision 1548).

        With a plan, an interval ending where the plan's tool is out of the material with no
        cut ahead is air whatever the signal says; the median of the last AIR_INTERVALS such
        values is the signal's floor. At AIR_LIMIT × the reference or above, a cut at the set
        point reads within 2× of air and the controller would regulate the floor (the feed
        drives' force estimates of a commissioned quaser-ux600 read 1–2 kN in air at 8000
        rev/min against a 222 N reference, and held the override at its 20 % floor through
        the whole approach): one WARNING alarm, and the feed is held at the programmed 100 %
        until the floor falls below AIR_CLEAR × the reference (a NOTE)."""
        if self.plan is None or entering or self._in_cut[self.loop.row]:
            return self._drowned
        self._air_vals.append(value)
        if len(self._air_vals) < AIR_MIN:
            return self._drowned
        floor = window_median(self._air_vals)
        ref = self.opts.reference
        unit = _UNITS[self.opts.quantity]
        t = chunk.t0_s + (chunk.start + e) / chunk.sample_rate_hz
        if not self._drowned and floor >= AIR_LIMIT * ref:
            self._drowned = True
            # a force (the feed drives' estimate): the spindle's signal is the quieter one; the
            # spindle's own torque or power: a cut this light is within its noise
            remedy = (
                "regulate the spindle power, or use a dynamometer"
                if self.opts.quantity == "force"
                else "the cut is too light for this signal; a dynamometer shows it"
            )
            events.append(Event(
                t, EventKind.ALARM, self.name,
                f"adaptive feed: in air '{self._signal_name()}' reads {floor:.4g} {unit} "
                f"(median of {len(self._air_vals)} intervals), {floor / ref:.2g} × the "
                f"{ref:.4g} {unit} reference: it cannot show the cut; the programmed feed is "
                f"held ({remedy})",
                name="adaptive_feed_noise", value=floor, sample=chunk.start + e,
                severity=Severity.WARNING,
            ))  # fmt: skip
        elif self._drowned and floor < AIR_CLEAR * ref:
            self._drowned = False
            events.append(Event(
                t, EventKind.NOTE, self.name,
                f"adaptive feed: in air '{self._signal_name()}' reads {floor:.4g} {unit}; "
                "regulating again", name="adaptive_feed_noise_clear", value=floor,
                sample=chunk.start + e, severity=Severity.INFO,
            ))  # fmt: skip
        return self._drowned

    def _dead_zone(self, y0: float, y1: float, u1: float, u2: float) -> float:
        """The RLS dead zone δ (Munasinghe Eq. 3.31: no update while |error| ≤ 2δ): the
        option's, or twice the regulated value's noise where that is larger (decision 1548).

        The dead zone is the bound of what the model cannot explain; seed 002's dynamometer peak
        stayed within 0.5 %, an observer's spindle power at high speed scatters by 1–2 % from one
        interval to the next. Inside that noise at a constant override nothing excites the
        model, and updating on the noise alone let it drift along the direction the data do not
        fix (a pole → 1 and b → 0 at the same static gain), on which the GPC's next move was
        five times too large. σ̂ is the median |y(k) − y(k−1)| of the last NOISE_INTERVALS
        intervals cut at one override, / (0.6745·√2), once NOISE_MIN_INTERVALS are held."""
        if u1 == u2 and math.isfinite(y1) and y1 > 0:
            self._dy.append(abs(y0 - y1))
        delta = self.opts.rls_delta
        if len(self._dy) >= NOISE_MIN_INTERVALS:
            delta = max(delta, 2.0 * sigma_from_abs_differences(self._dy))
        return delta

    def _command(
        self,
        chunk: Chunk,
        e: int,
        u: float,
        events: list[Event],
        severity: Severity,
        force: bool = False,
        why: str = "",
    ) -> None:
        """Send override ``u`` (fraction) as an event where it moves by ``min_change_pct`` or
        more (always with ``force``); ``why``: the rule that set it, for the event's message."""
        lp = self.loop
        du = u - lp.u
        lp.du_hist = [du, lp.du_hist[0]]
        lp.u_hist = [u, lp.u_hist[0], lp.u_hist[1]]
        if not force and abs(du) * 100.0 < self.opts.min_change_pct:
            lp.u_hist[0] = lp.u  # the move was not sent: the plant saw the old override
            lp.du_hist[0] = 0.0
            return
        lp.u = u
        self._sent = u
        t = chunk.t0_s + (chunk.start + e) / chunk.sample_rate_hz
        nc = x = y = z = None
        if self.plan is not None:
            r = lp.row
            nc = int(cnc_line(self.plan["nc_line"][r], self.plan["source_line"][r]))
            x, y, z = (float(self.plan[c][r]) for c in ("x_mm", "y_mm", "z_mm"))
        events.append(
            Event(
                t,
                EventKind.OVERRIDE,
                self.name,
                f"adaptive feed: override {100 * u:.1f} % ({why + ', ' if why else ''}peak "
                f"{self._peak:.4g} {_UNITS[self.opts.quantity]}, flag {lp.flag})",
                name="feed_override",
                value=100.0 * u,
                sample=chunk.start + e,
                severity=severity,
                values={"peak": self._peak, "reference": self.opts.reference, "flag": lp.flag},
                nc_line=nc,
                x_mm=x,
                y_mm=y,
                z_mm=z,
            )
        )

    # ------------------------------------------------------------------ look-ahead
    def _look(self, chunk: Chunk, e: int) -> tuple[int, float | None, bool]:
        """Look-ahead flag, the flag-1 override ceiling (None: no ceiling), and whether the
        plan's tool is out of the material with the cut resuming within the horizon (an
        entry, or the far wall of a cavity: decision 1626)."""
        if self.plan is None:
            return 0, None, False
        lp = self.loop
        xyz = [float(np.asarray(chunk.data[c])[e]) for c in self.tcp_channels]
        lp.matched = False
        if not all(map(math.isfinite, xyz)):
            return lp.flag, None, False
        row = int(self.plan.match(np.array([xyz]), from_row=lp.row)[0])
        if row >= 0:
            lp.row = row
            lp.matched = True
        if not self.opts.look_ahead:
            return 0, None, False
        la = self.plan.look_ahead(lp.row, self.opts.look_ahead_s, max(lp.u, 1e-3), self.opts.rise)
        if not self._in_cut[lp.row]:
            # the cut ahead within the horizon at V_max (at the override now in force the
            # horizon would shrink with the feed this verdict sets); latched until a revolution
            # is loaded, as the plan's first rows in cut are lighter than the air threshold
            ahead = self.plan.look_ahead(lp.row, self.opts.look_ahead_s, self.u_max, 0.0)
            lp.entering = ahead.rising
            lp.plan_entry = 0
        entering = lp.entering
        if la.flag == 1:
            lp.ff_until = max(lp.ff_until, la.last_row)
        if la.flag == 2 or lp.row > lp.ff_until:
            return la.flag, None, entering
        return la.flag, self._ceiling(lp.row), entering

    def _ceiling(self, row: int) -> float | None:
        """Largest override whose predicted peak force over the next ``feedforward_revs``
        revolutions of travel stays at the reference (decision 1613): κ·|E + u·S| = F_r with
        the common factor κ, or |α_E·E + u·α_S·S| = F_r once the two-part calibration has been
        fitted (decision 1656)."""
        lp = self.loop
        cols = self._plan_cols
        t = cols["t_s"]
        rev_s = self._last_interval_len / self.fs if self._last_interval_len else 0.06
        end = int(np.searchsorted(t, t[row] + lp.u * self.opts.feedforward_revs * rev_s, "right"))
        if lp.parts is not None:
            # two-part calibration: |α_E·E + u·α_S·S| = F_r (decision 1656)
            a_e, a_s = lp.parts
            c = self.opts.reference
        else:
            a_e = a_s = 1.0  # (a product by 1.0 is exact: the plan's parts as they are)
            kappa = lp.kappa_sum / lp.kappa_n if lp.kappa_n else 1.0
            c = self.opts.reference / max(kappa, 1e-6)
        found, u = _lowest_root(cols["edge_x"], cols["edge_y"], cols["shear_x"], cols["shear_y"],
                                row, max(end, row + 2), a_e, a_s, float(c))  # fmt: skip
        if not found:
            return None
        return float(max(u, 0.0))

    def _calibrate(self, y: float, flag: int) -> None:
        """Calibration of the plan's force to the measurement over the first
        ``calibration_revs`` revolutions in steady cut (seed 000 C16; decisions 1613, 1656).

        A revolution counts when the look-ahead flag is 0, the plan predicts a cut, and the
        override in force was already in force during the previous revolution: a revolution
        that starts with an override change cuts its first chips at a feed between the two
        (the tooth period before it and the axes' following lag), so it is not a steady cut.
        Each counted revolution adds measured/predicted to the common factor κ (used until
        the window is complete, and after it when the two-part fit is not adopted) and its
        edge part, shear part and measured peak to the two-part fit
        (:func:`_two_part_fit`), made once when the window is complete."""
        lp = self.loop
        if self.plan is None or flag != 0 or lp.kappa_n >= self.opts.calibration_revs:
            return
        u = lp.u_hist[0]
        if abs(u - lp.u_hist[1]) > 1e-12:
            return  # the override changed at this revolution's start (decision 1656)
        r = lp.row
        ex, ey = self._plan_cols["edge_x"][r], self._plan_cols["edge_y"][r]
        sx, sy = self._plan_cols["shear_x"][r], self._plan_cols["shear_y"][r]
        p_e, p_s = _split_prediction(ex, ey, sx, sy, u)
        pred = p_e + p_s
        if pred > self.opts.air:
            measured = y * self.opts.reference
            lp.kappa_sum += measured / pred
            lp.kappa_n += 1
            lp.cal.append((p_e, p_s, measured))
            if lp.kappa_n == self.opts.calibration_revs:
                lp.parts = _two_part_fit(lp.cal)


#: Significance level of the F-test that adopts the two-part calibration (decision 1656).
TWO_PART_SIGNIFICANCE = 0.05


def _split_prediction(ex: float, ey: float, sx: float, sy: float, u: float) -> tuple[float, float]:
    """The predicted peak |E + u·S| at override ``u`` split into its edge and shear parts
    along the predicted resultant: p_E = E·R/|R|, p_S = u·S·R/|R| with R = E + u·S, so that
    p_E + p_S = |R| (decision 1656). (0, 0) where nothing is predicted."""
    rx, ry = ex + u * sx, ey + u * sy
    n = math.hypot(rx, ry)
    if n <= 0.0:
        return 0.0, 0.0
    return (ex * rx + ey * ry) / n, u * (sx * rx + sy * ry) / n


def _two_part_fit(
    cal: list[tuple[float, float, float]], level: float = TWO_PART_SIGNIFICANCE
) -> tuple[float, float] | None:
    """Two-part calibration (decision 1656): measured ≈ α_E·p_E + α_S·p_S by least squares
    over the calibration revolutions (``cal`` rows: p_E, p_S, measured), so that the force
    that does not scale with the feed (the edge force, and the chip a runout adds to the
    leading flute) and the shear force (∝ the feed per tooth) are each scaled by their own
    factor and the prediction carries to another feed.

    Adopted only when the overrides of the window let the data separate the two parts: the
    fit has full rank, both factors are positive, and it explains the peaks better than one
    common factor (the nested least-squares κ) by an F-test at ``level`` (F(1, n − 2)).
    None otherwise: the caller keeps the common factor κ."""
    from scipy.special import fdtrc

    a = np.asarray(cal, dtype=np.float64)
    n = a.shape[0]
    if n < 3:
        return None
    design, m = a[:, :2], a[:, 2]
    coef, _, rank, _ = np.linalg.lstsq(design, m, rcond=None)
    if rank < 2 or not bool(np.all(coef > 0.0)):
        return None
    p = design.sum(axis=1)
    k1 = float(p @ m) / float(p @ p)
    rss1 = float(np.sum((m - k1 * p) ** 2))
    rss2 = float(np.sum((m - design @ coef) ** 2))
    if not rss1 > rss2:
        return None
    f = (rss1 - rss2) / (rss2 / (n - 2)) if rss2 > 0.0 else math.inf
    if not float(fdtrc(1, n - 2, f)) < level:
        return None
    return float(coef[0]), float(coef[1])


def _plan_force_columns(
    plan: VirtualPlan, quantity: str = "force", statistic: str = "peak"
) -> dict[str, FloatArray]:
    """The plan's predicted peak of the regulated quantity split into its edge part E and its
    shear part S (the shear part scales with the chip thickness, i.e. the feed override):
    F(u) = |E + u·S|. Force: the XY components at the resultant's peak (``fres_peak_{x,y}_n``
    and their shear parts); torque: ``torque_peak_nm`` and ``torque_peak_shear_nm`` (y = 0);
    power: the torque times the planned spindle speed; with ``statistic = "mean"`` the mean
    torque (``torque_avg_nm``, ``torque_avg_shear_nm``) or the mean resultant force
    (``fres_avg_n``, all of it scaled with the feed: the plan holds no edge part of it)."""
    t = np.asarray(plan["t_s"], dtype=np.float64)
    if quantity == "force" and statistic == "mean":
        fx = np.asarray(plan["fres_avg_n"], dtype=np.float64)
        sx = fx.copy()
        fy = np.zeros(len(plan))
        sy = np.zeros(len(plan))
    elif quantity == "force":
        fx = np.asarray(plan["fres_peak_x_n"], dtype=np.float64)
        fy = np.asarray(plan["fres_peak_y_n"], dtype=np.float64)
        sx = np.asarray(plan["fres_peak_shear_x_n"], dtype=np.float64)
        sy = np.asarray(plan["fres_peak_shear_y_n"], dtype=np.float64)
    else:
        scale = np.ones(len(plan))
        if quantity == "power":
            scale = np.abs(np.asarray(plan["spindle_rpm"], dtype=np.float64)) * 2 * math.pi / 60
        key = "torque_peak" if statistic == "peak" else "torque_avg"
        fx = np.abs(np.asarray(plan[f"{key}_nm"], dtype=np.float64)) * scale
        sx = np.abs(np.asarray(plan[f"{key}_shear_nm"], dtype=np.float64)) * scale
        fy = np.zeros(len(plan))
        sy = np.zeros(len(plan))
    cols = {"t_s": t, "edge_x": fx - sx, "edge_y": fy - sy, "shear_x": sx, "shear_y": sy}
    # contiguous: the ceiling's kernel (:func:`_lowest_root`) is compiled for these only
    return {k: np.ascontiguousarray(v) for k, v in cols.items()}


@numba.njit(cache=True)
def _lowest_root(
    ex: FloatArray,
    ey: FloatArray,
    sx: FloatArray,
    sy: FloatArray,
    lo: int,
    hi: int,
    a_e: float,
    a_s: float,
    c: float,
) -> tuple[bool, float]:
    """The flag-1 ceiling's override over the plan rows ``lo:hi`` (:meth:`AdaptiveFeedBlock.
    _ceiling`, decisions 1613, 1656): per row the largest root u of |α_E·E + u·α_S·S| = c,
    i.e. (S·S) u² + 2 (E·S) u + (E·E − c²) = 0 with the discriminant floored at 0, over the
    rows whose S·S > 1e-12; their smallest (NaN if any root is). (False, NaN) when no row has
    a shear part. One pass in the order numpy's element-wise steps took them, so the value is
    theirs bit for bit (the ceiling runs every revolution; a dozen small-array calls cost ≈
    30 µs)."""
    hi = min(hi, ex.shape[0])
    found = False
    low = np.nan
    for r in range(lo, hi):
        e_x = a_e * ex[r]
        e_y = a_e * ey[r]
        s_x = a_s * sx[r]
        s_y = a_s * sy[r]
        aa = s_x * s_x + s_y * s_y
        if not aa > 1e-12:
            continue
        bb = e_x * s_x + e_y * s_y
        cc = e_x * e_x + e_y * e_y - c * c
        disc = bb * bb - aa * cc
        if disc < 0.0:  # np.maximum(disc, 0.0): a NaN stays NaN
            disc = 0.0
        u = (-bb + np.sqrt(disc)) / aa
        if not found:
            low = u
            found = True
        elif low == low and (u < low or u != u):  # np.min: the smallest, NaN if any is
            low = u
    return found, low


@numba.njit(cache=True)
def _scan(
    q: FloatArray,
    speed: FloatArray,
    scale: float,
    n_stall: int,
    st_i: IntArray,
    st_f: FloatArray,
    use_mean: bool,
    ends: IntArray,
    peaks: FloatArray,
    bads: NDArray[np.bool_],
    frozen_end: IntArray,
    hits: IntArray,
) -> tuple[int, int]:
    """One pass over a chunk: revolution ends (first sample of each new revolution, integer
    spindle angle so chunking cannot move them), each ended revolution's peak, whether it held
    a non-finite sample, how long the signal had been frozen at its last sample; and the
    samples where a bit-identical non-zero value has repeated ``n_stall`` times. State carried
    in ``st_i`` = [angle, frozen run, samples in the running revolution] and ``st_f`` =
    [running peak, last sample, bad flag, running sum]; with ``use_mean`` the revolution's mean
    is reported instead of its peak."""
    angle = st_i[0]
    cnt = st_i[1]
    run_max = st_f[0]
    last = st_f[1]
    run_bad = st_f[2] != 0.0
    run_sum = st_f[3]
    run_n = st_i[2]
    n_end = 0
    n_hit = 0
    for k in range(q.size):
        s = speed[k]
        ok_s = np.isfinite(s)
        inc = np.int64(np.round(abs(s) * scale)) if ok_s else np.int64(0)
        new = angle + inc
        if (new >> 32) > (angle >> 32):
            ends[n_end] = k
            if use_mean:
                peaks[n_end] = abs(run_sum / run_n) if run_n > 0 else -np.inf
            else:
                peaks[n_end] = run_max
            bads[n_end] = run_bad
            frozen_end[n_end] = cnt
            n_end += 1
            run_max = -np.inf
            run_bad = False
            run_sum = 0.0
            run_n = 0
        angle = new
        v = q[k]
        fin = np.isfinite(v)
        if fin and ok_s:
            if v > run_max:
                run_max = v
            run_sum += v
            run_n += 1
        else:
            run_bad = True
        if fin and v != 0.0 and v == last:
            cnt += 1
        else:
            cnt = 0
        last = v
        if cnt == n_stall:
            hits[n_hit] = k
            n_hit += 1
    st_i[0] = angle
    st_i[1] = cnt
    st_f[0] = run_max
    st_f[1] = last
    st_f[2] = 1.0 if run_bad else 0.0
    st_f[3] = run_sum
    st_i[2] = run_n
    return n_end, n_hit
