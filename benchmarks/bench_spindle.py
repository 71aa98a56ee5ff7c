"""Benchmarks of the spindle drive and the interpolator."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.simulator.interpolator import Interpolator, Upsampler
from millsense.simulator.spindle import SpindleDriveSim


@benchmark("machine.spindle_realtime")
def _spindle() -> list[Metric]:
    p = SpindleDriveParams.aslan_quaser()
    SpindleDriveSim(p).advance(np.zeros(10), np.zeros(10))  # compile / load cache
    n = 600_000  # 60 s at 10 kHz
    t = np.arange(n) * 1e-4
    ref = np.full(n, 1000 * 2 * math.pi / 60)
    tau = 5.0 * (1 + np.sin(2 * math.pi * 33.3 * t))
    sim = SpindleDriveSim(p)
    t0 = time.perf_counter()
    for k in range(0, n, 10_000):  # 1 s chunks, as the closed-loop simulator calls it
        sim.advance(ref[k : k + 10_000], tau[k : k + 10_000])
    wall = time.perf_counter() - t0
    return [
        Metric(
            "x_realtime",
            60.0 / wall,
            "x",
            target=20.0,
            note="60 s at 10 kHz, 25 states (10 residual modes), 1 s chunks, after compilation",
        )
    ]


@benchmark("machine.interpolator_realtime")
def _interp() -> list[Metric]:
    rng = np.random.default_rng(0)
    pts = np.cumsum(rng.uniform(-0.002, 0.002, (2000, 5)), axis=0)
    Interpolator(pts, 0.01, 1.0).advance(10)
    ip = Interpolator(pts, 0.01, 1.0)
    up = Upsampler(30, pts[0], method="hermite")
    t0 = time.perf_counter()
    for _ in range(60):  # 60 s in 1 s chunks
        out = ip.advance(333)
        up(out["position"], out["velocity"], 3e-3)
    wall = time.perf_counter() - t0
    return [
        Metric(
            "x_realtime",
            60.0 / wall,
            "x",
            target=100.0,
            note="5-axis 2000-segment path, 3 ms periods, Hermite upsampling to 10 kHz, 1 s chunks",
        )
    ]
