"""Benchmark of the breakage and engagement monitors on a 10 kHz stream (issue 15).

The three breakage blocks (virtual threshold with an expected-torque channel, constant
threshold, dual residual on two force channels) and the per-revolution engagement monitor run
together on 60 s of a synthetic 10 kHz stream at 1000 rev/min (a 2-flute Ø20 mm cut's torque),
in 10 ms and in 0.1 s chunks, after compilation; the breakage blocks alone are reported too.
"""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.monitoring.breakage import BreakageBlock
from millsense.monitoring.engagement import EngagementBlock
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.streaming.block import Block, Chunk

FS = 10000.0


def _stream(seconds: float) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    omega = 1000 * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    eng = Engagement.radial(5e-3, 20e-3, "down")
    phi = 2 * math.pi * np.arange(600) / 600
    rev = milling_forces(tool, co, eng, 0.2e-3, 2e-3, phi).torque_nm
    tq = np.interp(np.mod(omega * t, 2 * math.pi), phi, rev, period=2 * math.pi)
    tq = tq + 0.05 * rng.standard_normal(n)
    return {
        "spindle/torque_est": tq,
        "spindle/speed": np.full(n, omega),
        "plan/torque": np.full(n, 3.0),
        "force_x": 300 * np.sin(2 * omega * t) + rng.standard_normal(n),
        "force_y": 200 * np.cos(2 * omega * t) + rng.standard_normal(n),
    }


def _blocks(engagement: bool) -> list[Block]:
    out: list[Block] = [
        BreakageBlock(2, "virtual", expected_channel="plan/torque"),
        BreakageBlock(2, "constant"),
        BreakageBlock(2, "dual", signal_channels=("force_x", "force_y")),
    ]
    if engagement:
        out.append(EngagementBlock(2, 20.0, 30.0, feed_per_tooth_mm=0.2, n_harmonics=15))
    return out


def _run(data: dict[str, np.ndarray], chunk: int, engagement: bool = True) -> float:
    blocks = _blocks(engagement)
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
    for engagement, what in ((True, "all"), (False, "breakage")):
        for chunk, label in ((100, "10ms"), (1000, "100ms")):
            wall = _run(data, chunk, engagement)
            note = "3 breakage blocks" + (" + engagement (1000 rev/min)" if engagement else "")
            out.append(
                Metric(
                    f"x_realtime_{what}_{label}",
                    seconds / wall,
                    "x",
                    target=500.0,
                    note=f"{note}, {seconds:.0f} s at 10 kHz, {label} chunks, one core",
                )
            )
    return out
