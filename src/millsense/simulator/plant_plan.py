"""The virtual machine's own plan of a program (decisions 1730, 1740).

An acceptance case whose plant cuts with the very plan object the controller or monitor uses
as its expectation shares the engagement, the tool (without runout) and the coefficients with
it, so "no false alarm" or "within ±5 % of the reference" is close to guaranteed. The plant's
plan is therefore its own: the same program(s), raw stock, tool geometry and material, but
planned on a finer z-map (:data:`PLANT_CELL_M`) by a tool carrying a radial runout
(:data:`PLANT_RUNOUT_M` at :data:`PLANT_RUNOUT_ANGLE_RAD`) the controller's and monitor's plan
does not know. The simulator reads this plan's engagement rows
(:func:`~millsense.simulator.plan_job.plan_job`); what the truth's process then adds (tool
dynamics, edge forces, wear, the truth spindle) is the simulator's as always.

What plant and controller/monitor share: the program, the raw stock and the tool's nameplate
geometry. What they do not share: the z-map cut of the stock (so the engagement rows), the
runout, the material's true coefficients (the nominal ones the caller gives × the lot's
factors :data:`PLANT_LOT_FACTORS`, decisions 1760 and 1798) and everything the truth's process
adds.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import Toolpath, VirtualPlan
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

#: z-map cell of the virtual machine's plan, m (the controller's and monitor's plans use
#: 0.1-0.5 mm).
PLANT_CELL_M = 0.05e-3
#: Radial runout of the virtual machine's tool (offset of the cutter axis, m) and its angle
#: (rad, :class:`~millsense.process.geometry.EndMill`): the seed 000 V7 value (decision 1730).
PLANT_RUNOUT_M = 5e-6
PLANT_RUNOUT_ANGLE_RAD = 0.4
#: The virtual machine's true cutting coefficients against the material preset every plan of a
#: controller or monitor uses (decisions 1760, 1798), chosen once before any comparison and
#: never fitted. The plate and the tools' grind are not the ones the preset was identified
#: with: K_tc +6 % (a plate of higher flow stress: the strength of 7050-T7451 plate falls with
#: thickness by about 10 %), K_rc −8 % (a rake ground about 2° larger than nominal lowers the
#: radial over tangential ratio), K_te +15 % and K_re +10 % (a larger edge hone radius: the
#: ploughing forces grow with it, by about the same 3.5–3.8 N/mm in both directions on the
#: preset's 25 and 35 N/mm).
PLANT_LOT_FACTORS: Mapping[str, float] = {"ktc": 1.06, "krc": 0.92, "kte": 1.15, "kre": 1.10}


def lot_coefficients(
    coeffs: CuttingCoefficients, factors: Mapping[str, float] = PLANT_LOT_FACTORS
) -> CuttingCoefficients:
    """The plant's true coefficients: ``coeffs`` (the nominal ones) × ``factors``."""
    return dataclasses.replace(coeffs, **{k: getattr(coeffs, k) * f for k, f in factors.items()})


def plant_plan(
    programs: Sequence[Toolpath],
    stock: Callable[[float], ZMapStock],
    tool: EndMill,
    coeffs: CuttingCoefficients,
    *,
    cell_m: float = PLANT_CELL_M,
    runout_m: float = PLANT_RUNOUT_M,
    runout_angle_rad: float = PLANT_RUNOUT_ANGLE_RAD,
    lot_factors: Mapping[str, float] = PLANT_LOT_FACTORS,
    metadata: Mapping[str, Any] | None = None,
    **plan_options: Any,
) -> VirtualPlan:
    """The virtual machine's own plan of the last of ``programs``.

    ``programs`` are planned in turn on the raw stock ``stock(cell_m)`` (a z-map of cell
    ``cell_m``, m; the earlier programs shape the stock the last one cuts) by ``tool`` with a
    radial runout of ``runout_m`` (m) at ``runout_angle_rad`` (rad) with the true coefficients
    ``coeffs`` × ``lot_factors`` (``coeffs``: the nominal ones the controller's or monitor's
    plan uses); the plan of the last program is returned. ``metadata`` and ``plan_options``
    (e.g. ``step_m``) go to :func:`~millsense.plan.virtual_plan.plan_program` of every
    program (the metadata to the last one only)."""
    from millsense.plan.virtual_plan import plan_program

    if not programs:
        raise ValueError("plant_plan needs at least one program")
    cutter = dataclasses.replace(tool, runout_offset_m=runout_m, runout_angle_rad=runout_angle_rad)
    true = lot_coefficients(coeffs, lot_factors)
    raw = stock(cell_m)
    for prog in programs[:-1]:
        plan_program(prog, raw, cutter, true, **plan_options)
    return plan_program(programs[-1], raw, cutter, true, metadata=metadata, **plan_options)
