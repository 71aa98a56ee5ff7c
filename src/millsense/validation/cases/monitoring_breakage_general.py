"""Tool breakage on a shop's cuts, beyond the seeds' one set-up (decision 1552).

Seed 000's V7 breaks a Ø20 mm 2-flute end mill in a slot at 1000 rev/min, where every tooth
period around the broken flute leaves the 40 % band. Issue 15 asks for breakage detection in
general, so six straight cuts with a Ø12 mm, 35° helix end mill in the demo part's Al7050
block are run as ``millsense run`` runs them (default session: the shipped commissioned spindle
observer, plan sync with the K_tc calibration, the virtual threshold at three phases, the
adaptive feed on the spindle power; the virtual machine cutting its own plan): 2, 3 and 4
flutes, full slots and half immersion (the tool centre on the block's edge), 3000 to
10 000 rev/min. Each cut runs twice: with flute 0 broken at 3.0 s (well inside the cut) and
intact, the whole program.
"""

from __future__ import annotations

import functools
import math
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from millsense.streaming.block import Event
from millsense.validation import Measured, case
from millsense.validation.cases._breakage_effect import EFFECT_DROP, latency_periods

#: (flutes, rev/min, "slot" or "half", feed mm/min, depth mm); chosen before the first run of
#: these cases (the cuts `millsense run --break-at-s 3` was first tried on, 2026-11-29).
CUTS = (
    (2, 3000, "slot", 900, 4.0),
    (3, 6000, "slot", 1500, 3.0),
    (4, 6000, "slot", 1500, 4.0),
    (2, 8000, "half", 2000, 4.0),
    (3, 8000, "half", 2000, 4.0),
    (4, 10000, "half", 3000, 4.0),
)
BREAK_S = 3.0
DIAMETER_MM = 12.0
HELIX_DEG = 35.0
#: Events that are false on an intact tool.
FALSE = ("breakage", "feed_hold")


def _program(rpm: int, kind: str, feed: int, depth: float) -> str:
    y = 30 if kind == "slot" else 80  # the demo block is 0..80 mm in Y: centre on its edge
    return (f"%\nO1 (BREAKAGE {kind.upper()})\nG21 G90 G17\nS{rpm} M3\nG0 X-12 Y{y} Z5\n"
            f"G1 Z-{depth:g} F600\nG1 X90 F{feed}\nG0 Z10\nM30\n%\n")  # fmt: skip


def _cuts(tmp: Path) -> Iterator[tuple[int, int, str, Path, Any]]:
    """Each of :data:`CUTS` as (flutes, rev/min, label, its program written in ``tmp``, its
    ``ToolConfig``)."""
    from millsense.core.config import ToolConfig

    for flutes, rpm, kind, feed, depth in CUTS:
        label = f"{flutes} flutes, {kind}, {rpm} rev/min, {depth:g} mm, F{feed}"
        prog = tmp / f"cut_{flutes}_{rpm}_{kind}.nc"
        prog.write_text(_program(rpm, kind, feed, depth))
        yield flutes, rpm, label, prog, ToolConfig(diameter_mm=DIAMETER_MM, flutes=flutes,
                                                   helix_deg=HELIX_DEG)  # fmt: skip


@dataclass
class CutRun:
    label: str
    flutes: int
    rpm: int
    broken: list[Event]  # breakage alarms of the run with the break
    intact: list[Event]  # false alarms of the intact run
    effect_s: float  # when the break shows in the tooth period's mean torque (decision 1731)

    @property
    def tooth_s(self) -> float:
        return 60.0 / (self.rpm * self.flutes)

    def latency_periods(self) -> float:
        """First alarm after the breakage's effect (decision 1731), in tooth periods (inf:
        none; negative: an alarm after the break but before it showed)."""
        return latency_periods((e.time_s for e in self.broken), BREAK_S, self.effect_s,
                               self.tooth_s)  # fmt: skip

    def break_latency_periods(self) -> float:
        """First alarm after the break instant, in tooth periods (inf: none)."""
        return latency_periods((e.time_s for e in self.broken), BREAK_S, BREAK_S, self.tooth_s)


@functools.lru_cache(maxsize=16)
def general_runs(breakage_torque: str = "dob", seed: int = 0) -> tuple[CutRun, ...]:
    """The six cuts, broken and intact, through `run`'s session; ``breakage_torque``: what its
    breakage monitor averages (decision 1726); ``seed``: the virtual machine's."""
    from millsense.online.session import SessionOptions
    from millsense.simulator.process_coupling import ToothBreak
    from millsense.validation.cases._breakage_effect import TruthTorque, effect_onset_s
    from millsense.validation.cases._program_session import program_session

    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for flutes, rpm, label, prog, tool in _cuts(Path(tmp)):
            opts = SessionOptions(breakage_torque=breakage_torque)
            truth_b, truth_i = TruthTorque(), TruthTorque()
            broken = program_session(prog, tool, events=(ToothBreak(BREAK_S, 0),), seed=seed,
                                     duration_s=BREAK_S + 1.0, options=opts,
                                     observer=truth_b).result  # fmt: skip
            intact = program_session(prog, tool, options=opts, observer=truth_i,
                                     seed=seed).result  # fmt: skip
            effect = effect_onset_s(truth_b.torque, truth_i.torque, broken.sample_rate_hz,
                                    60.0 / (rpm * flutes), BREAK_S)  # fmt: skip
            runs.append(CutRun(label, flutes, rpm,
                               [e for e in broken.events if e.name == "breakage"],
                               [e for e in intact.events if e.name in FALSE], effect))  # fmt: skip
    return tuple(runs)


def _table(runs: tuple[CutRun, ...]) -> str:
    rows = ["| cut | alarms before the break | effect after the break (tooth periods) "
            "| first alarm after the effect (tooth periods; path) | after the break (tooth "
            "periods, revolutions) | false alarms, intact run |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    for r in runs:
        before = [f"{e.time_s:.3f} s" for e in r.broken if e.time_s < BREAK_S] or ["none"]
        effect = (r.effect_s - BREAK_S) / r.tooth_s
        lat, lat_b = r.latency_periods(), r.break_latency_periods()
        after = "none" if math.isinf(lat) else f"{lat:.2f}"
        first = next((e for e in r.broken if e.time_s >= BREAK_S), None)
        if first is not None:  # which path confirmed it (decision 1684)
            ev = first.values.get("pattern_evidence")
            after += f" (flute pattern, {ev:.1f}σ)" if ev is not None else " (seed 000's rule)"
        since = "none" if math.isinf(lat_b) else f"{lat_b:.2f}, {lat_b / r.flutes:.2f}"
        false = ", ".join(f"{e.time_s:.2f} s {e.name}" for e in r.intact) or "none"
        rows.append(f"| {r.label} | {', '.join(before)} | {effect:.2f} | {after} | {since} "
                    f"| {false} |")  # fmt: skip
    return "\n".join(rows) + (
        f"\n\nFlute 0 breaks at {BREAK_S} s; Ø{DIAMETER_MM:g} mm end mill. The effect: the "
        f"tooth period's mean cutting torque {100 * EFFECT_DROP:g} % below the intact run's "
        "(the simulator's truth, decision 1731)."
    )


@case(
    "monitoring.breakage.general_cuts_detected",
    source="issue 15 item 2: a breakage event with the tooth, time and NC line (six shop cuts: "
    "2-4 flutes, slots and half immersion, 3000-10 000 rev/min)",
    reference=float(len(CUTS)),
    abs_tol=0.0,
    unit="cuts",
    quick=False,
    description="cuts of the six whose break (flute 0 at 3.0 s) raised a breakage alarm after "
    "it and none before it",
    issue=15,
)
def _detected() -> Measured:
    runs = general_runs()
    n = sum(
        math.isfinite(r.latency_periods()) and not any(e.time_s < BREAK_S for e in r.broken)
        for r in runs
    )
    return Measured(float(n), _table(runs))


@case(
    "monitoring.breakage.general_cuts_false_alarms",
    source="issue 15: no false alarm (the six cuts with the tool intact, entry, cut, exit and "
    "retract)",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms and feed holds over the six cuts run with the tool intact",
    issue=15,
)
def _false() -> Measured:
    runs = general_runs()
    return Measured(float(sum(len(r.intact) for r in runs)), _table(runs))


#: Seeds of the virtual machine for the intact cuts' held-out false-alarm count (decision
#: 1733): decisions 1732 and 1733 were made on seeds 0-39; these were first run after them.
HELD_OUT_SEEDS = range(40, 80)


@case(
    "monitoring.breakage.general_cuts_held_out_seeds_false_alarms",
    source="issue 15: no false alarm (the six cuts with the tool intact, entry, cut, exit and "
    "retract), on seeds of the virtual machine no decision was made on",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms and feed holds over the six cuts run intact through `run`'s "
    f"default session with the virtual machine's seeds {HELD_OUT_SEEDS.start}-"
    f"{HELD_OUT_SEEDS.stop - 1} ({6 * len(HELD_OUT_SEEDS)} runs; the noise, the runout's "
    "phase and the disturbances differ with the seed; decisions 1732 and 1733 were made on "
    "seeds 0-39, where 28 runs raised a false alarm before them)",
    issue=15,
)
def _held_out_false() -> Measured:
    from millsense.validation.cases._program_session import program_session

    rows = ["| cut | runs | false alarms (seed: time, evidence) |", "|---|---|---|"]
    total = 0
    with tempfile.TemporaryDirectory() as tmp:
        for _, _, label, prog, tool in _cuts(Path(tmp)):
            found = []
            for seed in HELD_OUT_SEEDS:
                res = program_session(prog, tool, seed=seed).result
                for e in res.events:
                    if e.name in FALSE:
                        ev = e.values.get("pattern_evidence")
                        how = f", {ev:.1f}σ" if ev is not None else ""
                        found.append(f"{seed}: {e.time_s:.3f} s {e.name}{how}")
            total += len(found)
            rows.append(f"| {label} | {len(HELD_OUT_SEEDS)} | {'; '.join(found) or 'none'} |")
    return Measured(float(total), "\n".join(rows))


@case(
    "monitoring.breakage.general_cuts_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 000 C17)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="the largest delay from the breakage's effect to its first alarm over the six "
    "cuts, in tooth periods (inf where a break is missed; the effect: the tooth period's mean "
    "cutting torque 5 % below the intact run's, from the simulator's truth, decision 1731), the "
    "session's breakage monitor averaging the spindle DOB's torque (seed 001 Eq. 2-15, the "
    "encoder's speed averaged over 0.9 ms; decisions 1726, 1727, the default); the table also "
    "gives the delay from the break instant (4.56 periods in the 4-flute slot, whose flute 0 "
    "breaks at the end of its arc and cuts again 2.5 periods later), the alarms before the "
    "break and on the intact runs",
    issue=15,
)
def _latency() -> Measured:
    return _worst_latency(general_runs())


def _worst_latency(runs: tuple[CutRun, ...]) -> Measured:
    """The largest first-alarm delay of ``runs``, in tooth periods, with their table."""
    return Measured(max(r.latency_periods() for r in runs), _table(runs))


#: Seeds of the virtual machine for the general cuts' latency on other realisations (the
#: cases above run seed 0).
OTHER_SEEDS = range(1, 9)


@case(
    "monitoring.breakage.general_cuts_other_seeds_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 000 C17), on "
    "other seeds of the virtual machine",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="the largest delay from the breakage's effect (decision 1731) to its first "
    "alarm over the six cuts and the virtual machine's seeds "
    f"{OTHER_SEEDS.start}-{OTHER_SEEDS.stop - 1} (the noise, the runout's phase and the "
    "disturbances differ with the seed), the session's default (the spindle DOB's torque); "
    "an alarm before the break or on an intact run counts as a miss (inf)",
    issue=15,
)
def _other_seeds_latency() -> Measured:
    rows = ["| seed | first alarm after the effect, tooth periods (the six cuts) | false alarms |",
            "|---|---|---|"]  # fmt: skip
    worst = 0.0
    for seed in OTHER_SEEDS:
        runs = general_runs("dob", seed)
        false = sum(len(r.intact) + sum(e.time_s < BREAK_S for e in r.broken) for r in runs)
        lats = [r.latency_periods() for r in runs]
        worst = max(worst, *lats, math.inf if false else 0.0)
        rows.append(f"| {seed} | {', '.join(f'{v:.2f}' for v in lats)} | {false} |")
    labels = "; ".join(r.label for r in general_runs("dob", OTHER_SEEDS[0]))
    return Measured(worst, "\n".join(rows) + f"\n\nThe cuts, in order: {labels}.")


@case(
    "monitoring.breakage.general_cuts_observer_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 000 C17), "
    "the session averaging the LQE spindle observer's torque (`--breakage-torque observer`)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="the largest delay from the breakage's effect (decision 1731) to its first "
    "alarm over the six cuts, in tooth periods (inf where a break is missed), with the breakage "
    "monitor on the machine file's LQE spindle observer's torque (Aslan Eq. 5.17-5.21; the "
    "default before decision 1727); the table also gives the delay from the break instant, "
    "the alarms before the break and on the intact runs",
    issue=15,
    gap="the tooth period's mean of the observer's torque carries the spindle encoder's "
    "quantisation through its inertial term (one count of 2^20 per revolution at 10 kHz is "
    "0.8 N·m of a 2.5 ms period's mean on the quaser-ux600; decision 1726): the broken flute's "
    "drop stands 7σ above it in one revolution only where the flute's share of the torque is "
    "large (2 flutes: 1.6 periods after the effect), and needs it repeated one or two "
    "revolutions on where it is small: the 3-flute slot (4.0), the 3-flute half immersion "
    "(4.1), the 4-flute slot (9.0, seed 000's rule first) and the 4-flute half immersion at 10 000 "
    "rev/min (9.2, seed 000's rule first). This is why the DOB is the default "
    "(decision 1727)",
)
def _observer_latency() -> Measured:
    return _worst_latency(general_runs("observer"))


@case(
    "monitoring.breakage.chatter_onset_false_alarms",
    source="issue 15: no breakage alarm where the cut chatters (seed 000 Fig. 6.16: chatter "
    "first), the session averaging the spindle DOB's torque (the default)",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of the default session (the DOB's torque, decisions 1726, "
    "1727) on the demo's chatter-prone pass (seed 000's T1, 5 flutes, 4500 rev/min), with the "
    "chatter avoidance on (the run ends 0.5 s after a feed hold, if any) and off (the chatter "
    "grows to its limit cycle and stays)",
    issue=15,
)
def _chatter_onset() -> Measured:
    import tempfile as _tempfile

    from millsense.demo_chatter import _plan, _plant_plan, _run
    from millsense.online.session import StopAfterHold

    rows = ["| chatter avoidance | breakage alarm, s | confirmed by |", "|---|---|---|"]
    count = 0
    with _tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for controlled in (True, False):
            res = _run(_plan(out), _plant_plan(), controlled, out / "c.h5",
                       out / "c.events.parquet", None,
                       wrap=lambda s: StopAfterHold(s, 0.5))  # fmt: skip
            alarms = [e for e in res.events if e.name == "breakage"]
            count += len(alarms)
            chatter = next((e.time_s for e in res.events if e.name == "chatter"), None)
            label = "on" if controlled else "off"
            for e in alarms:
                ev = e.values.get("pattern_evidence")
                how = f"the flute pattern, {ev:.2f}σ" if ev is not None else "seed 000 rule"
                rows.append(f"| {label} | {e.time_s:.4f} | {how} |")
            if not alarms:
                first = "none" if chatter is None else f"none (chatter alarm at {chatter:.2f} s)"
                rows.append(f"| {label} | {first} | |")
    return Measured(float(count), "\n".join(rows) + "\n\nBefore decision 1727 the flute "
                    "pattern confirmed a break at 1.4213 s (7.22σ) on the DOB's torque, before "
                    "the chatter monitor's 1.60 s: the chatter grew 1.5-4× a revolution in the "
                    "revolutions before the drop.")
