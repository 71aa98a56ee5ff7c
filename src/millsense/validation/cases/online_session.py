"""Acceptance of the integrated on-line session (issue 16 items 4–5): breakage → feed hold,
and the safety layer's answer to a failing link, in closed loop on the virtual machine.

Part: the V8 slot of :mod:`.control_adaptive` (Ø20 mm 2-flute, Al7050, 1000 rev/min,
400 mm/min, a step-down from 1.2 to 3 mm at X = 25 mm, the exit at X = 60 mm) on the
virtual machine's X/Y/Z (the simulator's truth plant). The session is what ``millsense run``
builds (:func:`~millsense.online.session.session_blocks`, default options: the spindle
observer of the commissioned walkthrough machine file, the plan synchronised and calibrated,
chatter and breakage monitors, the adaptive feed on the spindle power, the supervisor), behind
the source guard; the recording is written while running.

What plant and session share (decision 1740): the program, the stock, the tool's nameplate
geometry and the material's nominal coefficients. What they do not share: the virtual machine
cuts its own plan (:func:`~millsense.simulator.plant_plan.plant_plan`: a 0.05 mm z-map, 5 µm
of runout at 0.4 rad the session's plan does not know) through the truth's process; the
session's expectation is the nameplate plan (0.1 mm z-map for the V8 slot, 0.5 mm for the
chatter pass, 0.2 mm for the demo part).

- Breakage: flute 0 breaks at 8 s (in the deep part of the slot, X ≈ 38 mm). Issue 16: the feed hold
  within 3 tooth periods of the detection, the machine stopped within 200 ms of the hold, no
  breakage alarm before the break.
- Faults (issue 16): a stalled stream, NaNs on the spindle current, a dropped 20 ms of samples
  and a lost link, each at 8 s (in cut): the safe action (feed hold, since breakage is
  possible in cut) and an alarm within 100 ms; and the recording on disk holds every sample
  delivered before the end.
"""

from __future__ import annotations

import functools
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from millsense.streaming.block import Event, EventKind
from millsense.validation import Measured, case

BREAK_S = 8.0
FAULT_S = 8.0
TOOTH_S = 60.0 / 1000.0 / 2
#: The quaser-ux600 file the README walkthrough commissions (nameplate + identified).
MACHINE_FILE = (
    Path(__file__).resolve().parents[4] / "examples/walkthrough/quaser-ux600-commissioned.toml"
)
FAULTS = {
    "stall": f"stall@{FAULT_S}:0.3",
    "nan": f"nan@{FAULT_S}:0.01:spindle/current_cmd",
    "drop": f"drop@{FAULT_S}:0.02",
    "lost": f"lost@{FAULT_S}",
}


@dataclass
class SessionRun:
    events: list[Event]
    samples: int
    recorded: int
    feed: np.ndarray  # cnc/feed, m/s
    fs: float


@functools.lru_cache(maxsize=8)
def session_run(fault: str = "", break_s: float | None = None) -> SessionRun:
    """The V8 slot through ``millsense run``'s session, optionally with a link fault or a
    tooth break; the session's plan is :func:`.control_adaptive.step_plan`, the virtual
    machine cuts its own (:func:`.control_adaptive.plant_step_plan`)."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.io.recording_reader import opened_recording
    from millsense.online.faults import FaultyLink, LinkFault
    from millsense.online.session import SessionOptions, run_session, session_blocks
    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.process_coupling import ToothBreak
    from millsense.validation.cases.control_adaptive import (
        DEPTH_HIGH_MM,
        DEPTH_LOW_MM,
        plant_step_plan,
        step_plan,
    )
    from millsense.validation.cases.simulator_plan import machine_3axis

    plan = step_plan(DEPTH_LOW_MM, DEPTH_HIGH_MM)
    assert isinstance(plan, VirtualPlan)
    m = machine_3axis()
    breaks = [ToothBreak(break_s, 0)] if break_s is not None else []
    plant = plant_step_plan(DEPTH_LOW_MM, DEPTH_HIGH_MM)
    job, proc, _, _ = plan_job(plant, m, "v8_slot", events=breaks)
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=0))
    belief = load_preset(MachineConfig, str(MACHINE_FILE))
    belief = belief.with_axes("xyz", "3-axis")
    built = session_blocks(plan, belief, m.sample_rate_hz, SessionOptions(),
                           channels=sim.channel_names)  # fmt: skip
    source = FaultyLink(sim, [LinkFault.parse(fault)]) if fault else sim
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.h5"
        res = run_session(source, built.blocks, out=out, keep=("cnc/feed",))
        with opened_recording(out) as rec:
            recorded = rec.n_samples
            feed = np.asarray(rec.channel("cnc/feed"), dtype=np.float64)
    return SessionRun(res.events, res.samples, recorded, feed, m.sample_rate_hz)


def _first(events: list[Event], name: str, after: float = -1.0) -> Event | None:
    return next((e for e in events if e.name == name and e.time_s >= after), None)


def _describe(r: SessionRun) -> str:
    rows = [
        f"| {e.time_s:.3f} | {e.kind} | {e.source} | {e.name} | {e.message[:90]} |"
        for e in r.events
        if e.kind is not EventKind.OVERRIDE or e.name != "feed_override"
    ]
    return "| t [s] | kind | source | name | message |\n|---|---|---|---|---|\n" + "\n".join(rows)


@case(
    "online.breakage_hold_after_detection",
    source="issue 16: feed hold issued within 3 tooth periods of the breakage detection",
    reference=0.0,
    unit="tooth periods",
    abs_tol=3.0,
    quick=False,
    description="Feed hold time minus breakage alarm time, in tooth periods (30 ms).",
)
def _hold_latency() -> Measured:
    r = session_run(break_s=BREAK_S)
    alarm = _first(r.events, "breakage")
    hold = _first(r.events, "feed_hold")
    if alarm is None or hold is None:
        return Measured(float("nan"), "no breakage alarm or no feed hold\n\n" + _describe(r))
    return Measured((hold.time_s - alarm.time_s) / TOOTH_S, _describe(r))


@case(
    "online.breakage_machine_stop_ms",
    source="issue 16: the simulated machine stops within 200 ms of the feed hold",
    reference=100.0,
    unit="ms",
    abs_tol=100.0,
    quick=False,
    description=(
        "Time from the feed hold to the path feed below 1 % of the programmed (the CNC's "
        "deceleration; 0–200 ms accepted)."
    ),
)
def _machine_stop() -> Measured:
    r = session_run(break_s=BREAK_S)
    hold = _first(r.events, "feed_hold")
    if hold is None:
        return Measured(float("nan"), _describe(r))
    k0 = round(hold.time_s * r.fs)
    slow = np.flatnonzero(r.feed[k0:] < 0.01 * 400e-3 / 60)
    if slow.size == 0:
        return Measured(float("inf"), "the feed never fell below 1 %")
    return Measured(1000.0 * slow[0] / r.fs, _describe(r))


@case(
    "online.breakage_false_alarms",
    source="issue 16 / seed 000 V7: no breakage alarm at the entry, the step-down or the exit",
    reference=0.0,
    unit="alarms",
    abs_tol=0.0,
    quick=False,
    description="Breakage alarms before the break, in the session with the break at 8 s.",
)
def _false_breakage() -> Measured:
    r = session_run(break_s=BREAK_S)
    n = sum(1 for e in r.events if e.name == "breakage" and e.time_s < BREAK_S)
    return Measured(float(n), _describe(r))


def _fault_case(kind: str) -> Measured:
    r = session_run(fault=FAULTS[kind])
    if kind == "lost":
        act = _first(r.events, "source_lost", FAULT_S)
    else:
        act = _first(r.events, "feed_hold", FAULT_S)
        alarm = _first(r.events, "input_fault", FAULT_S)
        if alarm is None:
            act = None
    if act is None:
        return Measured(float("nan"), "no safe action\n\n" + _describe(r))
    lost = r.samples - r.recorded
    note = f"samples delivered {r.samples}, recorded {r.recorded} (lost: {lost})\n\n"
    if lost:
        return Measured(float("inf"), note + _describe(r))
    return Measured(1000.0 * (act.time_s - FAULT_S), note + _describe(r))


for _kind in FAULTS:

    def _make(kind: str = _kind) -> Measured:
        return _fault_case(kind)

    _make.__doc__ = f"Safe action after a {_kind} fault of the link."
    case(
        f"online.fault_{_kind}_safe_action_ms",
        source=(
            "issue 16: a stalled source, NaNs, a dropped chunk and a lost source each produce "
            "the safe action and an alarm within 100 ms; nothing recorded before is lost"
        ),
        reference=50.0,
        unit="ms",
        abs_tol=50.0,
        quick=False,
        ci=_kind == "stall",
        description=(
            f"Fault ({FAULTS[_kind]}) start to the feed hold with its alarm (lost: to the "
            "guard's hold on the command path); infinite if the recording misses samples."
        ),
    )(_make)


# ---------------------------------------------------------------- chatter in the session
#: The chatter-prone pass: the V5 T1 replica (Ø50 mm 5-flute, its modal table) slotting Al7050
#: at 4500 rev/min, 1.2 mm deep, 0.1 mm/tooth (the case of ``control.chatter_avoidance_*``),
#: here planned and run through ``millsense run``'s session; the plant runs the tool's table, the
#: session's lobes come from a simulated tap test of that tool (decision 1750).
CHATTER_RPM = 4500.0
CHATTER_DEPTH_MM = 1.2


@functools.lru_cache(maxsize=1)
def chatter_run() -> dict[str, object]:
    """The T1 slot through the session; the speed commands, alarms and the truth's chatter.
    The session's plan has a 0.5 mm z-map; the virtual machine cuts its own (0.05 mm z-map,
    5 µm of runout at 0.4 rad, decision 1740)."""
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import commissioned_machine, load_preset
    from millsense.core.units import MM
    from millsense.io.recording_reader import opened_recording
    from millsense.online.session import SessionOptions, run_session, session_blocks
    from millsense.plan.gcode import interpret
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.plant_plan import plant_plan
    from millsense.validation.cases.control_chatter_avoidance import stability_case, truth_modes
    from millsense.validation.cases.monitoring_chatter import TOOLS
    from millsense.validation.cases.simulator_plan import machine_3axis

    d, n = TOOLS["T1"][0], TOOLS["T1"][1]
    feed = 0.1 * n * CHATTER_RPM
    prog = (
        f"G21 G90 G17\nT1 M6\nS{CHATTER_RPM:.0f} M3\nG0 X-40 Y0 Z5\n"
        f"G1 Z{-CHATTER_DEPTH_MM} F{feed:.0f}\nX200\nG0 Z5\nM30\n"
    )

    def stock(cell_m: float) -> ZMapStock:
        return ZMapStock.from_box([0.0, -0.05, -0.03], [0.25, 0.05, 0.0], cell_m)

    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    toolpath = interpret(prog, source="t1_slot.nc")
    plan = plan_program(toolpath, stock(0.5 * MM), EndMill(d, n), coeffs, step_m=1.0 * MM)
    plant = plant_plan([toolpath], stock, EndMill(d, n), coeffs, step_m=1.0 * MM)
    m = machine_3axis()
    job, proc, _, _ = plan_job(plant, m, "t1_slot.nc", modes=truth_modes())
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=11))
    shipped = commissioned_machine("quaser-ux600")
    assert shipped is not None
    belief = shipped[0].with_axes("xyz", "3-axis")
    opts = SessionOptions(stability_case=stability_case())
    built = session_blocks(plan, belief, m.sample_rate_hz, opts, channels=sim.channel_names)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "t1.h5"
        res = run_session(
            sim, built.blocks, out=out, keep=("truth/process/chatter", "spindle/speed")
        )
        with opened_recording(out) as rec:
            chatter = np.asarray(rec.channel("truth/process/chatter")) > 0.5
            speed = np.asarray(rec.channel("spindle/speed"))
    return {"events": res.events, "chatter": chatter, "fs": m.sample_rate_hz, "speed": speed}


def _chatter_table(r: dict[str, object]) -> str:
    ev = r["events"]
    assert isinstance(ev, list)
    rows = [
        f"| {e.time_s:.3f} | {e.name} | {e.message[:110]} |"
        for e in ev
        if e.name in ("chatter", "chatter_end", "spindle_override", "breakage_set_aside",
                      "feed_hold", "breakage")
    ]  # fmt: skip
    return "| t [s] | event | message |\n|---|---|---|\n" + "\n".join(rows)


#: Why the truth of the T1 session is chatter-free only 1.2-1.3 s after its one speed change
#: (2026-11-28; decisions 1656 and 1539, the same evening, each moved it).
_T1_SLOW_END = (
    "one speed change, 4500 -> 6101 rev/min, the centre of lobe 1's stable pocket (decision "
    "1635), found at 2.1 s (512.8 Hz, ratio 8.95); the spindle is at the new speed within "
    "0.1 s and the monitor ends the episode 0.7 s after the change, but the truth has its "
    "first quiet second only 1.2 s after it. At the pocket's centre the tooth-passing "
    "frequency (about 510 Hz) sits on the truth's 546 Hz tool mode softened by about 7 % under "
    "the slot's load: the truth's tool vibration grows to 20-25 µm RMS, mostly periodic with "
    "the revolution (2-6 µm change from one revolution to the next, so the truth's chatter "
    "flag rises in short bursts) before it falls to the stable cut's 2 µm; a forced resonance "
    "on top of the lobe rather than chatter, as far as checked. The closed loop is sensitive "
    "to when and at what frequency the chatter is found: 1.267 s before decision 1656 (found "
    "at 2.3 s, 510.4 Hz, 6102 rev/min); 0.222 s with decision 1656 alone (2.4 s, 509.7 Hz, "
    "6098 rev/min: a pass by that shift); 1.172 s since decision 1539 found it 0.1-0.2 s "
    "sooner (2.2 s, 511.6 Hz, 6109 rev/min); 1.179 s since decision 1543 judged the entry's "
    "part from two revolutions on (2.1 s, 512.8 Hz, 6101 rev/min); 1.197 s with decision 1546 "
    "(the same detection and command to within a fraction of a rev/min; the ratio 8.94); "
    "0.263 s, a pass, since decision 1548 (the adaptive feed's interval of 3 revolutions and "
    "its dead zone: found at 2.1 s, 512.6 Hz, ratio 12.95, 6099 rev/min), 2 rev/min from the "
    "failing command; 0.366 s since decision 1555 (the air reference's start no longer reads "
    "900 W in air, which the adaptive feed answered with 150 % until 0.82 s: the tool now "
    "approaches at the entry feed from the first decision and meets the material 0.6 s later, "
    "and the chatter is found at 2.4 s, 534.8 Hz, ratio 1.56, 6107 rev/min). At the "
    "programmed feed "
    "(the demo's pass, `online.demo_chatter_pass_gone_s`) the truth is quiet 0.12 s after the "
    "change"
)


@case(
    "online.chatter_gone_after_last_speed_change_s",
    source="issue 16: chatter detected on the chatter-prone pass is gone within 1 s after the "
    "speed change (seed 000 C13)",
    reference=0.5,
    unit="s",
    abs_tol=0.5,
    quick=False,
    description=(
        "T1 replica slot at 4500 rev/min, 1.2 mm, through the session: time from the last "
        "spindle-speed command to the start of the first second free of chatter in the "
        "simulator's truth, s (0–1 s accepted)."
    ),
    gap=_T1_SLOW_END,
    issue=16,
)
def _chatter_gone() -> Measured:
    r = chatter_run()
    gone = _quiet_after_last_change_s(r)
    if gone is None:
        return Measured(float("nan"), "no speed change\n\n" + _chatter_table(r))
    return Measured(gone[0], _chatter_table(r))


def _quiet_after_last_change_s(r: dict[str, object]) -> tuple[float, bool] | None:
    """Time from the last spindle-speed command to the first sample after which the truth shows
    no chatter for a whole second, s, and whether there is such a second (None: no command). A
    later blip at the exit of the slot is another episode, not this one. Never quiet: the time
    from the command to the end of the record (a lower bound, finite so that the case is judged
    as a failure, not an error), and False."""
    ev = r["events"]
    assert isinstance(ev, list)
    cmds = [e for e in ev if e.name == "spindle_override"]
    if not cmds:
        return None
    chatter = r["chatter"]
    fs = r["fs"]
    assert isinstance(chatter, np.ndarray) and isinstance(fs, float)
    from millsense.demo_chatter import quiet_after

    k0 = round(cmds[-1].time_s * fs)
    quiet = quiet_after(chatter, k0, fs)
    if math.isfinite(quiet):
        return quiet, True
    return float(chatter.size - k0) / fs, False


@case(
    "online.chatter_speed_changes_until_stable",
    source="seed 000 C13 / issue 16: one speed change to a stable pocket of the lobes",
    reference=1.0,
    unit="changes",
    abs_tol=0.0,
    quick=False,
    description="Spindle-speed commands of the chatter avoidance in the session on the T1 slot "
    "(one more when the truth never stops chattering after the last one: the change it still "
    "needed; how soon it stops is `online.chatter_gone_after_last_speed_change_s`).",
)
def _chatter_changes() -> Measured:
    # the changes count only if they ended the chatter: a session that stops changing while the
    # truth chatters to the end of the record (a missed episode) counts the change it still
    # needed
    r = chatter_run()
    ev = r["events"]
    assert isinstance(ev, list)
    changes = float(sum(1 for e in ev if e.name == "spindle_override"))
    gone = _quiet_after_last_change_s(r)
    stable = gone is not None and gone[1]
    return Measured(changes if stable else changes + 1.0, _chatter_table(r))


@case(
    "online.chatter_no_false_hold",
    source="seed 000 Fig. 6.16: breakage is judged only when stable (decision 1621)",
    reference=0.0,
    unit="feed holds",
    abs_tol=0.0,
    quick=False,
    description="Feed holds in the T1 chatter run (the tool is intact).",
)
def _chatter_no_hold() -> Measured:
    r = chatter_run()
    ev = r["events"]
    assert isinstance(ev, list)
    return Measured(float(sum(1 for e in ev if e.name == "feed_hold")), _chatter_table(r))


#: The demo part's break (:data:`millsense.demo_online.BREAK_S`): in the open run the tool is
#: then cutting into the cavity's near wall, a transient of the plan.
DEMO_BREAK_S = 20.0


@functools.lru_cache(maxsize=1)
def demo_open_run() -> list[Event]:
    """The events of the demo part's open run (``millsense demo``: the session's monitors and
    controllers run, nothing reaches the machine, so the CNC runs the program as written and
    the timing is the program's) with flute 0 broken at :data:`DEMO_BREAK_S`."""
    from millsense.demo_online import BREAK_S, _plan, _plant_plan, _run

    assert BREAK_S == DEMO_BREAK_S
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        res = _run(_plan(out), _plant_plan(), False, out / "open.h5",
                   out / "open.events.parquet", None)  # fmt: skip
    return list(res.events)


def _demo_table(events: list[Event]) -> str:
    rows = [
        f"| {e.time_s:.3f} | {e.name} | {e.message[:110]} |"
        for e in events
        if e.name in ("breakage", "ktc_calibrated")
    ]
    return "| t [s] | name | message |\n|---|---|---|\n" + "\n".join(rows)


@case(
    "online.demo_part_breakage_latency",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 000 C17) on "
    "the demo part",
    reference=1.5,
    unit="tooth periods",
    abs_tol=1.5,
    quick=False,
    description=(
        "The demo part's open run (the program as written), flute 0 broken at 20 s while the "
        "tool cuts into the cavity's near wall (a transient of the plan): first breakage alarm "
        "after the break, minus the break, in tooth periods (30 ms), judged against the issue's "
        "≤ 3 tooth periods as monitoring.breakage.general_cuts_latency_periods is. Until "
        "decision 1684 the session's detector was seed 000's rule alone (confirmation over 3 "
        "tooth periods: 3.04 here, judged 3 ± 0.5); with the flute pattern it confirms from the "
        "broken flute's pattern. Seed 000's rule itself is judged by "
        "monitoring.breakage.v7_virtual_latency."
    ),
)
def _demo_latency() -> Measured:
    ev = demo_open_run()
    alarm = _first(ev, "breakage", after=DEMO_BREAK_S)
    if alarm is None:
        return Measured(float("nan"), "no breakage alarm after the break\n\n" + _demo_table(ev))
    return Measured((alarm.time_s - DEMO_BREAK_S) / TOOTH_S, _demo_table(ev))


@case(
    "online.demo_part_breakage_false_alarms",
    source="issue 15 / seed 000 V7: no alarm at the depth step, in cavities or at exits",
    reference=0.0,
    unit="alarms",
    abs_tol=0.0,
    quick=False,
    description="Breakage alarms before the break in the demo part's open run.",
)
def _demo_false() -> Measured:
    ev = demo_open_run()
    n = sum(1 for e in ev if e.name == "breakage" and e.time_s < DEMO_BREAK_S)
    return Measured(float(n), _demo_table(ev))


# ---------------------------------------------------------------- the demo's chatter-prone pass
@functools.lru_cache(maxsize=1)
def demo_chatter_run() -> dict[str, object]:
    """The summary of ``millsense demo``'s chatter-prone pass (decision 1660: the T1 slot at the
    programmed feed, controlled and open) and the controlled run's events."""
    from millsense.demo_chatter import run_chatter_demo
    from millsense.streaming.event_log import read_event_log

    with tempfile.TemporaryDirectory() as tmp:
        summary = run_chatter_demo(tmp)
        summary["events"] = read_event_log(Path(tmp) / "online_chatter.events.parquet")
    return summary


def _demo_controlled() -> tuple[dict[str, object], dict[str, Any]]:
    """The demo chatter pass's summary and its controlled run's figures."""
    s = demo_chatter_run()
    runs = s["runs"]
    assert isinstance(runs, dict)
    return s, runs["controlled"]


def _demo_chatter_detail(s: dict[str, object]) -> str:
    runs = s["runs"]
    assert isinstance(runs, dict)
    lines = ["| run | alarm [s] | at [Hz] | speed commands | last speed [rev/min] | "
             "truth chatters [% of cut] | quiet 1 s after [s] |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for k, r in runs.items():
        hz = "-" if r["alarm_hz"] is None else f"{r['alarm_hz']:.1f}"
        quiet = r["quiet_after_command_s"]
        lines.append(f"| {k} | {r['alarm_s']} | {hz} | {r['speed_commands']}"
                     f"{' (not sent)' if k == 'open' else ''} | {r['last_rpm']:.0f} | "
                     f"{100 * r['truth_chatter_share']:.0f} | "
                     f"{'-' if quiet is None else f'{quiet:.3f}'} |")  # fmt: skip
    ev = s["events"]
    assert isinstance(ev, list)
    return "\n".join(lines) + "\n\n" + _chatter_table({"events": ev})


@case(
    "online.demo_chatter_pass_speed_changes",
    source="seed 000 C13 / issue 16 item 6: the demo's chatter-prone pass, one speed change to a "
    "stable pocket",
    reference=1.0,
    unit="changes",
    abs_tol=0.0,
    quick=False,
    description="`millsense demo`'s chatter-prone pass (T1 slot, 4500 rev/min, 1.2 mm, at the "
    "programmed feed; decision 1660): spindle-speed commands of the controlled run (one more "
    "when the truth never has a quiet second after the last one).",
)
def _demo_chatter_changes() -> Measured:
    s, r = _demo_controlled()
    extra = 0.0 if r["stopped"] else 1.0
    return Measured(float(r["speed_commands"]) + extra, _demo_chatter_detail(s))


@case(
    "online.demo_chatter_pass_gone_s",
    source="issue 16: chatter detected on the chatter-prone pass is gone within 1 s after the "
    "speed change (seed 000 C13)",
    reference=0.5,
    unit="s",
    abs_tol=0.5,
    quick=False,
    description="`millsense demo`'s chatter-prone pass (decision 1660), controlled run: time from "
    "the last spindle-speed command to the start of the first second free of chatter in the "
    "simulator's truth, s (0–1 s accepted; the run's length when never quiet).",
)
def _demo_chatter_gone() -> Measured:
    s, r = _demo_controlled()
    if r["speed_commands"] == 0:
        return Measured(float("nan"), "no speed change\n\n" + _demo_chatter_detail(s))
    quiet = r["quiet_after_command_s"]
    value = float(r["seconds"]) if quiet is None else float(quiet)
    return Measured(value, _demo_chatter_detail(s))
