"""The source guard: what reaches the blocks of an on-line session is finite, gap-free and
marked where it is not to be trusted (issue 16 item 4, the safety layer's input side).

:class:`GuardedSource` wraps any :class:`~millsense.streaming.sources.Source` (the virtual
machine, a CNC link, a replay) and adds the per-sample channel ``guard/fault``:

- 1 **non-finite samples**: a NaN or inf is replaced by the channel's last finite value (the
  pipeline refuses non-finite inputs, decision 0009; a controller must not act on them);
- 2 **samples lost**: a chunk starting after the next expected sample (a dropped packet) is
  preceded by the missing samples, each channel held at its last value;
- 3 **stream stalled**: every measured channel (``truth/`` excluded) bit-identical to its
  previous sample for ``stall_s`` — a frozen buffer: real signals always carry noise;
- 4 **source lost**: the source raised an error while reading (the link is gone): the guard
  sends the machine a feed hold through the command path (a CNC's write channel is not its
  data stream) and ends the stream; the session closes what it recorded.

A live link that drops but reconnects by itself (the OPC UA source of :mod:`millsense.link`)
raises :class:`LinkInterrupted`: the guard raises the alarm (``link_interrupted``) and takes
the safe action at once — the programmed feed (feed override 100 %), written when the link is
back — and reads on; the samples missed meanwhile arrive as a gap (code 2) or, re-sent from
the server's buffer, not at all (decision 1803).

The supervisor (:class:`~millsense.control.arbitration.Supervisor`) turns a fault code into
the safe action within one control period. Events of the guard itself (a lost source, the
first sample of each fault run) are collected in :attr:`GuardedSource.events`.
"""

from __future__ import annotations

import math

import numpy as np

from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Chunk, Event, EventKind, Severity
from millsense.streaming.sources import SOURCE_FAULTS, Source, SourceWrapper

FAULT_CHANNEL = "guard/fault"
NAN, GAP, STALL, LOST = 1, 2, 3, 4

#: Errors of a source that mean its link is gone (a simulator's own bugs still propagate).
LINK_ERRORS: tuple[type[BaseException], ...] = (ConnectionError, TimeoutError, OSError, EOFError)


class LinkInterrupted(ConnectionError):
    """A live source's link dropped; the source reconnects on the next read (``sample``: the
    next sample expected)."""

    def __init__(self, message: str, sample: int = -1) -> None:
        super().__init__(message)
        self.sample = sample


class GuardedSource(SourceWrapper):
    """``inner`` with non-finite values held, gaps filled, stalls and loss detected.

    Parameters
    ----------
    inner : the source guarded.
    stall_s : how long every measured channel must stay bit-identical to count as stalled, s
        (50 ms: the fault then reaches the supervisor well within the 100 ms of issue 16).
    hold_on_loss : send ``feed_hold`` to ``inner`` when it is lost.
    """

    def __init__(self, inner: Source, stall_s: float = 0.05, hold_on_loss: bool = True) -> None:
        super().__init__(inner)
        self.hold_on_loss = hold_on_loss
        self.n_stall = max(1, round(stall_s * self.sample_rate_hz))
        self.events: list[Event] = []
        self._names = inner.channel_names
        self._measured = [n for n in self._names if not n.startswith("truth/")]
        self._measured_set = frozenset(self._measured)
        self._last: dict[str, float] = {}
        self._next = 0
        self._run = 0  # samples in a row with every measured channel unchanged
        self._queued: Chunk | None = None
        self._lost = False
        self._fault_on = 0

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [
            *self.inner.channel_info,
            ChannelInfo(FAULT_CHANNEL, "1", "source fault: 0 good, 1 NaN, 2 lost, 3 stall, 4 link"),
        ]

    def command(self, event: Event) -> None:
        if not self._lost:
            self.inner.command(event)

    # ------------------------------------------------------------------ reading
    def read(self, max_samples: int) -> Chunk | None:
        if self._queued is not None:
            c, self._queued = self._queued, None
            return self._guard(c)
        if self._lost:
            return None
        while True:
            try:
                got = self.inner.read(max_samples)
                break
            except LinkInterrupted as exc:
                self._interrupted(exc)
            except LINK_ERRORS as exc:
                self._lose(exc)
                return None
        if got is None:
            return None
        if got.start > self._next and self._last:
            self._queued = got
            return self._filled(got.start - self._next)
        return self._guard(got)

    def _lose(self, exc: BaseException) -> None:
        self._lost = True
        t = self.t0_s + self._next / self.sample_rate_hz
        msg = f"{self.name}: source lost at {t:.4f} s ({type(exc).__name__}: {exc})"
        self.events.append(Event(t, EventKind.ALARM, "guard", msg, name="source_lost",
                                 value=float(LOST), sample=self._next,
                                 severity=Severity.CRITICAL))  # fmt: skip
        if self.hold_on_loss:
            try:
                hold = Event(t, EventKind.OVERRIDE, "guard", "feed hold: source lost",
                             name="feed_hold", value=1.0, sample=self._next,
                             severity=Severity.CRITICAL)  # fmt: skip
                self.inner.command(hold)
            except LINK_ERRORS:
                pass  # the command path is gone too: the CNC's own watchdog must stop it

    def _interrupted(self, exc: BaseException) -> None:
        """The alarm and the safe action of an interrupted link (decision 1803)."""
        t = self.t0_s + self._next / self.sample_rate_hz
        self.events.append(Event(t, EventKind.ALARM, "guard", f"{self.name}: {exc}",
                                 name="link_interrupted", value=float(LOST), sample=self._next,
                                 severity=Severity.CRITICAL))  # fmt: skip
        safe = Event(t, EventKind.OVERRIDE, "guard", "programmed feed: link interrupted",
                     name="feed_override", value=100.0, sample=self._next,
                     severity=Severity.CRITICAL)  # fmt: skip
        self.events.append(safe)
        try:
            self.inner.command(safe)
        except LINK_ERRORS:
            pass  # queued by the source for the reconnection, or the CNC's watchdog acts

    def _filled(self, gap: int) -> Chunk:
        data = {n: np.full(gap, self._last.get(n, 0.0)) for n in self._names}
        data[FAULT_CHANNEL] = np.full(gap, float(GAP))
        c = Chunk(self._next, self.sample_rate_hz, self.t0_s, data)
        self._note(c)
        self._next += gap
        return c

    def _guard(self, c: Chunk) -> Chunk:
        n = c.n
        fault = np.zeros(n)
        data: dict[str, np.ndarray] = {}
        # "nothing changed" at each sample, over every measured channel; once every sample
        # has a change the other channels cannot bring it back, so they are not compared
        same = np.ones(n, dtype=bool)
        comparing = bool(self._measured and n)
        with np.errstate(over="ignore"):
            for name in self._names:
                v = np.asarray(c.data[name], dtype=np.float64)
                # one reduction finds a chunk without NaN or inf (the usual case); an overflowing
                # sum only sends a finite chunk through the full test
                if n and not math.isfinite(v.sum()):
                    bad = ~np.isfinite(v)
                    if bad.any():
                        v = _hold(v, bad, self._last.get(name, 0.0))
                        if not name.startswith("truth/"):
                            fault[bad] = NAN
                if comparing and name in self._measured_set:
                    same[0] &= bool(v[0] == self._last.get(name, np.nan))
                    same[1:] &= v[1:] == v[:-1]
                    comparing = bool(same.any())
                if n:
                    self._last[name] = float(v[-1])
                data[name] = v
        if self._measured and n and not comparing:
            self._run = 0  # every sample changed something
        elif self._measured and n:
            # run length of "nothing changed" carried between chunks
            idx = np.arange(1, n + 1)
            breaks = np.where(~same, idx, 0)
            last_break = np.maximum.accumulate(breaks)
            run = np.where(last_break == 0, self._run + idx, idx - last_break)
            self._run = int(run[-1])
            fault[(run >= self.n_stall) & (fault == 0)] = STALL
        data[FAULT_CHANNEL] = fault
        out = Chunk(c.start, c.sample_rate_hz, c.t0_s, data)
        self._note(out)
        self._next = c.start + n
        return out

    def _note(self, c: Chunk) -> None:
        """An ALARM at the first sample of each run of faults (the log says when it began)."""
        f = np.asarray(c.data[FAULT_CHANNEL]).astype(np.int64)
        if f.size == 0:
            return
        prev = np.empty_like(f)
        prev[0] = self._fault_on
        prev[1:] = f[:-1]
        for k in np.flatnonzero((f != 0) & (f != prev)).tolist():
            cur = int(f[k])
            t = c.t0_s + (c.start + k) / c.sample_rate_hz
            self.events.append(Event(t, EventKind.ALARM, "guard",
                                     f"{self.name}: {SOURCE_FAULTS[cur]} at {t:.4f} s",
                                     name="source_fault", value=float(cur), sample=c.start + k,
                                     severity=Severity.WARNING))  # fmt: skip
        self._fault_on = int(f[-1])


def _hold(v: np.ndarray, bad: np.ndarray, last: float) -> np.ndarray:
    """``v`` with its non-finite samples replaced by the last finite value before them."""
    idx = np.where(~bad, np.arange(v.size), -1)
    idx = np.maximum.accumulate(idx)
    out = np.where(idx >= 0, v[np.maximum(idx, 0)], last)
    return np.asarray(out, dtype=np.float64)
