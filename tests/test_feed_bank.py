"""The feed estimators of all axes as one block (decision 1652): bit for bit what the blocks
give one by one, in every chunking."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from millsense.core.config import MachineConfig
from millsense.core.presets import load_preset
from millsense.estimation.feed.bank import FeedEstimatorBank, bank_or_blocks
from millsense.estimation.from_config import build_estimators
from millsense.streaming.block import Block, Chunk

ROOT = Path(__file__).resolve().parents[1]
MACHINE_FILE = ROOT / "examples/walkthrough/quaser-ux600-commissioned.toml"
FS = 10000.0


def _stream(axes: list[str], n: int) -> dict[str, np.ndarray]:
    """Currents, encoder speeds and commanded positions: each axis moves, holds, reverses."""
    rng = np.random.default_rng(3)
    t = np.arange(n) / FS
    data = {}
    for i, ax in enumerate(axes):
        v = np.where((t > 0.05 * (i + 1)) & (t < 0.15 + 0.03 * i), 0.0, 0.02 * np.sin(9 * t + i))
        data[f"{ax}/position_cmd"] = np.cumsum(v) / FS
        data[f"{ax}/motor_speed"] = 50 * v + 0.05 * rng.standard_normal(n)
        noise = 0.1 * rng.standard_normal(n)
        data[f"{ax}/current_cmd"] = 2 * np.sin(2 * np.pi * 33 * t + i) + noise
    return data


def _run(blocks: list[Block], data: dict[str, np.ndarray], chunk: int) -> dict[str, np.ndarray]:
    for b in blocks:
        b.reset(FS)
    n = len(next(iter(data.values())))
    outs: dict[str, list[np.ndarray]] = {}
    for a in range(0, n, chunk):
        for b in blocks:
            c = Chunk(a, FS, 0.0, {k: data[k][a : a + chunk] for k in b.inputs})
            for k, v in b.process(c).channels.items():
                outs.setdefault(k, []).append(np.array(v, copy=True))
    return {k: np.concatenate(v) for k, v in outs.items()}


def test_bank_is_the_blocks_bit_for_bit_in_any_chunking() -> None:
    machine = load_preset(MachineConfig, str(MACHINE_FILE))
    axes = list(machine.axes)
    feed = build_estimators(machine, ["feed"], axes, FS)
    banked = bank_or_blocks(feed.blocks)
    assert len(banked) == 1 and isinstance(banked[0], FeedEstimatorBank)
    bank = banked[0]
    assert [c.name for c in bank.output_channels()] == [
        c.name for b in feed.blocks for c in b.output_channels()
    ]
    data = _stream(axes, 4000)
    for chunk in (4000, 100, 73, 1):
        # the blocks are chunk-invariant to rounding (a running mean restarts per chunk):
        # the bank is compared with them in the same chunking
        ref = _run(list(feed.blocks), data, chunk)
        got = _run([bank], data, chunk)
        assert got.keys() == ref.keys()
        for k in ref:
            assert np.array_equal(got[k], ref[k]), (chunk, k)
