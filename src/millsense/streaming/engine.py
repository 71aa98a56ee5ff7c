"""Pipeline of blocks and the loop that feeds it from a source.

The same :func:`run` serves a live source (the virtual machine tool, a CNC connection) and the
replay of a recording: a source hands out chunks, the pipeline processes them block by block,
override events go back to the source, outputs and events are collected (and optionally
written to a recording while running, so a crash loses at most the last unflushed chunk).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from operator import itemgetter

import numpy as np

from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, Chunk, Event, EventKind
from millsense.streaming.sources import Source


class Pipeline:
    """Blocks run in order; each sees the source channels plus earlier blocks' outputs.

    A block is handed only the channels it declares in ``inputs``; declaring a ``truth/``
    channel is refused unless the block sets ``reads_truth`` (evaluation blocks only), which
    enforces the rule that estimators never see the simulator's ground truth.
    """

    def __init__(self, blocks: Sequence[Block]) -> None:
        self.blocks = list(blocks)
        #: the blocks and the sorted channels they read (checked for NaN/inf per chunk)
        self._inputs: tuple[tuple[Block, ...], list[str]] = ((), [])
        #: of those, a getter of the ones the last chunk carried, and the others
        self._carried: tuple[_Getter, tuple[str, ...]] = (_channels_getter(()), ())
        names = [b.name for b in self.blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"block names must be unique, got {names}")
        for b in self.blocks:
            leaks = [c for c in b.inputs if c.startswith("truth/")]
            if leaks and not b.reads_truth:
                raise ValueError(
                    f"block '{b.name}' reads ground-truth channels {leaks}; "
                    "estimators, monitors and controllers may read only what a CNC provides"
                )

    def output_channels(self) -> list[ChannelInfo]:
        return [info for b in self.blocks for info in b.output_channels()]

    def check_inputs(self, available: Sequence[str], source_name: str) -> None:
        """Raise a one-line error if a block needs a channel nobody provides."""
        have = set(available)
        for b in self.blocks:
            for c in b.inputs:
                if c not in have:
                    raise InputDataError(
                        f"{source_name}: block '{b.name}' needs channel '{c}', which the source "
                        f"does not provide (available: {', '.join(sorted(have))})"
                    )
            have.update(info.name for info in b.output_channels())

    def reset(self, sample_rate_hz: float) -> None:
        for b in self.blocks:
            b.reset(sample_rate_hz)

    def set_source_name(self, name: str) -> None:
        self._source_name = name

    def _require_finite(self, chunk: Chunk) -> None:
        """One-line error naming the channel and time of the first NaN/inf a block would read
        (the channels the blocks read are listed once, not per chunk)."""
        blocks = tuple(self.blocks)
        if self._inputs[0] != blocks:
            self._inputs = (blocks, sorted({c for b in blocks for c in b.inputs}))
            self._carried = (_channels_getter(()), tuple(self._inputs[1]))
        data = chunk.data
        read = self._read(data)
        if not read or self._finite(read):
            return
        for name in self._inputs[1]:
            values = data.get(name)
            if values is None or np.isfinite(values).all():
                continue
            k = int(np.argmax(~np.isfinite(values)))
            t = chunk.t0_s + (chunk.start + k) / chunk.sample_rate_hz
            raise InputDataError(
                f"{getattr(self, '_source_name', 'source')}: channel '{name}' has "
                f"{values[k]} at sample {chunk.start + k} (t = {t:.6g} s)"
            )

    def _read(self, data: Mapping[str, np.ndarray]) -> tuple[np.ndarray, ...]:
        """The channels the blocks read that ``data`` carries, in name order: taken by the
        names the last chunk carried (one call), unless ``data`` lacks one of them or carries
        one of the others."""
        get, others = self._carried
        try:
            if not any(map(data.__contains__, others)):
                return get(data)
        except KeyError:
            pass
        names = self._inputs[1]
        get = _channels_getter(tuple(c for c in names if c in data))
        self._carried = (get, tuple(c for c in names if c not in data))
        return get(data)

    @staticmethod
    def _finite(read: tuple[np.ndarray, ...]) -> bool:
        """No value of ``read`` is NaN or inf: one sum of all the channels, finite unless a value
        is NaN or inf (or the sum overflows, which the channel-by-channel search of the caller
        then clears). Not a compiled pass over the tuple: numba compiles one per number of
        channels, which a live session's first chunk would wait for (decision 1549)."""
        return math.isfinite(np.add.reduce(np.concatenate(read, axis=None)))

    def process(self, chunk: Chunk) -> tuple[dict[str, np.ndarray], list[Event]]:
        """Run every block on ``chunk``; returns all block outputs and events."""
        data = dict(chunk.data)
        self._require_finite(chunk)
        outputs: dict[str, np.ndarray] = {}
        events: list[Event] = []
        n = chunk.n
        start, rate, t0 = chunk.start, chunk.sample_rate_hz, chunk.t0_s
        for b in self.blocks:
            # the chunk restricted to the block's inputs (as Chunk.restricted, without an
            # intermediate chunk)
            out = b.process(Chunk(start, rate, t0, {k: data[k] for k in b.inputs}))
            channels = out.channels
            for name, values in channels.items():
                if len(values) != n:
                    raise RuntimeError(
                        f"block '{b.name}' returned {len(values)} samples of '{name}' "
                        f"for a chunk of {n}"
                    )
            data.update(channels)
            outputs.update(channels)
            if out.events:
                events.extend(out.events)
        return outputs, events


_Getter = Callable[[Mapping[str, np.ndarray]], tuple[np.ndarray, ...]]


def _channels_getter(names: tuple[str, ...]) -> _Getter:
    """A function giving the values of ``names`` in a mapping, as a tuple (one C call)."""
    if len(names) >= 2:
        return itemgetter(*names)
    return lambda data: tuple(data[c] for c in names)


@dataclass
class RunResult:
    """Outputs of a run: block channels concatenated over chunks, and all events."""

    sample_rate_hz: float
    t0_s: float
    channels: dict[str, np.ndarray]
    channel_info: list[ChannelInfo]
    events: list[Event] = field(default_factory=list)

    @property
    def n_samples(self) -> int:
        for v in self.channels.values():
            return len(v)
        return 0


ChunkSink = Callable[[Chunk, dict[str, np.ndarray], list[Event]], None]


def run(
    source: Source,
    pipeline: Pipeline,
    chunk_samples: int,
    *,
    sink: ChunkSink | None = None,
    on_progress: Callable[[int], None] | None = None,
    collect: bool = True,
) -> RunResult:
    """Feed ``pipeline`` from ``source`` in chunks of ``chunk_samples`` until it ends.

    Override events are passed back to the source before the next chunk is read (a live
    source applies them with its own latency; a replay records them). ``sink`` receives every
    chunk with its outputs as soon as they exist (e.g. a live recording writer), and
    ``on_progress`` the number of samples processed so far.

    ``collect``: keep every output sample for :attr:`RunResult.channels` (the default). With
    ``collect=False`` the outputs exist only chunk by chunk in ``sink`` and the result's
    ``channels`` are empty: memory does not grow with the length of the stream (decision 0961).
    """
    if chunk_samples < 1:
        raise ValueError("chunk_samples must be >= 1")
    pipeline.check_inputs(source.channel_names, source.name)
    pipeline.set_source_name(source.name)
    pipeline.reset(source.sample_rate_hz)
    pieces: dict[str, list[np.ndarray]] = {c.name: [] for c in pipeline.output_channels()}
    events: list[Event] = []
    done = 0
    while True:
        chunk = source.read(chunk_samples)
        if chunk is None or chunk.n == 0:
            break
        outputs, chunk_events = pipeline.process(chunk)
        if collect:
            for name, values in outputs.items():
                pieces.setdefault(name, []).append(np.asarray(values))
        events.extend(chunk_events)
        for ev in chunk_events:
            if ev.kind is EventKind.OVERRIDE:
                source.command(ev)
        if sink is not None:
            sink(chunk, outputs, chunk_events)
        done += chunk.n
        if on_progress is not None:
            on_progress(done)
    channels = (
        {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in pieces.items()} if collect else {}
    )
    return RunResult(
        sample_rate_hz=source.sample_rate_hz,
        t0_s=source.t0_s,
        channels=channels,
        channel_info=pipeline.output_channels(),
        events=events,
    )
