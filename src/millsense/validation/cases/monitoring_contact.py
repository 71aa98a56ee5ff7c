"""Acceptance of contact detection and the rotational centre (seed 004 ch. 3, digest §4.2).

Simulated turning contact (digest §6 "Turning contact", Table 3.1 conditions): C axis at
24 min⁻¹ (T = 2.5 s), 100 kHz, torque command = a repeatable angle-dependent ripple (bearing
and cogging harmonics, the same in the air cut and the cut motion thanks to the C-axis
re-initialisation) + white noise (independent in each motion) + the contact torque, which rises
nonlinearly with the penetration p (∝ p^1.5, a 0.8 mm nose entering the surface; 2 N·m at the
0.1 mm maximum depth). X approaches at 244.8 mm/min from 5 mm above the surface after 5
preliminary revolutions; the encoder position carries 0.1 µm noise. Only the window from the
reference revolution to the end of the approach is generated (what the detector reads).

Table 3.2: the five printed contact points (relative to the pre-machining point) are fitted.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from millsense.validation import Measured, case

FS = 100_000.0
PERIOD_S = 60.0 / 24.0
V_X_MM_S = 244.8 / 60.0
RIPPLE_NM = ((1, 0.08), (3, 0.03), (36, 0.02))
NOISE_NM = 0.01
K_CONTACT = 2.0 / 0.1**1.5  # N·m per mm^1.5
#: Table 3.2 contact points (x, y) mm relative to p₁, and the printed results.
TABLE_3_2 = ((0.0, 0.0), (-0.205, 5.0), (-1.088, -7.0), (-3.979, -14.0), (-8.391, -20.0))
CENTRE_3_2 = (-30.972, 1.235)
DIAMETER_3_2 = 61.968


def simulate_contact(seed: int, surface_mm: float = 0.0) -> tuple[np.ndarray, ...]:
    """Cut torque, air torque, X position (mm, radius mode) from t₀ (spindle start) for one
    contact at X = ``surface_mm``; samples before the reference revolution are zeros."""
    rng = np.random.default_rng(seed)
    i0 = int(4 * PERIOD_S * FS)
    n = int((5 * PERIOD_S + 5.0 / V_X_MM_S + 0.1) * FS)
    t = np.arange(i0, n) / FS
    theta = 2 * math.pi * t / PERIOD_S
    phases = rng.uniform(0, 2 * math.pi, len(RIPPLE_NM))  # machine-specific, repeatable
    ripple = sum(a * np.sin(h * theta + ph) for (h, a), ph in zip(RIPPLE_NM, phases, strict=True))
    x = surface_mm + 5.0 - V_X_MM_S * np.maximum(t - 5 * PERIOD_S, 0.0)
    pen = np.clip(surface_mm - x, 0.0, 0.1)
    cut = ripple + K_CONTACT * pen**1.5 + NOISE_NM * rng.standard_normal(t.size)
    air = ripple + NOISE_NM * rng.standard_normal(t.size)
    pos = x + 1e-4 * rng.standard_normal(t.size)
    pad = np.zeros(i0)
    return (np.concatenate([pad, cut]), np.concatenate([pad, air]), np.concatenate([pad, pos]))


@functools.lru_cache(maxsize=1)
def thirty_contacts() -> np.ndarray:
    """Contact-position errors (µm) of 30 simulated contacts."""
    from millsense.monitoring.contact import detect_contact

    errs = []
    for k in range(30):
        cut, air, pos = simulate_contact(100 + k)
        c = detect_contact(cut, air, pos, FS, PERIOD_S)
        errs.append((c.position - 0.0) * 1e3)
    return np.array(errs)


@case(
    "monitoring.contact.repeatability_30",
    source="seed 004 §4.2 (Lee): σ = 1.18 µm over 30 contacts; issue 15 target ≤ 2 µm",
    reference=0.0,
    unit="µm",
    abs_tol=2.0,
    quick=False,
    description="Standard deviation of the detected contact position over 30 simulated contacts.",
)
def _repeatability() -> Measured:
    e = thirty_contacts()
    return Measured(
        float(np.std(e, ddof=1)),
        f"Mean error {np.mean(e):+.2f} µm (the line fit's bias against the nonlinear rise; "
        f"thesis: +13.46 µm measured with its real rise), σ {np.std(e, ddof=1):.2f} µm. Point "
        "B is where the rise leaves the noise band (η + κ) and the line runs through the "
        "confirming run after A (decision 1533); walking back to η itself, as the thesis, "
        "gave σ 3.11 µm: the 100-sample average of the noise hovers around η just before the "
        "rise, so B landed up to ~150 samples (6 µm of approach) early.",
    )


def _fit_3_2() -> object:
    from millsense.monitoring.contact import fit_circle

    pts = np.array(TABLE_3_2)
    return fit_circle(pts[:, 0], pts[:, 1])


@case(
    "monitoring.contact.table32_centre_x",
    source="seed 004 Table 3.2: identified rotational centre x = −30.972 mm",
    reference=CENTRE_3_2[0],
    unit="mm",
    abs_tol=0.002,
    quick=True,
    description="Gauss–Newton circle fit of the 5 printed contact points: centre x.",
)
def _centre_x() -> Measured:
    f = _fit_3_2()
    return Measured(f.x_c, f"σ_x {f.sigma_x * 1e3:.2f} µm")  # type: ignore[attr-defined]


@case(
    "monitoring.contact.table32_centre_y",
    source="seed 004 Table 3.2: identified rotational centre y = 1.235 mm",
    reference=CENTRE_3_2[1],
    unit="mm",
    abs_tol=0.002,
    quick=True,
    description="Gauss–Newton circle fit of the 5 printed contact points: centre y.",
)
def _centre_y() -> Measured:
    f = _fit_3_2()
    return Measured(f.y_c, f"σ_y {f.sigma_y * 1e3:.2f} µm")  # type: ignore[attr-defined]


@case(
    "monitoring.contact.table32_diameter",
    source="seed 004 Table 3.2: identified diameter 61.968 mm (refit of the printed points: "
    "61.991 mm, digest V5)",
    reference=DIAMETER_3_2,
    unit="mm",
    abs_tol=0.012,
    quick=False,
    description="Diameter of the circle fit of the 5 printed points.",
    issue=15,
    gap=(
        "The printed points give 61.991 mm (digest V5, residuals ≤ 1.2 µm); the thesis' 61.968 "
        "mm implies an unstated correction (decision 1527)."
    ),
)
def _diameter() -> Measured:
    f = _fit_3_2()
    return Measured(f.diameter, f"σ_D {f.sigma_diameter * 1e3:.2f} µm")  # type: ignore[attr-defined]
