"""A simulated tap test of the tool at rest: impact hammer on the tool tip, accelerometer beside
it (seed 000 Ch. 4 and C5: tap tests at the tool tip, 8192 Hz DAQ; issue 12: the controller's
lobes come from a measurement of the plant, never from its table).

The plant side only: the records a shop would take (hammer force, tip acceleration); their
analysis (H1 and a modal fit, :mod:`millsense.ident`) is the acceptance bench's
(:mod:`millsense.bench.tap_test`). The structure tapped is the plant's truth at rest: the tool
modes the simulator runs (:class:`~millsense.simulator.process_coupling.ToolModes`, receptance
Σ 1/(k_i (1 − r_i² + 2iζ_i r_i)), Aslan Eq. 3.13 with α = ω²/k), before the truth softens them
under load (:mod:`millsense.simulator.realism`).

What the test has that the table lacks (:class:`TapTestOptions`, values from common practice
with a medium impact hammer and a 100 mV/g ICP accelerometer on a Ø50 mm face mill):

- hits that differ: half-sine pulses of 0.25-0.35 ms (a steel tip; the force spectrum's first
  zero near 1.5/T ≈ 5 kHz, above Aslan's 1800 Hz band) and ±25 % in peak force;
- force-sensor noise (0.2 N rms) and accelerometer noise (0.05 m/s² rms: the sensor's floor
  and the shop floor's vibration with the machine idle);
- the hammer 3° off the measured axis (the force has a sin 3° component along the other
  direction) and 3 % transverse sensitivity of the accelerometer: the other direction's modes
  leak into the measured FRF at 0.16 % of their level, and the direct FRF is scaled by cos 3°;
- the accelerometer's 5 g mass riding on the tip (it lowers each mode by m_a/(2 m_r): 0.09 %
  for T1's stiffest mode, modal mass 2.8 kg);
- a holder/spindle mode the table does not list (3.4 kHz, ζ 3 %, 1.5·10⁹ N/m) outside the
  fitting band;
- the DAQ's anti-alias low-pass (zero phase, on both channels alike) and its sampling.

The structure is stepped exactly for a force linear between samples (:func:`simulate_foh`) at
sixteen times the DAQ rate, then filtered and decimated (:func:`daq`). Vectorised: the hits are a
loop over hits, never over samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal
from numpy.typing import NDArray

from millsense.models.modal_ss import ModalStateSpace
from millsense.stability.time_domain import DirectionModes

FloatArray = NDArray[np.float64]

__all__ = ["ModeSet", "TapRecord", "TapTestOptions", "daq", "simulate_foh", "tap_test"]


@dataclass(frozen=True)
class ModeSet:
    """Receptance modes Σ α_r/(s² + 2ζ_r ω_r s + ω_r²) of one input–output pair [m/N].

    Attributes
    ----------
    frequency_hz, damping, alpha : natural frequency [Hz], ζ [-], residue α [1/kg] per mode.
    """

    frequency_hz: tuple[float, ...]
    damping: tuple[float, ...]
    alpha: tuple[float, ...]

    @classmethod
    def from_direction(cls, modes: DirectionModes, added_mass_kg: float = 0.0) -> ModeSet:
        """The modes of one direction of the tool (f, ζ, k), with ``added_mass_kg`` riding on
        the tip: modal mass m = k/ω² becomes m + m_a, ω² = k/(m + m_a), ζ with the same
        damping coefficient c = 2ζωm."""
        w = 2 * np.pi * np.asarray(modes.natural_hz, dtype=float)
        k = np.asarray(modes.stiffness_n_per_m, dtype=float)
        m = k / w**2
        m_new = m + added_mass_kg
        w_new = np.sqrt(k / m_new)
        z_new = np.asarray(modes.damping_ratio) * w * m / (w_new * m_new)
        return cls(tuple(w_new / (2 * np.pi)), tuple(z_new), tuple(1.0 / m_new))

    def scaled(self, factor: float) -> ModeSet:
        """The same modes with every residue times ``factor``."""
        return ModeSet(self.frequency_hz, self.damping, tuple(a * factor for a in self.alpha))

    def __add__(self, other: ModeSet) -> ModeSet:
        return ModeSet(
            self.frequency_hz + other.frequency_hz,
            self.damping + other.damping,
            self.alpha + other.alpha,
        )

    def receptance(self, f_hz: FloatArray) -> NDArray[np.complex128]:
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        out = np.zeros(s.shape, dtype=complex)
        for f, z, a in zip(self.frequency_hz, self.damping, self.alpha, strict=True):
            w = 2 * np.pi * f
            out += a / (s * s + 2 * z * w * s + w * w)
        return out

    def accelerance_ss(self) -> ModalStateSpace:
        """s²·Σ α/(s² + 2ζωs + ω²) = Σα + Σ (−αω² − 2ζωα s)/(…) as a modal state space."""
        w = 2 * np.pi * np.asarray(self.frequency_hz)
        z = np.asarray(self.damping)
        a = np.asarray(self.alpha)
        return ModalStateSpace.from_modes(
            self.frequency_hz, self.damping, -a * w * w, -2 * z * w * a, float(np.sum(a))
        )


def simulate_foh(ss: ModalStateSpace, u: FloatArray, dt: float) -> FloatArray:
    """Response of ``ss`` to an input linear between samples (exact first-order hold).

    Each 2×2 block is stepped as x⁺ = Φx + Γ_a u_k + Γ_b (u_{k+1} − u_k), diagonalised and run
    by :func:`scipy.signal.lfilter` (no per-sample Python loop).
    """
    y = ss.d * u
    u_next = np.append(u[1:], u[-1])
    for k in range(ss.a.shape[0]):
        m = np.zeros((4, 4))
        m[:2, :2] = ss.a[k] * dt
        m[:2, 2] = ss.b[k] * dt
        m[2, 3] = 1.0
        e = scipy.linalg.expm(m)
        phi, ga, gb = e[:2, :2], e[:2, 2], e[:2, 3]
        v = np.outer(u, ga - gb) + np.outer(u_next, gb)  # x_{k+1} = Φ x_k + v_k
        lam, vec = np.linalg.eig(phi)
        w_in = np.linalg.solve(vec, v.T)  # (2, n)
        x = np.empty((2, u.size), dtype=complex)
        for i in range(2):
            # w_{k+1} = λ w_k + in_k, w_0 = 0  →  x_k uses inputs before k
            wk = scipy.signal.lfilter([0.0, 1.0], [1.0, -lam[i]], w_in[i])
            x[i] = wk
        xs = np.real(vec @ x)
        y = y + ss.c[k] @ xs
    return np.asarray(y, dtype=float)


def daq(x: FloatArray, oversample: int, cutoff_fraction: float = 0.95) -> FloatArray:
    """Zero-phase anti-alias low-pass at ``cutoff_fraction`` of the output Nyquist, decimate."""
    if oversample == 1:
        return x
    sos = scipy.signal.butter(12, cutoff_fraction / oversample, output="sos")
    return np.asarray(scipy.signal.sosfiltfilt(sos, x)[::oversample], dtype=float)


@dataclass(frozen=True)
class TapTestOptions:
    """The test and what it has that the modal table lacks (module notes).

    Attributes
    ----------
    sample_rate_hz : DAQ rate [Hz] (Aslan Ch. 4: 8192 Hz).
    n_hits : hits averaged per direction.
    spacing_s : time between hits [s] (the response has decayed long before: T1's slowest
        decay 1/(ζω) is 48 ms).
    peak_force_n, peak_spread : nominal peak force [N] and its uniform spread (±fraction).
    pulse_s : shortest and longest half-sine duration [s].
    force_noise_n, accel_noise_m_s2 : sensor noise, rms [N], [m/s²].
    misalignment_rad : angle of the hammer off the measured axis [rad].
    transverse_sensitivity : accelerometer cross-axis sensitivity [-].
    accelerometer_mass_kg : the accelerometer's mass on the tip [kg].
    extra_mode : an unlisted mode (f [Hz], ζ [-], k [N/m]) in both directions; None: none.
    oversample : simulation rate multiple of the DAQ rate. The first-order hold the force is
        stepped with low-passes it by sinc²(f/f_sim) against its samples: at 16 × 8192 Hz
        that is 0.05 % at 1.6 kHz (0.8 % at 4 ×, a stiffness error of the fit's own making).
    seed : random seed (hit times, amplitudes, widths, noise).
    """

    sample_rate_hz: float = 8192.0
    n_hits: int = 10
    spacing_s: float = 0.6
    peak_force_n: float = 400.0
    peak_spread: float = 0.25
    pulse_s: tuple[float, float] = (0.25e-3, 0.35e-3)
    force_noise_n: float = 0.2
    accel_noise_m_s2: float = 0.05
    misalignment_rad: float = math.radians(3.0)
    transverse_sensitivity: float = 0.03
    accelerometer_mass_kg: float = 0.005
    extra_mode: tuple[float, float, float] | None = (3400.0, 0.03, 1.5e9)
    oversample: int = 16
    seed: int = 0

    def noiseless(self) -> TapTestOptions:
        """The same test without noise, hammer error, accelerometer mass or extra mode (a
        fit of it must give the table back)."""
        from dataclasses import replace

        return replace(
            self,
            force_noise_n=0.0,
            accel_noise_m_s2=0.0,
            misalignment_rad=0.0,
            transverse_sensitivity=0.0,
            accelerometer_mass_kg=0.0,
            extra_mode=None,
        )


@dataclass(frozen=True)
class TapRecord:
    """The records of one direction's test: hammer force [N] and tip acceleration [m/s²]."""

    direction: str
    sample_rate_hz: float
    force_n: FloatArray
    accel_m_s2: FloatArray


def _hammer(opts: TapTestOptions, rng: np.random.Generator) -> FloatArray:
    """The hammer force at the simulation rate: ``n_hits`` half-sines of random width and
    peak, one per ``spacing_s`` (start jittered by ±10 ms)."""
    fs = opts.sample_rate_hz * opts.oversample
    n = round((opts.n_hits + 1) * opts.spacing_s * fs)
    t = np.arange(n) / fs
    force = np.zeros(n)
    widths = rng.uniform(*opts.pulse_s, opts.n_hits)
    peaks = opts.peak_force_n * (1 + opts.peak_spread * rng.uniform(-1, 1, opts.n_hits))
    starts = (np.arange(opts.n_hits) + 0.5) * opts.spacing_s + rng.uniform(-0.01, 0.01, opts.n_hits)
    for t0, w, p in zip(starts, widths, peaks, strict=True):  # per hit, not per sample
        i0, i1 = np.searchsorted(t, [t0, t0 + w])
        force[i0:i1] = p * np.sin(np.pi * (t[i0:i1] - t0) / w)
    return force


def tap_test(
    measured: DirectionModes,
    other: DirectionModes,
    direction: str,
    opts: TapTestOptions = TapTestOptions(),
) -> TapRecord:
    """Tap the tool tip along one direction and record force and acceleration.

    Parameters
    ----------
    measured : the truth's modes along the tapped direction (at rest).
    other : the truth's modes along the other direction (reached by the hammer's
        misalignment and the accelerometer's transverse sensitivity).
    direction : name of the tapped direction (``"x"`` or ``"y"``; for the record).
    opts : the test (module notes).

    Returns
    -------
    TapRecord at the DAQ rate, sensor noise included.
    """
    seed = opts.seed + (0 if direction == "x" else 1000)
    rng = np.random.default_rng(seed)
    over = opts.oversample
    fs = opts.sample_rate_hz * over
    force = _hammer(opts, rng)
    d = math.cos(opts.misalignment_rad)
    c = math.sin(opts.misalignment_rad) * opts.transverse_sensitivity
    ma = opts.accelerometer_mass_kg
    modes = ModeSet.from_direction(measured, ma).scaled(d)
    if other.natural_hz.size and c != 0.0:
        modes = modes + ModeSet.from_direction(other, ma).scaled(c)
    if opts.extra_mode is not None:
        f, z, k = opts.extra_mode
        modes = modes + ModeSet((f,), (z,), ((2 * math.pi * f) ** 2 / k * d,))
    accel = daq(simulate_foh(modes.accelerance_ss(), force, 1.0 / fs), over)
    f_daq = daq(force, over)
    f_daq = f_daq + opts.force_noise_n * rng.standard_normal(f_daq.size)
    accel = accel + opts.accel_noise_m_s2 * rng.standard_normal(accel.size)
    return TapRecord(direction, opts.sample_rate_hz, f_daq, accel)
