"""The synthetic 10 kHz stream and the breakage/engagement blocks shared by the monitoring
benchmarks (``bench_monitoring_breakage``, ``bench_monitoring_all``)."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from millsense.monitoring.breakage import BreakageBlock
from millsense.monitoring.breakage_phased import PhasedBreakage
from millsense.monitoring.engagement import (
    EngagementBlock,
    cycle_revolutions,
    harmonics_below_nyquist,
)
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.streaming.block import Block, Chunk

FS = 10000.0


#: Standard deviation per 10 kHz sample of the shipped spindle observer's torque estimate
#: against the virtual machine's truth, measured on `millsense run` recordings of slots at
#: 3000, 6000 and 10 000 rev/min (2.08, 2.16, 2.38 N·m; 2026-11-29).
OBSERVER_NOISE_NM = 2.1


def _stream(seconds: float, rpm: float = 1000.0, noise_nm: float = 0.05) -> dict[str, np.ndarray]:
    """The cut's torque plus white noise of ``noise_nm`` per sample (0.05 N·m: a clean
    signal; :data:`OBSERVER_NOISE_NM`: the sensorless estimate's)."""
    rng = np.random.default_rng(0)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    omega = rpm * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    eng = Engagement.radial(5e-3, 20e-3, "down")
    phi = 2 * math.pi * np.arange(600) / 600
    rev = milling_forces(tool, co, eng, 0.2e-3, 2e-3, phi).torque_nm
    tq = np.interp(np.mod(omega * t, 2 * math.pi), phi, rev, period=2 * math.pi)
    tq = tq + noise_nm * rng.standard_normal(n)
    return {
        "spindle/torque_est": tq,
        "spindle/speed": np.full(n, omega),
        "plan/torque": np.full(n, 3.0),
        "force_x": 300 * np.sin(2 * omega * t) + rng.standard_normal(n),
        "force_y": 200 * np.cos(2 * omega * t) + rng.standard_normal(n),
    }


def _blocks(engagement: bool, grouped: bool = False, rpm: float = 1000.0) -> list[Block]:
    """The three breakage detectors, the virtual one at three phases of the tooth period
    (decision 1552; the other two in its compiled call if ``grouped``, as ``millsense monitor``
    runs them), and the engagement monitor if ``engagement`` (15 tooth harmonics or those below
    the Nyquist frequency, decision 1734, and the monitoring cycle `millsense monitor` takes at
    ``rpm``, decision 1717: 1 revolution at 1000 rev/min)."""
    virtual = PhasedBreakage(2, method="virtual", expected_channel="plan/torque")
    others = [
        BreakageBlock(2, "constant"),
        BreakageBlock(2, "dual", signal_channels=("force_x", "force_y")),
    ]
    out: list[Block] = [virtual.with_companions(others)] if grouped else [virtual, *others]
    if engagement:
        out.append(_engagement_block(rpm))
    return out


def _engagement_block(rpm: float, cycle: int | None = None) -> EngagementBlock:
    """The engagement monitor on the stream's 2-flute Ø20 mm cut at ``rpm``: 15 tooth
    harmonics or those below the Nyquist frequency (decision 1734, as `millsense monitor` fits
    them), one estimate per ``cycle`` revolutions (None: the cycle `millsense monitor` takes,
    decision 1717)."""
    return EngagementBlock(
        2, 20.0, 30.0, feed_per_tooth_mm=0.2, n_harmonics=harmonics_below_nyquist(2, rpm, FS, 15),
        cycle_revolutions=cycle_revolutions(rpm) if cycle is None else cycle,
    )  # fmt: skip


def _time_blocks(
    blocks: Sequence[Block], data: dict[str, np.ndarray], chunk: int, repeats: int = 3
) -> float:
    """Wall time of ``blocks`` (reset first) fed ``data`` in chunks of ``chunk`` samples: the
    best of ``repeats`` runs (the host is shared; the fastest run is the least disturbed)."""
    fs = 10000.0
    n = len(data["spindle/speed"])
    best = math.inf
    for _ in range(repeats):
        for b in blocks:
            b.reset(fs)
        t0 = time.perf_counter()
        for i in range(0, n, chunk):
            for b in blocks:
                b.process(Chunk(i, fs, 0.0, {k: data[k][i : i + chunk] for k in b.inputs}))
        best = min(best, time.perf_counter() - t0)
    return best
