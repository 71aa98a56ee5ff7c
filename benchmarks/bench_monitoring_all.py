"""Benchmark of all process monitors together on one 10 kHz stream (issue 15).

The three chatter criteria as one group, the three breakage detectors as one group (as
``millsense monitor`` runs them) and the per-revolution engagement monitor run on 60 s of the
synthetic stream of ``bench_monitoring_breakage`` (a 2-flute Ø20 mm cut's torque at
1000 rev/min), in 10 ms and 0.1 s chunks, after compilation; each block gets its declared
channels per chunk as the pipeline hands them.
"""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from _monitoring_stream import OBSERVER_NOISE_NM, _blocks, _stream, _time_blocks
from millsense.monitoring.chatter import METHODS, ChatterGroup, ChatterMonitor, ChatterSettings
from millsense.streaming.block import Block, Chunk
from millsense.streaming.engine import Pipeline

FS = 10000.0


def _all_blocks() -> list[Block]:
    group = ChatterGroup(
        [
            ChatterMonitor(ChatterSettings(method=m, signal="spindle/torque_est", n_flutes=2))
            for m in METHODS
        ]
    )
    return [group, *_blocks(True, grouped=True)]


def _run(data: dict[str, np.ndarray], chunk: int) -> float:
    return _time_blocks(_all_blocks(), data, chunk)


def _run_pipeline(data: dict[str, np.ndarray], chunk: int, repeats: int = 3) -> float:
    """Wall time of the same blocks in a :class:`~millsense.streaming.engine.Pipeline` (as
    ``millsense monitor`` runs them: the NaN/inf check, a restricted chunk per block, the
    outputs merged), best of ``repeats`` runs."""
    n = len(data["spindle/speed"])
    best = math.inf
    for _ in range(repeats):
        pipeline = Pipeline(_all_blocks())
        pipeline.reset(FS)
        t0 = time.perf_counter()
        for i in range(0, n, chunk):
            pipeline.process(Chunk(i, FS, 0.0, {k: v[i : i + chunk] for k, v in data.items()}))
        best = min(best, time.perf_counter() - t0)
    return best


@benchmark("monitoring.all_speed")
def _speed() -> list[Metric]:
    _time_blocks(_all_blocks(), _stream(2.0), 100, repeats=1)  # compile / load the numba cache
    seconds = 60.0
    data = _stream(seconds)
    what = (
        "chatter-comb + chatter-sdft + chatter-threshold (one group), 3 breakage detectors (the "
        "virtual one at three phases, decision 1552; one compiled call), engagement (1000 "
        f"rev/min), {seconds:.0f} s at 10 kHz"
    )
    out = []
    streams = (
        ("", data, ""),
        ("sensorless_", _stream(seconds, noise_nm=OBSERVER_NOISE_NM),
         f" with the sensorless estimate's noise ({OBSERVER_NOISE_NM} N·m per sample, decision "
         "1557)"),
    )  # fmt: skip
    for prefix, stream, noise in streams:
        for chunk, label in ((100, "10ms"), (1000, "100ms")):
            wall = _run(stream, chunk)
            out.append(
                Metric(
                    f"x_realtime_{prefix}{label}",
                    seconds / wall,
                    "x",
                    target=500.0,
                    note=f"{what}{noise}, {label} chunks, one core, best of 3 runs",
                )
            )
    for chunk, label in ((100, "10ms"), (1000, "100ms")):
        wall = _run_pipeline(data, chunk)
        out.append(
            Metric(
                f"x_realtime_pipeline_{label}",
                seconds / wall,
                "x",
                note=f"the same blocks in a streaming Pipeline (NaN/inf check, a chunk per block, "
                f"outputs merged), {label} chunks, one core, best of 3 runs",
            )
        )
    return out


@benchmark("monitoring.engagement_speed")
def _engagement_speed() -> list[Metric]:
    """The engagement monitor alone (Lee's fit once a revolution) on the clean stream and on
    the same cut with the sensorless estimate's noise (:data:`OBSERVER_NOISE_NM` per sample),
    at 1000 and 6000 rev/min, 0.1 s chunks. With noise the previous revolution's solution never
    explains the next one to the accept misfit, which is what makes the global search run."""
    from millsense.monitoring.engagement import EngagementBlock

    def block() -> list[Block]:
        return [EngagementBlock(2, 20.0, 30.0, feed_per_tooth_mm=0.2, n_harmonics=15)]

    _time_blocks(block(), _stream(1.0, 6000.0, OBSERVER_NOISE_NM), 1000, repeats=1)  # compile
    seconds = 10.0
    out = []
    for rpm in (1000.0, 6000.0):
        for noise, label in ((0.05, "clean"), (OBSERVER_NOISE_NM, "sensorless")):
            wall = _time_blocks(block(), _stream(seconds, rpm, noise), 1000, repeats=2)
            out.append(
                Metric(
                    f"x_realtime_{label}_{rpm:.0f}rpm",
                    seconds / wall,
                    "x",
                    note=f"engagement monitor, 2-flute Ø20 mm cut at {rpm:.0f} rev/min, noise "
                    f"{noise:g} N·m per sample, {seconds:.0f} s at 10 kHz, 0.1 s chunks, one "
                    "core, best of 2",
                )
            )
    return out
