"""Sources of chunks: a recording replayed, or a live source (the simulator, a CNC link).

Both implement :class:`Source`, so the engine loop is the same for replay and live runs.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any

import numpy as np

from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Chunk, Event


class Source(ABC):
    """Hands out consecutive chunks at a common sample rate and accepts commands."""

    name: str = "source"
    sample_rate_hz: float
    t0_s: float = 0.0

    @property
    @abstractmethod
    def channel_info(self) -> list[ChannelInfo]:
        """Channels each chunk carries (measured ones, and ``truth/`` ones if simulated)."""

    @property
    def channel_names(self) -> list[str]:
        return [c.name for c in self.channel_info]

    @abstractmethod
    def read(self, max_samples: int) -> Chunk | None:
        """The next chunk of at most ``max_samples`` samples, or None at the end."""

    def command(self, event: Event) -> None:  # noqa: B027 - optional for sources
        """Apply an override command (a replay only records it)."""


class RecordingSource(Source):
    """Replays a recording chunk by chunk (overrides are recorded, not applied).

    ``recording``: an in-memory :class:`~millsense.core.recording.Recording`, or anything with
    its ``sample_rate_hz``, ``t0_s``, ``n_samples``, ``metadata``, ``channel_names``, ``info``
    and a ``window(name, start, stop)`` method (:class:`~millsense.io.recording_reader.
    RecordingReader`, which reads the samples from the file when they are needed).
    ``stop_sample``: the replay ends before this sample (None: at the end of the recording).
    ``channels``: replay only these channels (None: all); the others are never read.

    A windowed recording is read ahead in :data:`READ_AHEAD` samples per channel (few HDF5
    calls whatever the chunk size) and chunks are handed out of that buffer: the chunks are
    the same samples as from memory, so the replay's outputs do not depend on where the data
    come from, and memory is bounded by the read-ahead, not by the recording (decision 0961).
    """

    #: Samples per channel read from a windowed recording at once.
    READ_AHEAD = 16384

    def __init__(
        self,
        recording: Any,
        name: str | None = None,
        stop_sample: int | None = None,
        channels: Sequence[str] | None = None,
    ) -> None:
        self.recording = recording
        self.name = name or str(recording.metadata.get("source", "recording"))
        self.sample_rate_hz = recording.sample_rate_hz
        self.t0_s = recording.t0_s
        n = recording.n_samples
        self._stop = n if stop_sample is None else max(0, min(int(stop_sample), n))
        self._pos = 0
        wanted = None if channels is None else set(channels)
        self._names = [c for c in recording.channel_names if wanted is None or c in wanted]
        self._window = getattr(recording, "window", None)
        self._buf: dict[str, np.ndarray] = {}
        self._buf_start = 0
        self._buf_stop = 0
        self.commands: list[Event] = []

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [self.recording.info(n) for n in self._names]

    @property
    def channel_names(self) -> list[str]:
        return list(self._names)

    def _windowed(self, start: int, stop: int) -> dict[str, np.ndarray]:
        if stop > self._buf_stop or start < self._buf_start:
            end = min(self._stop, max(stop, start + self.READ_AHEAD))
            self._buf = {n: self._window(n, start, end) for n in self._names}  # type: ignore[misc]
            self._buf_start, self._buf_stop = start, end
        a, b = start - self._buf_start, stop - self._buf_start
        return {n: v[a:b] for n, v in self._buf.items()}

    def read(self, max_samples: int) -> Chunk | None:
        n_total = self._stop
        if self._pos >= n_total:
            return None
        stop = min(n_total, self._pos + max_samples)
        if self._window is not None:
            data = self._windowed(self._pos, stop)
        else:
            data = {n: self.recording.channel(n)[self._pos : stop] for n in self._names}
        chunk = Chunk(self._pos, self.sample_rate_hz, self.t0_s, data)
        self._pos = stop
        return chunk

    def command(self, event: Event) -> None:
        self.commands.append(event)


#: Codes of a source's fault channel (``guard/fault`` of :mod:`millsense.online.guard`), read
#: by the arbiter (:mod:`millsense.control.arbitration`): code → what happened.
SOURCE_FAULTS = {1: "non-finite samples", 2: "samples lost", 3: "stream stalled", 4: "source lost"}


class SourceWrapper(Source):
    """A source in front of another (a guard, an injected fault, a stop condition): by default
    the inner source's rate, start, channels, chunks and commands; what a live source offers
    beyond the contract (its events, stream rows, metadata) is passed on by attribute."""

    def __init__(self, inner: Source) -> None:
        self.inner = inner
        self.name = inner.name
        self.sample_rate_hz = inner.sample_rate_hz
        self.t0_s = inner.t0_s

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return self.inner.channel_info

    def read(self, max_samples: int) -> Chunk | None:
        return self.inner.read(max_samples)

    def command(self, event: Event) -> None:
        self.inner.command(event)

    def __getattr__(self, name: str) -> Any:
        if name == "inner":  # not yet set (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)
