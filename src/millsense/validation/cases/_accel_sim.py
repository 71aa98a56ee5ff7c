"""Simulation harness for the accelerometer estimators (İlme seed 003, Aslan Ch. 4).

Not an estimator: it plays the machine. Forces come from the sliced mechanistic model
(:func:`millsense.process.forces.milling_forces`), structures from modal sums realised by
:class:`millsense.models.modal_ss.ModalStateSpace`, stepped exactly for a force that is
linear between samples (first-order hold) at an oversampled rate, then low-passed without
phase (a delay-compensated DAQ anti-alias filter) and decimated (:class:`ModeSet`,
:func:`simulate_foh` and :func:`daq` live with the tool's tap test in
:mod:`millsense.simulator.tap_test`). FRFs the estimators use come
from simulated impact tests through :func:`millsense.ident.frf.impact_frf`, never from the
modal truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.ident.frf import FrfEstimate, impact_frf
from millsense.models.modal_ss import ModalStateSpace
from millsense.simulator.tap_test import ModeSet, daq, simulate_foh

FloatArray = NDArray[np.float64]


def impact_test(
    modes: Sequence[ModeSet],
    sample_rate_hz: float,
    *,
    n_hits: int = 10,
    record_s: float = 0.5,
    peak_force_n: float = 400.0,
    pulse_s: float = 2e-4,
    noise_rms: Sequence[float] | float = 0.0,
    oversample: int = 4,
    seed: int = 0,
) -> list[FrfEstimate]:
    """Simulated hammer test: half-sine hits, accelerometer responses with noise, H1 per output.

    Parameters
    ----------
    modes : receptance modes from the hammer point to each response point.
    sample_rate_hz : DAQ rate [Hz].
    n_hits, record_s, peak_force_n, pulse_s : hits, record per hit [s], hit peak [N] and
        duration [s].
    noise_rms : accelerometer noise [m/s²] per output (or one for all).
    oversample : simulation rate multiple.
    seed : random seed.

    Returns
    -------
    One :class:`FrfEstimate` (accelerance, (m/s²)/N) per output.
    """
    rng = np.random.default_rng(seed)
    fs = sample_rate_hz * oversample
    n_rec = round(record_s * fs)
    n = n_rec * (n_hits + 1)
    t = np.arange(n) / fs
    force = np.zeros(n)
    for h in range(n_hits):
        t0 = (h + 0.5) * record_s + 0.01 * rng.standard_normal()
        inside = (t >= t0) & (t <= t0 + pulse_s)
        force[inside] += peak_force_n * np.sin(np.pi * (t[inside] - t0) / pulse_s)
    f_daq = daq(force, oversample)
    noise = np.broadcast_to(np.asarray(noise_rms, dtype=float), (len(modes),))
    out = []
    for ms, sd in zip(modes, noise, strict=True):
        a = daq(simulate_foh(ms.accelerance_ss(), force, 1.0 / fs), oversample)
        a = a + sd * rng.standard_normal(a.size)
        out.append(
            impact_frf(f_daq, a, sample_rate_hz, record_s=record_s * 0.95, exp_tau_s=10 * record_s)
        )
    return out


# ---------------------------------------------------------------------------------------------
# İlme (seed 003): workpiece on a dynamometer-like structure, the 12-test matrix
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IlmeTest:
    """One row of İlme Table 4.5 (field units as printed)."""

    number: int
    diameter_mm: float
    n_flutes: int
    kind: str  # "down", "up", "full"
    rpm: float
    feed_mm_min: float
    ap_mm: float
    ae_mm: float

    @property
    def feed_per_tooth_m(self) -> float:
        return self.feed_mm_min / (self.n_flutes * self.rpm) * 1e-3

    @property
    def immersion_rad(self) -> tuple[float, float]:
        """θ_st, θ_ex (digest §3.4 convention: up [0, acos(1 − a_e/R)], down mirrored)."""
        r = self.diameter_mm / 2
        if self.kind == "full" or self.ae_mm >= self.diameter_mm:
            return 0.0, math.pi
        c = math.acos(1 - self.ae_mm / r)
        if self.kind == "up":
            return 0.0, c
        return math.pi - c, math.pi


#: İlme Table 4.5 (Tests 7 and 8 at the table's 2400 and 4800 rev/min, not the captions').
ILME_TESTS: tuple[IlmeTest, ...] = (
    IlmeTest(1, 12, 3, "down", 4500, 1500, 2, 6),
    IlmeTest(2, 12, 3, "full", 4800, 1500, 1, 12),
    IlmeTest(3, 12, 3, "down", 3000, 1000, 2, 6),
    IlmeTest(4, 12, 3, "full", 2000, 1500, 2, 12),
    IlmeTest(5, 12, 3, "full", 2500, 1500, 2, 12),
    IlmeTest(6, 12, 3, "up", 3000, 1800, 4, 6),
    IlmeTest(7, 16, 3, "full", 2400, 1000, 3, 16),
    IlmeTest(8, 16, 3, "full", 4800, 500, 4, 16),
    IlmeTest(9, 16, 3, "down", 2400, 500, 11, 2),
    IlmeTest(10, 16, 4, "down", 3000, 1000, 3, 8),
    IlmeTest(11, 16, 4, "down", 3000, 1500, 1, 8),
    IlmeTest(12, 16, 4, "down", 2400, 1200, 1, 8),
)

ILME_FS_HZ = 12800.0
ILME_HELIX_RAD = math.radians(45.0)
#: Workpiece Y accelerance modes: the poles of İlme's plant G2 (Eq. 3.16, digest §3.2) with
#: residues chosen for peaks of 1-2 (m/s²)/N (a workpiece of a few kg), plus a free mode
#: above the 20th harmonic.
ILME_WORKPIECE = ModeSet(
    frequency_hz=(894.8, 1455.0, 2156.1, 3006.2, 5600.0),
    damping=(0.010, 0.050, 0.0384, 0.0396, 0.03),
    alpha=(0.02, 0.2, 0.12, 0.1, 0.1),
)
#: Position dependence along the cut (tool moving along X): relative residue change of each
#: mode from the start to the end of the pass (İlme: ≤ 25 % at mode 1, > 60 % at mode 2 over
#: the whole edge; the pass here covers a part of it). The FRF is tapped mid-pass.
ILME_GAIN_DRIFT = (0.16, 0.30, 0.10, 0.10, 0.0)
#: Workpiece X accelerance modes (a second accelerometer axis; İlme used Y only).
ILME_WORKPIECE_X = ModeSet(
    frequency_hz=(1210.0, 1720.0, 2480.0, 3350.0, 6100.0),
    damping=(0.015, 0.040, 0.035, 0.040, 0.03),
    alpha=(0.03, 0.15, 0.12, 0.1, 0.1),
)
#: Cross accelerance X force → Y acceleration, relative to the direct one (unmodelled).
ILME_CROSS = 0.05
ILME_NOISE_RMS = 0.2  # m/s², accelerometer noise
ILME_TAP_NOISE_RMS = 0.02  # m/s², accelerometer noise in the tap test (machine at rest)
ILME_RUNOUT_M = 2e-6  # residual runout after dial-indicator minimisation


def ilme_modes_at(position: float, direction: str = "y") -> ModeSet:
    """Workpiece modes with the residues at ``position`` ∈ [0, 1] along the pass."""
    base = ILME_WORKPIECE if direction == "y" else ILME_WORKPIECE_X
    al = tuple(
        a * (1 + d * (position - 0.5)) for a, d in zip(base.alpha, ILME_GAIN_DRIFT, strict=True)
    )
    return ModeSet(base.frequency_hz, base.damping, al)


@dataclass(frozen=True)
class IlmeRecord:
    """A simulated İlme cut: measured channels and the truth."""

    test: IlmeTest
    sample_rate_hz: float
    spindle_angle_rad: FloatArray
    accel_y: FloatArray
    accel_x: FloatArray
    force_x_true: FloatArray
    force_y_true: FloatArray


def ilme_material() -> tuple[float, float, float, float]:
    """K_tc, K_rc [N/m²], K_te, K_re [N/m]: İlme Table 3.1 values (the truth's coefficients)."""
    return 700e6, 300e6, 25e3, 35e3


def simulate_ilme(
    test: IlmeTest, duration_s: float = 1.0, seed: int = 1, *, cutting: bool = True
) -> IlmeRecord:
    """Simulate one test of the matrix: sliced forces, workpiece structure, DAQ and noise.

    ``cutting=False`` records the free state instead (spindle at the test's speed in air, no
    cutting force): the same structure, DAQ filter and accelerometer noise, so its variance is
    what a user measures for İlme's R.

    Mismatch against the estimator (stated beside the figure): sliced force model with runout
    2 µm (estimator: Eq. 2.38 without runout); residues drift along the pass by
    ILME_GAIN_DRIFT (estimator: one FRF tapped mid-pass); 5 % cross accelerance X → Y
    (estimator: none); accelerometer noise ILME_NOISE_RMS (0.2 m/s² rms); estimator FRF from
    a noisy impact test; free vibration of a 5.6 kHz mode above the harmonic band.
    """
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    over = 4
    fs = ILME_FS_HZ * over
    n = round(duration_s * fs)
    t = np.arange(n) / fs
    omega = 2 * np.pi * test.rpm / 60
    phi = omega * t
    ktc, krc, kte, kre = ilme_material()
    tool = EndMill(
        diameter_m=test.diameter_mm * 1e-3,
        n_flutes=test.n_flutes,
        helix_rad=ILME_HELIX_RAD,
        runout_offset_m=ILME_RUNOUT_M,
        runout_angle_rad=0.3,
    )
    entry, exit_ = test.immersion_rad
    eng = Engagement.from_intervals([(entry, exit_)])
    coeffs = CuttingCoefficients(ktc, krc, 0.0, kte, kre, 0.0)
    if cutting:
        f = milling_forces(tool, coeffs, eng, test.feed_per_tooth_m, test.ap_mm * 1e-3, phi, 200)
        # entry ramp over 20 ms (tool entering the part) so the structure starts from rest
        ramp = np.clip(t / 0.02, 0.0, 1.0)
        fx, fy = f.fx_n * ramp, f.fy_n * ramp
    else:
        fx, fy = np.zeros(n), np.zeros(n)
    # the workpiece is loaded by the reaction −F
    s = t / t[-1]
    rng = np.random.default_rng(seed + test.number)
    acc = {}
    for d, u in (("y", -(fy + ILME_CROSS * fx)), ("x", -(fx + ILME_CROSS * fy))):
        a_start = simulate_foh(ilme_modes_at(0.0, d).accelerance_ss(), u, 1 / fs)
        a_end = simulate_foh(ilme_modes_at(1.0, d).accelerance_ss(), u, 1 / fs)
        a = daq((1 - s) * a_start + s * a_end, over)
        acc[d] = a + ILME_NOISE_RMS * rng.standard_normal(a.size)
    return IlmeRecord(test, ILME_FS_HZ, phi[::over], acc["y"], acc["x"], fx[::over], fy[::over])


def ilme_frf(seed: int = 7, direction: str = "y") -> FrfEstimate:
    """The estimator's FRF: a simulated impact test on the workpiece mid-pass."""
    return impact_test(
        [ilme_modes_at(0.5, direction)],
        ILME_FS_HZ,
        noise_rms=ILME_TAP_NOISE_RMS,
        seed=seed,
        record_s=0.5,
        n_hits=20,
    )[0]


# ---------------------------------------------------------------------------------------------
# Aslan Ch. 4: spindle with housing accelerometers, speed- and load-dependent modes
# ---------------------------------------------------------------------------------------------

ASLAN_FS_HZ = 8192.0
ASLAN_N_SENSORS = 5
#: Mode shapes at the accelerometers (tool tip = 1) for the modes ~620 Hz, 980→800 Hz,
#: 1450 Hz and 2300 Hz (the last outside the 200–1800 Hz fitting band of Aslan Ch. 4).
ASLAN_SHAPES = np.array(
    [
        [0.30, 0.25, 0.20, 0.35, 0.15],
        [0.25, 0.30, 0.15, 0.05, 0.20],
        [0.15, 0.10, 0.25, 0.10, 0.30],
        [0.10, 0.15, 0.10, 0.05, 0.12],
    ]
)
ASLAN_NOISE_RMS = 0.05  # m/s², accelerometer noise during cutting
ASLAN_TAP_NOISE_RMS = 0.01  # m/s², during the tap tests


def aslan_tip_modes(speed_rpm: float, load_n: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Tool-tip modes (f [Hz], ζ, α [1/kg]) of the simulated spindle at a speed and Z load.

    Aslan V4: the dominant X mode moves from 980 Hz to 800 Hz as the Z load goes 0 → 430 N;
    from 0 to 15000 rev/min its magnitude falls by 48 % and the ~600 Hz mode rises by 45 %.
    """
    s = speed_rpm / 15000.0
    lo = load_n / 430.0
    f = np.array([620.0, 980.0 - 180.0 * lo, 1450.0, 2300.0])
    z = np.array([0.03, 0.025, 0.03, 0.03])
    k = np.array([3e7, 2e7, 5e7, 8e7])  # modal stiffness at the tip [N/m]
    alpha = (2 * np.pi * f) ** 2 / k
    alpha = alpha * np.array([1 + 0.45 * s, 1 - 0.48 * s, 1.0, 1.0])
    return f, z, alpha


def aslan_modes(speed_rpm: float, load_n: float) -> tuple[ModeSet, list[ModeSet]]:
    """Receptances F₁ → tool tip and F₁ → each accelerometer (modal superposition)."""
    f, z, a = aslan_tip_modes(speed_rpm, load_n)
    tip = ModeSet(tuple(f), tuple(z), tuple(a))
    sensors = [
        ModeSet(tuple(f), tuple(z), tuple(a * ASLAN_SHAPES[:, m])) for m in range(ASLAN_N_SENSORS)
    ]
    return tip, sensors


def aslan_map(
    speeds_rpm: Sequence[float], loads_n: Sequence[float], workers: int = 1, seed: int = 11
) -> list[tuple[float, float, list[FrfEstimate]]]:
    """Simulated tap tests at the tool tip over a speed × load grid (Aslan §4.3).

    Returns per node (speed, load, [tip accelerance, sensor 1..5 accelerances]).
    """
    out = []
    for i, n in enumerate(speeds_rpm):
        for j, load in enumerate(loads_n):
            tip, sensors = aslan_modes(n, load)
            frfs = impact_test(
                [tip, *sensors],
                ASLAN_FS_HZ,
                n_hits=10,
                record_s=0.5,
                peak_force_n=300.0,
                noise_rms=ASLAN_TAP_NOISE_RMS,
                seed=seed + 100 * i + j,
            )
            out.append((float(n), float(load), frfs))
    return out


@dataclass(frozen=True)
class AslanRecord:
    """A simulated Ch. 4 cut: accelerometers, and the truth at the tool tip."""

    sample_rate_hz: float
    accel: FloatArray  # (5, n)
    force_true: FloatArray
    displacement_true: FloatArray


def simulate_aslan_cut(
    speed_rpm: float,
    load_n: float,
    *,
    radial_depth_mm: float = 5.0,
    duration_s: float = 0.6,
    seed: int = 5,
    cutting: bool = True,
) -> AslanRecord:
    """Aslan Ch. 4 Case 2: Ø20 mm 2-flute end mill, a = 5 mm, 0.1 mm/tooth, Al7050 preset.

    ``cutting=False`` is the air cut: the spindle at ``speed_rpm`` under ``load_n`` with no
    cutting force, through the same structure, DAQ filter and accelerometer noise.

    The force normal to the feed (our F_y) is F₁ along the spindle X modes. Runout 37 µm
    (Aslan: 35-40 µm), 30° helix, down milling; the modes are those at (speed, load).
    """
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    mat = load_preset(MaterialConfig, "al7050")
    coeffs = CuttingCoefficients(
        mat.ktc_n_mm2 * 1e6, mat.krc_n_mm2 * 1e6, 0.0, mat.kte_n_mm * 1e3, mat.kre_n_mm * 1e3
    )
    over = 4
    fs = ASLAN_FS_HZ * over
    n = round(duration_s * fs)
    t = np.arange(n) / fs
    phi = 2 * np.pi * speed_rpm / 60 * t
    tool = EndMill(
        diameter_m=0.020,
        n_flutes=2,
        helix_rad=math.radians(30),
        runout_offset_m=37e-6,
        runout_angle_rad=0.4,
    )
    eng = Engagement.radial(radial_depth_mm * 1e-3, 0.020, "down")
    if cutting:
        f = milling_forces(tool, coeffs, eng, 0.1e-3, 5e-3, phi, 60).fy_n
        f = f * np.clip(t / 0.01, 0.0, 1.0)
    else:
        f = np.zeros(n)
    tip, sensors = aslan_modes(speed_rpm, load_n)
    rng = np.random.default_rng(seed)
    acc = np.empty((ASLAN_N_SENSORS, len(range(0, n, over))))
    for m, ms in enumerate(sensors):
        a = daq(simulate_foh(ms.accelerance_ss(), f, 1 / fs), over)
        acc[m] = a + ASLAN_NOISE_RMS * rng.standard_normal(a.size)
    # tip displacement: receptance realised as a modal state space (α, β = 0, no feedthrough)
    tip_ss = ModalStateSpace.from_modes(
        tip.frequency_hz, tip.damping, tip.alpha, np.zeros(len(tip.alpha)), 0.0
    )
    disp = simulate_foh(tip_ss, f, 1 / fs)[::over]
    return AslanRecord(ASLAN_FS_HZ, acc, f[::over], disp)
