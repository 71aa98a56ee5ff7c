"""A breakage detector judged at several phases of the tooth period (decision 1552).

Seed 000's virtual threshold (:class:`~millsense.monitoring.breakage.BreakageBlock`, Aslan
Eq. 6.1) averages the torque over tooth periods whose boundaries fall where the integrated
spindle angle crosses multiples of 2π/N from the stream start: a phase that has nothing to do
with where the flutes cut. A broken flute removes a torque pulse that lasts its engagement
(plus the helix lag) and, delayed by the estimator, lies anywhere in those windows; split
between two of them, its drop is diluted. Measured on the virtual machine (Ø12 mm, 2–4 flutes,
slots and half immersion, 3000–10 000 rev/min; the observer's estimate), the relative drop of
the broken flute's period ranged over the window phase from −0.12 to −0.77 (2 flutes, half
immersion, 8000 rev/min), −0.27 to −0.58 (3-flute slot) and −0.26 to −0.39 (4-flute slot):
at the unlucky phase, below the seed's 40 % band, a break the monitor could never see.

Which phase is best depends on the engagement, the helix and the observer's delay, and it
cannot be known before the break (for a slot the best window starts at the flute's entry,
for a short pulse any window holding it). So the same detector runs at ``phases`` offsets,
j/P of a tooth period (j = 0 … P−1): the worst phase is then at most 1/(2P) of a period from
the best. The members run as one :class:`~millsense.monitoring.breakage.BreakageGroup` (one
compiled call per chunk). The block's output channels are those of phase 0 (the seed's
windows, unchanged); an alarm of any phase is the block's alarm, and an alarm
``dedupe_revolutions`` revolutions or fewer after the last one, reported or not (one breakage
seen by several phases, or again by one as its runs end and restart) is not repeated; the
arbiter's :meth:`PhasedBreakage.rearm` lets the next one through.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.monitoring.breakage import BreakageBlock, BreakageGroup
from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind, Severity

#: Decision 1553: a stretch of judged tooth periods this many revolutions long in which the
#: noise band is at least the expected torque (a broken flute could not leave it) is reported
#: as blind; it ends after as many revolutions with the band below CLEAR_FRACTION of it.
BLIND_REVOLUTIONS = 10
CLEAR_FRACTION = 0.8
#: Decision 1552: phases of the tooth period judged (worst phase ≤ 1/6 of a period from the
#: best one).
PHASES = 3
#: Decision 1552: an alarm this many revolutions or fewer after the last one (reported or
#: not) is the same breakage: a broken tool alarms again and again as its runs end and restart.
DEDUPE_REVOLUTIONS = 100


class PhasedBreakage(Block):
    """:class:`BreakageBlock` at ``phases`` phase offsets of the tooth period, one alarm per
    breakage (module notes; decision 1552).

    Parameters
    ----------
    n_flutes : number of flutes N.
    phases : phase offsets judged (1: the seed's detector alone).
    dedupe_revolutions : alarms this many revolutions or fewer after the last one (reported or
        not) are not reported.
    name : block name (the channels of phase 0 and the events carry it).
    companions : other detectors on the same speed channel and flute count run in the same
        compiled call (``millsense monitor``'s constant and dual detectors); their channels and
        events pass through unchanged.
    options : the detector's other parameters (:class:`BreakageBlock`; not ``phase_offset``).
    """

    def __init__(
        self,
        n_flutes: int,
        *,
        phases: int = PHASES,
        dedupe_revolutions: int = DEDUPE_REVOLUTIONS,
        name: str = "breakage",
        companions: Sequence[BreakageBlock] = (),
        **options: Any,
    ) -> None:
        if int(phases) != phases or phases < 1:
            raise ConfigError(f"breakage: phases must be an integer ≥ 1, got {phases!r}")
        if dedupe_revolutions < 0:
            raise ConfigError(
                f"breakage: dedupe_revolutions must be ≥ 0, got {dedupe_revolutions!r}"
            )
        if "phase_offset" in options:
            raise ConfigError("breakage: the phases set the phase offsets; give no phase_offset")
        self.members = [
            BreakageBlock(n_flutes, phase_offset=j / phases,
                          name=name if j == 0 else f"{name}.phase{j}", **options)
            for j in range(int(phases))
        ]  # fmt: skip
        first = self.members[0]
        self.name = name
        self.n_flutes = first.n_flutes
        self.method = first.method
        self.speed_channel = first.speed_channel
        self.phases = int(phases)
        self.dedupe_revolutions = int(dedupe_revolutions)
        self.options = dict(options)
        self.companions = list(companions)
        # phase 0 and the companions first: the group's outputs are theirs alone
        shown = [self.members[0], *self.companions]
        self._group = BreakageGroup([*shown, *self.members[1:]], name=name, shown=len(shown))
        self.inputs = self._group.inputs
        self._phase_sources = {m.name for m in self.members}
        self._last_period = -(10**18)
        self._phase_of = {m.name: j for j, m in enumerate(self.members)}

    def with_companions(self, companions: Sequence[BreakageBlock]) -> PhasedBreakage:
        """The same detector with ``companions`` run in its compiled call."""
        return PhasedBreakage(
            self.n_flutes,
            phases=self.phases,
            name=self.name,
            dedupe_revolutions=self.dedupe_revolutions,
            companions=[*self.companions, *companions],
            **self.options,
        )

    def output_channels(self) -> list[ChannelInfo]:
        return [c for m in (self.members[0], *self.companions) for c in m.output_channels()]

    def reset(self, sample_rate_hz: float) -> None:
        self._group.reset(sample_rate_hz)
        self._last_period = -(10**18)
        self._alarmed = False
        self._blind = False
        self._blind_run = 0
        self._seen_run = 0
        self._need = BLIND_REVOLUTIONS * self.n_flutes
        self._unit = self.members[0].unit

    def rearm(self) -> None:
        """Every phase forgets its running violation (:meth:`BreakageBlock.rearm`)."""
        for m in self.members:
            m.rearm()
        self._last_period = -(10**18)
        self._alarmed = False

    def process(self, chunk: Chunk) -> BlockOutput:
        out = self._group.process(chunk)
        k = int(self._group._counts[0])  # phase 0's tooth periods ending in the chunk
        if k and not self._alarmed:  # after a breakage alarm the cut is not the plan's
            self._watch_blind(chunk, k, out)
        if not out.events:
            return out
        kept = BlockOutput(out.channels)
        window = self.dedupe_revolutions * self.n_flutes  # in tooth periods
        for e in sorted(out.events, key=lambda e: (e.sample, e.source)):
            if e.source not in self._phase_sources or e.name != "breakage":
                # a companion's, or this block's blind/seen note
                kept.events.append(e)
                continue
            period = int(e.values["tooth_period"])
            seen = period - self._last_period <= window
            self._last_period = period  # a breakage still alarming extends the window
            if seen:
                continue
            phase = self._phase_of[e.source]
            values = {**e.values, "phase": float(phase) / self.phases}
            kept.events.append(replace(e, source=self.name, values=values))
            self._alarmed = True
        return kept

    def _watch_blind(self, chunk: Chunk, k: int, out: BlockOutput) -> None:
        """Where the noise band of phase 0's judged tooth periods reaches their expected torque
        (even the loss of a whole period's torque stays in the band), a WARNING
        ``breakage_blind`` after :data:`BLIND_REVOLUTIONS` revolutions of it, and a NOTE
        ``breakage_seen`` once the band has stayed below :data:`CLEAR_FRACTION` of the expected
        torque as long (decision 1553). Periods not judged (air, off speed) count for neither;
        after a breakage alarm (until :meth:`rearm`) the cut is not the plan's and nothing is
        said."""
        m0 = self.members[0]
        band = m0._pp[8, :k].tolist()
        expected = m0._pp[2, :k].tolist()
        for i in range(k):
            b, ex = band[i], expected[i]
            if not (b == b) or not ex > 0.0:  # not judged
                continue
            if b >= ex:
                self._blind_run += 1
                self._seen_run = 0
            elif b < CLEAR_FRACTION * ex:
                self._seen_run += 1
                self._blind_run = 0
            else:
                self._blind_run = self._seen_run = 0
            if not self._blind and self._blind_run >= self._need:
                self._blind = True
                out.events.append(self._blind_event(chunk, int(m0._pi[0, i]), b, ex, True))
            elif self._blind and self._seen_run >= self._need:
                self._blind = False
                out.events.append(self._blind_event(chunk, int(m0._pi[0, i]), b, ex, False))

    def _blind_event(self, chunk: Chunk, at: int, band: float, expected: float,
                     blind: bool) -> Event:  # fmt: skip
        sample = chunk.start + at
        u = self._unit
        if blind:
            message = (f"breakage cannot be seen here: the expected tooth-period average "
                       f"{expected:.3g} {u} lies inside the noise band ±{band:.3g} {u} "
                       f"({self.members[0].noise_k:g}σ of the tooth average); a broken flute "
                       "would not leave it")  # fmt: skip
        else:
            message = (f"breakage can be seen again: the noise band ±{band:.3g} {u} is below "
                       f"the expected tooth-period average {expected:.3g} {u}")  # fmt: skip
        return Event(
            time_s=chunk.t0_s + sample / chunk.sample_rate_hz,
            kind=EventKind.NOTE,
            source=self.name,
            message=message,
            name="breakage_blind" if blind else "breakage_seen",
            value=float(band / expected),
            sample=sample,
            severity=Severity.WARNING if blind else Severity.INFO,
            values={f"band_{self.members[0]._suffix}": float(band),
                    f"expected_{self.members[0]._suffix}": float(expected)},
        )  # fmt: skip
