"""What a chatter monitor judged (decision 1689): the windows it decided and those its cutting
gate took for a cut, and `monitor`'s summary of them where it raised no alarm."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from millsense.cli.cmd_monitor import _chatter_seen
from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings
from millsense.streaming.block import Chunk

FS, RPM, FLUTES = 10000.0, 6000.0, 4


def _stream(cut_from_s: float | None, seconds: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """A 4-flute cut's torque (tooth harmonics of 1 N·m on a 5 N·m mean) from ``cut_from_s``
    (None: never; air: the mean and 0.05 N·m of noise) at 6000 rev/min."""
    rng = np.random.default_rng(1)
    t = np.arange(int(seconds * FS)) / FS
    ang = 2 * math.pi * RPM / 60 * t
    x = 5.0 + 0.05 * rng.standard_normal(t.size)
    if cut_from_s is not None:
        tooth = sum(np.cos(k * FLUTES * ang + 0.3 * k) / k for k in range(1, 6))
        x += (t >= cut_from_s) * (2.0 + tooth)
    return x, np.full(t.size, RPM * 2 * math.pi / 60)


def _monitor(x: np.ndarray, speed: np.ndarray, method: str) -> ChatterMonitor:
    m = ChatterMonitor(ChatterSettings(method=method, signal="s", n_flutes=FLUTES))
    m.reset(FS)
    for a in range(0, x.size, 1000):
        m.process(Chunk(a, FS, 0.0, {"s": x[a : a + 1000], "spindle/speed": speed[a : a + 1000]}))
    return m


@pytest.mark.parametrize("method", ["chatter-comb", "chatter-sdft"])
def test_the_gated_criteria_judge_the_windows_in_the_cut(method: str) -> None:
    """A decision every 0.1 s once a window is full (4096 samples for the comb, 2048 for the
    SDFT), less up to three while the speed's statistics settle; a cut from 2 s: the windows
    decided from the entry on are judged (those straddling it by their part in the cut,
    decision 1539), 2.1 to 6.0 s, 40 windows, none in the air before it (±2: the window at the
    entry either way)."""
    x, speed = _stream(2.0)
    m = _monitor(x, speed, method)
    window_s = m.method.window / FS
    decided = math.floor((6.0 - window_s) / 0.1)
    assert decided - 3 <= m.windows_decided <= decided
    assert 38 <= m.windows_judged <= 42


def test_a_signal_without_a_cut_is_decided_and_not_judged() -> None:
    """The same stream in the air throughout: decided, judged at most twice (the gate's test
    of the tooth line is statistical: noise may pass it in a window); the threshold criterion
    (no gate, seed 002) judges every window it decides."""
    x, speed = _stream(None)
    for method in ("chatter-comb", "chatter-sdft"):
        m = _monitor(x, speed, method)
        assert m.windows_decided >= 50 and m.windows_judged <= 2
    thr = _monitor(x, speed, "chatter-threshold")
    assert thr.windows_decided >= 50 and thr.windows_judged == thr.windows_decided


def test_the_summary_says_what_was_judged() -> None:
    """`monitor`'s "no alarm" line: nothing added where every window was judged or for another
    monitor; the gate never open, no window decided, and the seconds judged of those decided."""
    settings = SimpleNamespace(hop_s=0.1)
    assert _chatter_seen(SimpleNamespace(windows_decided=40, windows_judged=40)) == ""
    assert _chatter_seen(SimpleNamespace(name="breakage")) == ""
    none = _chatter_seen(SimpleNamespace(windows_decided=40, windows_judged=0, settings=settings))
    assert none.startswith(", but nothing judged: in none of its 40 windows")
    assert "no window decided" in _chatter_seen(SimpleNamespace(windows_decided=0,
                                                                windows_judged=0))  # fmt: skip
    part = _chatter_seen(SimpleNamespace(windows_decided=95, windows_judged=25, settings=settings))
    assert part.startswith(" (judged 2.5 s of the 9.5 s decided")
