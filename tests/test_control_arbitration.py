"""The supervisor's priorities and safety layer (issue 16 item 4; seed 000 Fig. 6.16;
decision 1621) on scripted children: every rule is checked on the events it sends, and the
decisions do not depend on the chunking."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.control.arbitration import (
    MODE_CHATTER,
    MODE_FAULT,
    MODE_HOLD,
    MODE_NORMAL,
    Supervisor,
    SupervisorOptions,
)
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind, Severity

FS = 10000.0


class Scripted(Block):
    """Emits the scripted events (sample → (kind, name, value)) when their sample passes."""

    def __init__(self, name: str, script: dict[int, tuple[EventKind, str, float | None]]):
        self.name = name
        self.script = script
        self.inputs = ("sig",)
        self.ceilings: list[tuple[int, float | None, float]] = []
        self.rearmed: list[int] = []
        self._pos = 0

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(f"{self.name}/echo", "1", "input echoed")]

    def reset(self, sample_rate_hz: float) -> None:
        self._pos = 0
        self.ceilings = []
        self.rearmed = []

    def set_ceiling(self, ceiling: float | None, commanded: float) -> None:
        self.ceilings.append((self._pos, ceiling, commanded))

    def process(self, chunk: Chunk) -> BlockOutput:
        ev = []
        for k in range(chunk.start, chunk.start + chunk.n):
            if k in self.script:
                kind, name, value = self.script[k]
                ev.append(Event(k / FS, kind, self.name, name, name=name, value=value, sample=k))
        self._pos = chunk.start + chunk.n
        return BlockOutput({f"{self.name}/echo": np.asarray(chunk.data["sig"]) * 2}, ev)


class ScriptedBreakage(Scripted):
    """A scripted breakage monitor: it can be re-armed (what makes the supervisor count it as
    a breakage monitor, as BreakageBlock)."""

    def rearm(self) -> None:
        self.rearmed.append(self._pos)


def _run(
    sup: Supervisor,
    n: int,
    chunk: int,
    fault: np.ndarray | None = None,
    in_cut: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], list[Event]]:
    sup.reset(FS)
    data = {
        "sig": np.arange(n, dtype=float),
        "guard/fault": np.zeros(n) if fault is None else fault,
        "plan/in_cut": np.ones(n) if in_cut is None else in_cut,
    }
    outs: dict[str, list[np.ndarray]] = {}
    events: list[Event] = []
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        res = sup.process(Chunk(a, FS, 0.0, {k: v[a:b] for k, v in data.items()}))
        for k, v in res.channels.items():
            outs.setdefault(k, []).append(v)
        events += res.events
    return {k: np.concatenate(v) for k, v in outs.items()}, events


def _overrides(events: list[Event]) -> list[tuple[int, str, float | None]]:
    return [(e.sample, e.name, e.value) for e in events if e.kind is EventKind.OVERRIDE]


OVR, ALM, NOTE = EventKind.OVERRIDE, EventKind.ALARM, EventKind.NOTE


def _children() -> list[Block]:
    chatter = Scripted("chatter", {
        2050: (ALM, "chatter", 600.0),
        2060: (OVR, "spindle_override", 112.0),
        4000: (NOTE, "chatter_end", None),
    })  # fmt: skip
    breakage = ScriptedBreakage("breakage", {
        3000: (ALM, "breakage", None),  # during chatter: set aside
        7500: (ALM, "breakage", None),  # re-armed, still broken: acted on
    })  # fmt: skip
    adaptive = Scripted("adaptive_feed", {
        1005: (OVR, "feed_override", 130.0),
        2500: (OVR, "feed_override", 140.0),  # during chatter: not raised
        2600: (OVR, "feed_override", 90.0),  # during chatter: may fall
        5000: (OVR, "feed_override", 120.0),  # while re-judging (chatter mode): no rise
    })  # fmt: skip
    return [chatter, breakage, adaptive]


def test_priorities_chatter_then_breakage_then_adaptive() -> None:
    """Seed 000 Fig. 6.16: the feed may fall but not rise during chatter; a breakage alarm
    during chatter is set aside and the breakage monitor re-armed 0.3 s after the episode's end
    (decision 1621); the alarm it raises then gives a feed hold that latches; every decision
    falls on the next 10 ms boundary (100 samples)."""
    kids = _children()
    sup = Supervisor(kids, fault_channel="guard/fault", in_cut_channel="plan/in_cut")
    ch, events = _run(sup, 8000, 100)
    assert _overrides(events) == [
        (1100, "feed_override", 130.0),  # adaptive, next boundary after 1005
        (2100, "spindle_override", 112.0),  # chatter remedy passes
        (2700, "feed_override", 90.0),  # a fall during chatter passes; 140 % at 2500 did not
        (7600, "feed_hold", 1.0),  # the re-armed monitor's alarm (7500); 5000's 120 % refused
    ]
    mode = ch["supervisor/mode"]
    assert mode[1500] == MODE_NORMAL and mode[2500] == MODE_CHATTER and mode[7700] == MODE_HOLD
    assert mode[6500] == MODE_CHATTER  # the 0.3 s after the episode: still not stable
    assert [e.sample for e in events if e.name == "breakage_set_aside"] == [3100]
    breakage = kids[1]
    assert isinstance(breakage, ScriptedBreakage) and breakage.rearmed == [7000]
    assert ch["supervisor/feed_override"][1200] == pytest.approx(1.3)
    assert ch["supervisor/spindle_override"][2200] == pytest.approx(1.12)
    assert math.isnan(ch["supervisor/spindle_override"][100])
    assert np.array_equal(ch["adaptive_feed/echo"], 2 * np.arange(8000.0))  # children's outputs
    alarms = [e.name for e in events if e.kind is EventKind.ALARM]
    assert alarms == ["chatter", "breakage", "breakage"]  # passed on unchanged
    # an override applied as proposed carries the proposal's own line once (it names its
    # source and value); one applied otherwise says what it was and where it came from
    lines = {e.sample: e.message for e in events if e.kind is EventKind.OVERRIDE}
    assert lines[1100] == "feed_override"  # the scripted proposal's line, not repeated
    assert lines[7600].startswith("feed hold")


def test_adaptive_child_gets_the_ceiling_during_chatter_and_hold() -> None:
    kids = _children()
    sup = Supervisor(kids)
    _run(sup, 8000, 100)
    adaptive = kids[2]
    assert isinstance(adaptive, Scripted)
    by_sample = {s: (c, u) for s, c, u in adaptive.ceilings}
    assert by_sample[1500] == (None, pytest.approx(1.3))  # normal: its own limits
    assert by_sample[2500] == (pytest.approx(1.3), pytest.approx(1.3))  # chatter: no rise
    # once held, the ceilings stop changing: the last one set is 0 (nothing may move)
    assert adaptive.ceilings[-1][1] == 0.0


@pytest.mark.parametrize("chunk", [1, 7, 100, 333, 8000])
def test_decisions_do_not_depend_on_the_chunking(chunk: int) -> None:
    ref_ch, ref_ev = _run(Supervisor(_children()), 8000, 100)
    ch, ev = _run(Supervisor(_children()), 8000, chunk)
    assert _overrides(ev) == _overrides(ref_ev)
    for k in ref_ch:
        assert np.array_equal(ch[k], ref_ch[k], equal_nan=True), k


class CeilingFollower(Scripted):
    """An adaptive child whose output depends on the ceiling it was last told (its echo is the
    input × the ceiling, 1 without one), with AdaptiveFeedBlock's rule: a call without a
    ceiling that confirms its own last proposal changes nothing (decision 1671)."""

    def reset(self, sample_rate_hz: float) -> None:
        super().reset(sample_rate_hz)
        self.ceiling: float | None = None
        self.sent = 1.0

    def set_ceiling(self, ceiling: float | None, commanded: float) -> None:
        if ceiling is None and abs(commanded - self.sent) <= 1e-12 and self.ceiling is None:
            return
        self.ceilings.append((self._pos, ceiling, commanded))
        self.ceiling = ceiling
        self.sent = commanded

    def process(self, chunk: Chunk) -> BlockOutput:
        out = super().process(chunk)
        for e in out.events:
            if e.name == "feed_override" and e.value is not None:
                self.sent = e.value / 100.0
        scale = 1.0 if self.ceiling is None else self.ceiling
        return BlockOutput({f"{self.name}/echo": np.asarray(chunk.data["sig"]) * scale},
                           out.events)  # fmt: skip


@pytest.mark.parametrize("chunk", [7, 333, 1000, 2345, 8000])
def test_children_run_ahead_over_several_periods_as_period_by_period(chunk: int) -> None:
    """Decision 1671: a chunk of several control periods runs each child once, as far as the
    decisions allow (a chatter alarm, its end or a breakage alarm stops the later children at
    the end of its period); the adaptive child is told its ceiling at the same samples, its
    outputs (which follow the ceiling) and every event and override are those of 10 ms
    chunks, and the calls that change something are the same calls."""

    def kids() -> list[Block]:
        chatter, breakage, adaptive = _children()
        assert isinstance(adaptive, Scripted)
        return [chatter, breakage, CeilingFollower("adaptive_feed", adaptive.script)]

    ref_kids, kids_now = kids(), kids()
    ref_ch, ref_ev = _run(Supervisor(ref_kids), 8000, 100)
    ch, ev = _run(Supervisor(kids_now), 8000, chunk)
    assert [(e.sample, e.name, e.value, e.kind) for e in ev] == [
        (e.sample, e.name, e.value, e.kind) for e in ref_ev
    ]
    for k in ref_ch:
        assert np.array_equal(ch[k], ref_ch[k], equal_nan=True), k
    ref_ad, ad = ref_kids[2], kids_now[2]
    assert isinstance(ref_ad, CeilingFollower) and isinstance(ad, CeilingFollower)
    assert ad.ceilings == ref_ad.ceilings and len(ref_ad.ceilings) > 10
    assert ref_kids[1].rearmed == kids_now[1].rearmed == [7000]  # type: ignore[attr-defined]


def test_breakage_when_stable_holds_at_the_next_boundary() -> None:
    """A breakage alarm with no chatter: feed hold within one control period (10 ms), far
    inside issue 16's 3 tooth periods (60 ms at 1000 rev/min, 2 flutes)."""
    sup = Supervisor([ScriptedBreakage("breakage", {3042: (ALM, "breakage", None)})])
    _, events = _run(sup, 4000, 100)
    holds = [e for e in events if e.name == "feed_hold"]
    assert len(holds) == 1 and holds[0].sample == 3100
    assert holds[0].severity is Severity.CRITICAL
    assert (holds[0].sample - 3042) / FS <= 0.010


def test_fault_in_cut_with_breakage_possible_gives_a_feed_hold() -> None:
    from millsense.monitoring.breakage import BreakageBlock

    brk = BreakageBlock(2, "constant", signal_channels=("sig",), speed_channel="sig")
    sup = Supervisor([brk])
    fault = np.zeros(3000)
    fault[1234:1300] = 3  # a stalled stream
    _, events = _run(sup, 3000, 100, fault=fault)
    names = [(e.sample, e.name) for e in events]
    assert (1300, "input_fault") in names and (1300, "feed_hold") in names
    assert (1300 - 1234) / FS <= 0.1  # issue 16: the safe action within 100 ms


def test_fault_without_breakage_risk_caps_the_feed_at_programmed_and_clears() -> None:
    """Decision 1615/1621: the feed falls to 100 % from above, is never raised while the
    fault stands, and the fault clears after a clean period."""
    adaptive = Scripted("adaptive_feed", {
        500: (OVR, "feed_override", 140.0),
        1550: (OVR, "feed_override", 145.0),  # during the fault: refused
        2550: (OVR, "feed_override", 120.0),  # after: passes
    })  # fmt: skip
    sup = Supervisor([adaptive])
    fault = np.zeros(3000)
    fault[1420:1480] = 1
    ch, events = _run(sup, 3000, 100, fault=fault)
    assert _overrides(events) == [
        (600, "feed_override", 140.0),
        (1500, "feed_override", 100.0),
        (2600, "feed_override", 120.0),
    ]
    assert ch["supervisor/mode"][1550] == MODE_FAULT
    kinds = [e.name for e in events if e.kind is not EventKind.OVERRIDE]
    assert kinds == ["input_fault", "input_fault_cleared"]


def test_options_are_checked() -> None:
    from millsense.core.errors import ConfigError

    with pytest.raises(ConfigError, match="period_s"):
        SupervisorOptions(period_s=0.0)
    with pytest.raises(ConfigError, match="unique"):
        Supervisor([Scripted("a", {}), Scripted("a", {})])


def _run_with_requests(
    sup: Supervisor, n: int, requests: dict[int, tuple[str, object]]
) -> tuple[dict[str, np.ndarray], list[Event]]:
    """Like :func:`_run` in 100-sample chunks, the operator's requests made before the chunk
    starting at the given sample (as the dashboard's thread makes them between chunks)."""
    sup.reset(FS)
    data = {"sig": np.arange(n, dtype=float), "guard/fault": np.zeros(n),
            "plan/in_cut": np.ones(n)}  # fmt: skip
    outs: dict[str, list[np.ndarray]] = {}
    events: list[Event] = []
    for a in range(0, n, 100):
        if a in requests:
            what, arg = requests[a]
            if what == "control":
                sup.request_control(bool(arg))
            else:
                sup.acknowledge(*arg)  # type: ignore[misc]
        res = sup.process(Chunk(a, FS, 0.0, {k: v[a : a + 100] for k, v in data.items()}))
        for k, v in res.channels.items():
            outs.setdefault(k, []).append(v)
        events += res.events
    return {k: np.concatenate(v) for k, v in outs.items()}, events


def test_operator_control_off_restores_programmed_overrides_and_on_again() -> None:
    """Decision 1902: control off at 3000 → feed and spindle back to 100 % at the period's end
    (3100); proposals while off do not pass (4005: 140 %); on again at 5000 → the next proposal
    passes (6005 → 6100); the adaptive child is capped at the commanded feed while off."""
    chatter = Scripted("chatter", {1060: (OVR, "spindle_override", 112.0)})
    adaptive = Scripted("adaptive_feed", {
        1005: (OVR, "feed_override", 130.0),
        4005: (OVR, "feed_override", 140.0),
        6005: (OVR, "feed_override", 120.0),
    })  # fmt: skip
    sup = Supervisor([chatter, adaptive])
    ch, events = _run_with_requests(sup, 7000, {3000: ("control", False), 5000: ("control", True)})
    assert _overrides(events) == [
        (1100, "spindle_override", 112.0),  # chatter's first (seed 000 priorities)
        (1100, "feed_override", 130.0),
        (3100, "feed_override", 100.0),  # control off
        (3100, "spindle_override", 100.0),
        (6100, "feed_override", 120.0),  # on again: proposals pass
    ]
    notes = [(e.sample, e.name) for e in events if e.kind is EventKind.NOTE]
    assert notes == [(3100, "control_off"), (5100, "control_on")]
    assert ch["supervisor/feed_override"][4500] == 1.0
    assert ch["supervisor/spindle_override"][4500] == 1.0
    ceil = {s: c for s, c, _ in adaptive.ceilings}
    assert ceil[4500] == pytest.approx(1.0) and ceil[6500] is None


def test_operator_acknowledges_an_alarm_and_the_hold_stays() -> None:
    """An acknowledgement is a NOTE naming the alarm and its time; a feed hold latches (the
    tool is still broken) and control off does not release it."""
    sup = Supervisor([ScriptedBreakage("breakage", {1042: (ALM, "breakage", None)})])
    ch, events = _run_with_requests(
        sup, 3000, {2000: ("ack", ("breakage", 0.1042)), 2500: ("control", False)}
    )
    ack = [e for e in events if e.name == "alarm_acknowledged"]
    assert len(ack) == 1 and ack[0].sample == 2100
    assert ack[0].values["alarm_s"] == pytest.approx(0.1042)
    assert [e.name for e in events if e.kind is EventKind.OVERRIDE] == ["feed_hold"]
    assert ch["supervisor/mode"][-1] == MODE_HOLD


@pytest.mark.parametrize("chunk", [1, 100, 1000])
def test_children_events_are_located_on_the_tool_path_at_their_sample(chunk: int) -> None:
    """Decision 1715: with location channels (the session's ``plan/nc_line`` and ``tcp/x|y|z``)
    a child's alarm or note that does not say where it happened, and the feed hold an alarm
    causes, carry
    the NC line and position (mm) at the alarm's sample, whatever the chunking; an NC line of
    −1 (no plan row yet) is no line."""
    n = 4000
    k = np.arange(n, dtype=float)
    loc = {"plan/nc_line": np.where(k < 3000, -1.0, 7.0 + (k >= 3500)),
           "tcp/x": 1e-6 * k, "tcp/y": np.full(n, 0.04), "tcp/z": np.full(n, -0.003)}  # fmt: skip
    monitor = Scripted("monitor", {1200: (NOTE, "blind", None)})
    breakage = ScriptedBreakage("breakage", {3042: (ALM, "breakage", None)})
    sup = Supervisor([monitor, breakage],
                     location_channels=("plan/nc_line", "tcp/x", "tcp/y", "tcp/z"))  # fmt: skip
    assert set(loc) <= set(sup.inputs)
    sup.reset(FS)
    data = {"sig": k, "guard/fault": np.zeros(n), "plan/in_cut": np.ones(n), **loc}
    events: list[Event] = []
    for a in range(0, n, chunk):
        part = {c: v[a : a + chunk] for c, v in data.items()}
        events += sup.process(Chunk(a, FS, 0.0, part)).events
    (c,) = [e for e in events if e.name == "blind"]
    assert c.nc_line is None and c.x_mm == pytest.approx(1.2, abs=1e-9)  # before any row
    (b,) = [e for e in events if e.name == "breakage"]
    assert b.nc_line == 7
    assert (b.x_mm, b.y_mm, b.z_mm) == pytest.approx((3.042, 40.0, -3.0), abs=1e-9)
    (h,) = [e for e in events if e.name == "feed_hold"]
    assert (h.nc_line, h.x_mm) == (b.nc_line, b.x_mm)  # the hold names its cause's place
