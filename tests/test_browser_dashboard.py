"""The live dashboard in headless Chromium (issue 19): the page follows a session running in
real time — a Supervisor with the seed 000 breakage monitor (virtual threshold) on a simulated
spindle torque, a tooth breaking at 8.01 s — its plots update, the breakage alarm is on the
page within 1 s of the break, the operator acknowledges it and switches the control off, and
the page without the token is refused."""

from __future__ import annotations

import functools
import gc
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from tests.browser import chromium, console_errors, screenshot

from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Chunk, Event
from millsense.streaming.sources import Source

RPM = 1000.0
BREAK_S = 267 * 0.03  # 8.01 s: flute 0 breaks (2 flutes at 1000 rev/min)
# the stretch streamed (air cut, re-entry at 6.5 s, the break, a hold); the session runs on
# 5 s after the break, so that the operator's acknowledgement and switch-off (taken at the
# supervisor's next control period while it runs) fit in a loaded CI machine's page round
# trips: with 3 s (11.0) a fresh-clone CI beside other work timed out on the switch-off
START_S, STOP_S = 6.0, 13.0


@functools.lru_cache(maxsize=1)
def _stream() -> dict[str, np.ndarray]:
    """The breakage monitor tests' stream (tests/test_monitoring_breakage.py): slot, air cut
    6-6.5 s, flute 0 broken at 8.01 s, with the intact tool's revolution average as the plan's
    expected torque; the tool-centre point moving along X at 400 mm/min."""
    from millsense.monitoring.breakage import BreakageBlock  # noqa: F401  (imported for the test's blocks)
    from millsense.process.engagement import Engagement
    from millsense.simulator.process_coupling import (
        EngagementSchedule,
        EngagementSegment,
        ToothBreak,
    )
    from millsense.validation.cases._torque_sim import FS, simulate_torque

    sched = EngagementSchedule((Engagement.slot(),), (
        EngagementSegment(0.2, 0, 2e-3), EngagementSegment(3.0, 0, 3e-3),
        EngagementSegment(6.0, 0, 0.0), EngagementSegment(6.5, 0, 3e-3)), basis="time")  # fmt: skip
    t = np.arange(int(STOP_S * FS)) / FS
    feed = np.full(len(t), 400 / 60e3)
    _, obs, _ = simulate_torque(sched, feed * t, t, RPM, feed, (ToothBreak(BREAK_S, 0),))
    intact, _, _ = simulate_torque(sched, feed * t, t, RPM, feed)
    w = int(FS * 60 / RPM)
    return {
        "est/spindle/spindle/load": obs,
        "spindle/speed": np.full(len(t), RPM * 2 * math.pi / 60),
        "plan/expected_torque": np.convolve(intact, np.ones(w) / w, mode="same"),
        "tcp/x": feed * t,
        "tcp/y": np.zeros(len(t)),
        "cnc/feed_override": np.ones(len(t)),
    }


class PacedSource(Source):
    """Hands the stream out at real time (a machine does not run faster than its clock) and
    notes the wall time the break's sample was handed out; overrides are recorded."""

    def __init__(self, data: dict[str, np.ndarray], fs: float, start: int, stop: int) -> None:
        self.data, self.sample_rate_hz = data, fs
        self.pos, self.stop, self.start = start, stop, start
        self.commands: list[Event] = []
        self.break_wall: float | None = None
        self.t_wall0 = 0.0

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [ChannelInfo(k, "", k) for k in self.data]

    def read(self, max_samples: int) -> Chunk | None:
        if self.pos >= self.stop:
            return None
        if self.pos == self.start:
            self.t_wall0 = time.monotonic()
        b = min(self.stop, self.pos + max_samples)
        due = self.t_wall0 + (b - self.start) / self.sample_rate_hz
        time.sleep(max(0.0, due - time.monotonic()))
        if self.break_wall is None and b / self.sample_rate_hz >= BREAK_S:
            self.break_wall = time.monotonic()
        part = {k: v[self.pos : b] for k, v in self.data.items()}
        c = Chunk(self.pos, self.sample_rate_hz, 0.0, part)
        self.pos = b
        return c

    def command(self, event: Event) -> None:
        self.commands.append(event)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    yield from chromium()


def test_dashboard_follows_a_session_alarm_within_1_s(browser: Any) -> None:
    from millsense.control.arbitration import Supervisor
    from millsense.dashboard.live import LiveState
    from millsense.dashboard.server import DashboardServer
    from millsense.monitoring.breakage import BreakageBlock
    from millsense.online.session import run_session

    data = _stream()
    fs = 10000.0
    sup = Supervisor([BreakageBlock(2, "virtual", signal_channels=("est/spindle/spindle/load",),
                                    expected_channel="plan/expected_torque", name="breakage")],
                     fault_channel=None, in_cut_channel=None)  # fmt: skip
    path = (np.linspace(0, 80, 50), np.zeros(50))
    state = LiveState(sup, plan_xy_mm=path)
    server = DashboardServer(state)
    url = server.start()
    src = PacedSource(data, fs, int(START_S * fs), int(STOP_S * fs))
    result: dict[str, Any] = {}

    def session() -> None:
        result["res"] = run_session(src, [sup], observer=state.observe, guard=False,
                                    stop_after_hold_s=None)  # fmt: skip
        state.finish()

    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    errors = console_errors(page)
    try:
        page.goto(url)
        page.wait_for_function("Number(document.body.dataset.updates || 0) > 0")
        # the suite's earlier tests leave garbage in this process that a dashboard process does
        # not have: collected now, not in the middle of the timed part (CI once measured 1.10 s
        # where runs alone give 0.56-0.73 s)
        gc.collect()
        th = threading.Thread(target=session, daemon=True)
        th.start()
        # the plots update while the session runs: the last time drawn advances
        page.wait_for_function("Number(document.body.dataset.time || 0) > 7.0", timeout=5000)
        t1 = page.evaluate("Math.max(...document.getElementById('plot-torque').data[0].x)")
        page.wait_for_timeout(600)
        t2 = page.evaluate("Math.max(...document.getElementById('plot-torque').data[0].x)")
        assert t2 - t1 > 0.3  # 0.6 s of wall time at real time
        # the alarm: on the page within 1 s (wall) of the break's sample leaving the machine
        page.wait_for_selector("li.alarm[data-name='breakage']", timeout=5000)
        seen = time.monotonic()
        assert src.break_wall is not None
        latency = seen - src.break_wall
        screenshot(page, "dashboard_alarm.png")
        print(f"alarm on the page {latency:.3f} s after the break")
        assert 0.0 < latency < 1.0, latency
        # the operator acknowledges the alarm and switches the control off
        page.click("li.alarm[data-name='breakage'] button.ack")
        page.wait_for_selector("li.alarm.acknowledged[data-name='breakage']", timeout=2000)
        page.click("#control-off")
        page.wait_for_function("document.getElementById('control').textContent === 'off'",
                               timeout=3000)  # fmt: skip
        th.join(timeout=15)
        page.wait_for_function("document.body.dataset.finished === 'true'", timeout=3000)
        screenshot(page, "dashboard_end.png")
        # every plot drawn, the spectrum with its lines, the trail along X
        n_traces = page.evaluate(
            "['torque','feed','spectrum','position'].map(k => "
            "document.getElementById('plot-' + k).data.length)"
        )
        assert min(n_traces) >= 1
        # the status line: the feed commanded and in effect stay at 100 % (no adaptive control
        # here; the hold is a separate command), the spindle at 1000 rev/min
        assert page.inner_text("#feed") == "100.0" and page.inner_text("#feed_eff") == "100.0"
        assert page.inner_text("#rpm") == "1000" and page.inner_text("#mode") == "feed hold"
        trail_x = page.evaluate("document.getElementById('plot-position').data[1].x.slice(-1)[0]")
        assert trail_x == pytest.approx(STOP_S * 400 / 60, abs=0.1)  # mm, 400 mm/min
        assert errors == []
    finally:
        page.close()
        server.stop()
    names = [e.name for e in result["res"].events]
    assert names.count("breakage") == 1 and "feed_hold" in names
    assert "alarm_acknowledged" in names and "control_off" in names
    brk = next(e for e in result["res"].events if e.name == "breakage")
    assert BREAK_S < brk.time_s < BREAK_S + 10 * 0.03  # the monitor's own latency
    assert [e.name for e in src.commands] == ["feed_hold"]  # what reached the machine


def test_dashboard_page_without_the_token_is_refused(browser: Any) -> None:
    """The address without its token (or with another) gets 401, and a websocket opened
    without it is closed before it opens."""
    from millsense.dashboard.live import LiveState
    from millsense.dashboard.server import DashboardServer

    server = DashboardServer(LiveState())
    url = server.start()
    page = browser.new_page()
    try:
        bare = url.split("?")[0]
        assert page.goto(bare).status == 401
        assert page.goto(bare + "?token=wrong-token-wrong-token").status == 401
        assert page.goto(url).status == 200
        opened = page.evaluate(
            """() => new Promise(r => {
                 const ws = new WebSocket(location.origin.replace('http', 'ws') + '/ws');
                 ws.onopen = () => r('open'); ws.onclose = () => r('closed'); })"""
        )
        assert opened == "closed"
    finally:
        page.close()
        server.stop()
