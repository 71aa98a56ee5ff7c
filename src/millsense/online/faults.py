"""Faults of the link between a machine and millsense, injected for tests, validation and
demonstrations (issue 16: a stalled source, NaNs, a dropped chunk, a lost source).

:class:`FaultyLink` wraps a source and spoils what it hands out on a schedule; the machine
behind it runs on unaware (its commands still reach it, except after a loss). Each
:class:`LinkFault` acts on the samples whose times fall in ``[start_s, start_s + duration_s)``:

- ``nan``: the samples of ``channel`` (every measured channel when empty) become NaN;
- ``drop``: the samples are not delivered (the next chunk starts later);
- ``stall``: every measured channel repeats its value at ``start_s`` (a frozen buffer);
- ``lost``: from ``start_s`` on, reading raises :class:`ConnectionError`.

``millsense run --fault KIND@START_S[:DURATION_S][:CHANNEL]`` parses the same schedule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from millsense.core.errors import ConfigError
from millsense.streaming.block import Chunk
from millsense.streaming.sources import Source, SourceWrapper

KINDS = ("nan", "drop", "stall", "lost")


@dataclass(frozen=True)
class LinkFault:
    """One fault: ``kind`` over ``[start_s, start_s + duration_s)`` (see the module)."""

    kind: str
    start_s: float
    duration_s: float = 0.01
    channel: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"fault: kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if not (self.start_s >= 0 and self.duration_s > 0):
            raise ConfigError(
                f"fault {self.kind}: start ≥ 0 s and duration > 0 s needed, got "
                f"{self.start_s!r}, {self.duration_s!r}"
            )

    @classmethod
    def parse(cls, text: str) -> LinkFault:
        """``KIND@START_S[:DURATION_S][:CHANNEL]``, e.g. ``stall@2.0:0.3``, ``nan@1.5:0.01:x/
        current_cmd``, ``lost@3``."""
        kind, sep, rest = text.partition("@")
        if not sep:
            raise ConfigError(f"--fault {text}: expected KIND@START_S[:DURATION_S][:CHANNEL]")
        parts = rest.split(":", 2)
        try:
            start = float(parts[0])
            dur = float(parts[1]) if len(parts) > 1 and parts[1] else 0.01
        except ValueError:
            raise ConfigError(
                f"--fault {text}: START_S and DURATION_S must be numbers (seconds)"
            ) from None
        return cls(kind.strip(), start, dur, parts[2] if len(parts) > 2 else "")


class FaultyLink(SourceWrapper):
    """``inner`` delivered through a link that fails as ``faults`` schedule."""

    def __init__(self, inner: Source, faults: Sequence[LinkFault]) -> None:
        super().__init__(inner)
        self.faults = list(faults)
        names = inner.channel_names
        for f in self.faults:
            if f.channel and f.channel not in names:
                raise ConfigError(
                    f"--fault {f.kind}@{f.start_s:g}: no channel '{f.channel}' (the machine "
                    f"gives: {', '.join(n for n in names if not n.startswith('truth/'))})"
                )
        self._measured = [n for n in names if not n.startswith("truth/")]
        self._frozen: dict[str, float] = {}

    def read(self, max_samples: int) -> Chunk | None:
        while True:
            c = self.inner.read(max_samples)
            if c is None:
                return None
            # sample indices of the fault windows (rounded: no float edge effects)
            k = c.start + np.arange(c.n)
            fs = c.sample_rate_hz
            for f in self.faults:
                if f.kind == "lost" and k[-1] >= round((f.start_s - c.t0_s) * fs):
                    raise ConnectionError(f"link down at {f.start_s:g} s (injected)")
            data = {k: np.array(v, dtype=np.float64) for k, v in c.data.items()}
            keep = np.ones(c.n, dtype=bool)
            for f in self.faults:
                a = round((f.start_s - c.t0_s) * fs)
                sel = (k >= a) & (k < a + round(f.duration_s * fs))
                if not sel.any():
                    continue
                chans = [f.channel] if f.channel else self._measured
                if f.kind == "nan":
                    for ch in chans:
                        data[ch][sel] = np.nan
                elif f.kind == "stall":
                    for ch in self._measured:
                        first = int(np.argmax(sel))
                        v0 = self._frozen.setdefault(
                            f"{id(f)}:{ch}", float(data[ch][first - 1]) if first else
                            float(data[ch][first])
                        )  # fmt: skip
                        data[ch][sel] = v0
                elif f.kind == "drop":
                    keep &= ~sel
            if keep.all():
                return Chunk(c.start, c.sample_rate_hz, c.t0_s, data)
            # a packet is lost whole: the samples of this chunk up to the last dropped one go
            k0 = int(np.flatnonzero(~keep)[-1]) + 1
            if k0 >= c.n:
                continue  # nothing of this chunk arrives: read on
            return Chunk(c.start + k0, c.sample_rate_hz, c.t0_s,
                         {k: v[k0:] for k, v in data.items()})  # fmt: skip
