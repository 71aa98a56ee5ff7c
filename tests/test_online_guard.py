"""The source guard and the injected link faults (issue 16: a stalled source, NaNs, a dropped
chunk, a lost source): the guard marks each, keeps the stream finite and gap-free, and a lost
source gets a feed hold through the command path."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.core.recording import Recording
from millsense.online.faults import FaultyLink, LinkFault
from millsense.online.guard import FAULT_CHANNEL, GAP, NAN, STALL, GuardedSource
from millsense.streaming.block import Event, EventKind
from millsense.streaming.sources import RecordingSource

FS = 10000.0
N = 5000


class Commanded(RecordingSource):
    """A replay that keeps the commands it receives (a live machine would act on them)."""

    def __init__(self, rec: Recording) -> None:
        super().__init__(rec)
        self.commands: list[Event] = []

    def command(self, event: Event) -> None:
        self.commands.append(event)


def _source() -> Commanded:
    rng = np.random.default_rng(3)
    rec = Recording(FS, metadata={"source": "link.h5"})
    rec.add_channel("x/current_cmd", rng.standard_normal(N), "A")
    rec.add_channel("spindle/speed", 100 + 0.01 * rng.standard_normal(N), "rad/s")
    rec.add_channel("truth/x/load", np.zeros(N), "N")  # constant: truth never counts as stall
    return Commanded(rec)


def _read_all(src: GuardedSource, chunk: int = 100) -> dict[str, np.ndarray]:
    parts: dict[str, list[np.ndarray]] = {}
    starts = []
    while (c := src.read(chunk)) is not None:
        starts.append((c.start, c.n))
        for k, v in c.data.items():
            parts.setdefault(k, []).append(np.asarray(v))
    # contiguous: every chunk starts where the previous ended
    pos = 0
    for s, n in starts:
        assert s == pos
        pos += n
    return {k: np.concatenate(v) for k, v in parts.items()}


def test_clean_stream_passes_unchanged() -> None:
    src = _source()
    d = _read_all(GuardedSource(src))
    assert not d[FAULT_CHANNEL].any()
    assert np.array_equal(d["x/current_cmd"], src.recording.channel("x/current_cmd"))


def test_nan_samples_are_held_and_marked() -> None:
    src = _source()
    g = GuardedSource(FaultyLink(src, [LinkFault("nan", 0.2, 0.003, "x/current_cmd")]))
    d = _read_all(g)
    bad = slice(2000, 2030)
    assert np.all(d[FAULT_CHANNEL][bad] == NAN)
    assert np.count_nonzero(d[FAULT_CHANNEL]) == 30
    assert np.all(d["x/current_cmd"][bad] == src.recording.channel("x/current_cmd")[1999])
    assert [e.sample for e in g.events] == [2000]


def test_dropped_samples_are_filled_and_marked() -> None:
    src = _source()
    g = GuardedSource(FaultyLink(src, [LinkFault("drop", 0.2, 0.005)]))
    d = _read_all(g, 100)
    assert len(d[FAULT_CHANNEL]) == N  # the stream stays gap-free
    lost = np.flatnonzero(d[FAULT_CHANNEL] == GAP)
    # samples 2000..2049 lost (5 ms), held at sample 1999's value
    assert lost[0] == 2000 and lost[-1] == 2049 and lost.size == 50
    assert np.all(d["x/current_cmd"][lost] == src.recording.channel("x/current_cmd")[1999])


def test_stalled_stream_is_marked_after_stall_s() -> None:
    """Every measured channel frozen at its 0.3 s value for 0.1 s: marked from the 500th
    repetition (stall_s = 50 ms, so the supervisor acts well within 100 ms) to the end of the
    freeze, and nowhere else."""
    src = _source()
    g = GuardedSource(FaultyLink(src, [LinkFault("stall", 0.3, 0.1)]), stall_s=0.05)
    d = _read_all(g)
    st = np.flatnonzero(d[FAULT_CHANNEL] == STALL)
    assert st[0] == 3500 and st[-1] == 3999 and st.size == 500


def test_lost_source_sends_a_feed_hold_and_ends() -> None:
    src = _source()
    g = GuardedSource(FaultyLink(src, [LinkFault("lost", 0.25)]))
    d = _read_all(g)
    assert len(d[FAULT_CHANNEL]) == 2500
    assert [e.name for e in g.events] == ["source_lost"]
    assert [(e.kind, e.name) for e in src.commands] == [(EventKind.OVERRIDE, "feed_hold")]


def test_fault_specs_parse_and_refuse_nonsense() -> None:
    f = LinkFault.parse("nan@1.5:0.01:x/current_cmd")
    assert (f.kind, f.start_s, f.duration_s, f.channel) == ("nan", 1.5, 0.01, "x/current_cmd")
    assert LinkFault.parse("lost@3").start_s == 3.0
    with pytest.raises(ConfigError, match="KIND@START_S"):
        LinkFault.parse("stall")
    with pytest.raises(ConfigError, match="kind must be one of"):
        LinkFault.parse("melt@1")
    with pytest.raises(ConfigError, match="no channel 'z/current_cmd'"):
        FaultyLink(_source(), [LinkFault.parse("nan@1:0.1:z/current_cmd")])


def test_a_constant_channel_is_no_stall_and_huge_finite_values_pass() -> None:
    """A stall needs every measured channel frozen: a constant one (an NC line, a held
    override) beside a live one is none, and beside a frozen one it does not hide the stall.
    Finite values whose chunk sum overflows (±1e308) pass unchanged and unmarked; an inf is
    held and marked like a NaN."""
    rng = np.random.default_rng(5)
    live = rng.standard_normal(N)
    huge = np.where(np.arange(N) % 2 == 0, 1e308, 1e308 * 0.9)  # finite; sums overflow
    huge[4000] = np.inf
    rec = Recording(FS, metadata={"source": "link.h5"})
    rec.add_channel("cnc/nc_line", np.full(N, 10.0), "1")
    rec.add_channel("x/current_cmd", live, "A")
    rec.add_channel("y/current_cmd", huge, "A")
    d = _read_all(GuardedSource(Commanded(rec), stall_s=0.01))
    assert np.count_nonzero(d[FAULT_CHANNEL]) == 1 and d[FAULT_CHANNEL][4000] == NAN
    assert np.array_equal(d["y/current_cmd"][:4000], huge[:4000])
    assert d["y/current_cmd"][4000] == huge[3999]
    g = GuardedSource(FaultyLink(Commanded(rec), [LinkFault("stall", 0.2, 0.05)]), stall_s=0.01)
    st = np.flatnonzero(_read_all(g)[FAULT_CHANNEL] == STALL)
    # frozen 2000..2499: the 100th repetition (sample 2100) starts the mark
    assert st[0] == 2100 and st[-1] == 2499 and st.size == 400
