"""Validation cases of :mod:`millsense.process` (cutting mechanics)."""

from __future__ import annotations

import math

import numpy as np

from millsense.process.closed_forms import fit_slot_coefficients, slot_average_forces
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import chip_thickness, milling_forces
from millsense.process.geometry import EndMill
from millsense.process.harmonic import harmonic_forces
from millsense.validation import Measured, case

_K6 = CuttingCoefficients(ktc=700e6, krc=300e6, kac=100e6, kte=25e3, kre=35e3, kae=10e3)
_ILME_K = CuttingCoefficients(ktc=700e6, krc=300e6, kte=25e3, kre=35e3)
_ILME_GEO = dict(
    n_flutes=3,
    diameter_m=12e-3,
    helix_rad=math.radians(45.0),
    axial_depth_m=2e-3,
    entry_rad=math.pi / 2,
    exit_rad=math.pi,
)
_ILME_TX = 0.1667e-3


def _rev(n: int) -> np.ndarray:
    return np.linspace(0.0, 2 * math.pi, n, endpoint=False)


@case(
    "process.slot_average_vs_closed_form",
    source="benchmarks.md §3 (Altintas ch. 2 closed forms)",
    reference=0.0,
    unit="%",
    abs_tol=0.1,
    description="Largest relative error (x, y, z) of sliced slot average forces "
    "(4 flutes, helix 30°, 200 discs, 7200 angles) against the closed forms",
)
def _slot_average() -> Measured:
    tool = EndMill(10e-3, 4, helix_rad=math.radians(30.0))
    f = milling_forces(tool, _K6, Engagement.slot(), 0.1e-3, 3e-3, _rev(7200), n_discs=200)
    ref = slot_average_forces(4, 3e-3, 0.1e-3, _K6)
    errs = [
        abs(g - float(r)) / abs(float(r)) * 100 for g, r in zip(f.average()[:3], ref, strict=True)
    ]
    rows = "\n".join(
        f"| {ax} | {float(r):.4f} | {g:.4f} | {e:.2e} |"
        for ax, r, g, e in zip("xyz", ref, f.average()[:3], errs, strict=True)
    )
    return Measured(
        max(errs), "| axis | closed form [N] | sliced [N] | error [%] |\n|---|---|---|---|\n" + rows
    )


@case(
    "process.slot_identification_round_trip",
    source="benchmarks.md §3 (average-force identification)",
    reference=0.0,
    unit="%",
    abs_tol=3.0,
    description="Largest relative error of the six coefficients identified from slot "
    "averages at 6 feeds (0.05–0.30 mm) with σ = 1 N Gaussian noise (seed 7)",
)
def _identification() -> Measured:
    rng = np.random.default_rng(7)
    feeds = np.linspace(0.05e-3, 0.30e-3, 6)
    tool = EndMill(10e-3, 4, helix_rad=0.52)
    avgs = np.array(
        [
            milling_forces(tool, _K6, Engagement.slot(), c, 3e-3, _rev(3600), 40).average()[:3]
            for c in feeds
        ]
    )
    noisy = avgs + rng.normal(0.0, 1.0, avgs.shape)
    fit = fit_slot_coefficients(feeds, noisy[:, 0], noisy[:, 1], noisy[:, 2], 4, 3e-3)
    truth = np.array(_K6.as_tuple())
    got = np.array(fit.coefficients.as_tuple())
    err = np.abs(got - truth) / np.abs(truth) * 100
    names = ("ktc", "krc", "kac", "kte", "kre", "kae")
    rows = "\n".join(
        f"| {n} | {t:.4g} | {g:.4g} | {e:.2f} | {s:.3g} |"
        for n, t, g, e, s in zip(names, truth, got, err, fit.std_errors, strict=True)
    )
    return Measured(
        float(err.max()),
        "| coefficient | truth | identified | error [%] | std. error |\n|---|---|---|---|---|\n"
        + rows
        + f"\n\nR² (x, y, z) = {np.round(fit.r_squared, 6).tolist()}",
    )


def _ilme_fy(n: int = 12000, q: int = 100) -> np.ndarray:
    _, fy = harmonic_forces(_rev(n), _ILME_K, _ILME_TX, n_harmonics=q, **_ILME_GEO)  # type: ignore[arg-type]
    return fy


@case(
    "process.ilme_peak_fy",
    source="seed 003 Table 3.4 (Ilme Eq. 2.38)",
    reference=307.07,
    unit="N",
    rel_tol=1e-3,
    description="Peak y force of the angular-harmonic model, q = 100, down milling 90°→180°",
)
def _ilme_peak() -> float:
    return float(_ilme_fy().max())


@case(
    "process.ilme_rms_fy",
    source="seed 003 Table 3.4 (Ilme Eq. 2.38)",
    reference=200.05,
    unit="N",
    rel_tol=1e-3,
    description="RMS y force of the angular-harmonic model, q = 100, down milling 90°→180°",
)
def _ilme_rms() -> float:
    fy = _ilme_fy()
    return float(np.sqrt(np.mean(fy**2)))


@case(
    "process.ilme_sliced_peak_fy",
    source="seed 003 Table 3.4; benchmarks.md §4",
    reference=307.07,
    unit="N",
    rel_tol=1e-3,
    description="Peak y force of the sliced mechanistic model (200 discs) for the Ilme case",
)
def _ilme_sliced_peak() -> float:
    tool = EndMill(12e-3, 3, helix_rad=math.radians(45.0))
    eng = Engagement.from_intervals([(math.pi / 2, math.pi)])
    f = milling_forces(tool, _ILME_K, eng, _ILME_TX, 2e-3, _rev(12000), n_discs=200)
    return float(f.fy_n.max())


@case(
    "process.ilme_harmonic_vs_sliced",
    source="benchmarks.md §4 (agreement within 0.3 N)",
    reference=0.0,
    unit="N",
    abs_tol=0.3,
    description="Largest |F_harmonic − F_sliced| over x and y for the Ilme case "
    "(q = 800 harmonics, 2000 discs, 1000 angles over one tooth period)",
)
def _ilme_vs_sliced() -> float:
    phi = np.linspace(0, 2 * math.pi / 3, 1000, endpoint=False)
    tool = EndMill(12e-3, 3, helix_rad=math.radians(45.0))
    eng = Engagement.from_intervals([(math.pi / 2, math.pi)])
    f = milling_forces(tool, _ILME_K, eng, _ILME_TX, 2e-3, phi, n_discs=2000)
    fx, fy = harmonic_forces(phi, _ILME_K, _ILME_TX, n_harmonics=800, **_ILME_GEO)  # type: ignore[arg-type]
    return float(max(np.abs(fx - f.fx_n).max(), np.abs(fy - f.fy_n).max()))


def _v9(gain_mm: float) -> float:
    # Aslan V9: F_res = K_tc c Gain_CWE with no edge terms and K_rc = 0.5 K_tc (Eq. 5.34).
    # For one straight tooth in cut, peak F_res = K_tc c a √1.25, so Gain_CWE = a √1.25:
    # choose a = Gain/√1.25 and compute the peak resultant with the sliced model.
    k = CuttingCoefficients(ktc=758e6, krc=0.5 * 758e6)
    a = gain_mm * 1e-3 / math.sqrt(1.25)
    f = milling_forces(EndMill(10e-3, 2), k, Engagement.slot(), 0.2e-3, a, _rev(3600), 1)
    return float(f.resultant_n().max())


@case(
    "process.aslan_v9_gain_0976",
    source="seed 000 V9 (Aslan Fig. 6.4) and Eq. 5.34",
    reference=147.96,
    unit="N",
    rel_tol=1e-3,
    description="Peak resultant for K_tc = 758 N/mm², c = 0.2 mm, Gain_CWE = 0.976 mm "
    "(straight 2-flute slot, a = Gain/√1.25)",
)
def _v9a() -> float:
    return _v9(0.976)


@case(
    "process.aslan_v9_gain_2498",
    source="seed 000 V9 (Aslan Fig. 6.4) and Eq. 5.34",
    reference=378.7,
    unit="N",
    rel_tol=1e-3,
    description="Peak resultant for K_tc = 758 N/mm², c = 0.2 mm, Gain_CWE = 2.498 mm",
)
def _v9b() -> float:
    return _v9(2.498)


@case(
    "process.runout_chip_thickness",
    source="Lee Eqs. 2.3–2.5 (seed 004), rewritten in our convention",
    reference=0.0,
    unit="µm",
    abs_tol=1e-6,
    description="Largest |h − (c sin φ − 2ρ sin(π/N) sin(θ_j − π/N + ψ − λ))| where all "
    "4 flutes cut (ρ = 4 µm, λ = 0.7 rad, c = 0.1 mm, helix 34°)",
)
def _runout() -> float:
    rho, lam, c = 4e-6, 0.7, 0.1e-3
    tool = EndMill(10e-3, 4, helix_rad=0.6, runout_offset_m=rho, runout_angle_rad=lam)
    discs = tool.discs(2e-3, 5)
    phi = np.linspace(0.0, 2 * math.pi, 721)
    h = chip_thickness(tool, Engagement.slot(), c, phi, discs)
    imm = tool.immersion_angles(phi, discs)
    theta = tool.flute_angles_rad[None, :, None]
    closed = c * np.sin(imm) - 2 * rho * math.sin(math.pi / 4) * np.sin(
        theta - math.pi / 4 + discs.lag_rad[None, None, :] - lam
    )
    ok = (np.mod(imm, 2 * math.pi) < math.pi) & (closed > 2 * rho)
    return float(np.max(np.abs(h[ok] - closed[ok])) * 1e6)


@case(
    "process.variable_pitch_chip_load",
    source="geometry: flute j removes what flute j-1 left p_j earlier",
    reference=0.0,
    unit="%",
    abs_tol=1e-4,
    description="Largest relative deviation of per-flute peak chip thickness from "
    "N c p_j/(2π) for pitches 70/110/85/95°",
)
def _pitch() -> float:
    pitches = np.radians([70.0, 110.0, 85.0, 95.0])
    tool = EndMill(10e-3, 4, pitch_angles_rad=tuple(pitches))
    h = chip_thickness(tool, Engagement.slot(), 0.1e-3, _rev(36000), tool.discs(1e-3, 1))
    expected = 4 * 0.1e-3 * pitches / (2 * math.pi)
    return float(np.max(np.abs(h[:, :, 0].max(axis=0) / expected - 1)) * 100)
