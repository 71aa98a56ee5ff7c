"""``millsense simulate``: run the virtual machine on a program; record CNC and truth channels."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import typer

from millsense.cli.main import app
from millsense.cli.progress import progress_bar

if TYPE_CHECKING:
    from collections.abc import Callable

    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.streaming.block import Event


@app.command()
def simulate(
    machine: str = typer.Option("quaser-ux600", "--machine", help="Machine preset or .toml."),
    program: Path | None = typer.Option(
        None, "--program", help="G-code program (.nc); engagement from --engagement/--depth-mm."
    ),
    plan: Path | None = typer.Option(
        None,
        "--plan",
        help="Virtual plan (.parquet from `millsense plan`): its path, feed, spindle speed, "
        "NC lines and per-row engagement; tool and coefficients from the plan.",
    ),
    tool: str | None = typer.Option(
        None,
        "--tool",
        help="Tool preset or .toml (default: the plan's tool, else aslan-d20-2flute).",
    ),
    material: str | None = typer.Option(
        None,
        "--material",
        help="Material preset or .toml (default: the plan's coefficients, else al7050).",
    ),
    engagement: str = typer.Option(
        "slot", "--engagement", help="With --program: slot, ae_mm=VALUE or ae_mm=VALUE,up."
    ),
    depth_mm: float = typer.Option(2.0, "--depth-mm", help="With --program: axial depth [mm]."),
    air_mm: float = typer.Option(
        0.0,
        "--air-mm",
        help="With --program: the first AIR_MM [mm] of feed motion cut air (the stock starts that "
        "far along the first feed move): an air phase at cutting feed for `estimate --idle`.",
    ),
    out: Path = typer.Option(..., "-o", "--output", help="Recording to write (.h5)."),
    duration_s: float | None = typer.Option(None, "--duration-s", help="Stop after this [s]."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every noise generator."),
    cnc: str = typer.Option("open", "--cnc", help="Override channel: open or closed."),
    break_at_s: float | None = typer.Option(
        None, "--break-at-s", help="Break a tooth at this time [s]."
    ),
    break_flute: int = typer.Option(0, "--break-flute", help="Flute that breaks."),
    realism: bool | None = typer.Option(
        None,
        "--realism/--no-realism",
        help="The realism layer (friction drift, position-dependent modes...); default: on with "
        "--truth, off with --ideal.",
    ),
    ideal: bool = typer.Option(
        False,
        "--ideal/--truth",
        help="Default --truth: the simulator's own truth plant (coupled lumped-mass drives, "
        "true K_t, friction, ripple, current loop, dead times; the torsional truth spindle, "
        "decision 1210; realism on). --ideal, for debugging only: the simulator file's one-way "
        "model and Aslan's Ch. 5 spindle with realism off (decision 1062).",
    ),
    tool_modes: Path | None = typer.Option(
        None,
        "--tool-modes",
        help="TOML with the tool's [[structure.x]]/[[structure.y]] modes (natural_frequency_hz, "
        "damping_ratio, stiffness_n_m; x along the feed; a stability case file works): "
        "regenerative chatter, tool vibration, accelerometer and microphone content.",
    ),
    accelerometer: bool = typer.Option(False, "--accelerometer", help="Add accel/x, accel/y."),
    microphone: bool = typer.Option(False, "--microphone", help="Add mic/pressure."),
    chunk: int = typer.Option(1000, "--chunk", help="Samples per chunk written."),
    wear_vb_mm: float = typer.Option(
        0.0,
        "--wear-vb-mm",
        help="Flank wear land VB of the tool [mm]: the truth's worn-tool coefficients "
        "(flank-land force and edge rounding, decision 2001); stored as truth_wear_vb_mm.",
    ),
    tool_id: str | None = typer.Option(
        None, "--tool-id", help="The CNC's tool identity (tool number or serial) in metadata."
    ),
    tool_cutting_time_min: float | None = typer.Option(
        None,
        "--tool-cutting-time-min",
        help="The CNC's tool-life counter before this run [min], in metadata.",
    ),
    home_mm: str | None = typer.Option(
        None, "--home-mm", help="G28 reference X,Y,Z [mm] (machine frame), for programs with G28."
    ),
) -> None:
    """Simulate the virtual machine tool running a program or a virtual plan; write a
    crash-safe recording with CNC and truth/ channels.

    With --plan the machine runs the plan's rows (0.4 mm polyline) and cuts with the
    engagement of every row (e.g. `millsense simulate --machine quaser-ux600 --plan
    plan.parquet -o run.h5`); with --program it runs the program's exact vertices and the
    unit engagement of --engagement/--depth-mm on every feed move. Every chunk is appended
    to OUT while the simulation runs (flushed every 0.5 s of signal), so a killed run leaves
    a readable recording of everything flushed.
    """
    from millsense.io.safe_output import check_outputs

    check_outputs(
        {
            "the machine file": machine,
            "the program": program,
            "the plan": plan,
            "the tool file": tool,
            "the material file": material,
            "the --tool-modes file": tool_modes,
        },
        {"-o": out},
        suffixes={"-o": ".h5"},
    )
    req = dict(
        machine=machine,
        program=program,
        plan=plan,
        tool=tool,
        material=material,
        engagement=engagement,
        depth_mm=depth_mm,
        air_mm=air_mm,
        out=out,
        duration_s=duration_s,
        seed=seed,
        cnc=cnc,
        break_at_s=break_at_s,
        break_flute=break_flute,
        realism=realism,
        ideal=ideal,
        accelerometer=accelerometer,
        tool_modes=tool_modes,
        microphone=microphone,
        chunk=chunk,
        wear_vb_mm=wear_vb_mm,
        tool_id=tool_id,
        tool_cutting_time_min=tool_cutting_time_min,
        home_mm=home_mm,
    )
    with progress_bar("simulating", 1.0) as update:
        summary = run_simulation(on_progress=update, **req)  # type: ignore[arg-type]
    for note in summary.get("notes", []):
        typer.echo(f"millsense: note: {note}", err=True)
    for warning in summary.get("warnings", []):
        typer.echo(f"millsense: warning: {warning}", err=True)
    typer.echo(
        f"wrote {out}: {summary['samples']} samples ({summary['seconds']:.2f} s) in "
        f"{summary['wall_s']:.1f} s wall ({summary['seconds'] / summary['wall_s']:.1f}x real time)"
    )


def run_simulation(
    *,
    machine: str,
    program: Path | None,
    plan: Path | None,
    tool: str | None,
    material: str | None,
    engagement: str,
    depth_mm: float,
    out: Path,
    air_mm: float = 0.0,
    duration_s: float | None,
    seed: int,
    cnc: str,
    break_at_s: float | None,
    break_flute: int,
    realism: bool | None,
    accelerometer: bool,
    microphone: bool,
    chunk: int,
    on_progress: Callable[[float], None] | None = None,
    ideal: bool = False,
    tool_modes: Path | None = None,
    wear_vb_mm: float = 0.0,
    tool_id: str | None = None,
    tool_cutting_time_min: float | None = None,
    plant: VirtualPlan | None = None,
    home_mm: str | None = None,
) -> dict[str, Any]:
    """Build the virtual machine from the options, run it and write ``out`` while running.

    ``plant``: with ``plan``, the virtual machine's own plan of the same program (its own
    z-map, runout and true coefficients, decisions 1740, 1760): the machine cuts its rows,
    tool and coefficients, while the recording's metadata names ``plan`` (the plan the CNC
    runs and a monitor reads). None: the machine cuts ``plan`` itself.

    The recording's metadata ``first_engagement_path_m`` is the path length (m, along the
    programmed path from its start, the integral of ``cnc/feed``) at which the tool first
    enters the stock — what the CAM plan or the program's set-up tells the CNC, no truth
    channel — so that ``millsense estimate --idle auto`` can find the air phase before it.

    Raises
    ------
    ConfigError, ProgramError, InputDataError, RecordingError
        One-line user errors (bad preset, program, option or output path).
    """
    import time

    from millsense.core.budget import check_signal
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.errors import ConfigError, InputDataError, ProgramError
    from millsense.core.plausibility import Findings, check_depth, check_width
    from millsense.core.presets import load_preset
    from millsense.io import RecordingWriter
    from millsense.plan.checks import check_plan, check_program
    from millsense.plan.gcode import interpret_file
    from millsense.plan.path import vertex_path
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.interpolator import OverrideChannel
    from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.process_coupling import (
        EngagementSchedule,
        ProcessCoupling,
        ProcessEvent,
        ToothBreak,
    )
    from millsense.simulator.realism import RealismOptions
    from millsense.simulator.sensors import SensorOptions

    if plan is not None and program is not None:
        raise ConfigError("simulate: give --program or --plan, not both")
    if plan is None and program is None:
        raise ConfigError("simulate: give --program P.nc or --plan PLAN.parquet")
    if plant is not None and plan is None:
        raise ConfigError("simulate: the machine's own plan needs the plan it stands for")
    if cnc not in ("open", "closed"):
        raise ConfigError(f"--cnc: '{cnc}' (open or closed)")
    if chunk < 1:
        raise InputDataError(f"--chunk: must be ≥ 1, got {chunk}")
    if not (depth_mm > 0):
        raise ConfigError(f"--depth-mm: must be > 0, got {depth_mm}")
    if not (air_mm >= 0 and np.isfinite(air_mm)):
        raise ConfigError(f"--air-mm: must be ≥ 0, got {air_mm}")
    if air_mm > 0 and plan is not None:
        raise ConfigError("--air-mm: applies to --program only (a plan's rows hold their air)")
    if not (np.isfinite(wear_vb_mm) and 0.0 <= wear_vb_mm <= 2.0):
        raise ConfigError(f"--wear-vb-mm: must be in [0, 2] mm, got {wear_vb_mm:g}")
    if tool_cutting_time_min is not None and not (
        np.isfinite(tool_cutting_time_min) and tool_cutting_time_min >= 0
    ):
        raise ConfigError(f"--tool-cutting-time-min: must be ≥ 0, got {tool_cutting_time_min:g}")
    if duration_s is not None:
        check_signal(
            duration_s, f"--duration-s {duration_s:g}", "give a shorter --duration-s", ConfigError
        )
    mcfg = simulator_machine(machine)
    five = mcfg.kinematics == "5-axis-trunnion-ac"
    findings = Findings()
    events: list[ProcessEvent] = []
    if break_at_s is not None:
        events.append(ToothBreak(break_at_s, break_flute))
    notes: list[str] = []
    meta_extra: dict[str, Any] = {}
    modes = None
    if tool_modes is not None:
        from millsense.simulator.process_coupling import ToolModes

        modes = ToolModes.from_toml(tool_modes, findings)
    if plan is not None:
        from millsense.plan.virtual_plan import VirtualPlan

        vp = VirtualPlan.read(plan)
        check_plan(vp, findings, machine=mcfg)
        cut = vp if plant is None else plant
        if duration_s is None:
            check_signal(
                float(cut["t_s"][-1]) if len(cut) else 0.0,
                f"--plan {plan}",
                "give --duration-s to simulate its start, or plan part of the program",
                ProgramError,
            )
        from millsense.simulator.plan_job import plan_job

        job, process, meta_extra, plan_notes = plan_job(
            cut,
            mcfg,
            str(plan),
            tool=tool,
            material=material,
            events=events,
            modes=modes,
            wear_vb_m=wear_vb_mm * 1e-3,
        )
        notes += plan_notes
    else:
        assert program is not None
        tcfg = load_preset(ToolConfig, tool or "aslan-d20-2flute")
        mat = load_preset(MaterialConfig, material or "al7050")
        end_mill = EndMill.from_config(tcfg)
        check_depth(
            depth_mm, tcfg.diameter_mm, "--depth-mm", findings, stickout_mm=tcfg.stickout_mm
        )
        if engagement.strip().lower().startswith("ae_mm="):
            try:
                ae_mm = float(engagement.strip().lower().removeprefix("ae_mm=").split(",")[0])
            except ValueError:
                ae_mm = None  # from_spec names the option
            if ae_mm is not None:
                check_width(ae_mm, tcfg.diameter_mm, f"--engagement {engagement}")
        unit = EngagementSchedule.from_spec(engagement, end_mill.diameter_m, depth_mm * 1e-3)
        from .cmd_plan import _home

        toolpath = interpret_file(program, home_mm=_home(home_mm))
        check_program(
            toolpath,
            findings,
            machine=mcfg,
            cuts=True,
            flutes=tcfg.flutes,
            diameter_mm=tcfg.diameter_mm,
        )
        if duration_s is None:
            check_signal(
                float(toolpath.durations().sum()),
                f"--program {program}",
                "give --duration-s to simulate its start, or split the program",
                ProgramError,
            )
        job = Job.from_sampled_path(vertex_path(toolpath), five_axis=five)
        assert job.rapid is not None
        schedule = EngagementSchedule.along_cutting_moves(
            unit.table[0], depth_mm * 1e-3, job.arc_length(), job.rapid
        )
        schedule, first_cut = _with_air(schedule, air_mm * 1e-3, float(job.arc_length()[-1]))
        coeffs = CuttingCoefficients.from_config(mat)
        if wear_vb_mm > 0:
            from millsense.simulator.wear import FlankWearModel

            coeffs = FlankWearModel().coefficients(coeffs, wear_vb_mm * 1e-3)
        process = ProcessCoupling(
            end_mill,
            coeffs,
            schedule,
            events=events,
            modes=modes,
            sample_rate_hz=mcfg.sample_rate_hz,
        )
        meta_extra = {"program": str(program), "tool": tcfg.name, "flutes": int(tcfg.flutes),
                      "material": mat.name}  # fmt: skip
        if first_cut is not None:
            meta_extra["first_engagement_path_m"] = first_cut
        if air_mm > 0:
            meta_extra["air_mm"] = air_mm

    channel = OverrideChannel.open_cnc() if cnc == "open" else OverrideChannel.closed_cnc()
    opts = SimulatorOptions(
        feed_channel=channel,
        spindle_channel=channel,
        seed=seed,
        sensors=SensorOptions(accelerometer=accelerometer, microphone=microphone),
        realism=RealismOptions(enabled=(not ideal) if realism is None else realism),
        ideal=ideal,
    )
    sim = MachineSimulator(mcfg, job, process, opts, duration_s=duration_s)
    # expected length for the progress bar when the run ends with the path
    seg = np.linalg.norm(np.diff(job.path[:, :3], axis=0), axis=1)
    expect = sim.n_total or round(
        (float(np.sum(seg / job.feed_m_s)) + sim.start_s + 0.2) * sim.sample_rate_hz
    )
    meta = dict(sim.metadata)
    meta.update(meta_extra)
    if tool_modes is not None:
        meta["tool_modes"] = str(tool_modes)
    # the tool's true flank wear (ground truth: no step reads it; decision 2001)
    meta["truth_wear_vb_mm"] = float(wear_vb_mm)
    if tool_id is not None:
        meta["tool_id"] = str(tool_id)
    if tool_cutting_time_min is not None:
        meta["tool_cutting_time_s"] = float(tool_cutting_time_min) * 60.0
    writer = RecordingWriter(
        out,
        sim.sample_rate_hz,
        sim.channel_info,
        metadata=meta,
        streams={"cnc": sim.stream_fields()},
        flush_every_s=0.5,
    )
    t0 = time.perf_counter()
    crashes: list[Event] = []
    while (c := sim.read(chunk)) is not None:
        writer.append(c.data)
        crashes += sim.take_events()
        rows = sim.take_stream_rows()
        if len(rows["time_s"]):
            writer.append_stream(
                "cnc", rows["time_s"], {k: v for k, v in rows.items() if k != "time_s"}
            )
        if on_progress is not None:
            on_progress(min(1.0, sim.samples_read / max(expect, 1)))
    crashes += sim.take_events()
    findings.extend(e.message for e in crashes)
    writer.update_metadata(
        {"warnings": findings.warnings, "crash_events": [e.as_dict() for e in crashes]}
    )
    writer.close()
    n = sim.samples_read
    return {
        "samples": n,
        "seconds": n / sim.sample_rate_hz,
        "wall_s": max(time.perf_counter() - t0, 1e-9),
        "notes": notes,
        "warnings": findings.warnings,
        "crash_events": crashes,
    }


def _with_air(schedule: Any, air_m: float, path_end_m: float) -> tuple[Any, float | None]:
    """The schedule with its first cutting run starting ``air_m`` later, and that start.

    Parameters
    ----------
    schedule : :class:`~millsense.simulator.process_coupling.EngagementSchedule` by arc length.
    air_m : air travel at cutting feed before the stock, m (0: unchanged).
    path_end_m : length of the whole path, m (the end of a last run of feed moves).

    Returns
    -------
    (schedule, first engagement path length m, or None when nothing cuts).

    Raises
    ------
    ConfigError
        When the first run of feed moves is not longer than ``air_m`` (one line).
    """
    from dataclasses import replace

    from millsense.core.errors import ConfigError

    segs = list(schedule.segments)
    first = next((i for i, s in enumerate(segs) if s.depth_m > 0), None)
    if first is None:
        return schedule, None
    start = segs[first].start + air_m
    end = segs[first + 1].start if first + 1 < len(segs) else path_end_m
    if air_m > 0 and not start < end:
        raise ConfigError(
            f"--air-mm: {air_m * 1e3:g} mm is not shorter than the first run of feed moves "
            f"({(end - segs[first].start) * 1e3:.3g} mm)"
        )
    segs[first] = replace(segs[first], start=start)
    return replace(schedule, segments=tuple(segs)), start
