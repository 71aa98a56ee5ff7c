"""Benchmarks of millsense.process and the time-domain milling simulation."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.stability.time_domain import DirectionModes, TimeDomainMillingSim


def _td_sim() -> TimeDomainMillingSim:
    return TimeDomainMillingSim(
        EndMill(12e-3, 2, helix_rad=math.radians(30.0)),
        CuttingCoefficients(ktc=7e8, krc=2.5e8, kac=1e8, kte=2e4, kre=1.5e4, kae=5e3),
        Engagement.radial(6e-3, 12e-3, "down"),
        0.1e-3,
        2e-3,
        10000 * 2 * math.pi / 60,
        DirectionModes.from_arrays([600.0, 1400.0, 2600.0], [0.03, 0.02, 0.02], [3e7, 5e7, 8e7]),
        DirectionModes.from_arrays([650.0, 1500.0, 2800.0], [0.03, 0.02, 0.02], [3e7, 5e7, 8e7]),
        n_discs=20,
        steps_per_rev=100,  # 50 steps per tooth period, 2 flutes
    )


@benchmark("stability.time_domain_speed")
def _time_domain() -> list[Metric]:
    sim = _td_sim()
    sim.run(10)  # compile (or load the numba cache)
    sim = _td_sim()
    n_steps = round(1.0 / sim.dt_s)  # 1 s of cutting
    t0 = time.perf_counter()
    sim.run(n_steps)
    wall = time.perf_counter() - t0
    return [
        Metric(
            "x_realtime",
            1.0 / wall,
            "x",
            target=20.0,
            note="1 s of cutting, 2 flutes, 20 discs, 3 modes per direction, 50 steps per "
            f"tooth at 10 000 rev/min ({n_steps} steps), after compilation",
        )
    ]


@benchmark("process.milling_forces_rev")
def _forces() -> list[Metric]:
    tool = EndMill(12e-3, 4, helix_rad=math.radians(30.0), runout_offset_m=5e-6)
    k = CuttingCoefficients(ktc=7e8, krc=2.5e8, kac=1e8, kte=2e4, kre=1.5e4, kae=5e3)
    phi = np.linspace(0.0, 2 * math.pi, 3600, endpoint=False)
    eng = Engagement.radial(6e-3, 12e-3, "down")
    milling_forces(tool, k, eng, 0.1e-3, 3e-3, phi, n_discs=20)
    reps = 5
    t0 = time.perf_counter()
    for _ in range(reps):
        milling_forces(tool, k, eng, 0.1e-3, 3e-3, phi, n_discs=20)
    wall = (time.perf_counter() - t0) / reps
    return [
        Metric(
            "wall_time",
            wall,
            "s",
            higher_is_better=False,
            note="milling_forces: 1 revolution × 3600 angles × 20 discs, 4 flutes with runout",
        )
    ]
