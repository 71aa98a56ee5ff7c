"""Benchmark of the truth feed drive (coupled lumped masses, position-scheduled plant) against
today's one-way FeedDriveSim, side by side in the same run (issue 12)."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.truth_machine import load_truth, truth_feed_params


def _run(params: FeedDriveParams, seconds: float, fs: float, substeps: int) -> tuple[float, float]:
    """(wall, CPU) time of ``seconds`` of a reversing ±100 mm move with a 100 Hz load in 1 s
    chunks."""
    FeedDriveSim(params, fs).advance(np.zeros(10), np.zeros(10), np.zeros(10))  # compile
    n = round(seconds * fs)
    t = np.arange(n) / fs
    amp = 0.1 / params.transmission
    pos = amp * np.sin(2 * math.pi * 0.5 * t)
    vel = amp * 2 * math.pi * 0.5 * np.cos(2 * math.pi * 0.5 * t)
    load = 300.0 + 200.0 * np.sin(2 * math.pi * 100.0 * t)
    sim = FeedDriveSim(params, fs, substeps=substeps, seed=1)
    step = round(fs)
    t0, c0 = time.perf_counter(), time.thread_time()
    for a in range(0, n, step):
        sim.advance(pos[a : a + step], vel[a : a + step], load[a : a + step])
    return time.perf_counter() - t0, time.thread_time() - c0


@benchmark("machine.truth_drive_speed")
def _truth_drive() -> list[Metric]:
    machine = simulator_machine("quaser-ux600")
    truth = load_truth("quaser-ux600")
    fs, seconds = 10000.0, 10.0
    old = FeedDriveParams.from_config(machine.axis("x"))
    new = truth_feed_params(machine.axis("x"), truth["x"])
    assert new.plant_schedule is not None
    states = new.plant.a.shape[0]
    w_old, c_old = _run(old, seconds, fs, 10)
    w_new, c_new = _run(new, seconds, fs, truth["x"].substeps)
    return [
        Metric(
            "x_cpu_realtime",
            seconds / c_new,
            "x",
            target=50.0,
            higher_is_better=True,
            note="simulated s / CPU s of the thread (load-independent), X truth",
        ),
        Metric(
            "x_realtime",
            seconds / w_new,
            "x",
            higher_is_better=True,
            note=f"X truth: {states} mechanical states scheduled on "
            f"{len(new.plant_schedule.positions)} positions, LuGre, PI current loop, dead "
            f"times, ripple; 10 kHz, {truth['x'].substeps} substeps",
        ),
        Metric(
            "x_realtime_ideal",
            seconds / w_old,
            "x",
            note="today's one-way FeedDriveSim (rigid + 12 modal states, 10 substeps), same run",
        ),
        Metric(
            "ratio_to_ideal",
            c_old / c_new,
            "1",
            note="CPU real-time factor of the truth over today's model (1 = as fast)",
        ),
    ]
