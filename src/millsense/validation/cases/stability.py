"""Validation cases of :mod:`millsense.stability` (benchmarks.md §1–§3)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.optimize

from millsense.stability.lobes import LobeResult, critical_depth, sdm_lobes
from millsense.stability.milling import DepthFamily, immersion_angles, milling_dde, turning_dde
from millsense.stability.modal import ModalModel, Mode, OrientedMode, oriented_frf
from millsense.stability.sdm import fixed_point, step_means_from_callables
from millsense.stability.zoa import (
    directional_factors,
    orthogonal_curves,
    tlusty_limit,
    zoa_milling_curves,
)
from millsense.validation import Measured, case

# Insperger, Mann, Stépán & Bayly (2003), benchmarks.md §1
KT, KN, FLUTES = 6e8, 2e8, 2
FN, ZETA, MASS = 922.0, 0.011, 0.03993
INSPERGER = ModalModel(x=(Mode.from_stiffness(FN, ZETA, MASS * (2 * math.pi * FN) ** 2),))


def insperger_family(ratio: float, mode: str = "down") -> Callable[[float, int], DepthFamily]:
    """``(rpm, m) -> DepthFamily`` of the Insperger 1-DOF benchmark at radial immersion a/D."""
    st, ex = immersion_angles(ratio, 1.0, mode)

    def fam(n: float, m: int) -> DepthFamily:
        return milling_dde(INSPERGER, FLUTES, KT, KN, st, ex, n, m)

    return fam


def insperger_compliance(f: np.ndarray) -> np.ndarray:
    return np.asarray(np.abs(INSPERGER.frf(f)).max(axis=(-2, -1)))


def insperger_lobes(
    ratio: float, rpm: np.ndarray, m: int = 20, extrapolate: bool = True
) -> LobeResult:
    """SDM lobes of the Insperger benchmark (Richardson from m and 2m by default)."""
    return sdm_lobes(
        insperger_family(ratio), rpm, insperger_compliance, 2 * FN, m, extrapolate=extrapolate
    )


def depth_at(fam: Callable[[float, int], DepthFamily], rpm: float, m: int, start: float) -> float:
    """Critical depth [m] at one speed and m steps per period."""
    return critical_depth(fam(rpm, m), start, 0.05, growth=1.05).depth


def converged_depth(fam: Callable[[float, int], DepthFamily], rpm: float, start: float) -> float:
    """Richardson extrapolation from m = 100 and 200 (O(m⁻²), benchmarks.md §1)."""
    w1 = depth_at(fam, rpm, 100, start)
    w2 = depth_at(fam, rpm, 200, 0.99 * w1)
    return w2 + (w2 - w1) / 3.0


def refine_minima(ratio: float, n_minima: int) -> list[tuple[float, float]]:
    """Lobe minima (rpm, depth [m]) of a coarse diagram refined with converged depths."""
    rpm = np.arange(5000.0, 25001.0, 100.0)
    coarse = insperger_lobes(ratio, rpm)
    d = coarse.critical_depth_m
    local = [i for i in range(1, len(d) - 1) if d[i] <= d[i - 1] and d[i] <= d[i + 1]]
    local = sorted(local, key=lambda i: d[i])[:n_minima]
    fam = insperger_family(ratio)
    out = []
    for i in local:
        res = scipy.optimize.minimize_scalar(
            lambda n, i=i: converged_depth(fam, float(n), 0.97 * float(d[i])),
            bounds=(rpm[i] - 100.0, rpm[i] + 100.0),
            method="bounded",
            options={"xatol": 2.0},
        )
        out.append((float(res.x), float(res.fun)))
    return sorted(out, key=lambda t: t[1])


def _minima_table(minima: list[tuple[float, float]]) -> str:
    rows = ["| lobe minimum speed [rev/min] | converged critical depth [mm] |", "|---|---|"]
    rows += [f"| {n:.0f} | {w * 1e3:.4f} |" for n, w in minima]
    return "\n".join(rows)


@case(
    "stability.insperger.slot_min_depth",
    source="benchmarks.md §1 (Insperger et al. 2003)",
    reference=0.3159,
    unit="mm",
    rel_tol=0.015,
    quick=False,
    description="1-DOF slotting, minimum SDM critical depth over 5000-25000 rev/min (lobe "
    "minima of a 20/40-step diagram refined with depths extrapolated from 100/200 steps)",
)
def _slot_min() -> Measured:
    minima = refine_minima(1.0, 4)
    return Measured(minima[0][1] * 1e3, _minima_table(minima))


@case(
    "stability.insperger.slot_15870",
    source="benchmarks.md §1 (Insperger et al. 2003)",
    reference=0.3174,
    unit="mm",
    rel_tol=0.015,
    quick=True,
    description="1-DOF slotting critical depth at 15870 rev/min: convergence study in the "
    "steps per period and Richardson extrapolation",
)
def _slot_15870() -> Measured:
    fam = insperger_family(1.0)
    ms = (20, 40, 100, 200, 400)
    ws = {m: depth_at(fam, 15870.0, m, 3.0e-4) for m in ms}
    ext = ws[200] + (ws[200] - ws[100]) / 3.0
    ext2 = ws[400] + (ws[400] - ws[200]) / 3.0
    rows = [
        "| steps per period m | critical depth [mm] | vs reference 0.3174 mm |",
        "|---|---|---|",
    ]
    for m in ms:
        rows.append(f"| {m} | {ws[m] * 1e3:.5f} | {(ws[m] * 1e3 / 0.3174 - 1) * 100:+.2f} % |")
    for label, v in (
        ("Richardson 20/40", ws[40] + (ws[40] - ws[20]) / 3.0),
        ("Richardson 100/200", ext),
        ("Richardson 200/400", ext2),
    ):
        rows.append(f"| {label} | {v * 1e3:.5f} | {(v * 1e3 / 0.3174 - 1) * 100:+.2f} % |")
    return Measured(ext * 1e3, "\n".join(rows))


@case(
    "stability.insperger.slot_zoa",
    source="benchmarks.md §1: 2kζ(1+ζ)/h̄, h̄ = N K_n/4",
    reference=0.2981,
    unit="mm",
    rel_tol=0.005,
    quick=True,
    description="1-DOF slotting, ZOA minimum critical depth over 5000-25000 rev/min",
)
def _slot_zoa() -> float:
    curves = zoa_milling_curves(INSPERGER, FLUTES, KT, KN, 0.0, math.pi, 5000.0)
    return curves.min_depth(5000.0, 25000.0)[0] * 1e3


@case(
    "stability.insperger.half_down_min_depth",
    source="benchmarks.md §1 (Insperger et al. 2003)",
    reference=0.5995,
    unit="mm",
    rel_tol=0.015,
    quick=False,
    description="1-DOF half immersion down milling, minimum SDM critical depth",
)
def _half_min() -> Measured:
    minima = refine_minima(0.5, 2)
    return Measured(minima[0][1] * 1e3, _minima_table(minima))


@case(
    "stability.insperger.half_down_min_rpm",
    source="benchmarks.md §1 (Insperger et al. 2003)",
    reference=21727.0,
    unit="rev/min",
    rel_tol=0.005,
    quick=False,
    description="1-DOF half immersion down milling, speed of the minimum critical depth",
)
def _half_rpm() -> float:
    return refine_minima(0.5, 1)[0][0]


def _hayes() -> tuple[float, float]:
    from millsense.stability.sdm import analyse

    sm = step_means_from_callables(
        np.array([[-1.0]]), [np.array([[-1.0]])], [1.0], 0.1, 1, c=np.array([1.0])
    )
    return analyse(sm).spectral_radius, float(np.max(np.abs(fixed_point(sm) - 0.5)))


@case(
    "stability.sdm.hayes_spectral_radius",
    source="benchmarks.md §2 (SemiDiscretizationMethod.jl)",
    reference=0.941189374166563,
    unit="-",
    abs_tol=1e-9,
    description="Hayes equation x' = -x - x(t-1) + 1, first-order SDM, one step of 0.1",
)
def _hayes_rho() -> float:
    return _hayes()[0]


@case(
    "stability.sdm.hayes_fixed_point",
    source="benchmarks.md §2: x* = 1/(1 - a - b) = 0.5",
    reference=0.5,
    unit="-",
    abs_tol=1e-9,
    description="Hayes equation periodic fixed point (largest node deviation added to 0.5)",
)
def _hayes_fp() -> float:
    return 0.5 + _hayes()[1]


@case(
    "stability.sdm.mathieu_spectral_radius",
    source="benchmarks.md §2 (SemiDiscretizationMethod.jl)",
    reference=0.5131596340374617,
    unit="-",
    abs_tol=1e-9,
    description="Delayed Mathieu equation, first-order SDM, 628 steps of 0.01",
)
def _mathieu() -> float:
    from millsense.stability.sdm import analyse

    d, e, b0, a1 = 3.0, 2.0, -0.15, 0.1
    sm = step_means_from_callables(
        lambda t: np.array([[0.0, 1.0], [-(d + e * math.cos(t)), -a1]]),
        [np.array([[0.0, 0.0], [b0, 0.0]])],
        [2 * math.pi],
        0.01,
        628,
        c=lambda t: np.array([0.0, math.sin(2 * t)]),
    )
    return analyse(sm).spectral_radius


@case(
    "stability.zoa.directional_factors_slot",
    source="benchmarks.md §3 (Altintas & Budak 1995), check values (−0.666, −π, π, −0.666)",
    reference=0.0,
    unit="-",
    abs_tol=6e-4,
    description="largest deviation of the slotting directional factors (k_r = 0.212) from the "
    "check values printed to 3 decimals",
)
def _alpha_slot() -> float:
    ref = np.array([[-0.666, -math.pi], [math.pi, -0.666]])
    return float(np.max(np.abs(directional_factors(0.0, math.pi, 0.212) - ref)))


@case(
    "stability.zoa.directional_factors_half_down",
    source="benchmarks.md §3, check values (0.667, −1.359, 1.783, −1.333)",
    reference=0.0,
    unit="-",
    abs_tol=6e-4,
    description="largest deviation of the half-immersion down-milling directional factors "
    "(90°→180°, k_r = 0.212) from the check values printed to 3 decimals",
)
def _alpha_half() -> float:
    ref = np.array([[0.667, -1.359], [1.783, -1.333]])
    return float(np.max(np.abs(directional_factors(math.pi / 2, math.pi, 0.212) - ref)))


def _two_mode() -> list[OrientedMode]:
    return [
        OrientedMode(Mode.from_stiffness(250.0, 0.012, 2.26e8), math.radians(30.0)),
        OrientedMode(Mode.from_stiffness(150.0, 0.010, 2.13e8), math.radians(-45.0)),
    ]


@case(
    "stability.zoa.orthogonal_2mode",
    source="benchmarks.md §3 (Altintas, Manufacturing Automation)",
    reference=7.19,
    unit="mm",
    rel_tol=0.01,
    description="2-mode orthogonal cutting, Tlusty absolute limit −1/(2 K_f min Re Φ)",
)
def _orth() -> float:
    f = np.linspace(50.0, 600.0, 110001)
    return tlusty_limit(oriented_frf(_two_mode(), f), f, 1e9)[0] * 1e3


@case(
    "stability.zoa.orthogonal_2mode_frequency",
    source="benchmarks.md §3 (Altintas, Manufacturing Automation)",
    reference=253.0,
    unit="Hz",
    rel_tol=0.01,
    description="2-mode orthogonal cutting, chatter frequency at the absolute limit",
)
def _orth_f() -> float:
    f = np.linspace(50.0, 600.0, 110001)
    return tlusty_limit(oriented_frf(_two_mode(), f), f, 1e9)[1]


@case(
    "stability.sdm.turning_2mode",
    source="benchmarks.md §3: 7.19 mm (Tlusty closed form, exact for constant coefficients)",
    reference=7.19,
    unit="mm",
    rel_tol=0.01,
    description="2-mode turning as a DDE solved by the general SDM (200 steps per revolution) "
    "at the speed of the deepest lobe bottom",
)
def _turning_sdm() -> float:
    f = np.linspace(50.0, 600.0, 20001)
    G = oriented_frf(_two_mode(), f)
    _, n = orthogonal_curves(G, f, 1e9, 1000.0).min_depth(1000.0, 20000.0)
    fam = turning_dde(_two_mode(), 1e9, n, 200)
    return critical_depth(fam, 5e-3, 1.0).depth * 1e3


def low_immersion_flip_check() -> tuple[float, float, float]:
    """At a/D = 0.05 down milling: (rpm, SDM depth, ZOA depth) at the deepest flip point.

    The SDM lobes (20/40 steps, extrapolated) over 5000-25000 rev/min are searched for speeds
    where the critical multiplier is real and negative (period doubling); ZOA's depth there is
    returned for comparison.
    """
    rpm = np.arange(5000.0, 25001.0, 100.0)
    ratio = 0.05
    res = sdm_lobes(
        insperger_family(ratio),
        rpm,
        insperger_compliance,
        2 * FN,
        20,
        depth_max=0.1,
        extrapolate=True,
    )
    flip = np.array([b == "flip" for b in res.bifurcation])
    if not flip.any():
        return math.nan, math.nan, math.nan
    st, ex = immersion_angles(ratio, 1.0, "down")
    zoa = zoa_milling_curves(INSPERGER, FLUTES, KT, KN, st, ex, 5000.0).at_speeds(rpm[flip])
    i = int(np.argmin(res.critical_depth_m[flip]))
    return float(rpm[flip][i]), float(res.critical_depth_m[flip][i]), float(zoa.critical_depth_m[i])


@case(
    "stability.low_immersion.flip_missed_by_zoa",
    source="benchmarks.md §1 (Insperger et al. 2003; Merdol & Altintas 2004)",
    reference=1.0,
    unit="-",
    abs_tol=0.0,
    quick=True,
    description="a/D = 0.05 down milling: 1 if SDM finds a period-doubling lobe at a speed where "
    "ZOA predicts stability at 1.2× the SDM critical depth, else 0",
)
def _flip() -> Measured:
    n, w_sdm, w_zoa = low_immersion_flip_check()
    ok = math.isfinite(w_sdm) and w_zoa > 1.2 * w_sdm
    details = (
        f"Deepest flip point: {n:.0f} rev/min, SDM critical depth {w_sdm * 1e3:.3f} mm "
        f"(period doubling), ZOA critical depth {w_zoa * 1e3:.3f} mm."
    )
    return Measured(1.0 if ok else 0.0, details)
