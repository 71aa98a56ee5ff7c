"""``millsense simulate-fleet``: the recordings of a simulated tool life (several tools, several
programs of different depths and widths, growing flank wear) for ``batch`` and the wear monitor.

Four built-in programs cut a 60 × 30 × 20 mm Al7050 block along X with the Ø20 mm two-flute
tool at 1000 rev/min and 400 mm/min (0.2 mm/tooth): a 2 mm slot, a 3 mm cut at 10 mm width, a
4 mm cut at 5 mm width and a 1.5 mm slot — depths and widths that change the torque as much as
the wear does. Each program's virtual plan is written once (``plans/``): the monitor's plan
(:func:`~millsense.simulator.tool_life.fleet_plan`), which the recordings name and ``batch``
reads. The virtual machine cuts its own plan of the program
(:func:`~millsense.simulator.tool_life.fleet_plant_plan`: a finer z-map, runout and the lot's
true coefficients, decisions 1740, 1760; made in memory, never written beside the recordings)
with the tool's VB of that run (:func:`~millsense.simulator.tool_life.tool_life_runs`) and
the CNC's tool identity and tool-life counter in its metadata; the true VB is stored as
``truth_wear_vb_mm``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from millsense.cli.main import app
from millsense.simulator.tool_life import (
    DIAMETER_MM,
    FLEET_PROGRAMS,
    SPINDLE_RPM,
    fleet_plan,
    fleet_plant_plan,
    fleet_program,
)

if TYPE_CHECKING:
    from millsense.plan.virtual_plan import VirtualPlan


def write_fleet_plans(folder: Path) -> list[Path]:
    """The built-in programs (``.nc``) and the monitor's virtual plans of them (``.parquet``)
    in ``folder``; a plan present is reused."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, depth, width in FLEET_PROGRAMS:
        pq, nc = folder / f"{name}.parquet", folder / f"{name}.nc"
        nc.write_text(fleet_program(depth, width))
        if not pq.is_file():
            fleet_plan(nc).write(pq)
        out.append(pq)
    return out


def simulate_fleet(
    out: Path,
    *,
    tools: int,
    runs: int,
    part_cut_min: float,
    seed: int,
    on_progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Write the fleet's recordings ``out/T<k>_r<i>.h5`` (skipping those present), each the
    virtual machine cutting its own plan of the run's program while naming the monitor's plan
    in ``out/plans/`` (module docstring); returns one dict per run (tool, run, program, VB,
    path)."""
    from millsense.cli.cmd_simulate import run_simulation
    from millsense.simulator.tool_life import tool_life_runs

    plans = write_fleet_plans(out / "plans")
    speed = math.pi * DIAMETER_MM * 1e-3 * SPINDLE_RPM / 60.0
    schedule = tool_life_runs(tools, runs, len(plans), part_cut_s=part_cut_min * 60.0,
                              cutting_speed_m_s=speed, seed=seed)  # fmt: skip
    plants: dict[int, VirtualPlan] = {}  # the machine's own plans, made when first needed
    made = []
    for k, r in enumerate(schedule):
        path = out / f"{r.tool_id}_r{r.run_index:03d}.h5"
        if not path.is_file():
            if r.program not in plants:
                plants[r.program] = fleet_plant_plan(plans[r.program].with_suffix(".nc"))
            run_simulation(machine="quaser-ux600", program=None, plan=plans[r.program],
                           plant=plants[r.program],
                           tool=None, material=None, engagement="slot", depth_mm=2.0, out=path,
                           duration_s=None, seed=seed * 100_003 + k, cnc="open",
                           break_at_s=None, break_flute=0, realism=None, accelerometer=False,
                           microphone=False, chunk=2000, wear_vb_mm=r.vb_m * 1e3,
                           tool_id=r.tool_id,
                           tool_cutting_time_min=r.cutting_time_s / 60.0)  # fmt: skip
        made.append({"tool_id": r.tool_id, "run_index": r.run_index,
                     "program": FLEET_PROGRAMS[r.program][0], "vb_mm": r.vb_m * 1e3,
                     "path": str(path)})  # fmt: skip
        if on_progress is not None:
            on_progress(k + 1, len(schedule))
    return made


@app.command("simulate-fleet")
def simulate_fleet_command(
    out: Path = typer.Option(..., "-o", "--output", help="Folder of the recordings."),
    tools: int = typer.Option(5, "--tools", help="Tools of the fleet."),
    runs: int = typer.Option(20, "--runs", help="Runs (parts) per tool."),
    part_cut_min: float = typer.Option(
        6.0, "--part-cut-min", help="Cutting time of one part [min] (the tool's wear per run)."
    ),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the tools' life factors and noise."),
) -> None:
    """Simulate a tool life: TOOLS tools × RUNS runs of four programs with growing flank wear
    (the truth VB in each recording's metadata), for `millsense batch` and its wear monitor."""
    from millsense.cli.progress import progress_bar
    from millsense.core.errors import ConfigError

    if tools < 1 or runs < 1:
        raise ConfigError("--tools and --runs: must be ≥ 1")
    if not (math.isfinite(part_cut_min) and part_cut_min > 0):
        raise ConfigError(f"--part-cut-min: must be > 0, got {part_cut_min:g}")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a folder")
    with progress_bar("simulating the fleet", float(tools * runs)) as update:
        made = simulate_fleet(out, tools=tools, runs=runs, part_cut_min=part_cut_min, seed=seed,
                              on_progress=lambda k, _n: update(float(k)))  # fmt: skip
    worn = sum(1 for m in made if m["vb_mm"] >= 0.3)
    typer.echo(f"wrote {len(made)} recordings to {out} ({worn} with VB ≥ 0.3 mm)")
