"""Seed-001 observers at 10 kHz: MEDOB + vibration mode + predictive notch bank, one axis.

10 s of CNC data (current, motor angle, scale of a yamada-b cut), streamed in chunks of 100
samples (10 ms) as the online engine does, through the MEDOB (phase-lag delays, current-loop
model, 4th-order Butterworth), the vibration-mode estimator and a notch bank of 4 tracked
harmonics plus the 778.5 Hz torsional notch. Kernels are compiled before the timing.
"""

from __future__ import annotations

import time

import numpy as np

from _harness import Metric, benchmark
from millsense.estimation.dob.mode_decoupled import VibrationModeObserver
from millsense.estimation.dob.notch import NotchBank, NotchBankSpec
from millsense.estimation.dob.observers import DriveParameters, medob_observer
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine

FS_HZ = 10_000.0
SECONDS = 10.0
CHUNK = 100


def _run_chain(cur: np.ndarray, ang: np.ndarray, scale: np.ndarray, p: DriveParameters) -> float:
    r = p.transmission_m_rad
    medob = medob_observer(
        p, FS_HZ, cutoff_hz=500.0, delays_s=(0.4e-3, 0.0, 0.0), current_loop_hz=795.77
    )
    vib = VibrationModeObserver(p, FS_HZ, cutoff_hz=500.0, delays_s=(0.4e-3, 0.0, 0.0))
    bank = NotchBank(NotchBankSpec(p.lead_m / 512.0, fixed_hz=(778.5,)), FS_HZ)
    t0 = time.perf_counter()
    for k in range(0, len(cur), CHUNK):
        s = slice(k, k + CHUNK)
        xm = r * ang[s]
        f = medob.process(cur[s], [xm, scale[s]])
        bank.process(f, xm)
        vib.process(cur[s], xm, scale[s])
    return time.perf_counter() - t0


@benchmark("estimation.dob_chain_10khz")
def _b() -> list[Metric]:
    ax = simulator_machine("yamada-b").axis("x")
    p = DriveParameters.from_axis_config(ax)
    fp = FeedDriveParams.from_config(ax)
    n = int(SECONDS * FS_HZ)
    v = 2e-3 / fp.transmission
    t = np.arange(n) / FS_HZ
    out = FeedDriveSim(fp, FS_HZ).advance(v * t, np.full(n, v), np.zeros(n))
    cur, ang, scale = out["current_cmd"], out["angle"], out["scale"]
    _run_chain(cur[:1000], ang[:1000], scale[:1000], p)  # compile
    wall = _run_chain(cur, ang, scale, p)
    return [
        Metric(
            "wall_time",
            wall,
            "s",
            target=0.1,
            higher_is_better=False,
            note="10 s of 10 kHz data, chunks of 100",
        ),
        Metric(
            "real_time_factor",
            SECONDS / wall,
            "x",
            target=100.0,
            higher_is_better=True,
            note="MEDOB + vibration mode + 5-notch bank, one axis",
        ),
    ]
