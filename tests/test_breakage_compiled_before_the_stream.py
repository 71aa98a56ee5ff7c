"""Decision 1547: the breakage kernels are compiled (or loaded from numba's cache) when a
block is reset, before the stream: the first chunk of a session compiles nothing."""

from __future__ import annotations

import math

import numpy as np

from millsense.monitoring import _tooth_kernels as _k
from millsense.monitoring.breakage import BreakageBlock, BreakageGroup
from millsense.streaming.block import Chunk

#: the kernels the blocks call from Python (the others are compiled into these)
KERNELS = ("segment_periods", "periods_step", "segment_group", "periods_group", "group_step")


def _signatures() -> dict[str, int]:
    return {name: len(getattr(_k, name).signatures) for name in KERNELS}


def test_a_reset_block_compiles_nothing_on_its_first_chunks() -> None:
    fs, n = 10000.0, 3000
    t = np.arange(n) / fs
    speed = np.full(n, 2 * math.pi * 1500.0 / 60.0)
    torque = 5.0 + np.cos(2 * np.pi * 50.0 * t)
    one = BreakageBlock(2, "virtual", signal_channels=("torque",), expected_channel="plan")
    group = BreakageGroup([BreakageBlock(2, m, signal_channels=("torque",), name=m,
                                         expected_channel="plan")
                           for m in ("virtual", "constant")])  # fmt: skip
    one.reset(fs)
    group.reset(fs)
    ready = _signatures()
    assert all(v >= 1 for v in ready.values()), ready  # compiled at the reset
    data = {"torque": torque, "plan": np.full(n, 5.0), "spindle/speed": speed}
    for block in (one, group):
        for s in range(0, n, 100):
            block.process(Chunk(s, fs, 0.0, {k: v[s : s + 100] for k, v in data.items()}))
    assert _signatures() == ready  # the stream's chunks compiled nothing new
