"""Benchmark of the integrated on-line stack (issue 16: the full on-line stack ≥ 200× real time
on one core; decision latency per 10 ms block ≤ 1 ms, median and 99th percentile).

The stream: the V8 slot (``control_adaptive``: Ø20 mm 2-flute, 1000 rev/min, a step-down and an
exit) simulated once on the quaser-ux600's truth plant (5 axes, 10 kHz), held in memory. The
stacks (built as ``millsense run`` builds them, from the commissioned walkthrough machine file):

- ``full``: the five feed-drive estimators and the forces at the tool (Aslan Eq. 3.51), the
  spindle observer, the spindle gate, the TCP, the plan sync with K_tc calibration, and the
  supervisor with chatter avoidance, breakage and the adaptive feed on the estimated force;
- ``default``: what ``run`` runs by default (no feed estimators; adaptive feed on the spindle
  power).

Each is replayed in 10 ms and 0.1 s chunks after a warm-up; every chunk's pipeline call is timed
(wall clock and thread CPU time, which preemption by other processes does not inflate). × real
time is signal seconds over summed CPU time; the latency is the CPU time per 10 ms chunk of the
whole stack (the decision waits for all of it) and of the supervisor alone.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any

import numpy as np

from _harness import Metric, benchmark

FS = 10000.0
ROOT = Path(__file__).resolve().parents[1]
MACHINE_FILE = ROOT / "examples/walkthrough/quaser-ux600-commissioned.toml"


@functools.lru_cache(maxsize=1)
def _stream() -> tuple[dict[str, np.ndarray], object]:
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.plan_job import plan_job
    from millsense.validation.cases.control_adaptive import DEPTH_HIGH_MM, DEPTH_LOW_MM, step_plan

    plan = step_plan(DEPTH_LOW_MM, DEPTH_HIGH_MM)
    m = simulator_machine("quaser-ux600")
    job, proc, _, _ = plan_job(plan, m, "v8")
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=0), duration_s=12.0)
    parts: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(1000)) is not None:
        for k, v in c.data.items():
            parts.setdefault(k, []).append(np.asarray(v))
    data = {k: np.concatenate(v) for k, v in parts.items()}
    data["guard/fault"] = np.zeros(len(data["cnc/feed"]))
    return data, plan


def stack_blocks(stack: str) -> object:
    """The ``full`` or ``default`` stack's blocks (``SessionBlocks``) for the stream."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.online.session import SessionOptions, session_blocks

    data, plan = _stream()
    cfg = load_preset(MachineConfig, str(MACHINE_FILE))
    opts = (
        SessionOptions(quantity="force", force_from="estimate")
        if stack == "full"
        else SessionOptions()
    )
    return session_blocks(plan, cfg, FS, opts, channels=list(data))  # type: ignore[arg-type]


def _time(stack: str, chunk: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Signal seconds, CPU time per chunk of the whole pipeline and of the supervisor."""
    from millsense.streaming.block import Chunk
    from millsense.streaming.engine import Pipeline

    data, _ = _stream()
    built: Any = stack_blocks(stack)
    pipe = Pipeline(built.blocks)
    sup = built.supervisor
    n = len(data["cnc/feed"])
    for _ in range(2):  # the first pass compiles and warms the caches
        pipe.reset(FS)
        total, sup_t = [], []
        orig = sup.process

        def timed(c: Chunk, _orig=orig, _acc=sup_t) -> object:
            c0 = time.thread_time()
            out = _orig(c)
            _acc.append(time.thread_time() - c0)
            return out

        sup.process = timed  # type: ignore[method-assign]
        for a in range(0, n, chunk):
            c = Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in data.items()})
            c0 = time.thread_time()
            pipe.process(c)
            total.append(time.thread_time() - c0)
        sup.process = orig  # type: ignore[method-assign]
    return n / FS, np.array(total), np.array(sup_t)


@benchmark("online.stack")
def _online() -> list[Metric]:
    out: list[Metric] = []
    for stack in ("full", "default"):
        for chunk in (100, 1000):
            sec, tot, sup = _time(stack, chunk)
            what = f"{stack}_{chunk // 10}ms"
            note = (
                f"{stack} stack ({'5 feed estimators + tool forces + ' if stack == 'full' else ''}"
                f"spindle observer, plan sync, chatter, breakage, adaptive feed, supervisor), "
                f"{sec:.0f} s of the V8 slot on the 5-axis truth plant, {chunk // 10} ms chunks, "
                "thread CPU time, one core"
            )
            out.append(
                Metric(f"x_realtime_{what}", sec / float(tot.sum()), "x",
                       target=200.0 if stack == "full" else None, note=note)
            )
            if chunk == 100:
                out += [
                    Metric(f"latency_median_ms_{what}", 1e3 * float(np.median(tot)), "ms",
                           target=1.0, higher_is_better=False, note=note),
                    Metric(f"latency_p99_ms_{what}", 1e3 * float(np.percentile(tot, 99)), "ms",
                           target=1.0, higher_is_better=False, note=note),
                    Metric(f"supervisor_p99_ms_{what}", 1e3 * float(np.percentile(sup, 99)),
                           "ms", higher_is_better=False,
                           note=note + " (the supervisor and its children alone)"),
                ]  # fmt: skip
    return out
