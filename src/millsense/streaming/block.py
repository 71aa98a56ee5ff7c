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


class Severity(StrEnum):
    """How urgent an event is (issue 15: one event model for monitors and controllers)."""

    INFO = "info"  #: nothing to do (a calibration finished, a segment entered)
    WARNING = "warning"  #: the operator should look (chatter onset, a recommendation)
    CRITICAL = "critical"  #: the process must be acted on now (breakage, crash, feed hold)


@dataclass(frozen=True)
class Event:
    """A time-stamped event emitted by a block: the one event model shared by monitors,
    controllers and the simulator (issue 15, item 5).

    Attributes
    ----------
    time_s : time of the sample that triggered it, s.
    kind : alarm, override, note or crash.
    source : name of the block that emitted it.
    message : one human-readable line.
    name : machine-readable name (``chatter``, ``breakage``, ``feed_override``...).
    value : the event's main number (an override in percent, a chatter frequency in Hz...).
    sample : index of that sample since the start of the stream (-1: not known).
    severity : info, warning or critical.
    values : further named numbers, units in the names (``energy_ratio``, ``tooth``...).
    nc_line : the part-program line being executed (from the virtual plan), if known.
    x_mm, y_mm, z_mm : tool-tip position on the tool path (from the plan), if known.
    """

    time_s: float
    kind: EventKind
    source: str
    message: str
    name: str = ""
    value: float | None = None
    sample: int = -1
    severity: Severity = Severity.INFO
    values: Mapping[str, float] = field(default_factory=dict)
    nc_line: int | None = None
    x_mm: float | None = None
    y_mm: float | None = None
    z_mm: float | None = None

    def as_dict(self) -> dict[str, object]:
        return {
            "time_s": self.time_s,
            "sample": self.sample,
            "kind": str(self.kind),
            "severity": str(self.severity),
            "source": self.source,
            "name": self.name,
            "value": self.value,
            "values": dict(self.values),
            "nc_line": self.nc_line,
            "x_mm": self.x_mm,
            "y_mm": self.y_mm,
            "z_mm": self.z_mm,
            "message": self.message,
        }


@dataclass(frozen=True, slots=True, init=False)
class Chunk:
    """A run of consecutive samples at the common rate.

    ``start`` is the index of the first sample since the start of the stream, so a block can
    compute absolute times (``t0_s + (start + k) / sample_rate_hz``) whatever the chunking.

    Frozen, made once per block and chunk (the pipeline restricts each chunk to a block's
    inputs): the constructor writes the fields through their slots, ≈ 0.7 µs, where a frozen
    dataclass's generated one (an ``object.__setattr__`` per field) took ≈ 1.8 µs.
    """

    start: int
    sample_rate_hz: float
    t0_s: float
    data: Mapping[str, np.ndarray]

    def __init__(
        self, start: int, sample_rate_hz: float, t0_s: float, data: Mapping[str, np.ndarray]
    ) -> None:
        _set_start(self, start)
        _set_rate(self, sample_rate_hz)
        _set_t0(self, t0_s)
        _set_data(self, data)

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


# the slots' own setters, which a frozen class's ``__setattr__`` does not go through
_set_start = Chunk.__dict__["start"].__set__
_set_rate = Chunk.__dict__["sample_rate_hz"].__set__
_set_t0 = Chunk.__dict__["t0_s"].__set__
_set_data = Chunk.__dict__["data"].__set__


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


#: Held outputs of a block for one chunk length: (samples, channel → view).
HeldViews = tuple[int, dict[str, np.ndarray]]


def held_views(
    names: tuple[str, ...] | list[str],
    held: np.ndarray,
    cached: HeldViews | None,
    n: int,
) -> tuple[HeldViews, dict[str, np.ndarray]]:
    """Outputs that hold the values ``held`` (one per name) over ``n`` samples, as views of one
    array never written again: the ``cached`` views when they have ``n`` samples (the block
    resets ``cached`` to None whenever its held values change), else new ones. Returns the
    views to cache and a new dict of them (the engine may add to a block's dict)."""
    if cached is not None and cached[0] == n:
        return cached, dict(cached[1])
    a = np.empty((len(names), n))
    a[:] = held[:, None]
    out = dict(zip(names, a, strict=True))
    return (n, out), dict(out)
