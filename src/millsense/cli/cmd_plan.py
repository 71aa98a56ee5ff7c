"""``millsense plan`` and ``millsense schedule``: the virtual plan of a part program and a
feed-scheduled (optimised) program."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError

if TYPE_CHECKING:
    from millsense.virtual.plan import VirtualPlan


def _home(text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--home-mm {text!r}: expected X,Y,Z in mm") from None
    if len(vals) != 3:
        raise ConfigError(f"--home-mm {text!r}: expected three values X,Y,Z in mm")
    return (vals[0], vals[1], vals[2])


def _guard(
    program: Path, stock: Path, tool: Path, material: Path, outputs: dict[str, Path | None]
) -> None:
    """Refuse an output that is an input: the program, stock (and its STL), tool, material."""
    from millsense.io.safe_output import check_outputs

    inputs: dict[str, Path | None] = {
        "the program": program,
        "the stock file": stock,
        "the tool file": tool,
        "the material file": material,
    }
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
    if not value > 0:
        raise ConfigError(f"{name} {value!r}: must be > 0")


def _build(
    program: Path,
    stock: Path,
    tool: Path,
    material: Path,
    step_mm: float,
    resolution_mm: float,
    home_mm: str | None,
) -> tuple[VirtualPlan, Any]:
    from rich.console import Console
    from rich.progress import Progress

    from millsense.core.config import MaterialConfig, StockConfig, ToolConfig, load_config
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.virtual.gcode import interpret_file
    from millsense.virtual.plan import plan_program
    from millsense.virtual.stock import ZMapStock

    _positive("--step-mm", step_mm)
    _positive("--resolution-mm", resolution_mm)
    tool_cfg = load_preset(ToolConfig, tool)
    mat_cfg = load_preset(MaterialConfig, material)
    stock_cfg = load_config(StockConfig, stock)
    toolpath = interpret_file(program, home_mm=_home(home_mm))
    if stock_cfg.kind == "box":
        assert stock_cfg.min_mm is not None and stock_cfg.max_mm is not None
        zmap = ZMapStock.from_box(
            [v * MM for v in stock_cfg.min_mm],
            [v * MM for v in stock_cfg.max_mm],
            resolution_mm * MM,
        )
    else:
        assert stock_cfg.stl_path is not None
        stl = Path(stock_cfg.stl_path)
        if not stl.is_absolute():
            stl = Path(stock).parent / stl
        if not stl.is_file():
            raise ConfigError(f"{stock}: key 'stl_path' = {stock_cfg.stl_path!r}: no such file")
        zmap = ZMapStock.from_stl(stl, resolution_mm * MM)
    console = Console(stderr=True, soft_wrap=True)
    with Progress(console=console, transient=True) as bar:
        task = bar.add_task(f"plan {program.name}", total=1)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        plan = plan_program(
            toolpath,
            zmap,
            EndMill.from_config(tool_cfg),
            CuttingCoefficients.from_config(mat_cfg),
            step_m=step_mm * MM,
            progress=update,
            metadata={
                "tool_name": tool_cfg.name,
                "material_name": mat_cfg.name,
                "stock_file": str(stock),
            },
        )
    for note in plan.metadata.get("notes", []):
        console.print(f"millsense: note: {note}", markup=False)
    return plan, toolpath


_STOCK = typer.Option(..., "--stock", help="Stock TOML (box or STL).")
_TOOL = typer.Option(..., "--tool", help="Tool TOML or preset name.")
_MATERIAL = typer.Option(..., "--material", help="Material TOML or preset name.")
_STEP = typer.Option(0.4, "--step-mm", help="Path step [mm] (0.4, seed 000).")
_RES = typer.Option(0.1, "--resolution-mm", help="Z-map cell [mm].")
_HOME = typer.Option(None, "--home-mm", help="G28 reference X,Y,Z [mm].")


@app.command()
def plan(
    program: Path = typer.Argument(..., help="Part program (G-code)."),
    stock: Path = _STOCK,
    tool: Path = _TOOL,
    material: Path = _MATERIAL,
    output: Path = typer.Option(..., "-o", "--output", help="Plan file (Parquet)."),
    plot: Path | None = typer.Option(None, "--plot", help="Write a PNG of the plan."),
    step_mm: float = _STEP,
    resolution_mm: float = _RES,
    home_mm: str | None = _HOME,
) -> None:
    """Virtual plan: engagement and predicted forces, torque, power per path step."""
    import time

    _guard(program, stock, tool, material, {"-o": output, "--plot": plot})
    t0 = time.perf_counter()
    vp, _ = _build(program, stock, tool, material, step_mm, resolution_mm, home_mm)
    vp.write(output)
    if plot is not None:
        from millsense.report.plan_plots import plot_plan

        plot_plan(vp, plot)
    cut = vp["in_cut"]
    typer.echo(
        f"{output}: {len(vp)} steps, {int(cut.sum())} in cut, peak resultant "
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
) -> None:
    """Feed per step holding a force, torque or power limit; write an optimised program."""
    from millsense.core.units import MM, MM_PER_MIN
    from millsense.virtual.schedule import AT_LIMIT, schedule_feed, write_scheduled_program

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
    _positive(f"--limit-{kind}", float(value))
    _positive("--accel-mm-s2", accel_mm_s2)
    vp, toolpath = _build(program, stock, tool, material, step_mm, resolution_mm, home_mm)
    sched = schedule_feed(
        vp,
        float(value),
        kind=kind,
        max_feed_m_s=None if max_feed_mm_min is None else max_feed_mm_min * MM_PER_MIN,
        min_feed_m_s=None if min_feed_mm_min is None else min_feed_mm_min * MM_PER_MIN,
        accel_m_s2=accel_mm_s2 * MM,
    )
    text = Path(program).read_text(encoding="utf-8", errors="replace")
    added = write_scheduled_program(text, toolpath, vp, sched, output)
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
