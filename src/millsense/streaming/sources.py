"""Sources of chunks: a recording replayed, or a live source (the simulator, a CNC link).

Both implement :class:`Source`, so the engine loop is the same for replay and live runs.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from millsense.core.recording import ChannelInfo, Recording
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
    """Replays a :class:`Recording` chunk by chunk (overrides are recorded, not applied).

    ``stop_sample``: the replay ends before this sample (None: at the end of the recording).
    """

    def __init__(
        self, recording: Recording, name: str | None = None, stop_sample: int | None = None
    ) -> None:
        self.recording = recording
        self.name = name or str(recording.metadata.get("source", "recording"))
        self.sample_rate_hz = recording.sample_rate_hz
        self.t0_s = recording.t0_s
        n = recording.n_samples
        self._stop = n if stop_sample is None else max(0, min(int(stop_sample), n))
        self._pos = 0
        self.commands: list[Event] = []

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [self.recording.info(n) for n in self.recording.channel_names]

    def read(self, max_samples: int) -> Chunk | None:
        n_total = self._stop
        if self._pos >= n_total:
            return None
        stop = min(n_total, self._pos + max_samples)
        data = {
            n: self.recording.channel(n)[self._pos : stop] for n in self.recording.channel_names
        }
        chunk = Chunk(self._pos, self.sample_rate_hz, self.t0_s, data)
        self._pos = stop
        return chunk

    def command(self, event: Event) -> None:
        self.commands.append(event)
