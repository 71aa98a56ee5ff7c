"""The demo's chatter-prone pass: the third part of ``millsense demo`` (issue 16 item 6).

A slot that chatters, run through the same on-line session as the demo part
(:mod:`millsense.demo_online`) with and without control, so that the chatter monitor, the
chatter avoidance and the truth's vibration can be seen side by side.

The tool is seed 000's chatter-test tool T1 (Aslan Tables 5.3-5.4, digest P9: Ø50 mm 5-tooth
face mill, its modal table shipped as ``millsense/data/tool_modes/aslan-v5-t1.toml``), slotting
Al7050 1.2 mm deep at 4500 rev/min and 0.1 mm/tooth — the conditions of the validation cases
``control.chatter_avoidance_*`` and ``online.chatter_*``, which lie between two lobes. A Ø50 mm
slot does not fit beside the demo part's channel and slot on its 80 mm wide block, so the pass
runs on a bar of its own (200 × 80 × 30 mm, Al7050): decision 1660.

The virtual machine (the simulator's truth of the quaser-ux600, X/Y/Z) runs the tool's modes,
softened under load as its truth does, and cuts its own plan of the pass (a 0.05 mm z-map, 5 µm
of runout; decision 1740); the session plans on a 0.5 mm z-map without runout, takes its lobes'
cutting coefficients and settings from the tool file and their structure from a simulated tap
test of the plant's tool at rest (hammer and accelerometer with noise, H1, modal fit:
:mod:`millsense.bench.tap_test`, decision 1750; issue 12: the table itself is the plant's, not
the controller's) and runs the spindle observer of the commissioned machine file. Two runs:

- **controlled**: the chatter monitor's alarm makes the chatter avoidance command a new spindle
  speed (the centre of the widest stable pocket, decision 1635); the machine follows it;
- **open**: the same blocks run, nothing is sent: the slot chatters to its end.

Figures per run (:class:`ChatterFigures`): the first chatter alarm (time, frequency), the
spindle-speed commands and the last speed, the share of the cut in which the truth chatters,
and the time from the last speed command to the first whole second without chatter in the
truth.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from millsense.streaming.block import Event

MACHINE = "quaser-ux600"
SPINDLE_RPM = 4500.0
DEPTH_MM = 1.2
FEED_PER_TOOTH_MM = 0.1
FLUTES = 5
#: The virtual machine's seed of the pass (``millsense demo --seed S`` runs CHATTER_SEED + S).
CHATTER_SEED = 11
#: The bar's length along X, mm (the slot runs from X-30 to 30 mm past its end).
BAR_MM = 200.0
#: The truth's chatter flag, the measured speed and the chatter monitor's ratio, recorded.
KEEP = ("truth/process/chatter", "truth/process/engagement", "spindle/speed")
#: A chatter-free stretch counts when it lasts this long, s (issue 16: "gone within 1 s").
QUIET_S = 1.0


def program() -> str:
    """The G-code of the pass (one slot along X at Y40 of the bar)."""
    feed = FEED_PER_TOOTH_MM * FLUTES * SPINDLE_RPM
    return (
        "%\n"
        "O2052 (MILLSENSE DEMO - CHATTER-PRONE PASS, AL7050 BAR 200 X 80 X 30, TOP AT Z0)\n"
        f"(T2 D=50. 5FL FACE MILL - ASLAN T1, {SPINDLE_RPM:.0f} REV/MIN, {DEPTH_MM} MM DEEP)\n"
        "N10 G90 G94 G17 G21 G54\n"
        "N15 T2 M6\n"
        f"N20 S{SPINDLE_RPM:.0f} M3\n"
        "N25 G0 X-30. Y40.\n"
        "N30 G0 Z5.\n"
        f"N35 G1 Z{-DEPTH_MM:.1f} F{feed:.0f}.\n"
        f"N40 X{BAR_MM + 30.0:.0f}.\n"
        "N45 G0 Z5.\n"
        "N50 M5\n"
        "N55 M30\n"
        "%\n"
    )


def tool_modes_file() -> Any:
    """The shipped T1 tool-modes file (a stability case file), as a resource."""
    return resources.files("millsense.data").joinpath("tool_modes", "aslan-v5-t1.toml")


@dataclass(frozen=True)
class ChatterFigures:
    """What one run of the pass shows (times from the start of the run, s)."""

    seconds: float
    #: first chatter alarm of the session's monitor and its frequency (None: no alarm)
    alarm_s: float | None
    alarm_hz: float | None
    #: spindle-speed commands sent (controlled) or recommended (open: never sent)
    speed_commands: int
    first_rpm: float
    last_rpm: float
    #: share of the cut (tool engaged) in which the truth chatters
    truth_chatter_share: float
    #: from the last speed command to the first whole second without chatter in the truth
    #: (None: no command sent, or never quiet for a second after it: see ``stopped``)
    quiet_after_command_s: float | None
    #: the truth had a whole second without chatter after the last command (None: no command)
    stopped: bool | None


def _bar(cell_m: float) -> Any:
    """The bar of Al7050 the pass cuts (200 × 80 × 30 mm, top at Z0) as a z-map of ``cell_m``."""
    from millsense.core.units import MM
    from millsense.plan.stock import ZMapStock

    return ZMapStock.from_box([0.0, 0.0, -30 * MM], [BAR_MM * MM, 80 * MM, 0.0], cell_m)


def _plan(out: Path) -> Any:
    """The session's plan of the pass: 0.5 mm z-map, the nameplate tool (no runout)."""
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    text = program()
    (out / "online_chatter.nc").write_text(text)
    mat = load_preset(MaterialConfig, "al7050")
    return plan_program(interpret(text, source="online_chatter.nc"), _bar(0.5 * MM),
                        EndMill(50 * MM, FLUTES), CuttingCoefficients.from_config(mat),
                        step_m=1.0 * MM, metadata={"material_name": mat.name})  # fmt: skip


def _plant_plan() -> Any:
    """The virtual machine's own plan of the pass (decision 1740): the same program, bar, tool
    and material on a 0.05 mm z-map, the tool with 5 µm of runout at 0.4 rad that the
    session's plan does not know."""
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.plant_plan import plant_plan

    mat = load_preset(MaterialConfig, "al7050")
    return plant_plan([interpret(program(), source="online_chatter.nc")], _bar,
                      EndMill(50 * MM, FLUTES), CuttingCoefficients.from_config(mat),
                      step_m=1.0 * MM, metadata={"material_name": mat.name})  # fmt: skip


def pass_machine(plant: Any, seed: int = 0, modes: Any = None) -> tuple[Any, dict[str, Any]]:
    """The virtual machine of the pass (the quaser-ux600's simulator file, 3 axes, the T1
    modes ``modes``, a ``ToolModes``; None: read from :func:`tool_modes_file`; seed
    :data:`CHATTER_SEED` + ``seed``) cutting its own plan ``plant`` (:func:`_plant_plan`), and
    its job's metadata."""
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.process_coupling import ToolModes

    sim_cfg = simulator_machine(MACHINE).with_axes("xyz", "3-axis")
    if modes is None:
        with resources.as_file(tool_modes_file()) as modes_path:
            modes = ToolModes.from_toml(modes_path)
    job, proc, meta, _ = plan_job(plant, sim_cfg, "online_chatter.nc", modes=modes)
    return MachineSimulator(sim_cfg, job, proc, SimulatorOptions(seed=CHATTER_SEED + seed)), meta


def _run(plan: Any, plant: Any, controlled: bool, out: Path, events_out: Path,
         on_progress: Callable[[int], None] | None,
         wrap: Callable[[Any], Any] | None = None, seed: int = 0,
         breakage_torque: str = "dob") -> Any:  # fmt: skip
    """One closed-loop run of the session (on ``plan``) with the T1 modes on the virtual
    machine cutting its own plan ``plant``; the session's result. ``wrap``: put in front of
    the virtual machine (the warm-up's first seconds, :mod:`millsense.warm_up`); ``seed``:
    added to the virtual machine's seed of the pass (:data:`CHATTER_SEED`);
    ``breakage_torque``: what the breakage monitor averages (decision 1726)."""
    from millsense.bench.tap_test import tap_tested_case
    from millsense.core.presets import commissioned_machine
    from millsense.demo_online import _Open
    from millsense.online.session import SessionOptions, run_session, session_blocks
    from millsense.simulator.process_coupling import ToolModes
    from millsense.stability.cases import load_case
    from millsense.streaming.sources import Source

    shipped = commissioned_machine(MACHINE)
    assert shipped is not None
    belief, where = shipped[0].with_axes("xyz", "3-axis"), shipped[1]
    with resources.as_file(tool_modes_file()) as modes_path:
        modes = ToolModes.from_toml(modes_path)
        # the session's lobes: the file's coefficients and lobe settings, the structure fitted
        # to a simulated tap test of the plant's tool (decision 1750)
        case = tap_tested_case(load_case(modes_path), modes)
    sim, meta = pass_machine(plant, seed, modes)
    opts = SessionOptions(adaptive=False, stability_case=case, breakage_torque=breakage_torque)
    built = session_blocks(plan, belief, sim.sample_rate_hz, opts,
                           where=where, channels=sim.channel_names)  # fmt: skip
    source: Source = sim if controlled else _Open(sim)
    if wrap is not None:
        source = wrap(source)
    meta.update(dict(sim.metadata))
    meta.update({"source": "millsense demo (chatter-prone pass)", "machine_file": where,
                 "controlled": controlled})  # fmt: skip
    return run_session(source, built.blocks, out=out, events_out=events_out, metadata=meta,
                       keep=KEEP, on_progress=on_progress, stop_after_hold_s=None)  # fmt: skip


def quiet_after(flag: np.ndarray, start: int, fs: float, quiet_s: float = QUIET_S) -> float:
    """Time from sample ``start`` to the first sample that begins ``quiet_s`` without the
    truth's chatter flag, s (inf: no such stretch before the end)."""
    win = max(1, round(quiet_s * fs))
    tail = np.asarray(flag[start:], dtype=np.int64)
    if tail.size < win:
        return math.inf
    per_window = np.convolve(tail, np.ones(win, dtype=np.int64), mode="valid")
    quiet = np.flatnonzero(per_window == 0)
    return float(quiet[0]) / fs if quiet.size else math.inf


def chatter_figures(
    events: Sequence[Event], data: dict[str, np.ndarray], fs: float, controlled: bool = True
) -> ChatterFigures:
    """The :class:`ChatterFigures` of a run from its events and recorded channels
    (``truth/process/chatter``, ``truth/process/engagement``, ``spindle/speed`` in rad/s);
    ``controlled``: the speed commands reached the machine (else the quiet time is None)."""
    flag = np.asarray(data["truth/process/chatter"]) > 0.5
    engaged = np.asarray(data["truth/process/engagement"]) >= 0
    speed_rpm = np.asarray(data["spindle/speed"]) * 60.0 / (2 * math.pi)
    alarm = next((e for e in events if e.name == "chatter"), None)
    cmds = [e for e in events if e.name == "spindle_override"]
    quiet = stopped = None
    if cmds and controlled:
        q = quiet_after(flag, round(cmds[-1].time_s * fs), fs)
        stopped = math.isfinite(q)
        quiet = q if stopped else None
    share = float(np.mean(flag[engaged])) if engaged.any() else 0.0
    n = len(speed_rpm)
    tail = speed_rpm[max(0, n - round(0.2 * fs)) :]
    return ChatterFigures(
        seconds=n / fs,
        alarm_s=alarm.time_s if alarm is not None else None,
        alarm_hz=float(alarm.value) if alarm is not None and alarm.value is not None else None,
        speed_commands=len(cmds),
        first_rpm=float(np.median(speed_rpm[engaged][: round(0.2 * fs)])) if engaged.any()
        else float(speed_rpm[0]),
        last_rpm=float(np.median(tail)),
        truth_chatter_share=share,
        quiet_after_command_s=quiet,
        stopped=stopped,
    )  # fmt: skip


def run_chatter_demo(
    out_dir: str | Path, on_progress: Callable[[float], None] | None = None, seed: int = 0
) -> dict[str, Any]:
    """Plan the pass, run it controlled and open, compare; writes ``online_chatter.nc``,
    ``online_chatter.h5`` (the controlled run), ``online_chatter.events.parquet``,
    ``online_chatter_open.events.parquet``, ``online_chatter.png`` and
    ``online_chatter_summary.json``, and returns that summary (the figures of both runs).
    ``seed``: added to the virtual machine's seed of the pass (:data:`CHATTER_SEED`)."""
    import json
    import tempfile

    from millsense.demo_online import two_run_progress
    from millsense.io.recording_reader import opened_recording
    from millsense.io.safe_output import write_text
    from millsense.report.online_plots import plot_chatter_comparison

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = _plan(out)
    plant = _plant_plan()
    progress = two_run_progress(plan, on_progress)
    data: dict[str, dict[str, np.ndarray]] = {}
    events: dict[str, Sequence[Event]] = {}
    figs: dict[str, ChatterFigures] = {}
    fs = 10000.0
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        for key, controlled, rec_path, ev_path, offset in (
            ("controlled", True, out / "online_chatter.h5",
             out / "online_chatter.events.parquet", 0.0),
            ("open", False, Path(tmp) / "open.h5",
             out / "online_chatter_open.events.parquet", 0.5),
        ):  # fmt: skip
            res = _run(plan, plant, controlled, rec_path, ev_path, progress(offset), seed=seed)
            with opened_recording(rec_path) as rec:
                fs = rec.sample_rate_hz
                names = set(rec.channel_names)
                ratio = [c for c in names if c.endswith("/energy_ratio")]
                cols = [*KEEP, *ratio[:1]]
                d = {c: np.asarray(rec.channel(c)) for c in cols}
            if ratio:
                d["chatter/energy_ratio"] = d.pop(ratio[0])
            data[key] = d
            events[key] = list(res.events)
            figs[key] = chatter_figures(list(res.events), d, fs, controlled)
    plot_chatter_comparison(data, events, out / "online_chatter.png", sample_rate_hz=fs,
                            title="Chatter-prone pass (Aslan T1, 4500 rev/min, 1.2 mm slot): "
                                  "with and without chatter avoidance")  # fmt: skip
    summary = {
        "program": str(out / "online_chatter.nc"),
        "spindle_rpm": SPINDLE_RPM,
        "depth_mm": DEPTH_MM,
        "runs": {k: f.__dict__ for k, f in figs.items()},
        "recording": str(out / "online_chatter.h5"),
        "plot": str(out / "online_chatter.png"),
        "summary": str(out / "online_chatter_summary.json"),
    }
    write_text(out / "online_chatter_summary.json", json.dumps(summary, indent=2) + "\n")
    return summary
