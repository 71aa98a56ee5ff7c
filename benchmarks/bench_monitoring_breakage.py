"""Benchmark of the breakage monitors on a 10 kHz stream (issue 15 performance).

The three breakage blocks (virtual threshold with an expected-torque channel, constant
threshold, dual residual on two force channels) run together on 60 s of a synthetic 10 kHz
stream at 1000 rev/min with a 2-flute tool, in 10 ms and in 0.1 s chunks, after compilation.
"""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.monitoring.breakage import BreakageBlock
from millsense.streaming.block import Chunk

FS = 10000.0


def _stream(seconds: float) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    omega = 1000 * 2 * math.pi / 60
    tq = 3.0 + 1.5 * np.sin(2 * omega * t) + 0.05 * rng.standard_normal(n)
    return {
        "spindle/torque_est": tq,
        "spindle/speed": np.full(n, omega),
        "plan/torque": np.full(n, 3.0),
        "force_x": 300 * np.sin(2 * omega * t) + rng.standard_normal(n),
        "force_y": 200 * np.cos(2 * omega * t) + rng.standard_normal(n),
    }


def _blocks() -> list[BreakageBlock]:
    return [
        BreakageBlock(2, "virtual", expected_channel="plan/torque"),
        BreakageBlock(2, "constant"),
        BreakageBlock(2, "dual", signal_channels=("force_x", "force_y")),
    ]


def _run(data: dict[str, np.ndarray], chunk: int) -> float:
    blocks = _blocks()
    for b in blocks:
        b.reset(FS)
    n = len(data["spindle/speed"])
    t0 = time.perf_counter()
    for i in range(0, n, chunk):
        for b in blocks:
            b.process(Chunk(i, FS, 0.0, {k: data[k][i : i + chunk] for k in b.inputs}))
    return time.perf_counter() - t0


@benchmark("monitoring.breakage_speed")
def _speed() -> list[Metric]:
    _run(_stream(1.0), 100)  # compile / load the numba cache
    seconds = 60.0
    data = _stream(seconds)
    out = []
    for chunk, label in ((100, "10ms"), (1000, "100ms")):
        wall = _run(data, chunk)
        out.append(
            Metric(
                f"x_realtime_{label}",
                seconds / wall,
                "x",
                target=500.0,
                note=f"3 breakage blocks together, {seconds:.0f} s at 10 kHz, {label} chunks",
            )
        )
    return out
