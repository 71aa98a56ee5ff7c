"""The compiled per-chunk steps of the session's gates and plan sync (decision 1653) give bit
for bit what their former numpy forms gave, kept here as the oracles, in any chunking."""

from __future__ import annotations

import itertools

import numpy as np

from millsense.estimation.spindle_observer import hold_decimated
from millsense.online.gates import STILL, AirReference, SpindleAtSpeed
from millsense.streaming.block import Block, Chunk
from millsense.streaming.recursions import exponential_average

FS = 10000.0


class _NumpyAtSpeed:
    """The numpy form of :class:`SpindleAtSpeed` before decision 1653."""

    def __init__(self, gate: SpindleAtSpeed) -> None:
        self.g = gate
        self._run = 0
        self._last_cmd = np.nan

    def process(self, w: np.ndarray, cmd: np.ndarray) -> np.ndarray:
        n = cmd.size
        prev = np.empty(n)
        prev[0] = self._last_cmd
        prev[1:] = cmd[:-1]
        self._last_cmd = float(cmd[-1])
        still = np.abs(cmd - prev) <= STILL * np.abs(cmd)
        ok = (np.abs(cmd) > 0) & (np.abs(w - cmd) <= self.g.tolerance * np.abs(cmd)) & still
        idx = np.arange(1, n + 1)
        last_bad = np.maximum.accumulate(np.where(~ok, idx, 0))
        run = np.where(last_bad == 0, self._run + idx, idx - last_bad)
        self._run = int(run[-1])
        return (run > self.g.n_settle).astype(np.float64)


class _NumpyAir:
    """The numpy form of :class:`AirReference` before decision 1653, with the start of
    decision 1555 (the running mean of the first ``n_start`` used samples after the stream's
    start or a sample off speed, then the first-order average)."""

    def __init__(self, air: AirReference) -> None:
        self.a = air
        self._ref, self._seen, self._run, self._off = 0.0, 0, 0, True

    def process(self, tq: np.ndarray, in_cut: np.ndarray, at_speed: np.ndarray) -> np.ndarray:
        air, ok = in_cut < 0.5, at_speed > 0.5
        n = tq.size
        ref = np.full(n, self._ref)
        idx = np.arange(1, n + 1)
        last_cut = np.maximum.accumulate(np.where(~air, idx, 0))
        run = np.where(last_cut == 0, self._run + idx, idx - last_cut)
        self._run = int(run[-1])
        k = np.flatnonzero((run > self.a.n_settle) & ok & np.isfinite(tq))
        # a used sample is fresh where the spindle was off speed since the previous used one
        last_off = np.maximum.accumulate(np.where(~ok, idx, 0))
        prev_used = np.concatenate([[0], k[:-1] + 1])
        fresh = last_off[k] > prev_used
        if k.size:
            fresh[0] |= self._off
        self._off = bool(last_off[-1] > (k[-1] + 1 if k.size else 0)) or (self._off and not k.size)
        if k.size:
            x = tq[k]
            y = np.empty(k.size)
            starts = np.concatenate([np.flatnonzero(fresh), [k.size]])
            if starts[0] != 0:
                starts = np.concatenate([[0], starts])
            for a, b in itertools.pairwise(starts):
                seen = 0 if fresh[a] else self._seen
                prev = self._ref if a == 0 else float(y[a - 1])
                j = a
                while j < b and seen < self.a.n_start:
                    seen += 1
                    prev = float(x[j]) if seen == 1 else prev + (float(x[j]) - prev) / seen
                    y[j] = prev
                    j += 1
                if j < b:
                    y[j:b] = exponential_average(x[j:b], self.a.alpha, prev)
                self._seen = seen
            hold = np.full(n, -1)
            hold[k] = np.arange(k.size)
            pos = np.maximum.accumulate(hold)
            ref = np.where(pos >= 0, y[np.maximum(pos, 0)], self._ref)
            self._ref = float(y[-1])
        if self._off:
            self._seen = 0
        return ref


def _chunks(n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    cuts = np.unique(np.concatenate([[0, n], rng.integers(1, n, 40)]))
    return list(zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True))


def _block(b: Block, data: dict[str, np.ndarray], a: int, e: int) -> dict[str, np.ndarray]:
    return b.process(Chunk(a, FS, 0.0, {k: data[k][a:e] for k in b.inputs})).channels


def test_spindle_gate_equals_its_numpy_form() -> None:
    rng = np.random.default_rng(5)
    n = 20000
    cmd = np.repeat(rng.choice([0.0, 100.0, 104.0, -80.0], 20), n // 20)
    cmd[5000:5400] = np.linspace(0, 100, 400)  # a ramp setpoint
    w = cmd * (1 + 0.012 * rng.standard_normal(n))  # 1 % of the samples beyond 3 %
    data = {"spindle/speed": w, "spindle/speed_cmd": cmd}
    gate = SpindleAtSpeed(settle_s=0.005)
    gate.reset(FS)
    ref = _NumpyAtSpeed(gate)
    opened = shut = False
    for a, e in _chunks(n, rng):
        got = _block(gate, data, a, e)["spindle/at_speed"]
        assert np.array_equal(got, ref.process(w[a:e], cmd[a:e]))
        opened, shut = opened or got.any(), shut or not got.all()
    assert opened and shut


def test_air_reference_equals_its_numpy_form() -> None:
    rng = np.random.default_rng(6)
    n = 20000
    tq = 1.0 + 0.3 * rng.standard_normal(n)
    tq[rng.integers(0, n, 30)] = np.nan
    in_cut = np.repeat(rng.integers(0, 2, 25).astype(float), n // 25)
    at_speed = np.repeat(rng.integers(0, 2, 16).astype(float), n // 16)
    data = {"tq": tq, "plan/in_cut": in_cut, "spindle/at_speed": at_speed}
    air = AirReference("tq", settle_s=0.01, tau_s=0.02)  # 200 samples of running mean
    air.reset(FS)
    ref = _NumpyAir(air)
    counts = []
    for a, e in _chunks(n, rng):
        got = _block(air, data, a, e)
        want = ref.process(tq[a:e], in_cut[a:e], at_speed[a:e])
        assert np.array_equal(got["air_reference/torque"], want)
        assert np.array_equal(got["spindle/cutting_torque"], tq[a:e] - want, equal_nan=True)
        counts.append(air._state[1])
    # it went past the running mean into the first-order average, and restarted off speed
    assert max(counts) == air.n_start and 0.0 in counts[1:]


def test_held_observer_estimates_equal_the_repeat_form() -> None:
    rng = np.random.default_rng(7)
    for n, m in ((100, 10), (7, 10), (33, 4), (1, 1)):
        for first in range(min(m, n)):
            sel = np.arange(first, n, m)
            est = rng.standard_normal(sel.size)
            want = np.repeat(np.concatenate([[0.5], est]), np.diff(np.concatenate([[0], sel, [n]])))
            got = np.empty(n)
            hold_decimated(est, first, m, 0.5, got)
            assert np.array_equal(got, want)
