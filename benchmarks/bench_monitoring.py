"""Benchmarks of the process monitors (issue 15): x real time on one core."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.monitoring.chatter import METHODS, ChatterGroup, ChatterMonitor, ChatterSettings
from millsense.streaming.block import Chunk

FS = 10_000.0


def _stream(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """4-flute cut at 6000 rev/min (harmonics, noise) with chatter at 937 Hz in the second half."""
    rng = np.random.default_rng(0)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    ang = 2 * math.pi * 100.0 * t
    x = sum((1.0 if k % 4 == 0 else 0.1) * np.cos(k * ang) for k in range(1, 30))
    x = x + 0.05 * rng.standard_normal(n) + 3.0 * (t > seconds / 2) * np.cos(2 * math.pi * 937 * t)
    return np.asarray(x), np.full(n, 200 * math.pi)


def _time(chunk: int, x: np.ndarray, spd: np.ndarray) -> tuple[float, int]:
    # the three criteria as the monitor command runs them: one group sharing the comb filter
    blocks = [
        ChatterGroup(
            [ChatterMonitor(ChatterSettings(method=m, signal="s", n_flutes=4)) for m in METHODS]
        )
    ]
    for b in blocks:
        b.reset(FS)
    alarms = 0
    t0 = time.perf_counter()
    for s in range(0, len(x), chunk):
        c = Chunk(s, FS, 0.0, {"s": x[s : s + chunk], "spindle/speed": spd[s : s + chunk]})
        for b in blocks:
            alarms += sum(e.name == "chatter" for e in b.process(c).events)
    return time.perf_counter() - t0, alarms


@benchmark("monitoring.chatter_speed")
def _chatter() -> list[Metric]:
    seconds = 60.0
    x, spd = _stream(seconds)
    _time(1000, x[:50000], spd[:50000])  # compile / load the numba cache
    out = []
    for chunk, label in ((100, "10 ms"), (1000, "0.1 s")):
        wall, alarms = min(_time(chunk, x, spd) for _ in range(3))  # the least disturbed run
        out.append(
            Metric(
                f"x_realtime_{label.replace(' ', '')}_chunks",
                seconds / wall,
                "x",
                target=500.0,
                note=f"chatter-comb + chatter-sdft + chatter-threshold as one ChatterGroup, "
                f"60 s at 10 kHz in {label} chunks, one core, after compilation, best of 3 "
                f"({alarms} alarms)",
            )
        )
    return out
