"""Validation cases of :mod:`millsense.ident` (issue 6 items 1–2) and their simulated data.

The Y-axis case rebuilds the 12-mode drive disturbance FRF of Aslan Table 3.4 (ζ in % for Y,
seed 000 digest P5), simulates its response to a periodic multisine at 10 kHz with measurement
noise of the Y-axis air-cut level (Aslan Eq. 3.30, R = 0.1159 read as a variance in N²·m²,
docs/decisions/0003-current-noise-from-aslan-eq-3-30.md), estimates H1 and fits modes
automatically. The helpers here are also used by the tests and by ``benchmarks/bench_ident.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from millsense.ident.frf import FrfEstimate, multisine_frf, multisine_signal
from millsense.ident.modal_fit import ModalFit, fit_modes
from millsense.stability.modal import Mode, frf_sum
from millsense.validation import Measured, case

FloatArray = NDArray[np.float64]

#: Aslan Table 3.4, Y axis: f_n [Hz], ζ [%], α, β (digest P5; ζ is in % for Y).
ASLAN_Y_TABLE_3_4: tuple[tuple[float, float, float, float], ...] = (
    (16.3, 4.96, 518.0, 1.3),
    (31.0, 2.9, 2719.0, 7.1),
    (36.0, 3.3, 6183.0, 7.8),
    (47.0, 2.8, 2673.0, -10.2),
    (52.0, 5.0, 15591.0, 9.98),
    (63.5, 6.0, 8849.0, 21.1),
    (71.0, 2.2, 11459.0, 3.9),
    (77.5, 3.0, 57547.0, 96.1),
    (85.0, 2.2, 16125.0, 17.4),
    (102.0, 1.2, 5831.0, -10.0),
    (130.0, 9.8, 22339.0, 115.6),
    (180.0, 3.9, -108153.0, -158.2),
)

#: Y-axis air-cut torque noise variance [N²·m²] (Aslan Eq. 3.30, R for Y).
Y_NOISE_VARIANCE_NM2 = 0.1159
#: Fitting band of the Y-axis case [Hz] (contains the 16.3 Hz and the 180 Hz modes).
Y_BAND_HZ = (8.0, 250.0)


def aslan_y_modes() -> list[Mode]:
    """The 12 Y-axis disturbance modes of Aslan Table 3.4 (τ_c/τ_a, dimensionless)."""
    return [Mode.from_residues(f, z / 100.0, a, b) for f, z, a, b in ASLAN_Y_TABLE_3_4]


def simulate_modes(modes: Sequence[Mode], u: FloatArray, sample_rate_hz: float) -> FloatArray:
    """Response of a sum of modes (Aslan Eq. 3.13) to the sampled input ``u``.

    Each mode ``(β s + α)/(s² + 2ζωs + ω²)`` is discretised exactly for an input linear between
    samples (first-order hold, ``scipy.signal.cont2discrete(method="foh")``) and run with
    ``lfilter``; the modal state space is block diagonal, so this equals discretising the whole
    realisation. FOH is used because the excitations (multisine, chirp) are smooth band-limited
    signals; a zero-order hold would add a half-sample delay that is not in Φ(iω).
    """
    y = np.zeros(len(u))
    dt = 1.0 / sample_rate_hz
    for m in modes:
        den = [1.0, 2 * m.zeta * m.omega, m.omega**2]
        num, den_d, _ = scipy.signal.cont2discrete(([m.beta, m.alpha], den), dt, method="foh")
        y += scipy.signal.lfilter(np.ravel(num), den_d, u)
    return y


@dataclass(frozen=True)
class ModalAccuracy:
    """Worst errors of a fit against known modes over a band."""

    freq_err_pct: float
    damping_err_pct: float
    frf_err_db: float
    n_true: int
    n_fitted: int


def compare_fit(
    fit: ModalFit, truth: Sequence[Mode], band_hz: tuple[float, float]
) -> ModalAccuracy:
    """Match each true mode in the band to the nearest fitted mode; worst errors.

    The FRF error is ``max |20 log10(|H_fit| / |H_true|)|`` on 4000 points over the band.
    A true mode with no fitted mode gives an infinite error.
    """
    lo, hi = band_hz
    in_band = [m for m in truth if lo <= m.natural_frequency_hz <= hi]
    fw = np.array([m.omega for m in fit.modes])
    ef, ez = 0.0, 0.0
    for m in in_band:
        if len(fw) == 0:
            return ModalAccuracy(math.inf, math.inf, math.inf, len(in_band), 0)
        j = int(np.argmin(np.abs(fw - m.omega)))
        ef = max(ef, abs(fw[j] / m.omega - 1) * 100)
        ez = max(ez, abs(fit.modes[j].damping_ratio / m.zeta - 1) * 100)
    f = np.linspace(lo, hi, 4000)
    db = 20 * np.log10(np.abs(fit.frf(f)) / np.abs(frf_sum(truth, f)))
    return ModalAccuracy(ef, ez, float(np.max(np.abs(db))), len(in_band), len(fit.modes))


def y_axis_sweep(
    seed: int = 0, periods: int = 7, period_s: float = 10.0
) -> tuple[FrfEstimate, list[Mode]]:
    """Simulated noisy multisine test of the Aslan Y-axis disturbance FRF and its H1.

    A Schroeder multisine of 2 N·m RMS exciting every 1/period_s line in 4–260 Hz is applied
    at 10 kHz; white noise of variance 0.1159 N²·m² is added to the output; the first period
    is discarded as transient and H1 is averaged over the remaining periods.
    """
    fs = 10_000.0
    n_per = round(period_s * fs)
    modes = aslan_y_modes()
    u, _ = multisine_signal(fs, n_per, 4.0, 260.0, periods, rms=2.0)
    y = simulate_modes(modes, u, fs)
    rng = np.random.default_rng(seed)
    y = y + rng.normal(0.0, math.sqrt(Y_NOISE_VARIANCE_NM2), len(y))
    return multisine_frf(u, y, fs, n_per, skip_periods=1, names=("tau_a", "tau_c")), modes


_Y_CACHE: dict[str, tuple[ModalFit, ModalAccuracy]] = {}


def _y_case() -> tuple[ModalFit, ModalAccuracy]:
    if "fit" not in _Y_CACHE:
        est, modes = y_axis_sweep()
        fit = fit_modes(est, Y_BAND_HZ, max_modes=18)
        _Y_CACHE["fit"] = (fit, compare_fit(fit, modes, Y_BAND_HZ))
    return _Y_CACHE["fit"]


def _y_table(fit: ModalFit) -> str:
    rows = ["| f_n true [Hz] | f_n fit [Hz] | ζ true [%] | ζ fit [%] | α fit | β fit |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    fw = np.array([m.omega for m in fit.modes])
    for tm in aslan_y_modes():
        m = fit.modes[int(np.argmin(np.abs(fw - tm.omega)))]
        rows.append(
            f"| {tm.natural_frequency_hz:g} | {m.natural_frequency_hz:.3f} | "
            f"{tm.zeta * 100:.2f} | {m.damping_ratio * 100:.3f} | {m.alpha:.0f} | {m.beta:.2f} |"
        )
    return "\n".join(rows)


_SRC = "Aslan Table 3.4 (Y, ζ in %), Eq. 3.13, Eq. 3.30 noise; issue 6 acceptance"


@case(
    "ident.modal_fit_y_axis_freq_err",
    source=_SRC,
    reference=0.0,
    unit="%",
    abs_tol=1.0,
    quick=False,
    description="worst natural-frequency error of the 12 Y modes fitted from a noisy "
    "simulated multisine (H1, band 8-250 Hz, automatic order)",
)
def _y_freq() -> Measured:
    fit, acc = _y_case()
    return Measured(acc.freq_err_pct, _y_table(fit))


@case(
    "ident.modal_fit_y_axis_damping_err",
    source=_SRC,
    reference=0.0,
    unit="%",
    abs_tol=15.0,
    quick=False,
    description="worst relative damping-ratio error of the 12 Y modes (same fit)",
)
def _y_damp() -> float:
    return _y_case()[1].damping_err_pct


@case(
    "ident.modal_fit_y_axis_frf_db",
    source=_SRC,
    reference=0.0,
    unit="dB",
    abs_tol=1.0,
    quick=False,
    description="max |dB| error of the fitted FRF against the true Y FRF over 8-250 Hz",
)
def _y_db() -> float:
    return _y_case()[1].frf_err_db


@case(
    "ident.modal_fit_y_axis_mode_count",
    source=_SRC,
    reference=12.0,
    unit="modes",
    abs_tol=0.0,
    quick=False,
    description="number of modes selected automatically from the stabilisation diagram",
)
def _y_count() -> float:
    return float(len(_y_case()[0].modes))


# ---------------------------------------------------------------------------------------------
# Speed × load map of spindle tool-tip FRFs (Aslan Ch. 4 / digest V4), for the batch benchmark
# ---------------------------------------------------------------------------------------------

#: Speeds of the map [rev/min] (0–15000 in 1500 steps) and Z preloads [N] (digest V4).
MAP_SPEEDS_RPM = tuple(float(v) for v in range(0, 15001, 1500))
MAP_LOADS_N = (0.0, 100.0, 230.0, 330.0, 430.0)
#: Fitting band of Aslan Ch. 4 [Hz] and the measured range (FRFs up to 2000 Hz).
MAP_BAND_HZ = (200.0, 1800.0)


def spindle_map_modes(direction: str, speed_rpm: float, load_n: float) -> list[Mode]:
    """Synthetic tool-tip modes [m/N] with the speed and load trends of Aslan Ch. 4 (V4).

    X: 320, 625, 980, 1450 Hz in band and 2300 Hz above it; the 980 Hz mode moves linearly to
    800 Hz at 430 N preload and its peak falls by 48 % from 0 to 15000 rev/min (damping raised
    by 1/0.52), the 625 Hz peak rises by 45 %. Y: 300, 600, 980, 1200, 1650 Hz and 2300 Hz; the
    980 Hz peak falls by 82 % with speed (damping ×2 and stiffness ×2.78), the 600 Hz one
    rises by 25 %, both fall with load.
    Stiffnesses are of the order of Aslan Tables 5.3/5.4 (10⁷–10⁸ N/m).
    """
    s = speed_rpm / 15000.0
    q = load_n / 430.0
    if direction == "x":
        return [
            Mode.from_stiffness(320.0, 0.04, 6e7),
            Mode.from_stiffness(625.0, 0.03, 3e7 / (1 + 0.45 * s)),
            Mode.from_stiffness(980.0 - 180.0 * q, 0.025 / (1 - 0.48 * s), 2e7),
            Mode.from_stiffness(1450.0, 0.02, 8e7),
            Mode.from_stiffness(2300.0, 0.03, 1e8),
        ]
    return [
        Mode.from_stiffness(300.0, 0.015, 7e7),
        Mode.from_stiffness(600.0, 0.03 * (1 + 0.3 * q), 2.5e7 / (1 + 0.25 * s)),
        Mode.from_stiffness(
            980.0 - 60.0 * q, 0.025 * (1 + 0.5 * q) * (1 + 1.0 * s), 1.8e7 * (1 + 1.78 * s)
        ),
        Mode.from_stiffness(1200.0, 0.03, 1e8),
        Mode.from_stiffness(1650.0, 0.02, 9e7),
        Mode.from_stiffness(2300.0, 0.03, 1e8),
    ]


def spindle_map_frfs(
    seed: int = 0, noise: float = 0.003
) -> list[tuple[tuple[FloatArray, NDArray[np.complex128]], list[Mode]]]:
    """The 110 FRFs (55 X, 55 Y) of the map at 1 Hz lines up to 2000 Hz, with noise.

    Lines as from 1 s tap records at 8192 Hz (Aslan Ch. 4). Complex Gaussian noise of standard
    deviation ``noise`` × max|H| is added to each line (an averaged tap test: the residual noise
    is roughly constant in absolute terms, so relatively larger at antiresonances).
    """
    rng = np.random.default_rng(seed)
    f = np.arange(1.0, 2001.0)
    out = []
    for direction in ("x", "y"):
        for sp in MAP_SPEEDS_RPM:
            for ld in MAP_LOADS_N:
                modes = spindle_map_modes(direction, sp, ld)
                h = frf_sum(modes, f)
                sd = noise * float(np.max(np.abs(h))) / math.sqrt(2.0)
                h = h + sd * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))
                out.append(((f, h), modes))
    return out


# ---------------------------------------------------------------------------------------------
# Quick estimator cases (closed forms)
# ---------------------------------------------------------------------------------------------


@case(
    "ident.h1_input_noise_bias",
    source="closed form H1 = H·G_uu/(G_uu + G_mm) (Bendat & Piersol §9.1)",
    reference=0.8,
    unit="1",
    abs_tol=0.01,
    quick=True,
    description="mean |H1|/|H| with input noise of a quarter of the input variance (Welch)",
)
def _h1_bias() -> float:
    from millsense.ident.frf import welch_frf

    fs = 1000.0
    b, a = [0.2, 0.1], [1.0, -0.9, 0.2]
    rng = np.random.default_rng(11)
    u = rng.standard_normal(400_000)
    y = scipy.signal.lfilter(b, a, u)
    est = welch_frf(u + rng.normal(0, 0.5, len(u)), y, fs, resolution_hz=5.0)
    h = scipy.signal.freqz(b, a, worN=est.freq_hz, fs=fs)[1]
    return float(np.mean(np.abs(est.h1 / h)))


@case(
    "ident.stepped_sine_exact",
    source="linear steady state: lock-in fit of a pure sine is exact",
    reference=0.0,
    unit="1",
    abs_tol=1e-9,
    quick=True,
    description="max relative error of the stepped-sine FRF of a noiseless discrete resonator "
    "against freqz at 6 frequencies",
)
def _stepped() -> float:
    from millsense.ident.frf import stepped_sine_frf, stepped_sine_signal

    fs = 1000.0
    b, a = [0.05, 0.02], [1.0, -2 * 0.98 * math.cos(0.3), 0.98**2]
    freqs = [5.0, 30.0, 47.7, 48.0, 120.0, 333.3]
    u = stepped_sine_signal(fs, freqs, settle_s=1.5, dwell_s=0.5, amplitude=2.0)
    y = scipy.signal.lfilter(b, a, u)
    est = stepped_sine_frf(u, y, fs, freqs, settle_s=1.5, dwell_s=0.5)
    exact = scipy.signal.freqz(b, a, worN=freqs, fs=fs)[1]
    return float(np.max(np.abs(est.h1 / exact - 1)))
