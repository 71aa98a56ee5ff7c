"""Decision 1549: ``millsense warm-up`` compiles the on-line system's kernels into numba's cache
once, so that a later (live) session compiles nothing while the machine runs."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numba
import numpy as np

from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Chunk
from millsense.streaming.sources import Source
from millsense.warm_up import ONLINE_S, FirstSeconds, compiled_kernels, warm_up


class _Counter(Source):
    """1000 samples of a ramp at 10 kHz."""

    sample_rate_hz = 10000.0

    def __init__(self) -> None:
        self.k = 0

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [ChannelInfo("x", "1")]

    def read(self, max_samples: int) -> Chunk | None:
        n = min(max_samples, 1000 - self.k)
        if n <= 0:
            return None
        x = np.arange(self.k, self.k + n, dtype=float)
        c = Chunk(self.k, self.sample_rate_hz, 0.0, {"x": x})
        self.k += n
        return c


def test_first_seconds_ends_the_source_there() -> None:
    src = FirstSeconds(_Counter(), 0.05)  # 500 samples of the 1000
    sizes = []
    while (c := src.read(300)) is not None:
        sizes.append(c.n)
        last = c.data["x"][-1]
    assert sizes == [300, 200] and last == 499.0


def test_compiled_kernels_names_what_compiles_and_nothing_cached() -> None:
    @numba.njit
    def twice(x: float) -> float:  # a new dispatcher: compiled on its first call
        return 2.0 * x

    with compiled_kernels(__name__) as first:
        twice(1.0)
    with compiled_kernels(__name__) as again:
        twice(2.0)  # the same signature: nothing compiles
    assert [n.rsplit(".", 1)[-1] for n in first] == ["twice"] and again == []


def test_after_the_warm_up_a_longer_session_compiles_nothing() -> None:
    # the demo part's session runs for twice the warm-up's seconds (its first cut goes on, the
    # supervisor, monitors and adaptive feed keep running): every kernel it reaches is cached
    from millsense import demo_online

    warm_up()
    with compiled_kernels() as names, tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        plan, plant = demo_online._plan(out), demo_online._plant_plan()
        demo_online._run(plan, plant, True, out / "r.h5", out / "e.parquet", None,
                         wrap=lambda s: FirstSeconds(s, 2 * ONLINE_S))  # fmt: skip
    assert names == []


def test_after_the_warm_up_the_engagement_monitor_compiles_nothing() -> None:
    # another tool and engagement than the warm-up's (3 flutes, 8 mm radial, up milling, no
    # air revolution: the harmonics-only path), through the registry as `millsense monitor`
    # builds it: every kernel it reaches is cached
    import math

    from millsense.monitoring.engagement import EngagementBlock
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill
    from millsense.warm_up import _engagement_cuts

    _engagement_cuts()
    fs, n = 10000.0, 12000
    t = np.arange(n) / fs
    omega = 2 * math.pi * 1500.0 / 60.0
    phi = 2 * math.pi * np.arange(600) / 600
    co = CuttingCoefficients(ktc=700e6, krc=300e6, kte=20e3, kre=30e3)
    tool = EndMill(16e-3, 3, helix_rad=math.radians(35))
    eng = Engagement.radial(8e-3, 16e-3, "up")
    rev = milling_forces(tool, co, eng, 0.08e-3, 3e-3, phi).torque_nm
    tq = np.interp(np.mod(omega * t, 2 * math.pi), phi, rev, period=2 * math.pi)
    data = {"spindle/torque_est": tq, "spindle/speed": np.full(n, omega)}
    block = EngagementBlock(3, 16.0, 35.0, feed_per_tooth_mm=0.08)
    with compiled_kernels() as names:
        block.reset(fs)
        for k in range(0, n, 1000):
            block.process(Chunk(k, fs, 0.0, {c: v[k : k + 1000] for c, v in data.items()}))
    assert [e for _, e in block.estimates if e is not None]  # it evaluated revolutions
    assert names == []
