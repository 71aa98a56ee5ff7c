"""``millsense run`` and ``millsense replay``: the integrated on-line system (issue 16 item 5).

``run`` plans the part program, runs the virtual machine in closed loop with the estimators,
the plan, the monitors and the controllers (:mod:`millsense.online.session`), records the run
with its event log and prints a summary; ``replay`` runs the same blocks on a recording (the
overrides are recorded, not applied).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import typer

from millsense.cli import link_options as lo
from millsense.cli.cmd_report import report_line, report_path, write_run_report
from millsense.cli.main import app
from millsense.core.errors import ConfigError

#: Truth channels a replay of a simulated run keeps for the plot and the comparison.
PLOT_TRUTH = ("truth/spindle/torque", "truth/tool/force_x", "truth/tool/force_y")

_MACHINE_FILE = typer.Option(
    None,
    "--machine-file",
    help="Machine file of the estimators (made by `millsense commission --identify`): the "
    "spindle torque observer and, with --force-from estimate, the feed-drive estimators "
    "(default: the commissioned file millsense ships for the machine).",
)

_BREAKAGE_TORQUE = typer.Option(
    "dob",
    "--breakage-torque",
    help="What the breakage monitor averages per tooth period: dob (the spindle's disturbance "
    "observer, its encoder speed averaged over 0.9 ms: a multi-flute tool's break found in its "
    "first revolution; decisions 1726, 1727) or observer (the machine file's spindle observer, "
    "as the chatter monitor and the adaptive feed read it).",
)


def _options(
    adaptive: bool,
    regulate: str,
    reference: float | None,
    force_from: str,
    look_ahead: bool,
    chatter: bool,
    act_on_chatter: bool,
    breakage: bool,
    breakage_torque: str = "dob",
) -> Any:
    from millsense.control.adaptive_feed import QUANTITIES
    from millsense.core.errors import ConfigError
    from millsense.online.session import SessionOptions

    if regulate not in QUANTITIES:
        raise ConfigError(f"--regulate: one of {', '.join(QUANTITIES)}, got {regulate!r}")
    if reference is not None and not (math.isfinite(reference) and reference > 0):
        raise ConfigError(f"--reference: must be finite and > 0, got {reference}")
    return SessionOptions(
        adaptive=adaptive, quantity=regulate, reference=reference, force_from=force_from,
        look_ahead=look_ahead, chatter=chatter, avoid_chatter=act_on_chatter, breakage=breakage,
        breakage_torque=breakage_torque,
    )  # fmt: skip


@app.command()
def run(
    program: Path | None = typer.Option(None, "--program", help="Part program (G-code)."),
    stock: Path | None = typer.Option(None, "--stock", help="Stock TOML (with --program)."),
    tool: str | None = typer.Option(None, "--tool", help="Tool TOML or preset (with --program)."),
    material: str | None = typer.Option(
        None, "--material", help="Material TOML or preset (with --program)."
    ),
    plan: Path | None = typer.Option(
        None, "--plan", help="A virtual plan (.parquet) instead of --program/--stock/..."
    ),
    machine: str = typer.Option(
        "quaser-ux600", "--machine", help="Virtual machine (the simulator's preset)."
    ),
    machine_file: Path | None = _MACHINE_FILE,
    out: Path = typer.Option(..., "-o", "--output", help="Recording to write (.h5)."),
    events_out: Path | None = typer.Option(
        None, "--events", help="Event log (.parquet; default: beside the recording)."
    ),
    plan_out: Path | None = typer.Option(
        None, "--plan-out", help="Write the plan made from --program here (.parquet)."
    ),
    plot: Path | None = typer.Option(None, "--plot", help="PNG: feed, force, speed, events."),
    report: Path | None = typer.Option(
        None, "--report", help="HTML report of the run (default: beside the recording, .html)."
    ),
    adaptive: bool = typer.Option(True, "--adaptive/--no-adaptive", help="Adaptive feed."),
    regulate: str = typer.Option("power", "--regulate", help="power, torque or force."),
    reference: float | None = typer.Option(
        None,
        "--reference",
        help="Set point [W, N·m or N, as --regulate] (default: 90 % of the plan's largest).",
    ),
    force_from: str = typer.Option(
        "estimate", "--force-from", help="estimate (sensorless) or dynamometer (a sensor)."
    ),
    look_ahead: bool = typer.Option(True, "--look-ahead/--no-look-ahead", help="Plan look-ahead."),
    chatter: bool = typer.Option(True, "--chatter/--no-chatter", help="Chatter monitor."),
    act_on_chatter: bool = typer.Option(
        True, "--avoid-chatter/--recommend-only", help="Change the spindle speed on chatter."
    ),
    breakage: bool = typer.Option(True, "--breakage/--no-breakage", help="Breakage monitor."),
    breakage_torque: str = _BREAKAGE_TORQUE,
    break_at_s: float | None = typer.Option(
        None, "--break-at-s", help="Break a tooth of the virtual tool at this time [s]."
    ),
    break_flute: int = typer.Option(0, "--break-flute", help="Flute that breaks."),
    tool_modes: Path | None = typer.Option(
        None,
        "--tool-modes",
        help="Tool modes (a stability case TOML): the virtual tool chatters; with a full case "
        "file (tool, coefficients, immersion) the chatter avoidance checks the lobes of a "
        "simulated tap test of that tool.",
    ),
    fault: list[str] = typer.Option(
        [],
        "--fault",
        metavar="KIND@START_S[:DURATION_S][:CHANNEL]",
        help="Inject a link fault (nan, drop, stall, lost), e.g. stall@2.0:0.3; repeatable.",
    ),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every noise generator."),
    duration_s: float | None = typer.Option(None, "--duration-s", help="Stop after this [s]."),
    step_mm: float = typer.Option(0.4, "--step-mm", help="Plan step [mm]."),
    resolution_mm: float = typer.Option(0.2, "--resolution-mm", help="Z-map cell [mm]."),
    home_mm: str | None = typer.Option(
        None, "--home-mm", help="G28 reference X,Y,Z [mm] (machine frame), for programs with G28."
    ),
    dashboard: bool = typer.Option(
        False, "--dashboard", help="Serve the live dashboard of the session (prints its address)."
    ),
    dashboard_host: str = typer.Option(
        "127.0.0.1", "--dashboard-host", help="Address the dashboard binds (default: loopback)."
    ),
    dashboard_port: int = typer.Option(0, "--dashboard-port", help="Port (0: a free one)."),
    dashboard_allow_remote: bool = typer.Option(
        False, "--dashboard-allow-remote", help="Serve beyond this machine (needs TLS)."
    ),
    tls_cert: Path | None = typer.Option(None, "--tls-cert", help="TLS certificate (PEM)."),
    tls_key: Path | None = typer.Option(None, "--tls-key", help="TLS private key (PEM)."),
    dashboard_linger_s: float = typer.Option(
        0.0, "--dashboard-linger-s", help="Keep serving this long after the run [s]."
    ),
    source: str | None = typer.Option(
        None,
        "--source",
        help="opc.tcp://HOST:PORT: run on a live CNC (or `millsense serve-machine`) over OPC UA "
        "instead of the virtual machine in process; the plan is still needed.",
    ),
    node_map: Path | None = lo.NODE_MAP,
    user: str | None = lo.USER,
    pki: Path | None = lo.PKI,
    insecure: bool = lo.INSECURE,
    reconnect_s: float = lo.RECONNECT,
    connect_wait_s: float = lo.CONNECT_WAIT,
) -> None:
    """Run the integrated system on the virtual machine: plan, closed-loop simulation with
    estimators, monitors and controllers, recording with its event log, and a summary."""
    from millsense.io.safe_output import SESSION_SUFFIXES, check_outputs
    from millsense.streaming.event_log import default_event_log_path

    live = None
    if dashboard:
        from millsense.dashboard.server import DashboardOptions

        if not dashboard_linger_s >= 0:
            raise ConfigError(f"--dashboard-linger-s: must be ≥ 0, got {dashboard_linger_s}")
        live = DashboardOptions(host=dashboard_host, port=dashboard_port,
                                allow_remote=dashboard_allow_remote, tls_cert=tls_cert,
                                tls_key=tls_key)  # fmt: skip

    check_outputs(
        {"the program": program, "the stock": stock, "the plan": plan,
         "the machine file": machine_file, "the tool-modes file": tool_modes},
        {"-o": out, "--events": events_out or default_event_log_path(out),
         "--plan-out": plan_out, "--plot": plot, "--report": report or report_path(out)},
        SESSION_SUFFIXES,
    )  # fmt: skip
    opts = _options(adaptive, regulate, reference, force_from, look_ahead, chatter,
                    act_on_chatter, breakage, breakage_torque)  # fmt: skip
    _check_times(duration_s, break_at_s, break_flute)
    if source is not None:
        given = [k for k, v in (("--fault", fault), ("--break-at-s", break_at_s),
                                ("--tool-modes", tool_modes)) if v]  # fmt: skip
        if given:
            raise ConfigError(f"--source: {', '.join(given)} act on the virtual machine in process")
        nmap, connect = lo.link_opener(source, node_map, user, pki, insecure, reconnect_s,
                                       connect_wait_s)  # fmt: skip
        summary = run_over_link(
            nmap, connect, program=program, stock=stock, tool=tool, material=material, plan=plan,
            plan_out=plan_out, machine=machine, machine_file=machine_file, out=out,
            events_out=events_out, plot=plot, options=opts, duration_s=duration_s,
            step_mm=step_mm, resolution_mm=resolution_mm, home_mm=home_mm,
        )  # fmt: skip
        for line in summary["lines"]:
            typer.echo(line)
        return
    try:
        summary = run_online(
            program=program, stock=stock, tool=tool, material=material, plan=plan,
            machine=machine, machine_file=machine_file, out=out, events_out=events_out,
            plan_out=plan_out, plot=plot, report=report or report_path(out), options=opts,
            break_at_s=break_at_s,
            break_flute=break_flute, tool_modes=tool_modes, faults=fault, seed=seed,
            duration_s=duration_s, step_mm=step_mm, resolution_mm=resolution_mm, home_mm=home_mm,
            dashboard=live, dashboard_linger_s=dashboard_linger_s,
        )  # fmt: skip
    except KeyboardInterrupt:
        _interrupted(out, events_out or default_event_log_path(out))
    for line in summary["lines"]:
        typer.echo(line)


@app.command()
def replay(
    recording: Path = typer.Argument(..., help="Recording to replay (.h5)."),
    plan: Path = typer.Option(..., "--plan", help="Virtual plan of the program (.parquet)."),
    machine_file: Path | None = _MACHINE_FILE,
    out: Path | None = typer.Option(None, "-o", "--output", help="Block outputs (.h5)."),
    events_out: Path = typer.Option(..., "--events", help="Event log to write (.parquet)."),
    regulate: str = typer.Option("power", "--regulate", help="power, torque or force."),
    reference: float | None = typer.Option(
        None, "--reference", help="Set point [W, N·m or N, as --regulate]."
    ),
    force_from: str = typer.Option("estimate", "--force-from", help="estimate or dynamometer."),
    chunk: int = typer.Option(100, "--chunk", help="Samples per chunk (the control period)."),
    breakage_torque: str = _BREAKAGE_TORQUE,
    report: Path | None = typer.Option(
        None, "--report", help="HTML report of the replay (default with -o: beside it, .html)."
    ),
) -> None:
    """Run the on-line blocks on a recording (overrides recorded, not applied)."""
    from millsense.io.safe_output import SESSION_SUFFIXES, check_outputs

    if report is not None and out is None:
        raise ConfigError("--report: needs -o (the report shows the replay's block outputs)")
    if report is None and out is not None:
        report = report_path(out)
    check_outputs(
        {"the recording": recording, "the plan": plan, "the machine file": machine_file},
        {"-o": out, "--events": events_out, "--report": report},
        SESSION_SUFFIXES,
    )
    opts = _options(True, regulate, reference, force_from, True, True, True, True,
                    breakage_torque)  # fmt: skip
    try:
        summary = replay_online(recording, plan, machine_file, out, events_out, opts, chunk)
    except KeyboardInterrupt:
        _interrupted(out, events_out)
    if report is not None and out is not None:
        rep = write_run_report(report, out, plan=plan, events=summary["result"].events,
                               machine_file=machine_file)  # fmt: skip
        summary["lines"].append(report_line(rep, report))
    for line in summary["lines"]:
        typer.echo(line)


def _interrupted(out: Path | None, events: Path) -> NoReturn:
    """Ctrl-C during a session: one line saying what the recording and the event log hold (the
    session closed both at the last chunk processed), exit status 130."""
    from millsense.cli.main import err_console
    from millsense.io.recording_reader import opened_recording

    held = []
    if out is not None and out.exists():
        with opened_recording(out) as rec:
            held.append(f"{out} holds its first {rec.duration_s:.2f} s")
    if events.exists():
        held.append(f"{events} its events up to there")
    what = "; ".join(held) if held else "nothing was written"
    err_console.print(f"millsense: interrupted: {what}", markup=False)
    raise typer.Exit(130)


def _check_times(duration_s: float | None, break_at_s: float | None, break_flute: int) -> None:
    """One line for a run's impossible times, before anything is planned: a duration that is
    not finite and > 0, a tooth break before the start (or not finite), a negative flute."""
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigError(f"--duration-s: must be finite and > 0, got {duration_s}")
    if break_at_s is not None and not (math.isfinite(break_at_s) and break_at_s >= 0):
        raise ConfigError(f"--break-at-s: must be finite and ≥ 0 (the run starts at 0 s), "
                          f"got {break_at_s}")  # fmt: skip
    if break_flute < 0:
        raise ConfigError(f"--break-flute: must be ≥ 0 (flutes count from 0), got {break_flute}")


def _belief(machine_file: Path | None, sim_machine: Any) -> tuple[Any, str]:
    """The estimators' machine file (``--machine-file``, else the commissioned file shipped for
    the machine), cut to the simulator's axes and kinematics, and its name."""
    cfg, where = _machine_file(machine_file, sim_machine.name)
    missing = [a for a in sim_machine.axes if a not in cfg.axes]
    if missing:
        raise ConfigError(f"{where}: no axes {', '.join(missing)} of {sim_machine.name}")
    return cfg.with_axes(list(sim_machine.axes), sim_machine.kinematics), where


def _machine_file(machine_file: Path | None, name: str) -> tuple[Any, str]:
    from millsense.core.config import MachineConfig
    from millsense.core.presets import commissioned_machine, load_preset

    if machine_file is not None:
        return load_preset(MachineConfig, str(machine_file)), str(machine_file)
    shipped = commissioned_machine(name)
    if shipped is None:
        raise ConfigError(
            f"give --machine-file: no commissioned file ships for '{name}', and the estimators "
            "know the machine only through one made by commissioning (millsense commission "
            f"--machine {name} --axis x,y,z --identify -o DIR writes DIR/machine.toml)"
        )
    return shipped


def run_online(
    *,
    program: Path | None,
    stock: Path | None,
    tool: str | None,
    material: str | None,
    plan: Path | None,
    machine: str,
    machine_file: Path | None,
    out: Path,
    events_out: Path | None,
    plan_out: Path | None,
    plot: Path | None,
    options: Any,
    report: Path | None = None,
    break_at_s: float | None = None,
    break_flute: int = 0,
    tool_modes: Path | None = None,
    faults: list[str] | None = None,
    seed: int = 0,
    duration_s: float | None = None,
    step_mm: float = 0.4,
    resolution_mm: float = 0.2,
    home_mm: str | None = None,
    chunk: int = 100,
    dashboard: Any = None,
    dashboard_linger_s: float = 0.0,
) -> dict[str, Any]:
    """Plan, simulate in closed loop, monitor, control and record (the body of ``run``);
    ``dashboard``: :class:`~millsense.dashboard.server.DashboardOptions` to serve the live
    dashboard of the session (its address printed before the run), or None."""
    from millsense.online.faults import FaultyLink, LinkFault
    from millsense.online.session import run_session, session_blocks
    from millsense.simulator.machine_file import simulator_machine
    from millsense.streaming.event_log import default_event_log_path

    link_faults = [LinkFault.parse(f) for f in faults or []]
    belief, belief_name = _belief(machine_file, simulator_machine(machine))
    vm = virtual_machine(
        program=program, stock=stock, tool=tool, material=material, plan=plan,
        plan_out=plan_out, machine=machine, break_at_s=break_at_s, break_flute=break_flute,
        tool_modes=tool_modes, seed=seed, duration_s=duration_s, step_mm=step_mm,
        resolution_mm=resolution_mm, home_mm=home_mm,
    )  # fmt: skip
    vp, sim, meta, notes, findings = vm.plan, vm.sim, vm.metadata, vm.notes, vm.findings
    notes_pre: list[str] = []
    if tool_modes is not None:
        from dataclasses import replace

        from millsense.bench.tap_test import tap_tested_case
        from millsense.simulator.process_coupling import ToolModes
        from millsense.stability.cases import load_case

        try:
            # the file's modes are the virtual machine's tool; the session's lobes take its
            # coefficients and settings with the structure of a simulated tap test of that
            # tool (decision 1750), as a shop would measure it
            case = tap_tested_case(load_case(tool_modes), ToolModes.from_toml(tool_modes))
            options = replace(options, stability_case=case)
        except ConfigError as exc:
            notes_pre.append(f"chatter avoidance without lobes ({exc}): nearest faster lobe")
    built = session_blocks(vp, belief, sim.sample_rate_hz, options, where=belief_name,
                           channels=sim.channel_names)  # fmt: skip
    source: Any = FaultyLink(sim, link_faults) if link_faults else sim
    ev_path = events_out or default_event_log_path(out)
    meta.update({"source": "millsense run", "machine_file": belief_name,
                 "faults": [f.__dict__ for f in link_faults]})  # fmt: skip
    expect = sim.n_total or int((float(vp["t_s"][-1]) + sim.start_s + 0.5) * sim.sample_rate_hz)
    server = state = None
    if dashboard is not None:
        from millsense.dashboard.live import LiveState
        from millsense.dashboard.server import DashboardServer

        flutes = int(vp.metadata.get("tool", {}).get("flutes", 2))
        unit = next((c.unit for b in built.blocks for c in b.output_channels()
                     if c.name == "adaptive_feed/peak"), "")  # fmt: skip
        state = LiveState(built.supervisor, (vp["x_mm"], vp["y_mm"]), flutes,
                          regulated_unit=unit)  # fmt: skip
        server = DashboardServer(state, dashboard)
        typer.echo(f"dashboard: {server.start()}", err=True)
    try:
        res = _with_progress(
            "running", expect,
            lambda cb: run_session(source, built.blocks, out=out, events_out=ev_path,
                                   metadata=meta, chunk_samples=chunk, on_progress=cb,
                                   observer=None if state is None else state.observe),
            built.supervisor,
        )  # fmt: skip
    finally:
        if server is not None and state is not None:
            state.finish()
            import time

            time.sleep(dashboard_linger_s)
            server.stop()
    lines = [f"millsense: note: {n}" for n in notes_pre + notes + built.notes]
    lines += [f"millsense: warning: {w}" for w in findings.warnings]
    if break_at_s is not None and break_at_s >= res.seconds:
        lines.append(
            f"millsense: note: --break-at-s {break_at_s:g}: the run ended at "
            f"{res.seconds:.2f} s, before the tooth broke: the tool stayed intact"
        )
    lines += _summary_lines(res, out, ev_path)
    if plot is not None:
        from millsense.report.online_plots import plot_run

        plot_run(out, res.events, plot)
        lines.append(f"wrote {plot}")
    if report is not None:
        rep = write_run_report(report, out, plan=vp, events=res.events, machine_file=machine_file)
        lines.append(report_line(rep, report))
    return {"lines": lines, "result": res}


def _plan(program: Path | None, stock: Path | None, tool: str | None, material: str | None,
          plan: Path | None, plan_out: Path | None, step_mm: float,
          resolution_mm: float, home_mm: str | None = None) -> tuple[Any, str, Any]:  # fmt: skip
    """The virtual plan of ``--program`` (with stock, tool, material) or ``--plan``, its name
    and the planner's findings."""
    from millsense.core.plausibility import Findings
    from millsense.plan.virtual_plan import VirtualPlan

    if plan is not None and program is not None:
        raise ConfigError("run: give --program (with --stock, --tool, --material) or --plan")
    if plan is not None:
        # what plans a program: with --plan it would be ignored, the run made with the plan's
        # own tool and material whatever these say
        named = (("--stock", stock), ("--tool", tool), ("--material", material),
                 ("--plan-out", plan_out), ("--home-mm", home_mm))  # fmt: skip
        given = [o for o, v in named if v is not None]
        if given:
            raise ConfigError(
                f"--plan {plan}: {', '.join(given)} act only with --program (the plan holds its "
                "tool, material and stock; plan the program again to change them)"
            )
    if plan is None:
        if program is None or stock is None or tool is None or material is None:
            raise ConfigError("run: --program needs --stock, --tool and --material")
        from .cmd_plan import _build

        vp, _, findings = _build(
            program, stock, Path(tool), Path(material), step_mm, resolution_mm, home_mm
        )
        if plan_out is not None:
            vp.write(plan_out)
        return vp, str(plan_out or program), findings
    return VirtualPlan.read(plan), str(plan), Findings()


def run_over_link(
    node_map: Any,
    connect: Any,
    *,
    program: Path | None,
    stock: Path | None,
    tool: str | None,
    material: str | None,
    plan: Path | None,
    plan_out: Path | None,
    machine: str,
    machine_file: Path | None,
    out: Path,
    events_out: Path | None,
    plot: Path | None,
    options: Any,
    duration_s: float | None = None,
    step_mm: float = 0.4,
    resolution_mm: float = 0.2,
    home_mm: str | None = None,
    chunk: int = 100,
) -> dict[str, Any]:
    """The on-line session on a live OPC UA link (``run --source``): the same blocks as in
    process, on the machine file's axes that the node map provides; the link is opened by
    ``connect()`` once the blocks are built (building them takes a while) and closed at the
    end."""
    from millsense.link.client import StopAt
    from millsense.online.session import run_session, session_blocks
    from millsense.streaming.event_log import default_event_log_path

    vp, plan_name, findings = _plan(program, stock, tool, material, plan, plan_out,
                                    step_mm, resolution_mm, home_mm)  # fmt: skip
    cfg, where = _machine_file(machine_file, machine)
    names = [c.name for c in node_map.channels]
    axes = [a for a in cfg.axes if f"{a}/position_cmd" in names]
    cfg = cfg.with_axes(axes, cfg.kinematics)
    built = session_blocks(vp, cfg, node_map.sample_rate_hz, options, where=where,
                           channels=names)  # fmt: skip
    link = connect()
    try:
        src: Any = link if duration_s is None else StopAt(link, duration_s)
        ev_path = events_out or default_event_log_path(out)
        meta = {**link.metadata, "plan": plan_name, "machine_file": where,
                "source": f"millsense run --source {link.url}"}  # fmt: skip
        expect = int((float(vp["t_s"][-1]) + 0.5) * link.sample_rate_hz)
        res = _with_progress(
            "running", expect,
            lambda cb: run_session(src, built.blocks, out=out, events_out=ev_path,
                                   metadata=meta, chunk_samples=chunk, on_progress=cb),
            built.supervisor,
        )  # fmt: skip
    finally:
        link.close()
    lines = [f"millsense: note: {n}" for n in built.notes]
    lines += [f"millsense: warning: {w}" for w in findings.warnings]
    lines += link_summary(link)
    lines += _summary_lines(res, out, ev_path)
    if plot is not None:
        from millsense.report.online_plots import plot_run

        plot_run(out, res.events, plot)
        lines.append(f"wrote {plot}")
    return {"lines": lines, "result": res}


def link_summary(link: Any) -> list[str]:
    """What the link saw: blocks received, duplicates, lost intervals, interruptions."""
    fs = link.sample_rate_hz
    lines = [f"link: {link.received} samples received, {link.asm.duplicates} duplicate blocks "
             f"dropped, {len(link.asm.gaps)} lost intervals"]  # fmt: skip
    for a, b in link.asm.gaps:
        lines.append(f"  lost {a / fs:.4f}–{b / fs:.4f} s ({b - a} samples)")
    for what, _t, k, why in link.link_log:
        lines.append(f"  link {what} at sample {k} ({k / fs:.4f} s): {why}")
    return lines


@dataclass
class VirtualMachine:
    """The virtual machine running a plan (what ``run`` and ``serve-machine`` build)."""

    plan: Any
    config: Any
    sim: Any
    metadata: dict[str, Any]
    notes: list[str]
    findings: Any


def virtual_machine(
    *,
    program: Path | None,
    stock: Path | None,
    tool: str | None,
    material: str | None,
    plan: Path | None,
    plan_out: Path | None,
    machine: str,
    break_at_s: float | None = None,
    break_flute: int = 0,
    tool_modes: Path | None = None,
    seed: int = 0,
    duration_s: float | None = None,
    step_mm: float = 0.4,
    resolution_mm: float = 0.2,
    home_mm: str | None = None,
) -> VirtualMachine:
    """The plan of ``--program`` (or ``--plan``) checked against the machine, and the virtual
    machine ready to run it (``millsense.simulator.plan_job``)."""
    from millsense.plan.checks import check_plan
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.process_coupling import ProcessEvent, ToolModes, ToothBreak

    vp, plan_name, findings = _plan(program, stock, tool, material, plan, plan_out, step_mm,
                                    resolution_mm, home_mm)  # fmt: skip
    sim_cfg = simulator_machine(machine)
    check_plan(vp, findings, machine=sim_cfg)
    events: list[ProcessEvent] = []
    if break_at_s is not None:
        events.append(ToothBreak(break_at_s, break_flute))
    modes = ToolModes.from_toml(tool_modes, findings) if tool_modes is not None else None
    plant = vp
    if program is not None and stock is not None and tool is not None and material is not None:
        plant = _plant_plan(program, stock, tool, material, step_mm, resolution_mm, home_mm)
    job, process, meta, notes = plan_job(plant, sim_cfg, plan_name, events=events, modes=modes)
    # the session plan's names and program digest (the plant's own plan carries neither)
    for key, name in (("tool", "tool_name"), ("material", "material_name"),
                      ("program_sha256", "program_sha256")):  # fmt: skip
        if vp.metadata.get(name):
            meta[key] = str(vp.metadata[name])
    if plant is vp:
        notes = [*notes, "the virtual machine cuts the given --plan itself (no program to plan "
                 "its own cut from: give --program for a machine that differs from its plan)"]
    sim = MachineSimulator(sim_cfg, job, process, SimulatorOptions(seed=seed),
                           duration_s=duration_s)  # fmt: skip
    meta.update(dict(sim.metadata))
    return VirtualMachine(vp, sim_cfg, sim, meta, notes, findings)


#: The most z-map cells the virtual machine's own plan of a ``run`` may take (64 MB of float32).
PLANT_MAX_CELLS = 16_000_000


def plant_cell_m(stock_cfg: Any, make_stock: Any, resolution_m: float) -> float:
    """The z-map cell of the virtual machine's own plan in ``run``: four times finer than the
    session's (``resolution_m``) and at least :data:`~millsense.simulator.plant_plan.PLANT_CELL_M`,
    coarser where the stock would take more than :data:`PLANT_MAX_CELLS` cells (a large part),
    but never coarser than half the session's cell (the plant's cut stays its own)."""
    from millsense.simulator.plant_plan import PLANT_CELL_M

    if stock_cfg.kind == "box":
        lo, hi = stock_cfg.min_mm, stock_cfg.max_mm
        area = abs(hi[0] - lo[0]) * abs(hi[1] - lo[1]) * 1e-6
    else:
        coarse = make_stock(resolution_m)
        area = coarse.nx * coarse.ny * resolution_m**2
    cell = max(PLANT_CELL_M, resolution_m / 4.0, math.sqrt(area / PLANT_MAX_CELLS))
    return min(cell, max(PLANT_CELL_M, resolution_m / 2.0))


def _plant_plan(program: Path, stock: Path, tool: str, material: str, step_mm: float,
                resolution_mm: float, home_mm: str | None = None) -> Any:  # fmt: skip
    """The virtual machine's own plan of ``--program`` (decision 1740,
    :func:`~millsense.simulator.plant_plan.plant_plan`): the same program, stock, tool and
    material as the session's plan, on a z-map 4 times finer (0.05 mm at least) by the tool
    with the plant's runout, so the machine does not cut the session's expectation."""
    from rich.console import Console
    from rich.progress import Progress

    from millsense.core.config import MaterialConfig, StockConfig, ToolConfig, load_config
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret_file
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.plant_plan import plant_plan

    from .cmd_plan import _home, program_start_mm, stock_maker

    tool_cfg = load_preset(ToolConfig, Path(tool))
    mat_cfg = load_preset(MaterialConfig, Path(material))
    stock_cfg = load_config(StockConfig, stock)
    make_stock = stock_maker(stock_cfg, stock)
    cell_m = plant_cell_m(stock_cfg, make_stock, resolution_mm * MM)
    # the session plan's start (decision 1709), from a coarse z-map of the same stock
    start = program_start_mm(make_stock(max(resolution_mm * MM, 1e-3)).max_height_m)
    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("plan of the virtual machine", total=1)
        return plant_plan(
            [interpret_file(program, home_mm=_home(home_mm), initial_position_mm=start)],
            make_stock,
            EndMill.from_config(tool_cfg), CuttingCoefficients.from_config(mat_cfg),
            cell_m=cell_m, step_m=step_mm * MM,
            progress=lambda done, total: bar.update(task, completed=done, total=total),
        )  # fmt: skip


def replay_online(
    recording: Path,
    plan: Path,
    machine_file: Path | None,
    out: Path | None,
    events_out: Path,
    options: Any,
    chunk: int,
) -> dict[str, Any]:
    """The on-line blocks on a recording (the body of ``replay``)."""
    from millsense.cli.plan_match import check_plan_matches
    from millsense.core.errors import ConfigError, InputDataError
    from millsense.io.recording_reader import opened_recording
    from millsense.models.kinematics import kinematics_for
    from millsense.online.guard import FAULT_CHANNEL
    from millsense.online.session import run_session, session_blocks
    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.streaming.sources import RecordingSource

    if chunk < 1:
        raise ConfigError(f"--chunk: must be ≥ 1, got {chunk}")
    vp = VirtualPlan.read(plan)
    with opened_recording(recording) as rec:
        check_plan_matches(vp, plan, rec, recording)
        cfg, where = _machine_file(machine_file, str(rec.metadata.get("machine", "")))
        kin = str(rec.metadata.get("kinematics", cfg.kinematics))
        axes = [a for a in cfg.axes if f"{a}/position_cmd" in rec.channel_names]
        # the tool-centre point takes the machine's first n axes, as the kinematics needs them
        need = list(cfg.axes)[: kinematics_for(kin).n_axes]
        missing = [a for a in need if a not in axes]
        if missing:
            raise InputDataError(
                f"{recording}: no {', '.join(f'{a}/position_cmd' for a in missing)}: the "
                f"tool-centre point of the plan sync ({kin} kinematics) needs the positions of "
                f"{', '.join(need)}; record them (a recording whose rotary axes stood at 0: "
                'metadata kinematics = "3-axis")'
            )
        cfg = cfg.with_axes(axes, kin)
        built = session_blocks(vp, cfg, rec.sample_rate_hz, options, where=where,
                               channels=rec.channel_names)  # fmt: skip
        # only what the blocks read (and the truth the plot shows): a recording of an earlier
        # run also holds that run's block outputs, which these blocks recompute
        have = set(rec.channel_names)
        made = {c.name for b in built.blocks for c in b.output_channels()} | {FAULT_CHANNEL}
        wanted = {c for b in built.blocks for c in b.inputs if c in have and c not in made}
        wanted |= {c for c in ("cnc/feed_override", *PLOT_TRUTH) if c in have}
        src = RecordingSource(rec, name=str(recording), channels=sorted(wanted))
        res = _with_progress(
            "replaying", rec.n_samples,
            lambda cb: run_session(src, built.blocks, out=out, events_out=events_out,
                                   metadata={"source": "millsense replay",
                                             "recording": str(recording), "machine_file": where,
                                             "machine": str(rec.metadata.get("machine", ""))},
                                   chunk_samples=chunk, on_progress=cb,
                                   stop_after_hold_s=None),
            built.supervisor,
        )  # fmt: skip
    lines = [f"millsense: note: {n}" for n in built.notes]
    lines += _summary_lines(res, out, events_out)
    return {"lines": lines, "result": res}


def _with_progress(what: str, total: int, job: Any, supervisor: Any) -> Any:
    """Run ``job(callback)`` under a progress bar with the live feed and spindle overrides."""
    from millsense.cli.progress import progress_bar

    def live(done: float) -> str:
        sp = supervisor.spindle
        spindle = "" if sp != sp else f" spindle {100 * sp:.0f} %"
        mode = ("normal", "chatter", "fault", "HOLD")[supervisor.mode]
        feed = f"feed {100 * supervisor.feed:5.1f} %"
        return f"t {done / supervisor.fs:6.2f} s  {feed}{spindle}  {mode}"

    with progress_bar(what, max(total, 1), live) as update:
        return job(update)


def _summary_lines(res: Any, out: Path | None, events_path: Path) -> list[str]:
    from collections import Counter

    from millsense.streaming.block import EventKind

    counts = Counter(e.name for e in res.events)
    lines = [
        f"{res.seconds:.2f} s of signal in {res.wall_s:.1f} s wall "
        f"({res.seconds / max(res.wall_s, 1e-9):.1f}x real time)"
    ]
    for e in res.events:
        if e.kind in (EventKind.ALARM, EventKind.CRASH) or e.name in (
            "feed_hold", "spindle_override", "ktc_calibrated", "chatter_end", "breakage_blind",
            "breakage_seen",
        ):  # fmt: skip
            where = f" line {e.nc_line}" if e.nc_line is not None else ""
            lines.append(f"  {e.time_s:8.3f} s {e.severity:8s} {e.name}{where}: {e.message}")
    lines.append(
        "events: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) if counts else
        "events: none"
    )  # fmt: skip
    if out is not None:
        lines.append(f"wrote {out}")
    lines.append(f"wrote {events_path}")
    return lines
