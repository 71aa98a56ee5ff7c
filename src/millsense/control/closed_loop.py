"""Closed loop: a live source (the virtual machine, later a CNC), controller blocks in the
pipeline, their override events fed back to the source (:func:`~millsense.streaming.engine.run`
does the feeding back before the next chunk is read, so a 10 ms chunk is a 10 ms control
block).

:class:`Dynamometer` stands for the table dynamometer of seed 002 (Kistler 9257A) on the
virtual machine: it passes the simulator's true tool force on as a measured channel, so a
controller can regulate on it without itself being allowed to read ``truth/`` channels
(decision 1616). :func:`run_closed_loop` runs the loop and keeps the source channels asked
for beside the blocks' outputs; it does not import the simulator (``control`` sits below it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind
from millsense.streaming.engine import Pipeline, run
from millsense.streaming.sources import Source

#: White noise of the virtual table dynamometer a controller reads on the virtual machine, N RMS
#: per axis (the on-line session's and the V6/V8 cases', decision 1798).
DYNAMOMETER_NOISE_N = 2.0


class Dynamometer(Block):
    """Measured XY force from the source's true tool force (a table dynamometer).

    Outputs ``force_x``, ``force_y`` (N): the true force plus optional white noise of
    ``noise_n`` N (seeded, drawn per absolute sample index so chunking does not matter).
    """

    reads_truth = True

    def __init__(
        self,
        truth: tuple[str, str] = ("truth/tool/force_x", "truth/tool/force_y"),
        out: tuple[str, str] = ("force_x", "force_y"),
        noise_n: float = 0.0,
        seed: int = 0,
        name: str = "dynamometer",
    ) -> None:
        self.inputs = truth
        self.out = out
        self.noise_n = float(noise_n)
        self.seed = seed
        self.name = name

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(c, "N", "dynamometer force") for c in self.out]

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = sample_rate_hz

    def process(self, chunk: Chunk) -> BlockOutput:
        out: dict[str, np.ndarray] = {}
        for i, (src, dst) in enumerate(zip(self.inputs, self.out, strict=True)):
            v = np.asarray(chunk.data[src], dtype=np.float64)
            if self.noise_n > 0 and chunk.n:
                idx = chunk.start + np.arange(chunk.n, dtype=np.uint64)
                # counter-based noise: a hash of (seed, channel, sample) → N(0, 1) by Box–Muller
                u1, u2 = _uniform(idx, self.seed * 2 + i)
                v = v + self.noise_n * np.sqrt(-2 * np.log(u1)) * np.cos(2 * np.pi * u2)
            out[dst] = v
        return BlockOutput(out)


def _uniform(idx: np.ndarray, key: int) -> tuple[np.ndarray, np.ndarray]:
    """Two uniform (0, 1] streams from a splitmix64 hash of the sample index."""

    def mix(z: np.ndarray) -> np.ndarray:
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))

    with np.errstate(over="ignore"):
        base = idx * np.uint64(2) + np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
        a = mix(base)
        b = mix(base + np.uint64(1))
    scale = 1.0 / 2.0**64
    return (a.astype(np.float64) + 1.0) * scale, (b.astype(np.float64) + 1.0) * scale


@dataclass
class ClosedLoopResult:
    """Kept source channels and block outputs over the run, and all events."""

    sample_rate_hz: float
    channels: dict[str, np.ndarray]
    events: list[Event] = field(default_factory=list)

    def overrides(self, source: str | None = None) -> list[Event]:
        """The ``feed_override`` events (of one block if ``source`` is given)."""
        return [
            e
            for e in self.events
            if e.kind is EventKind.OVERRIDE
            and e.name == "feed_override"
            and (source is None or e.source == source)
        ]

    @property
    def time_s(self) -> np.ndarray:
        n = len(next(iter(self.channels.values()))) if self.channels else 0
        return np.arange(n) / self.sample_rate_hz


def run_closed_loop(
    source: Source,
    blocks: Sequence[Block],
    keep: Sequence[str] = (),
    chunk_samples: int = 100,
) -> ClosedLoopResult:
    """Run ``blocks`` on ``source`` in chunks of ``chunk_samples``, override events fed back.

    ``keep``: source channels to keep beside every block output (e.g. ``truth/...`` channels
    for scoring, ``cnc/feed_override``).
    """
    pipe = Pipeline(blocks)
    kept: dict[str, list[np.ndarray]] = {k: [] for k in keep}

    def sink(chunk: Chunk, outputs: dict[str, np.ndarray], events: list[Event]) -> None:
        for k in keep:
            kept[k].append(np.asarray(chunk.data[k]))

    res = run(source, pipe, chunk_samples, sink=sink)
    chans = {k: np.concatenate(v) if v else np.zeros(0) for k, v in kept.items()}
    chans.update(res.channels)
    return ClosedLoopResult(source.sample_rate_hz, chans, list(res.events))
