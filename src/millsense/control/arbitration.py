"""Arbitration of the on-line monitors and controllers, and the safety layer (seed 000 §6.5,
Fig. 6.16; issue 16 item 4).

:class:`Supervisor` is a composite :class:`~millsense.streaming.block.Block`: it runs its
children (chatter monitor or chatter avoidance, breakage monitor, adaptive feed control, in
any order; each sees the chunk plus the earlier children's outputs, as in a pipeline; on a
chunk of several control periods they run ahead of the decisions where nothing pending acts on
them, decision 1671), passes
their channels and ALARM/NOTE events on, and is the only block that sends OVERRIDE events to
the machine. Once per control period (10 ms by default, aligned on absolute sample indices so
that the decisions do not depend on how the stream is cut into chunks) it decides, with seed
000's priorities (decision 1621):

1. **chatter first** — while a chatter episode is open (a ``chatter`` alarm not yet followed
   by ``chatter_end``), ``spindle_override`` proposals pass and the feed may fall but not
   rise (the adaptive controller's ceiling is its override at the onset);
2. **then breakage if stable** — a ``breakage`` alarm with no chatter open gives a feed hold
   at once (CRITICAL) that latches for the rest of the run; a breakage alarm during chatter,
   or within ``rejudge_s`` after its end (the speed change settling), is not acted on: the
   chatter corrupts the tooth-period torque the detector judges. Instead the breakage
   monitors are re-armed when the episode has closed and settled (``rearm``), so a tool that
   is still broken alarms again on the torque it then cuts with;
3. **then adaptive control if chatter-free and intact** — ``feed_override`` proposals pass.

The safety layer: the source's fault channel (``guard/fault`` of
:class:`~millsense.online.guard.GuardedSource`: NaNs, a dropped chunk, a stalled stream) turns
into the safe action within one control period — the
feed at min(override, 100 %) and an ALARM; where breakage is possible (a breakage monitor is
running and the tool is in cut, or nothing says it is not) a feed hold instead. The feed is
never raised by a fault (decision 1615), and it is not raised again before the input has
been clean for ``fault_clear_s`` (0.1 s). A controller's own input faults
(``adaptive_feed_fault``) are its own safe action (decision 1615), which passes as a proposal
like any other.

The operator (the live dashboard, issue 19; decision 1902) acts through two thread-safe
requests taken at the next control period: :meth:`Supervisor.request_control` switches the
control off (the feed and spindle overrides back to 100 %, the programmed values; the
adaptive feed and the chatter avoidance then only propose) or on again, and
:meth:`Supervisor.acknowledge` records that an alarm was seen. Safety stays on with the
control off (a breakage or a fault still holds the feed), and an acknowledgement does not
release a feed hold: both are NOTE events in the log.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.core.units import MM
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
from millsense.streaming.sources import SOURCE_FAULTS

#: Modes of the supervisor (its ``/mode`` channel).
MODE_NORMAL, MODE_CHATTER, MODE_FAULT, MODE_HOLD = 0, 1, 2, 3


@dataclass(frozen=True)
class SupervisorOptions:
    """Settings of :class:`Supervisor`.

    Attributes
    ----------
    period_s : control period, s (the decisions fall on whole periods of absolute samples;
        10 ms: one CNC interpolation block of seed 000's 100 Hz loop).
    hold_on_breakage : send a feed hold on a breakage alarm (else an alarm only).
    hold_on_fault : a fault where breakage is possible gives a feed hold (else the feed at
        min(override, 100 %)).
    chatter_timeout_s : a chatter episode with no ``chatter_end`` closes after this long
        without a new chatter alarm (a monitor that stopped reporting must not freeze the
        feed for ever).
    fault_clear_s : a source fault clears after this long without a faulty sample (a burst
        of NaNs or a flickering link must not let the feed rise in between).
    rejudge_s : after a chatter episode closes, breakage alarms are still set aside for this
        long; then the breakage monitors are re-armed.
    """

    period_s: float = 0.01
    hold_on_breakage: bool = True
    hold_on_fault: bool = True
    chatter_timeout_s: float = 5.0
    fault_clear_s: float = 0.1
    rejudge_s: float = 0.3

    def __post_init__(self) -> None:
        if not (self.period_s > 0 and math.isfinite(self.period_s)):
            raise ConfigError(f"supervisor: period_s must be > 0, got {self.period_s!r}")
        if not (self.chatter_timeout_s > 0 and self.fault_clear_s >= 0):
            raise ConfigError("supervisor: chatter_timeout_s > 0 and fault_clear_s ≥ 0 needed")


class Supervisor(Block):
    """Runs monitor and controller children and arbitrates their commands (see the module).

    Parameters
    ----------
    children : blocks run in order on every chunk (names must differ).
    options : :class:`SupervisorOptions`.
    fault_channel : per-sample fault code of the source (0 = good), or None.
    in_cut_channel : per-sample 1/0 "the plan says the tool is in cut", or None (unknown:
        breakage is taken as possible).
    location_channels : per-sample NC line and tool-centre x, y, z (m), e.g. the plan sync's
        ``plan/nc_line`` and ``tcp/x|y|z``, or None: a child's event that does not say where on
        the tool path it happened is given the values at its sample (decision 1715).
    name : block name (channel prefix, event source).

    Outputs: ``{name}/feed_override`` and ``{name}/spindle_override`` (commanded, fraction;
    NaN for the spindle until a spindle command), ``{name}/mode`` (0 normal, 1 chatter,
    2 fault, 3 feed hold), plus every child's channels. Events: the children's ALARM and NOTE
    events; OVERRIDE events only from the supervisor (``feed_override``, ``spindle_override``,
    ``feed_hold``), each naming the child whose proposal it carries; ALARMs ``input_fault``,
    NOTEs of suppressed proposals are not written (they would flood the log): the ``/mode``
    channel shows why a proposal did not pass.
    """

    def __init__(
        self,
        children: Sequence[Block],
        options: SupervisorOptions | None = None,
        *,
        fault_channel: str | None = "guard/fault",
        in_cut_channel: str | None = "plan/in_cut",
        location_channels: tuple[str, str, str, str] | None = None,
        name: str = "supervisor",
    ) -> None:
        self.children = list(children)
        names = [c.name for c in self.children]
        if len(set(names)) != len(names) or name in names:
            raise ConfigError(f"supervisor: child names must be unique, got {names}")
        self.opts = options or SupervisorOptions()
        self.name = name
        self.fault_channel = fault_channel
        self.in_cut_channel = in_cut_channel
        produced: set[str] = set()
        ins: list[str] = []
        for c in self.children:
            ins += [i for i in c.inputs if i not in produced]
            produced.update(info.name for info in c.output_channels())
        ins += [i for i in (fault_channel, in_cut_channel) if i is not None]
        self.location_channels = location_channels
        ins += [i for i in location_channels or () if i not in produced]
        self.inputs = tuple(dict.fromkeys(ins))
        self.reads_truth = any(c.reads_truth for c in self.children)
        # a breakage monitor is a child that can be re-armed (BreakageBlock.rearm)
        self.breakage_possible = any(hasattr(c, "rearm") for c in self.children)
        self._operator: deque[tuple[str, tuple[str, float] | bool]] = deque()
        self.reset(10000.0)

    # ------------------------------------------------------------------ contract
    def output_channels(self) -> list[ChannelInfo]:
        own = [
            ChannelInfo(f"{self.name}/feed_override", "1", "commanded feed override (fraction)"),
            ChannelInfo(
                f"{self.name}/spindle_override", "1", "commanded spindle override (fraction)"
            ),
            ChannelInfo(f"{self.name}/mode", "1", "0 normal, 1 chatter, 2 fault, 3 feed hold"),
        ]
        return own + [info for c in self.children for info in c.output_channels()]

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        self.period = max(1, round(self.opts.period_s * self.fs))
        for c in self.children:
            c.reset(sample_rate_hz)
        # the adaptive children's ceilings (looked up once a stream, not at every decision)
        self._setters = [
            s for s in (getattr(c, "set_ceiling", None) for c in self.children) if s is not None
        ]
        # children the decisions act on: 2 an adaptive controller (set_ceiling), 1 a breakage
        # monitor (rearm), 0 none; ahead of the decisions only in that order (decision 1671)
        kinds = [
            2 if hasattr(c, "set_ceiling") else 1 if hasattr(c, "rearm") else 0
            for c in self.children
        ]
        self._ahead_ok = kinds == sorted(kinds)
        self.feed = 1.0
        self.spindle = math.nan
        self.mode = MODE_NORMAL
        self._own = tuple(f"{self.name}/{c}" for c in ("feed_override", "spindle_override", "mode"))
        self._held_key: tuple[float, float, float] | None = None
        self._held_views: HeldViews | None = None
        self._defer_to = 0  # decisions before this sample of the chunk defer the ceilings
        self._stop = 0
        self.chatter_open = False
        self.chatter_last_s = -math.inf
        self.breakage_pending: Event | None = None
        self.rejudge_at: float | None = None  # time the breakage monitors are re-armed
        self.held = False
        self.fault = False
        self.in_cut = True
        self._pending: list[Event] = []
        self._fault_seen = 0
        self._fault_sample = -1
        self._fault_last = -1
        self._clear = round(self.opts.fault_clear_s * self.fs)
        self.control = True
        self._operator.clear()

    # ------------------------------------------------------------------ the operator
    def request_control(self, enabled: bool) -> None:
        """Switch the control on or off at the next control period (any thread). Off: the
        feed and spindle overrides go back to 100 % and no controller's proposal passes
        until it is on again; the safety actions (breakage, faults) stay."""
        self._operator.append(("control", bool(enabled)))

    def acknowledge(self, name: str, time_s: float) -> None:
        """Record at the next control period that the operator saw the alarm ``name`` raised
        at ``time_s`` (any thread); a feed hold stays."""
        self._operator.append(("ack", (str(name), float(time_s))))

    def _operator_requests(self, t: float, k: int, events: list[Event]) -> None:
        while self._operator:
            _, arg = self._operator.popleft()
            if isinstance(arg, tuple):  # an acknowledgement
                name, at = arg
                events.append(Event(t, EventKind.NOTE, self.name,
                                    f"{name} alarm of {at:.3f} s acknowledged by the operator",
                                    name="alarm_acknowledged", sample=k,
                                    values={"alarm_s": at}))  # fmt: skip
            elif bool(arg) != self.control:
                self.control = bool(arg)
                state = "on" if self.control else "off: overrides back to 100 %"
                events.append(Event(t, EventKind.NOTE, self.name,
                                    f"control {state} (operator)",
                                    name="control_on" if self.control else "control_off",
                                    sample=k, severity=Severity.WARNING))  # fmt: skip
                if not self.control and not self.held:
                    if abs(self.feed - 1.0) > 1e-12:
                        self._feed(t, k, 1.0, None, events, "operator: control off")
                    if math.isfinite(self.spindle) and abs(self.spindle - 1.0) > 1e-12:
                        self.spindle = 1.0
                        events.append(Event(t, EventKind.OVERRIDE, self.name,
                                            "spindle override 100.0 % (operator: control off)",
                                            name="spindle_override", value=100.0, sample=k,
                                            severity=Severity.WARNING))  # fmt: skip

    # ------------------------------------------------------------------ streaming
    def process(self, chunk: Chunk) -> BlockOutput:
        n = chunk.n
        events: list[Event] = []
        d = chunk.data
        # the source's fault codes are looked at piece by piece only in a chunk that has a
        # faulty sample; the plan's in-cut flag is read at each piece's last sample (the
        # decisions fall period by period, decision 1654; the children run ahead of them over
        # the chunk where nothing pending acts on them, decision 1671)
        # (any sample non-zero, NaN included: counted, without a reduction set up)
        faulty = self.fault_channel is not None and bool(np.count_nonzero(d[self.fault_channel]))
        in_cut = None if self.in_cut_channel is None else d[self.in_cut_channel]
        a = chunk.start
        if 0 < n <= self.period - a % self.period:
            # a chunk within one control period (10 ms chunks on 10 ms periods): one piece,
            # the children's arrays passed on as they are, as the pipeline passes a block's
            # outputs; the overrides and the mode held over it are those before its decision
            channels = {}
            for res in self._children(chunk, events):
                channels.update(res)
            held = (self.feed, self.spindle, float(self.mode))
            self._after_piece(chunk, chunk, n, faulty, in_cut, events)
            feed, spindle, mode = self._held_outputs(held, n)
        else:
            held_out = _HeldRuns(n)
            ahead = self._run_ahead(chunk) if self._ahead_ok and not faulty and self._calm() else []
            # the adaptive children have run ahead to here: the decisions before it do not
            # tell them their ceilings (in calm periods a call that would change nothing), the
            # decision at its end does (decision 1671)
            self._defer_to = min(
                (r.end for r, c in zip(ahead, self.children, strict=False)
                 if hasattr(c, "set_ceiling")), default=0,
            )  # fmt: skip
            parts: list[dict[str, list[np.ndarray]]] = [{} for _ in self.children]
            # every child ran ahead over the whole chunk without an event: its periods have
            # nothing to hand the decisions
            quiet = len(ahead) == len(self.children) and all(
                r.end == n and not r.events for r in ahead
            )
            pos = 0
            while pos < n:
                stop = min(n, pos + self.period - (a + pos) % self.period)
                self._stop = stop
                if not quiet:
                    self._pieces(chunk, pos, stop, events, ahead, parts)
                held_out.hold(pos, self.feed, self.spindle, self.mode)
                piece = _slice(chunk, pos, stop) if faulty else chunk
                self._after_piece(chunk, piece, stop, faulty, in_cut, events)
                pos = stop
            self._defer_to = 0
            feed, spindle, mode = held_out.rows()
            channels = {}
            for i, got in enumerate(parts):
                early = ahead[i].channels if i < len(ahead) else {}
                for k, v in early.items():
                    channels[k] = np.concatenate([v, *got[k]]) if k in got else v
                for k, vs in got.items():
                    if k not in early:
                        channels[k] = vs[0] if len(vs) == 1 else np.concatenate(vs)
        channels[f"{self.name}/feed_override"] = feed
        channels[f"{self.name}/spindle_override"] = spindle
        channels[f"{self.name}/mode"] = mode
        return BlockOutput(channels, events)

    def _held_outputs(
        self, held: tuple[float, float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The feed and spindle overrides and the mode held over a chunk of ``n`` samples, as
        views of one array never written again (new ones only when a value or ``n``
        changes)."""
        cached = self._held_views
        if cached is None or cached[0] != n or self._held_key != held:
            self._held_key = held
            cached = self._held_views = held_views(self._own, np.array(held), None, n)[0]
        v = cached[1]
        return v[self._own[0]], v[self._own[1]], v[self._own[2]]

    def _children(self, piece: Chunk, events: list[Event]) -> list[dict[str, np.ndarray]]:
        """Run the children on one piece (each sees the piece and the earlier children's
        outputs); their channels, child by child; their events gathered for the next
        decision."""
        data = dict(piece.data)
        channels: list[dict[str, np.ndarray]] = []
        start, rate, t0 = piece.start, piece.sample_rate_hz, piece.t0_s
        for c in self.children:
            res = c.process(Chunk(start, rate, t0, {k: data[k] for k in c.inputs}))
            data.update(res.channels)
            channels.append(res.channels)
            if res.events:
                self._gather(self._located(res.events, start, data), events)
        return channels

    def _located(
        self, child_events: Sequence[Event], start: int, data: Mapping[str, np.ndarray]
    ) -> list[Event]:
        """The events, those without an NC line or a position given the location channels'
        values at their sample (clipped into the chunk that starts at ``start``; decision
        1715): seed 000's monitors report where on the tool path an alarm happened, and the
        session's blocks judge the plan's channels, not the plan."""
        if self.location_channels is None or not child_events:
            return list(child_events)
        cols = [data.get(c) for c in self.location_channels]
        if any(c is None or len(c) == 0 for c in cols):
            return list(child_events)
        n = len(cols[0])  # type: ignore[arg-type]
        out = []
        for ev in child_events:
            if ev.nc_line is not None and ev.x_mm is not None:
                out.append(ev)
                continue
            i = min(max((ev.sample if ev.sample is not None else start) - start, 0), n - 1)
            nc, x, y, z = (float(c[i]) for c in cols)  # type: ignore[index]
            line = ev.nc_line if ev.nc_line is not None else (int(nc) if nc >= 0 else None)
            pos = (x, y, z) if all(math.isfinite(v) for v in (x, y, z)) else None
            out.append(replace(
                ev, nc_line=line,
                x_mm=ev.x_mm if ev.x_mm is not None or pos is None else pos[0] / MM,
                y_mm=ev.y_mm if ev.y_mm is not None or pos is None else pos[1] / MM,
                z_mm=ev.z_mm if ev.z_mm is not None or pos is None else pos[2] / MM,
            ))  # fmt: skip
        return out

    def _gather(self, child_events: Sequence[Event], events: list[Event]) -> None:
        """A child's events for the next decision; its ALARM and NOTE events passed on (its
        OVERRIDE proposals only through the decision)."""
        self._pending.extend(child_events)
        events.extend(ev for ev in child_events if ev.kind is not EventKind.OVERRIDE)

    def _calm(self) -> bool:
        """Nothing the decisions of the coming periods do to the children is pending: no
        chatter episode or its settling, no fault, no breakage alarm waiting (decided or still
        to be, from the end of the last chunk), the control on and no operator request queued
        (decision 1671)."""
        return not (
            any(_acts_on_children(e) for e in self._pending)
            or self.chatter_open
            or self.rejudge_at is not None
            or self.fault
            or self._fault_seen
            or self.breakage_pending is not None
            or not self.control
            or self._operator
        )

    def _run_ahead(self, chunk: Chunk) -> list[_Ahead]:
        """The children run on a chunk of several control periods before its decisions
        (decision 1671): while no decision acts on them, their outputs over the chunk are
        those of period-by-period runs (chunk-size invariance), so each child runs once, as far
        as the decisions allow: an event that changes what the decisions do to the children
        (a chatter alarm or its end, a breakage alarm) stops every later child at the end of
        its control period; the periods after it run one by one (:meth:`_pieces`). Exact given
        the children's order (monitors, then breakage monitors, then adaptive controllers) and
        events whose ``sample`` lies in the chunk they came from."""
        n, a = chunk.n, chunk.start
        limit = n
        data = dict(chunk.data)
        out: list[_Ahead] = []
        for c in self.children:
            sub = {k: data[k] if limit == n else data[k][:limit] for k in c.inputs}
            res = c.process(Chunk(a, chunk.sample_rate_hz, chunk.t0_s, sub))
            data.update(res.channels)
            out.append(_Ahead(dict(res.channels), self._located(res.events, a, data), limit))
            for ev in res.events:
                if _acts_on_children(ev):
                    s = min(max((ev.sample if ev.sample is not None else a) - a, 0), limit - 1)
                    limit = min(limit, s + self.period - (a + s) % self.period)
        return out

    def _pieces(
        self,
        chunk: Chunk,
        pos: int,
        stop: int,
        events: list[Event],
        ahead: list[_Ahead],
        parts: list[dict[str, list[np.ndarray]]],
    ) -> None:
        """One control period of a chunk: each child's events in it (from its run ahead, or
        from running it on the piece where its run ahead stopped earlier), gathered for the
        decision as :meth:`_children` does."""
        data: dict[str, np.ndarray] | None = None
        piece = chunk
        end = chunk.start + stop if stop < chunk.n else None  # the last piece takes them all
        for i, c in enumerate(self.children):
            early = ahead[i] if i < len(ahead) else None
            if early is not None and stop <= early.end:
                evs = early.take(end)
                if data is not None:
                    data.update({k: v[pos:stop] for k, v in early.channels.items()})
            else:
                if data is None:
                    piece = _slice(chunk, pos, stop)
                    data = dict(piece.data)
                    for j in range(i):
                        prior = ahead[j] if j < len(ahead) else None
                        if prior is not None and stop <= prior.end:
                            data.update({k: v[pos:stop] for k, v in prior.channels.items()})
                        else:
                            data.update({k: v[-1] for k, v in parts[j].items()})
                res = c.process(Chunk(piece.start, piece.sample_rate_hz, piece.t0_s,
                                      {k: data[k] for k in c.inputs}))  # fmt: skip
                data.update(res.channels)
                for k, v in res.channels.items():
                    parts[i].setdefault(k, []).append(np.asarray(v))
                evs = res.events
            self._gather(evs, events)

    def _after_piece(
        self,
        chunk: Chunk,
        piece: Chunk,
        stop: int,
        faulty: bool,
        in_cut: np.ndarray | None,
        events: list[Event],
    ) -> None:
        """The faults and the in-cut flag of a piece ending at sample ``stop`` of ``chunk``,
        and the decision when the piece ends a control period."""
        if faulty:
            self._watch_faults(piece)
        if in_cut is not None:
            last = float(in_cut[stop - 1])
            if math.isfinite(last):
                self.in_cut = last > 0.5
        if (chunk.start + stop) % self.period == 0:
            self._decide(chunk, stop, events)

    def _watch_faults(self, piece: Chunk) -> None:
        assert self.fault_channel is not None
        f = np.asarray(piece.data[self.fault_channel])
        bad = np.flatnonzero(f != 0)
        if bad.size:
            self._fault_last = piece.start + int(bad[-1])
            if self._fault_seen == 0:
                self._fault_seen = int(f[bad[0]])
                self._fault_sample = piece.start + int(bad[0])

    # ------------------------------------------------------------------ decisions
    def _decide(self, chunk: Chunk, e: int, events: list[Event]) -> None:
        """One decision at the end of a control period (sample ``e`` of ``chunk``)."""
        t = chunk.t0_s + (chunk.start + e) / chunk.sample_rate_hz
        k = chunk.start + e
        pending, self._pending = self._pending, []
        feed_prop: Event | None = None
        spindle_prop: Event | None = None
        for ev in pending:  # in time order within the period
            if ev.name == "chatter" and ev.kind is EventKind.ALARM:
                self.chatter_open = True
                self.chatter_last_s = ev.time_s
            elif ev.name == "chatter_end":
                if self.chatter_open:
                    self.rejudge_at = ev.time_s + self.opts.rejudge_s
                self.chatter_open = False
            elif ev.name == "breakage" and ev.kind is EventKind.ALARM:
                if self.chatter_open or self.rejudge_at is not None:
                    events.append(Event(t, EventKind.NOTE, self.name,
                                        f"breakage alarm of {ev.source} at {ev.time_s:.3f} s set "
                                        "aside: chatter; the monitor is re-armed once stable",
                                        name="breakage_set_aside", sample=k))  # fmt: skip
                elif self.breakage_pending is None:
                    self.breakage_pending = ev
            elif ev.kind is EventKind.OVERRIDE and ev.name == "feed_override":
                feed_prop = ev
            elif ev.kind is EventKind.OVERRIDE and ev.name == "spindle_override":
                spindle_prop = ev
        self._operator_requests(t, k, events)
        if not self.control:  # the controllers only propose
            feed_prop = spindle_prop = None
        if self.chatter_open and t - self.chatter_last_s > self.opts.chatter_timeout_s:
            self.chatter_open = False
            self.rejudge_at = t + self.opts.rejudge_s
        if self.rejudge_at is not None and not self.chatter_open and t >= self.rejudge_at:
            self.rejudge_at = None
            for c in self.children:
                rearm = getattr(c, "rearm", None)
                if rearm is not None:
                    rearm()
        if self.held:
            self.mode = MODE_HOLD
            return
        # safety: a fault of the source
        if self._fault_seen:
            code, at = self._fault_seen, self._fault_sample
            self._fault_seen = 0
            self._on_fault(chunk, t, k, code, at, events)
            if self.held:
                return
        elif self.fault and k - 1 - self._fault_last >= self._clear:
            # fault_clear_s without a faulty sample: the fault clears
            self.fault = False
            self._fault_sample = -1
            events.append(Event(t, EventKind.NOTE, self.name, "input fault cleared",
                                name="input_fault_cleared", sample=k))  # fmt: skip
        # 1. chatter
        if spindle_prop is not None:
            self._spindle(t, k, spindle_prop, events)
        # 2. breakage, once stable
        if self.breakage_pending is not None:
            self._hold_for_breakage(t, k, self.breakage_pending, events)
            return
        # 3. adaptive control
        if feed_prop is not None and feed_prop.value is not None:
            u = float(feed_prop.value) / 100.0
            if self._unsettled() or self.fault:
                u = min(u, self.feed)  # may fall, never rise
            if abs(u - self.feed) > 1e-12:
                self._feed(t, k, u, feed_prop, events)
        self._set_ceilings()
        self.mode = MODE_FAULT if self.fault else (MODE_CHATTER if self._unsettled() else 0)

    def _unsettled(self) -> bool:
        """A chatter episode is open or has not settled for ``rejudge_s``."""
        return self.chatter_open or self.rejudge_at is not None

    def _on_fault(
        self, chunk: Chunk, t: float, k: int, code: int, at: int, events: list[Event]
    ) -> None:
        """The safe action for a source fault (decision 1621)."""
        why = SOURCE_FAULTS.get(code, f"fault {code}")
        t_at = chunk.t0_s + at / chunk.sample_rate_hz
        first = not self.fault
        self.fault = True
        if self.opts.hold_on_fault and self.breakage_possible and self.in_cut:
            events.append(Event(t, EventKind.ALARM, self.name,
                                f"input fault at {t_at:.4f} s ({why}) while breakage is possible: "
                                "feed hold", name="input_fault", value=float(code), sample=k,
                                severity=Severity.CRITICAL, values={"fault_s": t_at}))  # fmt: skip
            self._hold(t, k, "input fault: breakage could go unseen", events)
            return
        if first:
            events.append(Event(t, EventKind.ALARM, self.name,
                                f"input fault at {t_at:.4f} s ({why}): feed at "
                                f"{100 * min(self.feed, 1.0):.0f} %, not raised until the input "
                                "is clean", name="input_fault", value=float(code), sample=k,
                                severity=Severity.WARNING, values={"fault_s": t_at}))  # fmt: skip
        if self.feed > 1.0:
            self._feed(t, k, 1.0, None, events)
        self._set_ceilings()
        self.mode = MODE_FAULT

    def _spindle(self, t: float, k: int, prop: Event, events: list[Event]) -> None:
        assert prop.value is not None
        self.spindle = float(prop.value) / 100.0
        events.append(Event(t, EventKind.OVERRIDE, self.name,
                            f"spindle override {prop.value:.1f} % ({prop.source}: "
                            f"{prop.message})", name="spindle_override", value=prop.value,
                            sample=k, severity=prop.severity, values=dict(prop.values),
                            nc_line=prop.nc_line, x_mm=prop.x_mm, y_mm=prop.y_mm,
                            z_mm=prop.z_mm))  # fmt: skip

    def _feed(
        self,
        t: float,
        k: int,
        u: float,
        prop: Event | None,
        events: list[Event],
        why: str = "safety",
    ) -> None:
        self.feed = u
        # the proposal's own line says which of its rules set the override (decision 1555);
        # applied as proposed, it is the line (it names its source and value already)
        if prop is not None and prop.value is not None and abs(prop.value - 100.0 * u) < 0.05:
            line = prop.message
        else:
            src = f"{prop.source}: {prop.message}" if prop is not None else why
            line = f"feed override {100 * u:.1f} % ({src})"
        events.append(Event(t, EventKind.OVERRIDE, self.name, line, name="feed_override",
                            value=100.0 * u, sample=k,
                            severity=prop.severity if prop is not None else Severity.WARNING,
                            values=dict(prop.values) if prop is not None else {},
                            nc_line=prop.nc_line if prop is not None else None,
                            x_mm=prop.x_mm if prop is not None else None,
                            y_mm=prop.y_mm if prop is not None else None,
                            z_mm=prop.z_mm if prop is not None else None))  # fmt: skip

    def _hold_for_breakage(self, t: float, k: int, alarm: Event, events: list[Event]) -> None:
        self.breakage_pending = None
        if not self.opts.hold_on_breakage:
            return
        late = t - alarm.time_s
        self._hold(t, k, f"breakage ({alarm.source}, {late * 1000:.0f} ms after its alarm)",
                   events, alarm)  # fmt: skip

    def _hold(
        self, t: float, k: int, why: str, events: list[Event], cause: Event | None = None
    ) -> None:
        self.held = True
        self.mode = MODE_HOLD
        self._set_ceilings()
        events.append(Event(t, EventKind.OVERRIDE, self.name, f"feed hold: {why}",
                            name="feed_hold", value=1.0, sample=k, severity=Severity.CRITICAL,
                            values=dict(cause.values) if cause is not None else {},
                            nc_line=cause.nc_line if cause is not None else None,
                            x_mm=cause.x_mm if cause is not None else None,
                            y_mm=cause.y_mm if cause is not None else None,
                            z_mm=cause.z_mm if cause is not None else None))  # fmt: skip

    def _set_ceilings(self) -> None:
        """Tell adaptive children how far they may go: nothing above the commanded feed while
        chatter, a fault or a hold stands (their own state then follows what was sent)."""
        if self._stop < self._defer_to:
            return
        limit: float | None = None
        if self.held:
            limit = 0.0
        elif self._unsettled() or self.fault or not self.control:
            limit = self.feed
        for setter in self._setters:
            setter(limit, self.feed)


class _HeldRuns:
    """The feed and spindle overrides and the mode over a chunk of several control periods,
    each value held from the period it was set in (written once per run of equal values, not
    once per period)."""

    __slots__ = ("out", "since", "values")

    def __init__(self, n: int) -> None:
        self.out = np.empty((3, n))
        self.since = 0
        self.values: tuple[float, float, float] | None = None

    def hold(self, pos: int, feed: float, spindle: float, mode: float) -> None:
        """``feed``, ``spindle`` and ``mode`` from sample ``pos`` on."""
        values = (feed, spindle, mode)
        if values != self.values:  # (a NaN spindle may compare unequal: one more write)
            self._write(pos)
            self.since = pos
            self.values = values

    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The three outputs, the last values held to the end of the chunk."""
        self._write(self.out.shape[1])
        return self.out[0], self.out[1], self.out[2]

    def _write(self, stop: int) -> None:
        if self.values is not None and stop > self.since:
            a, out = self.since, self.out
            out[0, a:stop], out[1, a:stop], out[2, a:stop] = self.values


class _Ahead:
    """A child's run ahead over a chunk's first ``end`` samples: its channels and the events
    not yet given to a decision."""

    __slots__ = ("channels", "end", "events")

    def __init__(self, channels: dict[str, np.ndarray], events: list[Event], end: int) -> None:
        self.channels = channels
        self.events = events
        self.end = end

    def take(self, before: int | None) -> list[Event]:
        """The events whose sample is before ``before`` (absolute; None: all), in their order;
        an event without a sample goes with the first period."""
        if not self.events:
            return []
        if before is None:
            now, self.events = self.events, []
            return now
        now = [e for e in self.events if e.sample is None or e.sample < before]
        if now:
            self.events = [e for e in self.events if not (e.sample is None or e.sample < before)]
        return now


def _acts_on_children(ev: Event) -> bool:
    """An event whose decision acts on the children: a chatter alarm (the adaptive ceiling),
    a chatter episode's end (the breakage monitors re-armed after it settles), a breakage alarm
    (the feed hold)."""
    if ev.name == "chatter_end":
        return True
    return ev.kind is EventKind.ALARM and ev.name in ("chatter", "breakage")


def _slice(chunk: Chunk, a: int, b: int) -> Chunk:
    if a == 0 and b == chunk.n:
        return chunk
    data = {k: v[a:b] for k, v in chunk.data.items()}
    return Chunk(chunk.start + a, chunk.sample_rate_hz, chunk.t0_s, data)
