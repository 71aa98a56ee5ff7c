"""Validation cases of the virtual plan (issue 4 items 5–7 acceptance).

Set-up: a block z ∈ [0, 20] mm on a 0.1 mm grid, 0.4 mm path steps along +x, slotting at
y = 20 mm; the figures are read at x = 30 mm (steady). Predictions come from
:func:`millsense.plan.predict.predict_states` (signature grouping, machine frame).
"""

from __future__ import annotations

import math

import numpy as np

from millsense.plan.cwe import compute_engagement
from millsense.plan.predict import ProcessPrediction, predict_states
from millsense.plan.stock import ZMapStock
from millsense.process.closed_forms import slot_average_forces
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.validation import Measured, case

_TOP = 0.02
_FEED = 400.0 / 60e3  # m/s, seed 000: 400 mm/min
_OMEGA = 1000.0 * 2 * math.pi / 60  # rad/s, 1000 rev/min → c = 0.2 mm/tooth with 2 flutes


def _slot(
    tool: EndMill, depth: float, coeffs: CuttingCoefficients
) -> tuple[int, ProcessPrediction]:
    stock = ZMapStock.from_box((0.0, 0.0, 0.0), (0.06, 0.04, _TOP), 1e-4)
    x = np.arange(-0.015, 0.045, 0.4e-3)
    n = x.size
    eng = compute_engagement(stock, tool, x, np.full(n, 0.02), np.full(n, _TOP - depth))
    pred = predict_states(eng, coeffs, np.full(n, _FEED), np.full(n, _OMEGA))
    return int(np.argmin(np.abs(x - 0.03))), pred


def _v9(gain_mm: float) -> Measured:
    tool = EndMill(20e-3, 2)
    ktc = 758e6
    k, pred = _slot(tool, gain_mm * 1e-3 / math.sqrt(1.25), CuttingCoefficients(ktc, 0.5 * ktc))
    peak = float(pred.stats["fres_peak"][k])
    return Measured(
        peak,
        f"chip load {pred.chip_load_m[k] * 1e3:.4f} mm/tooth; predicted peak F_res "
        f"{peak:.3f} N; K_tc c Gain_CWE = 758 × 0.2 × {gain_mm} = {758 * 0.2 * gain_mm:.3f} N",
    )


@case(
    "plan.plan_aslan_v9_slot",
    source="seed 000 V9 (Aslan Fig. 6.4): F_res = K_tc c Gain_CWE = 758 × 0.2 × 0.976",
    reference=147.96,
    unit="N",
    rel_tol=1e-3,
    quick=True,
    description="Plan prediction (peak XY resultant) of a slot step, c = 0.2 mm/tooth from "
    "400 mm/min at 1000 rev/min, K_tc = 758 N/mm², K_rc = 0.5 K_tc, straight 2-flute Ø20",
)
def _v9_shallow() -> Measured:
    return _v9(0.976)


@case(
    "plan.plan_aslan_v9_deep_slot",
    source="seed 000 V9 (Aslan Fig. 6.4): 758 × 0.2 × 2.498 = 378.7 N (deeper step)",
    reference=378.7,
    unit="N",
    rel_tol=1e-3,
    quick=True,
    description="As virtual.plan_aslan_v9_slot for the deeper step, Gain_CWE = 2.498 mm",
)
def _v9_deep() -> Measured:
    return _v9(2.498)


@case(
    "plan.plan_slot_average_force",
    source="benchmarks.md §3 (closed-form slot averages)",
    reference=0.0,
    unit="%",
    abs_tol=1.0,
    quick=True,
    description="Largest relative error of the plan's mean F_X, F_Y in a steady slot (Ø20, "
    "2 flutes, 30° helix, a = 3 mm, c = 0.2 mm, Al7050 preset coefficients) against the "
    "closed forms",
)
def _slot_average() -> Measured:
    coeffs = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30.0))
    k, pred = _slot(tool, 3e-3, coeffs)
    ref = slot_average_forces(2, 3e-3, 0.2e-3, coeffs)
    got = (float(pred.stats["fx_avg"][k]), float(pred.stats["fy_avg"][k]))
    errs = [abs(g - float(r)) / abs(float(r)) * 100 for g, r in zip(got, ref[:2], strict=True)]
    rows = "\n".join(
        f"| {ax} | {float(r):.3f} | {g:.3f} | {e:.2e} |"
        for ax, r, g, e in zip("XY", ref[:2], got, errs, strict=True)
    )
    return Measured(
        max(errs), "| axis | closed form [N] | plan [N] | error [%] |\n|---|---|---|---|\n" + rows
    )
