"""The plausibility layer (:mod:`millsense.core.plausibility`) applied to programs and plans.

Adapters only: they pick the moves or plan rows that cut and hand their feeds, spindle speeds,
depths, forces and powers to the shared checks, naming ``file:line`` in every message.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from millsense.core.errors import ProgramError
from millsense.core.plausibility import (
    Findings,
    check_against_limits,
    check_cutting_moves,
    check_depth,
    check_feed_limit,
)
from millsense.core.units import MM_PER_MIN, RPM
from millsense.plan.path import ARC, LINE, Toolpath

if TYPE_CHECKING:
    from millsense.core.config import MachineConfig, MachineLimitsConfig
    from millsense.plan.virtual_plan import VirtualPlan


def _limits(machine: MachineConfig | None) -> MachineLimitsConfig | None:
    return None if machine is None else machine.limits


def check_program(
    toolpath: Toolpath,
    findings: Findings,
    *,
    machine: MachineConfig | None = None,
    cuts: bool = False,
    flutes: int = 2,
    diameter_mm: float = 0.0,
) -> None:
    """The feed moves of a program: feed within the machine's (or the absolute) limit; with
    ``cuts`` (every feed move cuts, as ``simulate --program`` runs it) also the spindle running
    and the feed per tooth in range.

    The spindle follows the simulator's rule: it runs from the start at the first programmed
    speed (M3 before motion), so only moves after an M5, or a program without S/M3, have it
    stopped.
    """
    length = np.linalg.norm(toolpath.end[:, :3] - toolpath.start[:, :3], axis=1)
    feed_move = ((toolpath.kind == LINE) | (toolpath.kind == ARC)) & (
        (length > 0) | (toolpath.kind == ARC)
    )
    idx = np.flatnonzero(feed_move)
    if idx.size == 0:
        return
    lines = toolpath.source_line[idx]

    def label(k: int) -> str:
        return f"{toolpath.source}:{int(lines[k])}"

    feed_mm_min = toolpath.feed[idx] / MM_PER_MIN
    check_feed_limit(feed_mm_min, label, _limits(machine), error=ProgramError)
    if not cuts:
        return
    spin = np.where(toolpath.spindle_dir != 0, toolpath.spindle_speed, 0.0)
    nz = np.flatnonzero(spin)
    if nz.size:
        spin[: nz[0]] = spin[nz[0]]
    max_rpm = None
    if machine is not None and machine.spindle is not None:
        max_rpm = machine.spindle.max_rpm
    check_cutting_moves(
        feed_mm_min,
        spin[idx] / RPM,
        flutes,
        diameter_mm,
        label,
        findings,
        max_rpm=max_rpm,
        error=ProgramError,
    )


def check_plan(
    plan: VirtualPlan,
    findings: Findings,
    *,
    machine: MachineConfig | None = None,
    stickout_mm: float | None = None,
) -> None:
    """The rows of a plan that cut: axial depth against the tool, feed per tooth, the
    spindle against the machine, and the predicted peak force and power against its limits."""
    meta = plan.metadata
    where = str(meta.get("program", "plan"))
    tool = meta.get("tool", {})
    diameter = float(tool.get("diameter_mm", 0.0))
    flutes = int(tool.get("flutes", 1))
    _check_rapids_in_material(plan, where, findings)
    cut = np.asarray(plan["in_cut"], dtype=bool) & ~np.asarray(plan["rapid"], dtype=bool)
    idx = np.flatnonzero(cut)
    if idx.size == 0:
        return
    src = np.asarray(plan["source_line"])[idx]

    def label(k: int) -> str:
        return f"{where}:{int(src[k])}"

    depth = np.asarray(plan["axial_depth_mm"])[idx]
    k = int(np.argmax(depth))
    if diameter > 0:
        check_depth(
            float(depth[k]),
            diameter,
            label(k),
            findings,
            stickout_mm=stickout_mm,
            error=ProgramError,
        )
    max_rpm = None
    if machine is not None and machine.spindle is not None:
        max_rpm = machine.spindle.max_rpm
    check_cutting_moves(
        np.asarray(plan["feed_mm_min"])[idx],
        np.asarray(plan["spindle_rpm"])[idx],
        flutes,
        diameter,
        label,
        findings,
        max_rpm=max_rpm,
        error=ProgramError,
    )
    force = np.asarray(plan["fres_peak_n"])[idx]
    power = np.asarray(plan["power_w"])[idx]
    kf = int(np.argmax(force))
    kp = int(np.argmax(power))
    check_against_limits(_limits(machine), label(kf), findings, peak_force_n=float(force[kf]))
    check_against_limits(_limits(machine), label(kp), findings, power_w=float(power[kp]))


def _check_rapids_in_material(plan: VirtualPlan, where: str, findings: Findings) -> None:
    """A rapid (G0) whose steps the plan finds in material: on a machine a collision (the tool
    meets the stock at the rapid rate), in the plan steps without predicted forces. A warning
    naming the program's lines (it was a note of the plan before; found by exploratory QA)."""
    rapid_in_cut = np.asarray(plan["in_cut"], dtype=bool) & np.asarray(plan["rapid"], dtype=bool)
    if not rapid_in_cut.any():
        return
    src = np.asarray(plan["source_line"])[rapid_in_cut]
    lines = sorted({int(v) for v in src})
    shown = ", ".join(str(v) for v in lines[:10]) + (" ..." if len(lines) > 10 else "")
    findings.warn(
        f"{where}:{lines[0]}: a rapid (G0) moves through material ({int(rapid_in_cut.sum())} "
        f"steps, line(s) {shown}): a collision on a machine; no forces are predicted there"
    )
