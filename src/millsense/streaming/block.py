"""The streaming contract every online algorithm follows.

A :class:`Block` consumes chunks of samples of any length, keeps its own state between chunks,
and emits, for every input sample, its output channels, plus time-stamped :class:`Event`
objects (alarm, override command, note). Its outputs must not depend on how the stream was cut
into chunks (chunks of 1, 7, 100 samples or the whole recording give the same result, to
floating-point tolerance); the test-suite checks this property for every block it ships.

A block declares the channels it reads (``inputs``); the pipeline hands it those and nothing
else, so an estimator cannot read ``truth/`` channels unless it is explicitly an evaluation
block (``reads_truth = True``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from millsense.core.recording import ChannelInfo


class EventKind(StrEnum):
    """What an event asks of the machine or tells the user."""

    ALARM = "alarm"  #: a condition the operator must see (chatter, breakage)
    OVERRIDE = "override"  #: a feed/spindle override or feed-hold command for the source
    NOTE = "note"  #: information (calibration done, segment entered)
    CRASH = "crash"  #: the machine would crash (tool engaged with the spindle stopped, a force
    #: or power beyond the machine's limits): raised by the simulator


@dataclass(frozen=True)
class Event:
    """A time-stamped event emitted by a block.

    Attributes
    ----------
    time_s : time of the sample that triggered it, s.
    kind : alarm, override, note or crash.
    source : name of the block that emitted it.
    message : one human-readable line.
    name : machine-readable name (``chatter``, ``feed_override``...).
    value : optional number (an override in percent, a frequency in Hz...).
    """

    time_s: float
    kind: EventKind
    source: str
    message: str
    name: str = ""
    value: float | None = None

    def as_dict(self) -> dict[str, object]:
        return {
            "time_s": self.time_s,
            "kind": str(self.kind),
            "source": self.source,
            "name": self.name,
            "value": self.value,
            "message": self.message,
        }


@dataclass(frozen=True)
class Chunk:
    """A run of consecutive samples at the common rate.

    ``start`` is the index of the first sample since the start of the stream, so a block can
    compute absolute times (``t0_s + (start + k) / sample_rate_hz``) whatever the chunking.
    """

    start: int
    sample_rate_hz: float
    t0_s: float
    data: Mapping[str, np.ndarray]

    @property
    def n(self) -> int:
        for v in self.data.values():
            return len(v)
        return 0

    @property
    def time_s(self) -> np.ndarray:
        return self.t0_s + (self.start + np.arange(self.n)) / self.sample_rate_hz

    def restricted(self, names: tuple[str, ...]) -> Chunk:
        """The same chunk carrying only ``names``."""
        return Chunk(self.start, self.sample_rate_hz, self.t0_s, {k: self.data[k] for k in names})


@dataclass
class BlockOutput:
    """What a block returns for one chunk: channels aligned with its samples, and events."""

    channels: dict[str, np.ndarray] = field(default_factory=dict)
    events: list[Event] = field(default_factory=list)


class Block(ABC):
    """Base class of an online algorithm (estimator, monitor, controller).

    Subclasses set ``name`` and ``inputs``, implement :meth:`output_channels`,
    :meth:`reset` (called once with the sample rate before the first chunk) and
    :meth:`process`.
    """

    name: str = "block"
    inputs: tuple[str, ...] = ()
    reads_truth: bool = False

    @abstractmethod
    def output_channels(self) -> list[ChannelInfo]:
        """Channels this block emits, one value per input sample."""

    @abstractmethod
    def reset(self, sample_rate_hz: float) -> None:
        """Prepare for a new stream at ``sample_rate_hz``; forget all state."""

    @abstractmethod
    def process(self, chunk: Chunk) -> BlockOutput:
        """Consume ``chunk`` (only the declared inputs) and return its outputs and events."""
