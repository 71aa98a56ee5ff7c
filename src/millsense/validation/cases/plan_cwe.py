"""Validation cases of :mod:`millsense.plan` engagement (z-map CWE) — issue 4 acceptance.

Set-up shared by the cases: a block from z = 0 to 20 mm on a 0.1 mm grid, a straight
2-flute Ø20 mm flat end mill (seed 000's tool without helix), 0.4 mm path steps along +x,
0.5° angle bins. Angle tolerances follow :mod:`millsense.plan.cwe`: one bin plus
1.5 h/(R |sin φ|) at a boundary crossing the periphery at φ.
"""

from __future__ import annotations

import math

import numpy as np

from millsense.plan.cwe import EngagementResult, compute_engagement
from millsense.plan.stock import ZMapStock
from millsense.process.closed_forms import slot_average_forces
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.validation import Measured, case

_H = 1e-4
_R = 10e-3
_TOP = 0.02
_TOOL = EndMill(2 * _R, 2)
_BIN_DEG = 0.5


def _tol_deg(phi_deg: float) -> float:
    return _BIN_DEG + math.degrees(1.5 * _H / (_R * abs(math.sin(math.radians(phi_deg)))))


def _block(lx: float = 0.06, ly: float = 0.04) -> ZMapStock:
    return ZMapStock.from_box((0.0, 0.0, 0.0), (lx, ly, _TOP), _H)


def _cut_x(
    stock: ZMapStock,
    y: float,
    z: float,
    x0: float = -0.015,
    x1: float = 0.045,
    tool: EndMill = _TOOL,
    step: float = 0.4e-3,
) -> tuple[np.ndarray, EngagementResult]:
    x = np.arange(x0, x1 + 1e-12, step)
    res = compute_engagement(stock, tool, x, np.full(x.size, y), np.full(x.size, z))
    return x, res


def _degrees_table(res: EngagementResult, k: int) -> str:
    rows = [
        f"| {i} | "
        + ", ".join(f"[{math.degrees(a):.2f}°, {math.degrees(b):.2f}°]" for a, b in iv)
        + " |"
        for i, iv in enumerate(res.intervals(k))
    ]
    return "| layer | intervals |\n|---|---|\n" + "\n".join(rows)


@case(
    "plan.cwe_slot_interval_error",
    source="issue 4 acceptance (straight slot 0°→180°)",
    reference=0.0,
    unit="°",
    abs_tol=1e-4,
    description="Largest |entry − 0°|, |exit − 180°| over the 10 layers of a 2 mm deep "
    "first-pass slot (0.1 mm z-map)",
)
def _slot() -> Measured:
    x, res = _cut_x(_block(), 0.02, _TOP - 2e-3)
    k = int(np.argmin(np.abs(x - 0.03)))
    err = 0.0
    for layer in res.intervals(k):
        if len(layer) != 1:
            return Measured(float("inf"), _degrees_table(res, k))
        a, b = layer[0]
        err = max(err, abs(math.degrees(a)), abs(math.degrees(b) - 180.0))
    return Measured(err, _degrees_table(res, k))


def _entry_exit(y_centre: float, which: int) -> Measured:
    x, res = _cut_x(_block(), y_centre, _TOP - 3e-3)
    k = int(np.argmin(np.abs(x - 0.03)))
    vals = {iv[0][which] for iv in res.intervals(k) if len(iv) == 1}
    if len(vals) != 1 or any(len(iv) != 1 for iv in res.intervals(k)):
        return Measured(float("nan"), _degrees_table(res, k))
    return Measured(math.degrees(vals.pop()), _degrees_table(res, k))


@case(
    "plan.cwe_half_immersion_down_entry",
    source="benchmarks.md §1: down milling enters at arccos(2 a_e/D − 1) = 90° for a_e = R",
    reference=90.0,
    unit="°",
    abs_tol=_tol_deg(90.0),
    description="Entry angle, half-immersion down milling on the z-map (exit is 180°)",
)
def _half_down() -> Measured:
    return _entry_exit(0.04, 0)


@case(
    "plan.cwe_half_immersion_up_exit",
    source="benchmarks.md §1: up milling exits at arccos(1 − 2 a_e/D) = 90° for a_e = R",
    reference=90.0,
    unit="°",
    abs_tol=_tol_deg(90.0),
    description="Exit angle, half-immersion up milling on the z-map (entry is 0°)",
)
def _half_up() -> Measured:
    return _entry_exit(0.0, 1)


@case(
    "plan.cwe_quarter_immersion_down_entry",
    source="benchmarks.md §1: arccos(2·¼ − 1) = 120° for a_e = D/4",
    reference=120.0,
    unit="°",
    abs_tol=_tol_deg(120.0),
    description="Entry angle, quarter-immersion down milling on the z-map",
)
def _quarter_down() -> Measured:
    return _entry_exit(0.045, 0)


@case(
    "plan.cwe_ball_axial_depth",
    source="issue 4 acceptance (ball end mill at known depth)",
    reference=3.0,
    unit="mm",
    abs_tol=1e-5,
    description="Engaged height of a Ø10 ball end mill slotting 3 mm deep (all layers "
    "φ ∈ [0, 180°] required, else NaN)",
)
def _ball() -> Measured:
    ball = EndMill(10e-3, 2, shape="ball")
    x, res = _cut_x(_block(), 0.02, _TOP - 3e-3, tool=ball)
    k = int(np.argmin(np.abs(x - 0.03)))
    ok = all(
        len(iv) == 1 and abs(iv[0][0]) < 1e-6 and abs(iv[0][1] - math.pi) < 1e-6
        for iv in res.intervals(k)
    )
    radii = ", ".join(f"{r * 1e3:.3f}" for r in res.layer_radii_m(k))
    details = _degrees_table(res, k) + f"\n\nLayer radii [mm]: {radii}"
    return Measured(float(res.axial_depth_m[k]) * 1e3 if ok else float("nan"), details)


@case(
    "plan.cwe_second_pass_steps_in_cut",
    source="issue 4 acceptance (second pass over already-cut material)",
    reference=0.0,
    unit="steps",
    abs_tol=0.0,
    description="Steps in cut when a slot is run again at the same depth (inside the first)",
)
def _second_pass() -> float:
    stock = _block()
    _cut_x(stock, 0.02, _TOP - 2e-3, x1=0.06)
    _, res = _cut_x(stock, 0.02, _TOP - 2e-3, x1=0.04)
    return float(res.in_cut.sum())


@case(
    "plan.cwe_depth_step_position",
    source="issue 4 acceptance (a step in depth within one grid cell)",
    reference=0.0,
    unit="mm",
    abs_tol=0.1,
    description="|x + R − X_s| at the first step cutting 6 mm instead of 3 mm, material top "
    "rising 3 mm at X_s = 30 mm (0.05 mm path steps)",
)
def _depth_step() -> float:
    stock = _block()
    stock.heights[:, 300:] = np.float32(_TOP + 3e-3)
    x, res = _cut_x(stock, 0.02, _TOP - 3e-3, x1=0.025, step=0.05e-3)
    deep = np.flatnonzero(res.axial_depth_m > 4.5e-3)
    if deep.size == 0:
        return float("inf")
    return abs(float(x[deep[0]]) + _R - 0.03) * 1e3


@case(
    "plan.cwe_slot_crossing_exit",
    source="issue 4 (tool crossing a slot: two intervals); R sin φ = R/2 at 1.5 R before it",
    reference=30.0,
    unit="°",
    abs_tol=_tol_deg(30.0),
    description="Exit of the first of two intervals, centre 15 mm before a Ø20 slot "
    "(NaN unless every layer has two intervals)",
)
def _crossing() -> Measured:
    stock = _block(0.06, 0.06)
    ys = np.arange(-0.015, 0.075, 0.4e-3)
    compute_engagement(stock, _TOOL, np.full(ys.size, 0.03), ys, np.full(ys.size, _TOP - 3e-3))
    x, res = _cut_x(stock, 0.03, _TOP - 3e-3, x1=0.03)
    k = int(np.argmin(np.abs(x - 0.015)))
    exits = {iv[0][1] for iv in res.intervals(k) if len(iv) == 2}
    if len(exits) != 1 or any(len(iv) != 2 for iv in res.intervals(k)):
        return Measured(float("nan"), _degrees_table(res, k))
    return Measured(math.degrees(exits.pop()), _degrees_table(res, k))


@case(
    "plan.aslan_v9_cwe_slot",
    source="seed 000 V9 (Aslan Fig. 6.4): F_res = K_tc c Gain_CWE = 758 × 0.2 × 0.976",
    reference=147.96,
    unit="N",
    rel_tol=1e-3,
    description="Peak resultant of the sliced model on the z-map engagement of a slot step "
    "with Gain_CWE = 0.976 mm (K_tc = 758 N/mm², K_rc = 0.5 K_tc, c = 0.2 mm)",
)
def _v9() -> Measured:
    depth = 0.976e-3 / math.sqrt(1.25)  # docs/decisions/0015-aslan-v9-shape-check.md
    x, res = _cut_x(_block(), 0.02, _TOP - depth)
    k = int(np.argmin(np.abs(x - 0.03)))
    ktc = 758e6
    f = milling_forces(
        _TOOL,
        CuttingCoefficients(ktc, 0.5 * ktc),
        res.engagement(k),
        0.2e-3,
        float(res.axial_depth_m[k]),
        np.arange(720) * math.pi / 360,
        20,
    )
    peak = float(f.resultant_n().max())
    closed = ktc * 0.2e-3 * float(res.gain_cwe_m[k])
    return Measured(
        peak,
        f"Gain_CWE = {res.gain_cwe_mm[k]:.5f} mm; K_tc c Gain_CWE = {closed:.3f} N; "
        f"sliced peak = {peak:.3f} N",
    )


@case(
    "plan.cwe_slot_average_force",
    source="benchmarks.md §3 (closed-form slot averages)",
    reference=0.0,
    unit="%",
    abs_tol=1.0,
    description="Largest relative error of the mean F_x, F_y of the sliced model on a z-map "
    "slot engagement (Ø20, 2 flutes, 30° helix, a = 3 mm, c = 0.2 mm, Al7050 preset "
    "coefficients) against the closed forms",
)
def _slot_average() -> Measured:
    tool = EndMill(2 * _R, 2, helix_rad=math.radians(30.0))
    x, res = _cut_x(_block(), 0.02, _TOP - 3e-3, tool=tool)
    k = int(np.argmin(np.abs(x - 0.03)))
    coeffs = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    phi = np.linspace(0.0, 2 * math.pi, 7200, endpoint=False)
    f = milling_forces(
        tool, coeffs, res.engagement(k), 0.2e-3, float(res.axial_depth_m[k]), phi, 200
    )
    ref = slot_average_forces(2, 3e-3, 0.2e-3, coeffs)
    got = f.average()[:2]
    errs = [abs(g - float(r)) / abs(float(r)) * 100 for g, r in zip(got, ref[:2], strict=True)]
    rows = "\n".join(
        f"| {ax} | {float(r):.3f} | {g:.3f} | {e:.2e} |"
        for ax, r, g, e in zip("xy", ref[:2], got, errs, strict=True)
    )
    return Measured(
        max(errs),
        "| axis | closed form [N] | z-map + sliced [N] | error [%] |\n|---|---|---|---|\n" + rows,
    )
