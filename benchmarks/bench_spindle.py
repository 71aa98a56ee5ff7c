"""Benchmarks of the spindle drive and the interpolator."""

from __future__ import annotations

import math
import time

import numpy as np

from _harness import Metric, benchmark
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.simulator.interpolator import Interpolator, Upsampler
from millsense.simulator.spindle import SpindleDriveSim
from millsense.simulator.truth_spindle import TruthSpindleSim, load_truth_spindle


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


@benchmark("machine.truth_spindle_realtime")
def _truth_spindle() -> list[Metric]:
    """The truth spindle (decision 1210) against Aslan's Ch. 5 kernel in the same run: the
    same 60 s in 1 s chunks, the better of three runs each, alternating."""
    p = SpindleDriveParams.aslan_quaser()
    t = load_truth_spindle("quaser-ux600")
    n = 600_000
    tt = np.arange(n) * 1e-4
    ref = np.full(n, 5000 * 2 * math.pi / 60)  # range 2, the ripple and drag active
    tau = 5.0 * (1 + np.sin(2 * math.pi * 166.7 * tt))
    walls: dict[str, float] = {"ideal": math.inf, "truth": math.inf}
    for _ in range(3):
        for name in ("ideal", "truth"):
            sim = SpindleDriveSim(p) if name == "ideal" else TruthSpindleSim(t)
            sim.advance(ref[:10], tau[:10])  # compile / load cache
            t0 = time.perf_counter()
            for k in range(0, n, 10_000):
                sim.advance(ref[k : k + 10_000], tau[k : k + 10_000])
            walls[name] = min(walls[name], time.perf_counter() - t0)
    return [
        Metric(
            "x_realtime",
            60.0 / walls["truth"],
            "x",
            target=20.0,
            note="truth spindle: 4 inertias + current (9 states), current PI at 20 kHz "
            "(2 ZOH steps per sample), ripple 4 harmonics, drag; 60 s at 10 kHz, 1 s chunks",
        ),
        Metric(
            "x_realtime_ideal_same_run",
            60.0 / walls["ideal"],
            "x",
            note="Aslan's Ch. 5 kernel (25 states, 1 step per sample), same run",
        ),
        Metric(
            "cost_ratio_truth_over_ideal",
            walls["truth"] / walls["ideal"],
            "x",
            higher_is_better=False,
            baseline="machine.spindle_realtime kernel (Aslan Ch. 5), same run",
            note="wall time of the truth / the ideal kernel, best of 3 each, same run",
        ),
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


@benchmark("estimation.spindle_dob_speed")
def _spindle_dob() -> list[Metric]:
    """The spindle DOB for breakage (decision 1726) with its air reference, as a session runs
    them by default (decision 1727): 60 s at 10 kHz of the commissioned quaser-ux600's
    spindle, in 10 ms and 0.1 s chunks, after compilation, best of 3."""
    from millsense.core.presets import commissioned_machine
    from millsense.estimation.from_config import spindle_dob_from_config
    from millsense.estimation.spindle_dob import DOB_TORQUE
    from millsense.online.gates import AirReference
    from millsense.streaming.block import Chunk

    shipped = commissioned_machine("quaser-ux600")
    assert shipped is not None
    fs, seconds = 10000.0, 60.0
    n = int(seconds * fs)
    rng = np.random.default_rng(0)
    w = 2 * math.pi * 50.0
    data = {
        "spindle/current_cmd": 2.0 + 0.3 * rng.standard_normal(n),
        "spindle/speed": w + 0.06 * rng.standard_normal(n),
        "spindle/speed_cmd": np.full(n, w),
        "plan/in_cut": (np.arange(n) > fs).astype(float),
        "spindle/at_speed": np.ones(n),
    }
    out = []
    for chunk, label in ((100, "10ms"), (1000, "100ms")):
        best = math.inf
        for _ in range(4):  # the first run compiles / loads the cache
            blocks = [spindle_dob_from_config(*shipped),
                      AirReference(DOB_TORQUE, "plan/in_cut", "spindle/at_speed",
                                   out="dob_cutting", name="dob_air")]  # fmt: skip
            for b in blocks:
                b.reset(fs)
            t0 = time.perf_counter()
            for k in range(0, n, chunk):
                d = {c: v[k : k + chunk] for c, v in data.items()}
                d[DOB_TORQUE] = blocks[0].process(Chunk(k, fs, 0.0, d)).channels[DOB_TORQUE]
                blocks[1].process(Chunk(k, fs, 0.0, d))
            best = min(best, time.perf_counter() - t0)
        out.append(Metric(f"us_per_chunk_{label}", best / (n / chunk) * 1e6, "us",
                          higher_is_better=False,
                          note=f"spindle DOB + its air reference, {label} chunks (each block "
                          "handed its chunk, as a pipeline does), 60 s at 10 kHz, one core, "
                          "best of 3 after a compiling run"))  # fmt: skip
    return out
