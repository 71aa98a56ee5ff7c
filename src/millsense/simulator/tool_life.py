"""A simulated tool life: which runs a fleet of tools makes and how worn each tool is at each
run (issue 20 acceptance: the wear monitor over varying depths and widths; decision 2001).

Each tool makes ``runs`` runs; each run machines one part with one of the programs (cycled
with a per-tool offset, so consecutive runs change depth and width) and represents
``part_cut_s`` of cutting — the short plan the virtual machine simulates is a sample of the
part, and the tool's wear between runs comes from the whole part. The tool's VB before the run
follows :class:`~millsense.simulator.wear.FlankWearModel`'s growth at the tool's cutting speed,
with a per-tool life factor (tools of one type do not wear alike: ±30 % is common in tool-life
tests) drawn from a seeded generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import ConfigError
from millsense.plan.virtual_plan import VirtualPlan
from millsense.simulator.wear import FlankWearModel

__all__ = [
    "FLEET_PROGRAMS",
    "ToolLifeRun",
    "fleet_plan",
    "fleet_program",
    "tool_life_runs",
]

#: (name, axial depth mm, radial width mm; 20 = slot) of the built-in fleet programs:
#: depths and widths that change the torque as much as the wear does.
FLEET_PROGRAMS = (("slot2", 2.0, 20.0), ("side3w10", 3.0, 10.0), ("side4w5", 4.0, 5.0),
                  ("slot1p5", 1.5, 20.0))  # fmt: skip
SPINDLE_RPM = 1000.0
FEED_MM_MIN = 400.0
DIAMETER_MM = 20.0


@dataclass(frozen=True)
class ToolLifeRun:
    """One run of the schedule: tool, run number, program index, the tool's cutting time
    before the run (s, what the CNC's tool-life counter shows) and its true VB (m)."""

    tool_id: str
    run_index: int
    program: int
    cutting_time_s: float
    vb_m: float


def tool_life_runs(
    n_tools: int,
    runs: int,
    n_programs: int,
    *,
    part_cut_s: float,
    cutting_speed_m_s: float,
    model: FlankWearModel | None = None,
    life_spread: float = 0.3,
    seed: int = 0,
    max_vb_m: float = 0.6e-3,
) -> list[ToolLifeRun]:
    """The runs of ``n_tools`` tools × ``runs`` each (module docstring), VB capped at
    ``max_vb_m`` (a tool is replaced long before)."""
    if n_tools < 1 or runs < 1 or n_programs < 1:
        raise ConfigError("tool life: n_tools, runs and n_programs must be ≥ 1")
    if not (math.isfinite(part_cut_s) and part_cut_s > 0):
        raise ConfigError(f"tool life: part_cut_s must be > 0, got {part_cut_s!r}")
    m = model if model is not None else FlankWearModel()
    rng = np.random.default_rng(seed)
    factors = rng.uniform(1 - life_spread, 1 + life_spread, n_tools)
    out: list[ToolLifeRun] = []
    for k in range(n_tools):
        t = np.arange(runs) * part_cut_s
        teq = m.equivalent_time_s(t, cutting_speed_m_s) * factors[k]
        vb = np.minimum(m.vb_at(teq), max_vb_m)
        for i in range(runs):
            prog = (i + k) % n_programs
            out.append(ToolLifeRun(f"T{k + 1}", i, prog, float(t[i]), float(vb[i])))
    return out


def fleet_program(depth_mm: float, width_mm: float) -> str:
    """A straight cut along X through a 60 × 30 × 20 mm block (top edge at Y0) with the
    Ø20 mm tool at 1000 rev/min and 400 mm/min: the tool centre at Y = R − width (Y = −15 for
    a slot, the block spanning Y −30..0), air before X −10."""
    r = DIAMETER_MM / 2
    y = -15.0 if width_mm >= DIAMETER_MM else r - width_mm
    return (
        "%\nO7001 (MILLSENSE FLEET RUN)\nG21 G90 G17 G94\nT1 M6\n"
        f"S{SPINDLE_RPM:.0f} M3\nG0 X-16. Y{y:.3f} Z5.\nG1 Z-{depth_mm:.3f} F{FEED_MM_MIN:.0f}.\n"
        "X30.\nG0 Z5.\nM30\n%\n"
    )


def _fleet_tool_material() -> tuple[Any, Any, dict[str, str]]:
    """The fleet's tool and coefficients (presets ``aslan-d20-2flute``, ``al7050``) and their
    names for a plan's metadata."""
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import load_preset
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    tool_cfg = load_preset(ToolConfig, "aslan-d20-2flute")
    mat = load_preset(MaterialConfig, "al7050")
    names = {"tool_name": tool_cfg.name, "material_name": mat.name}
    return EndMill.from_config(tool_cfg), CuttingCoefficients.from_config(mat), names


def _fleet_stock(cell_m: float) -> Any:
    """The fleet's Al7050 block (60 × 30 × 20 mm) on a z-map of cell ``cell_m``."""
    from millsense.plan.stock import ZMapStock

    return ZMapStock.from_box([0.0, -0.03, -0.02], [0.06, 0.0, 0.0], cell_m)


def fleet_plan(program: Path) -> VirtualPlan:
    """The virtual plan of a fleet program (:func:`fleet_program`) on the Al7050 block with the
    Ø20 mm two-flute tool (the presets ``aslan-d20-2flute``, ``al7050``), 0.25 mm z-map: the
    monitor's plan."""
    from millsense.plan.gcode import interpret_file
    from millsense.plan.virtual_plan import plan_program

    tool, coeffs, names = _fleet_tool_material()
    return plan_program(interpret_file(program), _fleet_stock(0.25e-3), tool, coeffs,
                        metadata={"program": str(program), **names})  # fmt: skip


def fleet_plant_plan(program: Path) -> VirtualPlan:
    """The virtual machine's own plan of a fleet program
    (:func:`~millsense.simulator.plant_plan.plant_plan`, decision 1740): the block, tool and
    material of :func:`fleet_plan` on a 0.05 mm z-map, the tool with 5 µm of runout at 0.4 rad
    and the lot's true coefficients (the preset's ×
    :data:`~millsense.simulator.plant_plan.PLANT_LOT_FACTORS`, decisions 1760, 1798)
    the monitor's plan does not know."""
    from millsense.plan.gcode import interpret_file
    from millsense.simulator.plant_plan import plant_plan

    tool, coeffs, names = _fleet_tool_material()
    return plant_plan([interpret_file(program)], _fleet_stock, tool, coeffs,
                      metadata={"program": str(program), **names})  # fmt: skip
