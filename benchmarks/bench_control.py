"""Benchmark of the adaptive feed controller (issue 16: decision latency per 10 ms block ≤ 1 ms,
median and 99th percentile; × real time).

The stream is the V8 slot's plan (``control_adaptive``: 1.2 mm deep, step-down to 3 mm, exit)
traversed open loop at the programmed feed, 10 kHz: TCP from the plan rows, a 2-flute force of
the plan's predicted peak per row, the spindle at 1000 rev/min; repeated end to end to 60 s.
The block runs with the plan (match + look-ahead every revolution) and without it, in 10 ms
chunks, after a warm-up pass; each ``process`` call is timed (wall clock, and thread CPU
time, which a loaded machine's preemption does not inflate).
"""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.control.adaptive_feed import AdaptiveFeedBlock, AdaptiveFeedOptions
from millsense.plan.virtual_plan import VirtualPlan
from millsense.streaming.block import Chunk

FS = 10000.0
OMEGA = 1000 * 2 * math.pi / 60


def _stream(plan: VirtualPlan, seconds: float) -> dict[str, np.ndarray]:
    t_rows = np.asarray(plan["t_s"], dtype=np.float64)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    tl = np.mod(t, t_rows[-1])  # repeat the program
    xyz = plan.xyz_m
    row = np.clip(np.searchsorted(t_rows, tl, side="right") - 1, 0, len(plan) - 1)
    f = np.asarray(plan["fres_peak_n"], dtype=np.float64)[row]
    f = f * np.abs(np.sin(2 * OMEGA * t)) + np.random.default_rng(0).normal(0, 1.0, n)
    return {
        "force_x": 0.6 * f,
        "force_y": 0.8 * f,
        "spindle/speed": np.full(n, OMEGA),
        "x/position_cmd": np.interp(tl, t_rows, xyz[:, 0]),
        "y/position_cmd": np.interp(tl, t_rows, xyz[:, 1]),
        "z/position_cmd": np.interp(tl, t_rows, xyz[:, 2]),
    }


def _run(
    block: AdaptiveFeedBlock, data: dict[str, np.ndarray], chunk: int
) -> tuple[np.ndarray, np.ndarray]:
    """Wall-clock and CPU (thread) time of every ``process`` call, s."""
    block.reset(FS)
    n = len(data["force_x"])
    wall, cpu = [], []
    for i in range(0, n, chunk):
        c = Chunk(i, FS, 0.0, {k: data[k][i : i + chunk] for k in block.inputs})
        t0, c0 = time.perf_counter(), time.thread_time()
        block.process(c)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    return np.array(wall), np.array(cpu)


@benchmark("control.adaptive_feed_latency")
def _latency() -> list[Metric]:
    from millsense.validation.cases.control_adaptive import (
        DEPTH_HIGH_MM,
        DEPTH_LOW_MM,
        step_plan,
    )

    plan = step_plan(DEPTH_LOW_MM, DEPTH_HIGH_MM)
    assert isinstance(plan, VirtualPlan)
    seconds = 60.0
    data = _stream(plan, seconds)
    out = []
    for with_plan in (True, False):
        blk = AdaptiveFeedBlock(AdaptiveFeedOptions(), plan if with_plan else None)
        _run(blk, _stream(plan, 2.0), 100)  # warm-up (numba kernels of the plan match)
        lat, cpu = _run(blk, data, 100)
        what = "plan" if with_plan else "noplan"
        note = (
            "look-ahead (plan match + flags every revolution)" if with_plan else "no plan"
        ) + f", {seconds:.0f} s at 10 kHz, 1000 rev/min, 10 ms chunks, one core"
        out += [
            Metric(
                f"latency_median_ms_{what}",
                1e3 * float(np.median(lat)),
                "ms",
                target=1.0,
                higher_is_better=False,
                note=note,
            ),
            Metric(
                f"latency_p99_ms_{what}",
                1e3 * float(np.percentile(lat, 99)),
                "ms",
                target=1.0,
                higher_is_better=False,
                note=note,
            ),
            Metric(
                f"latency_p99_cpu_ms_{what}",
                1e3 * float(np.percentile(cpu, 99)),
                "ms",
                target=1.0,
                higher_is_better=False,
                note=note + " (thread CPU time: without the other processes' preemption)",
            ),
            Metric(f"x_realtime_{what}", seconds / float(np.sum(lat)), "x", note=note),
        ]
    return out
