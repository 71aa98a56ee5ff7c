"""Benchmarks of the feed-drive simulator (millsense.simulator.feed_drive)."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine


@benchmark("machine.feed_drive_speed")
def _feed_drive() -> list[Metric]:
    # Quaser X: rigid body + 6 Table 3.4 modes (12 states) + LuGre + cascade + noise, 10 kHz,
    # 10 substeps; 10 s of a reversing move with a 100 Hz load, in 1 s chunks
    params = FeedDriveParams.from_config(simulator_machine("quaser-ux600").axis("x"))
    assert params.modes is not None and params.modes.n_states == 12
    fs = 10000.0
    FeedDriveSim(params, fs).advance(np.zeros(10), np.zeros(10), np.zeros(10))  # compile
    seconds = 10.0
    n = round(seconds * fs)
    t = np.arange(n) / fs
    pos = 50.0 * np.sin(2 * math.pi * 0.5 * t)
    vel = 50.0 * 2 * math.pi * 0.5 * np.cos(2 * math.pi * 0.5 * t)
    load = 300.0 + 200.0 * np.sin(2 * math.pi * 100.0 * t)
    sim = FeedDriveSim(params, fs, seed=1)
    t0 = time.perf_counter()
    for a in range(0, n, 10000):
        sim.advance(pos[a : a + 10000], vel[a : a + 10000], load[a : a + 10000])
    wall = time.perf_counter() - t0
    return [
        Metric(
            "x_realtime",
            seconds / wall,
            "x",
            target=50.0,
            higher_is_better=True,
            note="one axis, 12 modal states + LuGre + cascade, 10 kHz, 10 substeps",
        ),
        Metric("wall_time", wall, "s", target=0.2, higher_is_better=False, note="10 s simulated"),
    ]
