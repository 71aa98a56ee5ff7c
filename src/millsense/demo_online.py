"""The integrated system on the demo part: the second half of ``millsense demo`` (issue 16
item 6).

A short program on the demo stock (Al7050, 100 × 80 × 30 mm; Ø20 mm 2-flute, 1000 rev/min,
400 mm/min, the conditions of seed 000 V7–V9): a channel along Y (the cavity), then a slot
along X with an entry, a step-down from 1.5 to 3.5 mm, the crossing of the cavity and the exit
of the part. Flute 0 of the virtual tool breaks late in the program, at 20 s of each run
(:data:`BREAK_S`): the open run is then in the deep slot (X ≈ 38 mm), alarmed within about 3
tooth periods; the controlled run, slower at its entries (decision 1626), is at the end of the
shallow slot, 0.04 s before the steep step-down ramp (N65), a light cut the breakage monitor
does not judge (decision 1622), and the alarm comes in the deep slot after it (decision 1674
judges drops in the plan's transients where the load is heavy enough). The summary gives the
peak force while the tool is intact (the controller's effect) apart from the peak with the
broken tooth. The
virtual machine (the simulator's truth of the quaser-ux600) runs the program twice with the
same on-line session (:mod:`millsense.online.session`: the spindle observer of the commissioned
machine file, plan sync and K_tc calibration, chatter and breakage monitors, adaptive feed on
the spindle power with the virtual look-ahead, the supervisor):

What the virtual machine and the session share (decision 1740): the program, the stock, the
tool's nameplate geometry and the material's nominal coefficients. What they do not share: the
virtual machine cuts its own plan (:func:`_plant_plan`: a 0.05 mm z-map, 5 µm of runout at
0.4 rad) through the truth's process; the session's expectation is its plan (:func:`_plan`,
0.2 mm z-map, no runout).

- **controlled**: the supervisor's commands reach the machine;
- **open**: the same monitors and controllers run, but nothing is sent (the CNC as
  programmed), so the breakage alarm is raised and the program cuts on with the broken tool.

Outputs in the folder: ``online.h5`` (the controlled run: CNC channels, truth and every block
output), ``online.events.parquet``, ``online_open.events.parquet``, ``online_demo.nc`` (the
program), ``online_demo.png`` (feed, spindle power and true force with and without control,
events marked), ``online.html`` (the report of the controlled run,
:mod:`millsense.report.run_report`: its figures are those of the summary, from the same
:func:`~millsense.report.run_scan.run_figures`) and ``online_summary.json``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from millsense.streaming.block import Event
from millsense.streaming.sources import SourceWrapper

PROGRAM = """\
%
O2051 (MILLSENSE ON-LINE DEMO - AL7050 BLOCK 100 X 80 X 30, TOP AT Z0)
(T1 D=20. 2FL 30DEG HELIX, 1000 REV/MIN, 400 MM/MIN)
N10 G90 G94 G17 G21 G54
N15 T1 M6
N20 S1000 M3
(CAVITY - A CHANNEL ALONG Y AT X60, 6 MM DEEP)
N25 G0 X60. Y-12.
N30 G0 Z5.
N35 G1 Z-6. F400.
N40 Y45.
N45 G0 Z5.
(SLOT - ALONG X AT Y25: ENTRY, STEP DOWN 1.5 -> 3.5 MM AT X25, CROSSES THE CAVITY, EXITS)
N50 G0 X-12. Y25.
N55 G1 Z-1.5 F400.
N60 X25.
N65 X25.4 Z-3.5
N70 X112.
N75 G0 Z5.
N80 M5
N85 M30
%
"""
MACHINE = "quaser-ux600"
#: Flute 0 breaks at this time of each run, s (module notes: where each run is then).
BREAK_S = 20.0
#: Source channels kept in the recording (the rest of the CNC's and the truth are not needed).
KEEP = (
    "spindle/current_cmd",
    "spindle/speed",
    "spindle/speed_cmd",
    "cnc/feed",
    "cnc/feed_override",
    "cnc/spindle_override",
    "cnc/nc_line",
    "x/position_cmd",
    "y/position_cmd",
    "z/position_cmd",
    "truth/spindle/torque",
    "truth/tool/force_x",
    "truth/tool/force_y",
    "truth/process/broken",
)


def _tool_material() -> tuple[Any, Any]:
    """The demo's tool and material presets (``aslan-d20-2flute``, ``al7050``)."""
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import load_preset

    return load_preset(ToolConfig, "aslan-d20-2flute"), load_preset(MaterialConfig, "al7050")


def _stock(cell_m: float) -> Any:
    """The demo stock (100 × 80 × 30 mm) on a z-map of cell ``cell_m``."""
    from millsense.core.units import MM
    from millsense.plan.stock import ZMapStock

    return ZMapStock.from_box([0.0, 0.0, -30 * MM], [100 * MM, 80 * MM, 0.0], cell_m)


def _plan(out: Path) -> Any:
    """The session's plan of :data:`PROGRAM` (0.2 mm z-map, the nameplate tool without
    runout); also writes the program to ``out``."""
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    (out / "online_demo.nc").write_text(PROGRAM)
    tool, mat = _tool_material()
    return plan_program(
        interpret(PROGRAM, source="online_demo.nc"),
        _stock(0.2 * MM),
        EndMill.from_config(tool),
        CuttingCoefficients.from_config(mat),
        metadata={"tool_name": tool.name, "material_name": mat.name},
    )


def _plant_plan() -> Any:
    """The virtual machine's own plan of :data:`PROGRAM`
    (:func:`~millsense.simulator.plant_plan.plant_plan`, decision 1740): the same program,
    stock, tool and material on a 0.05 mm z-map, the tool with 5 µm of runout at 0.4 rad the
    session's plan (:func:`_plan`) does not know."""
    from millsense.plan.gcode import interpret
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.plant_plan import plant_plan

    tool, mat = _tool_material()
    return plant_plan([interpret(PROGRAM, source="online_demo.nc")], _stock,
                      EndMill.from_config(tool), CuttingCoefficients.from_config(mat),
                      metadata={"tool_name": tool.name, "material_name": mat.name})  # fmt: skip


def two_run_progress(
    plan: Any, on_progress: Callable[[float], None] | None
) -> Callable[[float], Callable[[int], None] | None]:
    """Progress of two runs of ``plan`` one after the other, as a fraction of both: called with
    the run's offset (0 or 0.5), gives the run's callback of samples done (None without
    ``on_progress``)."""
    expect = int((float(plan["t_s"][-1]) + 1.0) * 10000)

    def progress(offset: float) -> Callable[[int], None] | None:
        if on_progress is None:
            return None
        return lambda n: on_progress(min(1.0, offset + 0.5 * n / expect))

    return progress


class _Open(SourceWrapper):
    """The virtual machine with its commands dropped (the CNC as programmed)."""

    def command(self, event: Event) -> None:
        pass


def _run(
    plan: Any,
    plant: Any,
    controlled: bool,
    out: Path,
    events_out: Path,
    on_progress: Callable[[int], None] | None,
    wrap: Callable[[Any], Any] | None = None,
    options: Any = None,
    seed: int = 0,
) -> Any:
    """One closed-loop run of the session (its plan ``plan``) on the virtual machine (cutting
    its own plan ``plant``, :func:`_plant_plan`); the session's result. ``wrap``: put in front
    of the virtual machine (the warm-up's first seconds, :mod:`millsense.warm_up`);
    ``options``: the session's (:class:`~millsense.online.session.SessionOptions`; None: the
    defaults)."""
    from millsense.core.presets import commissioned_machine
    from millsense.online.session import SessionOptions, run_session, session_blocks
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.process_coupling import ToothBreak
    from millsense.streaming.sources import Source

    sim_cfg = simulator_machine(MACHINE)
    shipped = commissioned_machine(MACHINE)
    assert shipped is not None
    belief, where = shipped
    job, proc, meta, _ = plan_job(plant, sim_cfg, "online_demo.nc",
                                  events=[ToothBreak(BREAK_S, 0)])  # fmt: skip
    sim = MachineSimulator(sim_cfg, job, proc, SimulatorOptions(seed=seed))
    opts = options if options is not None else SessionOptions()
    built = session_blocks(plan, belief, sim.sample_rate_hz, opts, where=where,
                           channels=sim.channel_names)  # fmt: skip
    source: Source = sim if controlled else _Open(sim)
    if wrap is not None:
        source = wrap(source)
    meta.update(dict(sim.metadata))
    meta.update({"source": "millsense demo (on-line system)", "machine_file": where,
                 "controlled": controlled})  # fmt: skip
    res = run_session(source, built.blocks, out=out, events_out=events_out, metadata=meta,
                      keep=KEEP, on_progress=on_progress,
                      stop_after_hold_s=0.5 if controlled else None)  # fmt: skip
    return res


def run_online_demo(
    out_dir: str | Path,
    on_progress: Callable[[float], None] | None = None,
    validation: tuple[list[dict[str, str]], str] | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Plan, run controlled and open, compare; writes the files named in the module notes.
    ``seed``: the virtual machine's (its noise and realism), the same for both runs.

    ``validation``: the recorded status of the cases of what the session runs (rows and where
    recorded, :mod:`millsense.validation.status`) for the report, or None.
    """
    import tempfile

    from millsense.io.recording_reader import opened_recording
    from millsense.io.safe_output import write_text
    from millsense.report.run_report import write_report
    from millsense.report.run_scan import RunFigures, run_figures

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = _plan(out)
    plant = _plant_plan()
    progress = two_run_progress(plan, on_progress)
    runs: dict[str, tuple[Any, dict[str, np.ndarray]]] = {}
    figs: dict[str, RunFigures] = {}
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        for key, controlled, rec_path, ev_path, offset in (
            ("controlled", True, out / "online.h5", out / "online.events.parquet", 0.0),
            ("open", False, Path(tmp) / "open.h5", out / "online_open.events.parquet", 0.5),
        ):
            res = _run(plan, plant, controlled, rec_path, ev_path, progress(offset), seed=seed)
            cols = (*KEEP, "plan/cutting_torque", "supervisor/feed_override",
                    "adaptive_feed/peak", "adaptive_feed/reference")  # fmt: skip
            with opened_recording(rec_path) as rec:
                data = {c: np.asarray(rec.channel(c)) for c in cols}
                figs[key] = run_figures(rec, res.events)
            runs[key] = (res, data)
    from millsense.report.online_plots import plot_comparison

    plot_comparison(
        {k: d for k, (_, d) in runs.items()},
        {k: r.events for k, (r, _) in runs.items()},
        out / "online_demo.png",
        title="On-line system on the demo part: with and without control",
    )
    from millsense.core.presets import commissioned_machine

    shipped = commissioned_machine(MACHINE)
    assert shipped is not None
    rows, where = validation if validation is not None else (None, "")
    write_report(
        out / "online.html", out / "online.h5", events=runs["controlled"][0].events, plan=plan,
        machine=shipped[0], machine_where=shipped[1], validation=rows, validation_where=where,
        title="millsense demo: the on-line system on the demo part (controlled run)",
        runs=figs,
    )
    summary = {
        "program": str(out / "online_demo.nc"),
        "break_s": BREAK_S,
        "runs": {k: f.__dict__ for k, f in figs.items()},
        "recording": str(out / "online.h5"),
        "plot": str(out / "online_demo.png"),
        "report": str(out / "online.html"),
    }
    write_text(out / "online_summary.json", json.dumps(summary, indent=2) + "\n")
    return summary
