"""Tool breakage without a plan: `millsense monitor` on the virtual machine's V7 recording.

A shop's CNC trace often comes without a virtual plan. `monitor --methods
breakage-dual,breakage-constant` then runs seed 002's dual-residual detector and the constant
reference on the spindle observer's torque, gated by the torque alone (decision 1706) and,
for the dual one, on a broken flute's drop and the next flute's rise (decision 1707).

The recording is V7's (:func:`~millsense.validation.cases.monitoring_breakage.v7_plant`): the
demo part's three slots, the virtual machine cutting its own plan (its z-map, runout and true
coefficients), flute 0 broken in SLOT3, the CNC running the program as written from the
spindle's start. The monitor reads what a CNC records and the commissioned machine file; it
sees no plan. The slots hold a depth step, two crossings, a cavity and two exits: every change
of the cut a shop's part has. Issue 15: "both residuals exceed their thresholds at the
breakage and only there"; breakage effect to event ≤ 3 tooth periods.

A second recording (decision 1723): a slot whose program changes the spindle's speed right
before the entry, the cut beginning during the ramp, as a shop's programs and overrides do;
with a 2-flute and a 3-flute end mill (decision 1724).
"""

from __future__ import annotations

import functools
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

from millsense.streaming.block import Event
from millsense.streaming.event_log import read_event_log
from millsense.validation import Measured, case
from millsense.validation.cases._breakage_effect import EFFECT_DROP, latency_periods
from millsense.validation.cases.monitoring_breakage import MACHINE_FILE, TOOTH_S_V7

METHODS = ("breakage-dual", "breakage-constant")


@dataclass
class PlanFreeRun:
    break_s: float
    events: dict[str, list[Event]]

    def false_alarms(self) -> int:
        return sum(e.time_s < self.break_s for ev in self.events.values() for e in ev)

    def latency_periods(self, method: str) -> float:
        alarms = (e.time_s for e in self.events[method])
        return latency_periods(alarms, self.break_s, self.break_s, TOOTH_S_V7)

    def table(self) -> str:
        rows = ["| detector | alarms before the break | first alarm after it (tooth periods) |",
                "|---|---|---|"]  # fmt: skip
        for m in METHODS:
            before = [f"{e.time_s:.2f} s" for e in self.events[m] if e.time_s < self.break_s]
            lat = self.latency_periods(m)
            rows.append(f"| {m} | {', '.join(before) or 'none'} | "
                        f"{'none' if math.isinf(lat) else f'{lat:.2f}'} |")  # fmt: skip
        return "\n".join(rows) + f"\n\nFlute 0 breaks at {self.break_s:.3f} s (SLOT3)."


def _monitor(path: Path) -> list[Event]:
    """`millsense monitor` on the recording ``path`` without a plan, as a shop runs it (the
    commissioned machine file, :data:`METHODS`), in its own process: validation sits below the
    command line and may not import it. Its event log."""
    import subprocess
    import sys

    log = path.with_suffix(".events.parquet")
    cmd = [sys.executable, "-m", "millsense", "monitor", str(path), "--machine",
           str(MACHINE_FILE), "--methods", ",".join(METHODS), "-o", str(log)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"millsense monitor failed: {done.stderr.strip()[-500:]}")
    return read_event_log(log)


@functools.lru_cache(maxsize=1)
def plan_free_run() -> PlanFreeRun:
    """V7's plant run to its end (seed 7, as the V7 case), recorded as a CNC records it, then
    `millsense monitor` without a plan, in its own process (≈ 30 s)."""
    from millsense.io.recording_file import write_recording
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.validation.cases._program_session import cnc_recording
    from millsense.validation.cases.monitoring_breakage import v7_plant
    from millsense.validation.cases.simulator_plan import machine_3axis

    m = machine_3axis()
    job, proc, break_s, _ = v7_plant()
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=7))
    rec = cnc_recording(sim, {"flutes": 2, "program": "demo_part_slots.nc"})
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "v7.h5"
        write_recording(path, rec)
        logged = _monitor(path)
    events = {mth: [e for e in logged if e.source == mth and e.name == "breakage"]
              for mth in METHODS}  # fmt: skip
    return PlanFreeRun(break_s, events)


@case(
    "monitoring.breakage.plan_free_false_alarms",
    source="issue 15 (seed 002 breakage pattern): both residuals beyond their thresholds at "
    "the breakage and only there, on a recording without a plan (V7's slots: a depth step, "
    "crossings, a cavity, exits)",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors before the break, "
    "without a plan (decisions 1706, 1707)",
    issue=15,
)
def _false() -> Measured:
    run = plan_free_run()
    return Measured(float(run.false_alarms()), run.table())


@case(
    "monitoring.breakage.plan_free_dual_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 002's "
    "dual-residual detector, no plan)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="first dual-residual alarm after the break, in tooth periods (inf: missed), "
    "`monitor` without a plan",
    issue=15,
)
def _latency() -> Measured:
    run = plan_free_run()
    return Measured(run.latency_periods("breakage-dual"), run.table())


#: Decision 1723: a program whose S word comes right before the entry, as many do (the spindle
#: ramps from 1500 to 3000 rev/min while the Ø12 mm 2-flute end mill enters a 4 mm slot of the
#: demo part's Al7050 block); flute 0 breaks at ``SPEED_BREAK_S``. Decision 1706's gate forgot
#: the air at the speed change and took the cut for it: the detectors judged nothing.
SPEED_PROGRAM = (
    "%\nO1 (S WORD BEFORE THE ENTRY)\nG21 G90 G17\nS1500 M3\nG0 X-12 Y30 Z5\nG1 Z-4 F600\n"
    "G1 X-6.5 F900\nS3000\nG1 X90\nG0 Z10\nM30\n%\n"
)
SPEED_BREAK_S = 3.0
SPEED_RPM = 3000.0


def speed_tooth_s(flutes: int) -> float:
    """A tooth period at the program's cutting speed, s."""
    return 60.0 / (SPEED_RPM * flutes)


@dataclass
class SpeedRuns:
    """`monitor`'s breakage alarms on the broken and the intact run of :data:`SPEED_PROGRAM`,
    and when the break showed (decision 1731)."""

    runs: dict[str, list[Event]]  # "broken", "intact"
    effect_s: float
    flutes: int

    def latency_periods(self, method: str = "breakage-dual", since: float | None = None) -> float:
        """The first alarm of ``method`` at or after the break, in tooth periods after
        ``since`` (None: the breakage's effect, decision 1731; inf: none)."""
        alarms = (e.time_s for e in self.runs["broken"] if e.source == method)
        start = self.effect_s if since is None else since
        return latency_periods(alarms, SPEED_BREAK_S, start, speed_tooth_s(self.flutes))

    def table(self) -> str:
        rows = ["| run | detector | alarms |", "|---|---|---|"]
        for label, events in self.runs.items():
            for m in METHODS:
                times = [f"{e.time_s:.4f} s" for e in events if e.source == m]
                rows.append(f"| {label} | {m} | {', '.join(times) or 'none'} |")
        tooth = speed_tooth_s(self.flutes)
        lat, lat_b = self.latency_periods(), self.latency_periods(since=SPEED_BREAK_S)
        return "\n".join(rows) + (
            f"\n\nS1500 -> S3000 right before the entry; flute 0 breaks at {SPEED_BREAK_S} s in "
            f"the broken run ({self.flutes} flutes, tooth period {1e3 * tooth:.3g} ms). The break "
            f"shows {(self.effect_s - SPEED_BREAK_S) / tooth:.2f} tooth periods after it (the "
            f"tooth period's mean cutting torque {100 * EFFECT_DROP:g} % below the intact run's, "
            f"decision 1731); the first dual alarm comes {lat:.2f} tooth periods after that, "
            f"{lat_b:.2f} after the break."
        )


@functools.lru_cache(maxsize=8)
def speed_change_runs(flutes: int = 2) -> SpeedRuns:
    """`monitor`'s breakage alarms on :data:`SPEED_PROGRAM` run by the virtual machine open
    loop with a Ø12 mm end mill of ``flutes`` flutes, with flute 0 broken at
    :data:`SPEED_BREAK_S` (``broken``) and intact (``intact``), and the break's effect."""
    from millsense.core.config import ToolConfig
    from millsense.simulator.process_coupling import ToothBreak
    from millsense.validation.cases._breakage_effect import TruthTorque, effect_onset_s
    from millsense.validation.cases._program_session import program_recording

    tool = ToolConfig(diameter_mm=12.0, flutes=flutes, helix_deg=35.0)
    runs = {}
    truth = {"broken": TruthTorque(), "intact": TruthTorque()}
    with tempfile.TemporaryDirectory() as tmp:
        prog = Path(tmp) / "s_word_before_entry.nc"
        prog.write_text(SPEED_PROGRAM)
        for label, events in (("broken", (ToothBreak(SPEED_BREAK_S, 0),)), ("intact", ())):
            path = Path(tmp) / f"{label}.h5"
            program_recording(prog, tool, path, events=events, observer=truth[label])
            runs[label] = [e for e in _monitor(path) if e.name == "breakage"]
    effect = effect_onset_s(truth["broken"].torque, truth["intact"].torque,
                            truth["broken"].sample_rate_hz,
                            speed_tooth_s(flutes), SPEED_BREAK_S)  # fmt: skip
    return SpeedRuns(runs, effect, flutes)


@case(
    "monitoring.breakage.plan_free_speed_change_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 002's "
    "dual-residual detector, no plan; the spindle's speed changed as the tool entered the cut)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="first dual-residual alarm after the breakage's effect (decision 1731), in "
    "tooth periods (inf: missed), `monitor` without a plan on a program whose S word comes "
    "right before the entry (decision 1723)",
    issue=15,
)
def _speed_latency() -> Measured:
    return _dual_latency(2)


def _dual_latency(flutes: int) -> Measured:
    """The dual detector's first alarm after the break's effect, in tooth periods, on
    :func:`speed_change_runs` (inf: missed)."""
    runs = speed_change_runs(flutes)
    return Measured(runs.latency_periods(), runs.table())


def _false_alarms(flutes: int) -> Measured:
    """Alarms of either detector on the intact run and before the break (:func:`speed_change_
    runs`)."""
    runs = speed_change_runs(flutes)
    n = len(runs.runs["intact"]) + sum(e.time_s < SPEED_BREAK_S for e in runs.runs["broken"])
    return Measured(float(n), runs.table())


@case(
    "monitoring.breakage.plan_free_speed_change_false_alarms",
    source="issue 15: no false alarm (air cuts, speed changes, an entry and an exit), without a "
    "plan",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors on the intact run "
    "and before the break, the program with its S word right before the entry (decision 1723)",
    issue=15,
)
def _speed_false() -> Measured:
    return _false_alarms(2)


@case(
    "monitoring.breakage.plan_free_three_flutes_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 002's "
    "dual-residual detector, no plan; a 3-flute end mill, whose broken flute's drop and the "
    "next flute's rise lie two tooth periods apart in a slot)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="first dual-residual alarm after the breakage's effect (decision 1731), in "
    "tooth periods (inf: missed), `monitor` without a plan, the S-word program with a 3-flute "
    "end mill (decision 1724); the flute check waits for the next flute's rise, two tooth "
    "periods after the broken flute's drop in a slot: 3.33 periods after the break instant",
    issue=15,
)
def _three_latency() -> Measured:
    return _dual_latency(3)


@case(
    "monitoring.breakage.plan_free_three_flutes_false_alarms",
    source="issue 15: no false alarm (air cuts, speed changes, an entry and a retract), "
    "without a plan, a 3-flute end mill",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors on the intact run "
    "and before the break, the S-word program with a 3-flute end mill (decision 1724)",
    issue=15,
)
def _three_false() -> Measured:
    return _false_alarms(3)


#: Decision 1728: end mills of more flutes on the S-word program (each flute's share of the
#: torque smaller, the broken flute's drop and the next flute's rise up to ⌈N/2⌉ periods apart).
MANY_FLUTES = (4, 5, 6)


@case(
    "monitoring.breakage.plan_free_many_flutes_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 002's "
    "dual-residual detector, no plan; 4-, 5- and 6-flute end mills)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="the largest first dual-residual alarm after the breakage's effect (decision "
    "1731) over 4, 5 and 6 flutes, in tooth periods (inf: missed), `monitor --machine` without "
    "a plan (the spindle DOB's torque, decision 1728) on the S-word program",
    issue=15,
    gap="every break is found (on the LQE observer's torque the 6-flute one was missed, "
    "decision 1726), 2.68, 3.60 and 3.54 periods after its effect with 4, 5 and 6 flutes "
    "(3.44, 4.55, 4.68 after the break instant): the flute check waits for the next flute's "
    "rise, up to ⌈N/2⌉ periods after the broken flute's drop in a slot (decision 1724)",
)
def _many_latency() -> Measured:
    rows = [(f, _dual_latency(f)) for f in MANY_FLUTES]
    text = "\n\n".join(f"**{f} flutes** (first dual alarm {m.value:.2f} tooth periods after "
                         f"the break's effect)\n\n{m.details}" for f, m in rows)  # fmt: skip
    return Measured(max(m.value for _, m in rows), text)


@case(
    "monitoring.breakage.plan_free_many_flutes_false_alarms",
    source="issue 15: no false alarm (air cuts, speed changes, an entry and a retract), "
    "without a plan, 4-, 5- and 6-flute end mills",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors on the intact runs "
    "and before the break, the S-word program with 4-, 5- and 6-flute end mills (decision 1728)",
    issue=15,
)
def _many_false() -> Measured:
    rows = [(f, _false_alarms(f)) for f in MANY_FLUTES]
    text = "\n\n".join(f"**{f} flutes**\n\n{m.details}" for f, m in rows)
    return Measured(float(sum(m.value for _, m in rows)), text)


#: Seeds of the virtual machine for the plan-free detectors' false-alarm count on other
#: realisations of the S-word program (the cases above run seed 0).
OTHER_SEEDS = range(1, 21)


@case(
    "monitoring.breakage.plan_free_other_seeds_false_alarms",
    source="issue 15: no false alarm (air cuts, speed changes, an entry and a retract), "
    "without a plan, on other seeds of the virtual machine",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors (`--machine`, no "
    "plan) on the S-word program run intact with 2-6 flute end mills and the virtual "
    f"machine's seeds {OTHER_SEEDS.start}-{OTHER_SEEDS.stop - 1} "
    f"({5 * len(OTHER_SEEDS)} runs: the noise, the runout's phase and the disturbances differ "
    "with the seed)",
    issue=15,
)
def _other_seeds_false() -> Measured:
    from millsense.core.config import ToolConfig
    from millsense.validation.cases._program_session import program_recording

    rows = ["| flutes | runs | false alarms (seed: time, detector) |", "|---|---|---|"]
    total = 0
    with tempfile.TemporaryDirectory() as tmp:
        prog = Path(tmp) / "s_word_before_entry.nc"
        prog.write_text(SPEED_PROGRAM)
        for flutes in (2, 3, *MANY_FLUTES):
            tool = ToolConfig(diameter_mm=12.0, flutes=flutes, helix_deg=35.0)
            found = []
            for seed in OTHER_SEEDS:
                path = Path(tmp) / f"intact_{flutes}_{seed}.h5"
                program_recording(prog, tool, path, seed=seed)
                found += [f"{seed}: {e.time_s:.3f} s {e.source}" for e in _monitor(path)
                          if e.name == "breakage"]  # fmt: skip
                path.unlink()
            total += len(found)
            rows.append(f"| {flutes} | {len(OTHER_SEEDS)} | {'; '.join(found) or 'none'} |")
    return Measured(float(total), "\n".join(rows))


@case(
    "monitoring.breakage.plan_free_chatter_onset_false_alarms",
    source="issue 15: no breakage alarm where the cut chatters (seed 000 Fig. 6.16: chatter "
    "first), without a plan",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor --machine`'s dual and constant detectors (the "
    "spindle DOB's torque, no plan) on the demo's chatter-prone pass recorded as a CNC records "
    "it, the program run as written: seed 000's T1, 5 flutes, 4500 rev/min, chattering from "
    "its entry (at 511 Hz) to its end (decision 1728)",
    issue=15,
)
def _chatter_false() -> Measured:
    from millsense.demo_chatter import _plant_plan, pass_machine
    from millsense.io.recording_file import write_recording
    from millsense.validation.cases._program_session import cnc_recording

    sim, _ = pass_machine(_plant_plan())
    rec = cnc_recording(sim, {"flutes": 5, "program": "online_chatter.nc"})
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "chatter_pass.h5"
        write_recording(path, rec)
        logged = [e for e in _monitor(path) if e.name == "breakage"]
    rows = ["| detector | alarms |", "|---|---|"]
    for m in METHODS:
        times = [f"{e.time_s:.4f} s" for e in logged if e.source == m]
        rows.append(f"| {m} | {', '.join(times) or 'none'} |")
    return Measured(float(len(logged)), "\n".join(rows) + "\n\nBefore decision 1728 both "
                    "alarmed at 1.52 s on the DOB's torque (the chatter's onset).")
