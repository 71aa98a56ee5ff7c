"""``millsense plan`` and ``millsense schedule``: the virtual plan of a part program and a
feed-scheduled (optimised) program."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError
from millsense.core.plausibility import Findings

if TYPE_CHECKING:
    from millsense.plan.virtual_plan import VirtualPlan


def _home(text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--home-mm {text!r}: expected X,Y,Z in mm") from None
    if len(vals) != 3:
        raise ConfigError(f"--home-mm {text!r}: expected three values X,Y,Z in mm")
    if not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"--home-mm {text!r}: X,Y,Z must be finite (mm)")
    return (vals[0], vals[1], vals[2])


def program_start_mm(stock_top_m: float) -> tuple[float, float, float]:
    """Where the tool tip is before the program's first block (machine frame, mm): X0 Y0 and
    Z0, or the stock's highest top where that lies above Z0 (decision 1709). A G-code program
    does not say where the machine is when it starts; a machine never starts one with its
    tool in the material, so neither does the plan (a rapid from inside the stock would be a
    collision the user did not program)."""
    return (0.0, 0.0, max(0.0, round(stock_top_m * 1e3, 6)))


def _guard(
    program: Path,
    stock: Path,
    tool: Path | list[str],
    material: Path,
    outputs: dict[str, Path | None],
) -> None:
    """Refuse an output that is an input: the program, stock (and its STL), tool(s) (``--tool
    TOOL`` or ``--tool Tn=TOOL``), material."""
    from millsense.io.safe_output import check_outputs

    inputs: dict[str, Path | None] = {
        "the program": program,
        "the stock file": stock,
        "the material file": material,
    }
    for spec in [tool] if isinstance(tool, Path) else tool:
        name = str(spec).partition("=")[2] or str(spec)
        inputs[f"the tool file {name}"] = Path(name)
    try:
        from millsense.core.config import StockConfig, load_config

        stl = load_config(StockConfig, stock).stl_path
    except Exception:  # a bad stock file is reported, with its line, by _build
        stl = None
    if stl is not None:
        inputs["the stock's STL"] = (
            Path(stl) if Path(stl).is_absolute() else Path(stock).parent / stl
        )
    check_outputs(inputs, outputs)


def _positive(name: str, value: float) -> None:
    if not math.isfinite(value):
        raise ConfigError(f"{name} {value!r}: must be finite")
    if not value > 0:
        raise ConfigError(f"{name} {value!r}: must be > 0")


#: The option of each limit kind of ``schedule``.
_LIMIT_OPTION = {
    "force": "--limit-force-n",
    "torque": "--limit-torque-nm",
    "power": "--limit-power-w",
}


def stock_maker(stock_cfg: Any, stock: Path) -> Callable[[float], Any]:
    """The raw stock of the stock file ``stock`` (its parsed ``StockConfig``) as a function of
    the z-map cell (m): a box, or the STL it names (relative to the stock file). The STL is
    checked at once (one-line error naming the file and key)."""
    from millsense.core.units import MM
    from millsense.plan.stock import ZMapStock

    if stock_cfg.kind == "box":
        assert stock_cfg.min_mm is not None and stock_cfg.max_mm is not None
        lo = [v * MM for v in stock_cfg.min_mm]
        hi = [v * MM for v in stock_cfg.max_mm]
        return lambda cell_m: ZMapStock.from_box(lo, hi, cell_m)
    assert stock_cfg.stl_path is not None
    stl = Path(stock_cfg.stl_path)
    if not stl.is_absolute():
        stl = Path(stock).parent / stl
    if not stl.is_file():
        raise ConfigError(f"{stock}: key 'stl_path' = {stock_cfg.stl_path!r}: no such file")
    return lambda cell_m: ZMapStock.from_stl(stl, cell_m)


def _build(
    program: Path,
    stock: Path,
    tool: Path,
    material: Path,
    step_mm: float,
    resolution_mm: float,
    home_mm: str | None,
    machine: str | None = None,
) -> tuple[VirtualPlan, Any, Findings]:
    """Plan a program of one tool (:func:`_build_plans`; a program with tool changes to
    several tools is refused naming the line of the second one)."""
    plans, toolpath, findings = _build_plans(
        program, stock, [str(tool)], material, step_mm, resolution_mm, home_mm, machine,
        one_tool=True,
    )
    return plans[0][1], toolpath, findings


def _build_plans(
    program: Path,
    stock: Path,
    tools: list[str],
    material: Path,
    step_mm: float,
    resolution_mm: float,
    home_mm: str | None,
    machine: str | None = None,
    one_tool: bool = False,
) -> tuple[list[tuple[int, VirtualPlan]], Any, Findings]:
    """Plan the program, each tool's moves with its tool on one stock (``tools``: the
    ``--tool`` options, :func:`millsense.plan.tools.assign_tools`; decision 1683): the tool
    number and plan of every segment in program order. Impossible input raises one line,
    implausible input is a warning (printed, and kept in the plans' metadata ``warnings``).
    ``one_tool``: the command takes one tool (``assign_tools``)."""
    import functools
    import hashlib

    from rich.console import Console
    from rich.progress import Progress

    from millsense.core.config import (
        MachineConfig,
        MaterialConfig,
        StockConfig,
        ToolConfig,
        load_config,
    )
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.plan.checks import check_plan, check_program
    from millsense.plan.gcode import interpret_file
    from millsense.plan.tools import assign_tools, tool_segments
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    _positive("--step-mm", step_mm)
    _positive("--resolution-mm", resolution_mm)
    home = _home(home_mm)
    toolpath = interpret_file(program, home_mm=home)
    segments = tool_segments(toolpath)
    names = assign_tools(segments, tools, toolpath.source, one_tool)
    tool_cfgs = {name: load_preset(ToolConfig, Path(name)) for name in dict.fromkeys(names)}
    for name, tool_cfg in tool_cfgs.items():
        if 1.5 * resolution_mm >= tool_cfg.diameter_mm:
            # the CWE resolves no radial depth below about 1.5 cells (millsense.plan.cwe)
            raise ConfigError(
                f"--resolution-mm {resolution_mm:g}: a cell of D/1.5 = "
                f"{tool_cfg.diameter_mm / 1.5:.4g} mm or more resolves no engagement of the "
                f"Ø{tool_cfg.diameter_mm:g} mm tool {name}, not even a slot (default 0.1 mm)"
            )
    mat_cfg = load_preset(MaterialConfig, material)
    stock_cfg = load_config(StockConfig, stock)
    mcfg = None if machine is None else load_preset(MachineConfig, machine)
    findings = Findings()
    check_program(toolpath, findings, machine=mcfg)
    program_warnings = list(findings.warnings)
    zmap = stock_maker(stock_cfg, stock)(resolution_mm * MM)
    start = program_start_mm(zmap.max_height_m)
    if start[2] > 0.0:  # a stock standing above Z0: the tool starts above it (decision 1709)
        toolpath = interpret_file(program, home_mm=home, initial_position_mm=start)
        segments = tool_segments(toolpath)
    console = Console(stderr=True, soft_wrap=True)
    sha = hashlib.sha256(program.read_bytes()).hexdigest()
    plans: list[tuple[int, VirtualPlan]] = []
    printed: set[str] = set()
    for seg, name in zip(segments, names, strict=True):
        tool_cfg = tool_cfgs[name]
        label = program.name if len(segments) == 1 else f"{program.name} T{seg.tool}"
        with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
            task = bar.add_task(f"plan {label}", total=1)
            # one stock for all tools: each segment cuts what the ones before it left
            plan = plan_program(
                seg.path,
                zmap,
                EndMill.from_config(tool_cfg),
                CuttingCoefficients.from_config(mat_cfg),
                step_m=step_mm * MM,
                progress=functools.partial(_progress, bar, task),
                metadata={
                    "tool_name": tool_cfg.name,
                    "material_name": mat_cfg.name,
                    "stock_file": str(stock),
                },
            )
        seg_findings = Findings()
        check_plan(plan, seg_findings, machine=mcfg, stickout_mm=tool_cfg.stickout_mm)
        findings.extend(seg_findings.warnings)
        plan.metadata["warnings"] = program_warnings + [
            w for w in seg_findings.warnings if w not in program_warnings
        ]
        # the program's bytes, so that a plan and a recording of two programs of one file
        # name are told apart (cli.plan_match)
        plan.metadata["program_sha256"] = sha
        if len(segments) > 1:
            plan.metadata["tool_number"] = seg.tool
            plan.metadata["program_tools"] = [s.tool for s in segments]
            plan.metadata["segment_first_line"] = seg.first_line
        if machine is not None:
            plan.metadata["machine"] = machine
        # each segment keeps the program's notes: each printed once
        for note in plan.metadata.get("notes", []):
            if note not in printed:
                printed.add(note)
                console.print(f"millsense: note: {note}", markup=False)
        plans.append((seg.tool, plan))
    return plans, toolpath, findings


def _progress(bar: Any, task: Any, done: int, total: int) -> None:
    bar.update(task, completed=done, total=total)


def plan_outputs(output: Path, tools: list[int]) -> list[Path]:
    """The file of each segment's plan: ``output`` for one, else ``STEM_Tn.SUFFIX`` (a tool
    that comes back later: ``STEM_Tn-2.SUFFIX``)."""
    if len(tools) == 1:
        return [output]
    seen: dict[int, int] = {}
    out = []
    for t in tools:
        seen[t] = seen.get(t, 0) + 1
        tag = f"T{t}" if seen[t] == 1 else f"T{t}-{seen[t]}"
        out.append(output.with_name(f"{output.stem}_{tag}{output.suffix}"))
    return out


def _print_warnings(findings: Findings) -> None:
    for w in findings.warnings:
        typer.echo(f"millsense: warning: {w}", err=True)


_STOCK = typer.Option(..., "--stock", help="Stock TOML (box or STL).")
_TOOL = typer.Option(..., "--tool", help="Tool TOML or preset name.")
_MATERIAL = typer.Option(..., "--material", help="Material TOML or preset name.")
_STEP = typer.Option(0.4, "--step-mm", help="Path step [mm] (0.4, seed 000).")
_RES = typer.Option(0.1, "--resolution-mm", help="Z-map cell [mm].")
_HOME = typer.Option(None, "--home-mm", help="G28 reference X,Y,Z [mm].")
_MACHINE = typer.Option(
    None,
    "--machine",
    help="Machine preset or .toml: feeds, spindle speed, forces and power are checked against "
    "its [limits] and max_rpm (default: no machine, only physical ranges).",
)


@app.command()
def plan(
    program: Path = typer.Argument(..., help="Part program (G-code)."),
    stock: Path = _STOCK,
    tool: list[str] = typer.Option(
        ...,
        "--tool",
        help="Tool TOML or preset name; a program with tool changes: Tn=TOOL for each tool "
        "(repeat; one plan per tool, OUTPUT_Tn.parquet, on one stock).",
    ),
    material: Path = _MATERIAL,
    output: Path = typer.Option(..., "-o", "--output", help="Plan file (Parquet)."),
    plot: Path | None = typer.Option(None, "--plot", help="Write a PNG of the plan."),
    step_mm: float = _STEP,
    resolution_mm: float = _RES,
    home_mm: str | None = _HOME,
    machine: str | None = _MACHINE,
) -> None:
    """Virtual plan: engagement and predicted forces, torque, power per path step.

    A program with tool changes (T2 M6): each tool's moves are planned with its tool, given as
    --tool T1=TOOL --tool T2=TOOL, in program order on one stock, one plan per tool
    (OUTPUT_T1.parquet, ...; decision 1683); simulate and run take each with --plan."""
    import time

    _guard(program, stock, tool, material, {"-o": output, "--plot": plot})
    t0 = time.perf_counter()
    plans, _, findings = _build_plans(
        program, stock, tool, material, step_mm, resolution_mm, home_mm, machine
    )
    numbers = [t for t, _ in plans]
    outs = plan_outputs(output, numbers)
    plots: list[Path | None] = [None] * len(outs)
    if plot is not None:
        plots = list(plan_outputs(plot, numbers))
    if len(outs) > 1:  # the per-tool files must not be inputs either
        _guard(program, stock, tool, material, {
            **{f"-o ({o.name})": o for o in outs},
            **{f"--plot ({q.name})": q for q in plots if q is not None},
        })  # fmt: skip
    _print_warnings(findings)
    for (_, vp), out, png in zip(plans, outs, plots, strict=True):
        vp.write(out)
        if png is not None:
            from millsense.report.plan_plots import plot_plan

            plot_plan(vp, png)
        cut = vp["in_cut"]
        typer.echo(
            f"{out}: {len(vp)} steps, {int(cut.sum())} in cut, peak resultant "
            f"{float(vp['fres_peak_n'].max()):.1f} N, peak mean torque "
            f"{float(vp['torque_avg_nm'].max()):.3f} N·m ({time.perf_counter() - t0:.2f} s)"
        )


@app.command()
def schedule(
    program: Path = typer.Argument(..., help="Part program (G-code)."),
    stock: Path = _STOCK,
    tool: Path = _TOOL,
    material: Path = _MATERIAL,
    output: Path = typer.Option(..., "-o", "--output", help="Optimised program."),
    limit_force_n: float | None = typer.Option(None, "--limit-force-n", help="Peak XY force [N]."),
    limit_torque_nm: float | None = typer.Option(
        None, "--limit-torque-nm", help="Peak torque [N·m]."
    ),
    limit_power_w: float | None = typer.Option(None, "--limit-power-w", help="Mean power [W]."),
    max_feed_mm_min: float | None = typer.Option(
        None, "--max-feed-mm-min", help="Upper feed bound [mm/min] (default: programmed)."
    ),
    min_feed_mm_min: float | None = typer.Option(
        None, "--min-feed-mm-min", help="Lower feed bound [mm/min] (default: 10 % of programmed)."
    ),
    accel_mm_s2: float = typer.Option(1000.0, "--accel-mm-s2", help="Path acceleration [mm/s²]."),
    plot: Path | None = typer.Option(None, "--plot", help="Write a PNG with the feeds."),
    step_mm: float = _STEP,
    resolution_mm: float = _RES,
    home_mm: str | None = _HOME,
    machine: str | None = _MACHINE,
) -> None:
    """Feed per step holding a force, torque or power limit; write an optimised program."""
    from millsense.core.errors import InputDataError
    from millsense.core.units import MM, MM_PER_MIN
    from millsense.plan.gcode import read_program
    from millsense.plan.schedule import AT_LIMIT, schedule_feed, write_scheduled_program

    limits = [
        (k, v)
        for k, v in (
            ("force", limit_force_n),
            ("torque", limit_torque_nm),
            ("power", limit_power_w),
        )
        if v is not None
    ]
    if len(limits) != 1:
        raise ConfigError("give exactly one of --limit-force-n, --limit-torque-nm, --limit-power-w")
    _guard(program, stock, tool, material, {"-o": output, "--plot": plot})
    kind, value = limits[0]
    _positive(_LIMIT_OPTION[kind], float(value))
    _positive("--accel-mm-s2", accel_mm_s2)
    for name, feed in (
        ("--min-feed-mm-min", min_feed_mm_min),
        ("--max-feed-mm-min", max_feed_mm_min),
    ):
        if feed is not None:
            _positive(name, feed)
    if min_feed_mm_min is not None and max_feed_mm_min is not None:
        if min_feed_mm_min > max_feed_mm_min:
            raise ConfigError(
                f"--min-feed-mm-min {min_feed_mm_min:g} exceeds --max-feed-mm-min "
                f"{max_feed_mm_min:g}"
            )
    vp, toolpath, findings = _build(
        program, stock, tool, material, step_mm, resolution_mm, home_mm, machine
    )
    try:
        sched = schedule_feed(
            vp,
            float(value),
            kind=kind,
            max_feed_m_s=None if max_feed_mm_min is None else max_feed_mm_min * MM_PER_MIN,
            min_feed_m_s=None if min_feed_mm_min is None else min_feed_mm_min * MM_PER_MIN,
            accel_m_s2=accel_mm_s2 * MM,
        )
    except InputDataError as exc:
        # the only bound the options can still break: a minimum above a programmed feed
        raise ConfigError(
            f"--min-feed-mm-min {min_feed_mm_min}: {exc} (the programmed feed of "
            f"{program} where --max-feed-mm-min is not given)"
        ) from None
    _unreachable(vp, sched, kind, float(value), findings)
    _print_warnings(findings)
    text, encoding = read_program(program)
    added = write_scheduled_program(text, toolpath, vp, sched, output, encoding=encoding)
    if plot is not None:
        from millsense.report.plan_plots import plot_plan

        plot_plan(vp, plot, sched.feed_m_s / MM_PER_MIN)
    t_prog = float(vp["t_s"][-1])
    dt = (vp["s_mm"][1:] - vp["s_mm"][:-1]) * MM
    rapid = vp["rapid"][:-1].astype(bool)
    t_new = float(
        (dt[~rapid] / sched.feed_m_s[:-1][~rapid]).sum()
        + (vp["t_s"][1:] - vp["t_s"][:-1])[rapid].sum()
    )
    typer.echo(
        f"{output}: {int((sched.status == AT_LIMIT).sum())} steps at the {kind} limit, "
        f"{added} blocks added; time at programmed feed {t_prog:.1f} s -> {t_new:.1f} s"
    )


_UNITS = {"force": "N", "torque": "N·m", "power": "W"}


def _unreachable(vp: VirtualPlan, sched: Any, kind: str, limit: float, findings: Findings) -> None:
    """Warn when the limit cannot be held: steps whose scheduled feed (clipped at the minimum
    feed) is above the feed that holds it, or where the edge forces alone exceed it (the feed
    holding it is 0). No feed in the allowed range reaches the limit there."""
    import numpy as np

    from millsense.core.units import MM_PER_MIN

    cut = (sched.target_m_s < sched.feed_m_s * (1 - 1e-6)) & ~vp["rapid"].astype(bool)
    if not cut.any():
        return
    k = int(np.flatnonzero(cut)[0])
    lines = sorted({int(v) for v in vp["source_line"][cut]})
    where = ", ".join(str(v) for v in lines[:5]) + (" ..." if len(lines) > 5 else "")
    unit = _UNITS[kind]
    hold = float(sched.target_m_s[k]) / MM_PER_MIN
    why = (
        "the edge forces alone exceed it at any feed"
        if hold <= 0
        else f"it needs {hold:.4g} mm/min, below --min-feed-mm-min"
    )
    findings.warn(
        f"{_LIMIT_OPTION[kind]} {limit:g} {unit}: no feed reaches it on {int(cut.sum())} "
        f"steps (lines {where}): "
        f"{why}; those steps run at the minimum feed "
        f"{float(sched.feed_m_s[k]) / MM_PER_MIN:.4g} mm/min and exceed the limit"
    )
