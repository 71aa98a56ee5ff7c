"""Acceptance of contact detection and the rotational centre (seed 004 ch. 3, digest §4.2).

Simulated turning contact (digest §6 "Turning contact", Table 3.1 conditions): C axis at
24 min⁻¹ (T = 2.5 s), 100 kHz, torque command = an angle-dependent ripple (bearing and cogging
harmonics) + white noise + the contact torque, which rises nonlinearly with the penetration p
(∝ p^1.5, a 0.8 mm nose entering the surface; 2 N·m at the 0.1 mm maximum depth). X approaches
at 244.8 mm/min from 5 mm above the surface after 5 preliminary revolutions; the encoder
position carries 0.1 µm noise. Only the window from the reference revolution to the end of the
approach is generated (what the detector reads).

The air cut and the cut motion are two runs (decision 1780, issue 12). The detector subtracts
them sample by sample from each record's spindle start t₀, not by angle; the thesis makes the
ripple repeat by re-initialising the C axis (counter-rotating it), so its phase is kept, not
re-drawn, but each record carries its own

* start error: t₀ of each record uncertain by ±0.5 ms (uniform; the motion starts on the NC's
  1 ms interpolation clock, which a 100 kHz recording does not share; assumption, the thesis
  gives none) plus the C axis' return error after the counter-rotation, 5″ RMS (a lathe C
  axis' repeatability; negligible beside the timing): the ripple shifts by that angle;
* ripple amplitude: each harmonic × (1 + 2 % RMS) per record (bearing friction and cogging
  drift with temperature and lubricant between runs; "a few %", an assumption);
* noise: an independent realisation per record.

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
#: Per-record differences of the ripple between the air cut and the cut motion (module notes)
START_JITTER_S = 0.5e-3  # half-width of the uniform t₀ error of each record
C_RETURN_RAD = math.radians(5.0 / 3600.0)  # RMS C-axis return error after the counter-rotation
RIPPLE_DRIFT = 0.02  # RMS relative amplitude change of each harmonic per record
K_CONTACT = 2.0 / 0.1**1.5  # N·m per mm^1.5
#: Table 3.2 contact points (x, y) mm relative to p₁, and the printed results.
TABLE_3_2 = ((0.0, 0.0), (-0.205, 5.0), (-1.088, -7.0), (-3.979, -14.0), (-8.391, -20.0))
CENTRE_3_2 = (-30.972, 1.235)
DIAMETER_3_2 = 61.968


def simulate_contact(
    seed: int,
    surface_mm: float = 0.0,
    start_jitter_s: float = START_JITTER_S,
    c_return_rad: float = C_RETURN_RAD,
    ripple_drift: float = RIPPLE_DRIFT,
) -> tuple[np.ndarray, ...]:
    """Cut torque, air torque, X position (mm, radius mode) from t₀ (spindle start) for one
    contact at X = ``surface_mm``; samples before the reference revolution are zeros.

    The ripple of each record is shifted by its own start error and its harmonics scaled by
    their own drift (module notes); zero ``start_jitter_s``, ``c_return_rad`` and
    ``ripple_drift`` give the bit-identical ripple of an ideal air cut."""
    rng = np.random.default_rng(seed)
    run = np.random.default_rng((seed, 1))  # the per-record differences: own stream
    i0 = int(4 * PERIOD_S * FS)
    n = int((5 * PERIOD_S + 5.0 / V_X_MM_S + 0.1) * FS)
    t = np.arange(i0, n) / FS
    theta = 2 * math.pi * t / PERIOD_S
    phases = rng.uniform(0, 2 * math.pi, len(RIPPLE_NM))  # machine-specific, repeatable

    def ripple() -> np.ndarray:
        shift = (
            2 * math.pi * run.uniform(-start_jitter_s, start_jitter_s) / PERIOD_S
            + c_return_rad * run.standard_normal()
        )
        gain = 1.0 + ripple_drift * run.standard_normal(len(RIPPLE_NM))
        return np.asarray(
            sum(
                g * a * np.sin(h * (theta + shift) + ph)
                for (h, a), ph, g in zip(RIPPLE_NM, phases, gain, strict=True)
            )
        )

    x = surface_mm + 5.0 - V_X_MM_S * np.maximum(t - 5 * PERIOD_S, 0.0)
    pen = np.clip(surface_mm - x, 0.0, 0.1)
    cut = ripple() + K_CONTACT * pen**1.5 + NOISE_NM * rng.standard_normal(t.size)
    air = ripple() + NOISE_NM * rng.standard_normal(t.size)
    pos = x + 1e-4 * rng.standard_normal(t.size)
    pad = np.zeros(i0)
    return (np.concatenate([pad, cut]), np.concatenate([pad, air]), np.concatenate([pad, pos]))


#: the thesis' repeatability of the contact position over 30 contacts, µm (seed 004 §4.2)
THESIS_SIGMA_UM = 1.18
#: Two-sided tolerance around the thesis' σ and the too-good factor (decision 1780): the σ of 30
#: contacts has a sampling scatter of about 1/√(2·29) = 13 % (the thesis' figure the same), so
#: the ratio of two such figures about 19 %; ±50 % is 2.6 of those; 2× better is flagged (the
#: registry's other replicas of measured errors: seed 000 V1, seed 003 Table 4.6).
SIGMA_REL_TOL = 0.5
SIGMA_TOO_GOOD = 2.0


@functools.lru_cache(maxsize=2)
def thirty_contacts(ideal_air_cut: bool = False) -> np.ndarray:
    """Contact-position errors (µm) of 30 simulated contacts; ``ideal_air_cut``: the air cut's
    ripple bit-identical to the cut's (the simulation before decision 1780), for comparison."""
    from millsense.monitoring.contact import detect_contact

    kw = {"start_jitter_s": 0.0, "c_return_rad": 0.0, "ripple_drift": 0.0} if ideal_air_cut else {}
    errs = []
    for k in range(30):
        cut, air, pos = simulate_contact(100 + k, **kw)
        c = detect_contact(cut, air, pos, FS, PERIOD_S)
        errs.append((c.position - 0.0) * 1e3)
    return np.array(errs)


def _contact_details() -> str:
    e = thirty_contacts()
    ideal = thirty_contacts(ideal_air_cut=True)
    return (
        f"Mean error {np.mean(e):+.2f} µm (the line fit's bias against the nonlinear rise; "
        f"thesis: +13.46 µm measured with its real rise), σ {np.std(e, ddof=1):.2f} µm "
        f"(thesis {THESIS_SIGMA_UM} µm), errors {np.min(e):+.2f} to {np.max(e):+.2f} µm. The air "
        f"cut is a separate run: its ripple is shifted by its own start error (±"
        f"{START_JITTER_S * 1e3:g} ms, C return {math.degrees(C_RETURN_RAD) * 3600:g}″ RMS) and "
        f"its harmonics drift by {RIPPLE_DRIFT * 100:g} % RMS, noise independent (module notes, "
        f"decision 1780). With the cut's ripple bit-identical in the air cut (the simulation "
        f"before decision 1780) σ {np.std(ideal, ddof=1):.2f} µm, mean {np.mean(ideal):+.2f} µm. "
        "Point B is where the rise leaves the noise band (η + κ) and the line runs through the "
        "confirming run after A (decision 1533); walking back to η itself, as the thesis, gave "
        "σ 3.11 µm with the identical ripple: the 100-sample average of the noise hovers around "
        "η just before the rise, so B landed up to ~150 samples (6 µm of approach) early."
    )


@case(
    "monitoring.contact.repeatability_30",
    source="issue 15: σ of the contact position over 30 simulated contacts ≤ 2 µm (seed 004 "
    "§4.2, Lee: σ = 1.18 µm)",
    reference=0.0,
    unit="µm",
    abs_tol=2.0,
    quick=False,
    description=(
        "Standard deviation of the detected contact position over 30 simulated contacts, the "
        "air cut a separate run (its ripple shifted and drifting; decision 1780). Issue 15's "
        "bound, kept as the issue states it; the thesis comparison is repeatability_30_thesis."
    ),
)
def _repeatability() -> Measured:
    return Measured(float(np.std(thirty_contacts(), ddof=1)), _contact_details())


@case(
    "monitoring.contact.repeatability_30_thesis",
    source=f"seed 004 §4.2 (Lee): σ = {THESIS_SIGMA_UM} µm over 30 measured contacts",
    reference=THESIS_SIGMA_UM,
    unit="µm",
    rel_tol=SIGMA_REL_TOL,
    too_good_factor=SIGMA_TOO_GOOD,
    quick=False,
    description=(
        "The σ of repeatability_30 against the thesis' measured σ (two-sided "
        f"±{SIGMA_REL_TOL * 100:g} %; more than {SIGMA_TOO_GOOD:g}× better is flagged too good: "
        "the simulated contact would then be more benign than the machine; decision 1780)."
    ),
)
def _repeatability_thesis() -> Measured:
    return Measured(float(np.std(thirty_contacts(), ddof=1)), _contact_details())


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
    "61.991 mm; digest V5: treat D as ±0.025 mm, decision 1691)",
    reference=DIAMETER_3_2,
    unit="mm",
    abs_tol=0.025,
    quick=False,
    description="Diameter of the circle fit of the 5 printed points, judged with the tolerance "
    "the seed digest gives it (V5: the thesis' 61.968 mm is 23 µm off the fit of its own printed "
    "points, 61.991 mm, for an unstated correction; decision 1691).",
)
def _diameter() -> Measured:
    f = _fit_3_2()
    return Measured(f.diameter, f"σ_D {f.sigma_diameter * 1e3:.2f} µm")  # type: ignore[attr-defined]
