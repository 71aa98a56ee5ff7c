"""Estimate vs truth: mean and tooth-harmonic amplitudes over the steady cut.

Aslan V1 (seed 000 §3.6) compares estimated and measured forces at the tooth passing frequency
and its harmonics. Here the truth is the simulator's ``truth/{axis}/load``; the window is the
longest stretch in cut (``truth/process/engagement`` ≥ 0), trimmed by 20 % at each end to drop
entry and exit transients (the whole record, trimmed, when the channel is absent). Amplitudes
are the least-squares fit of ``c₀ + Σ_k (a_k cos kω_t t + b_k sin kω_t t)`` at the tooth
frequency ``ω_t = N·Ω̄`` (Ω̄ the mean of ``spindle/speed`` over the window): exact for a
periodic signal sampled over any length, no leakage from a non-integer number of periods.
The error per harmonic is ``| |Ê_k| − |T_k| | / |T_k|`` (amplitude error, as the thesis' spectra
compare amplitudes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError


@dataclass(frozen=True)
class HarmonicComparison:
    """One estimate against truth on one axis.

    Attributes
    ----------
    method, axis : estimator and axis.
    tooth_hz : tooth passing frequency, Hz.
    harmonics : harmonic orders 1…n.
    est_amp, true_amp : amplitudes at the harmonics (N or N·m).
    error : relative amplitude error per harmonic.
    mean_est, mean_true : means over the window.
    window : (first, last+1) sample of the window (truth time base).
    """

    method: str
    axis: str
    tooth_hz: float
    harmonics: NDArray[np.int64]
    est_amp: NDArray[np.float64]
    true_amp: NDArray[np.float64]
    error: NDArray[np.float64]
    mean_est: float
    mean_true: float
    window: tuple[int, int]

    @property
    def mean_error(self) -> float:
        """Relative error of the mean, ``(mean_est − mean_true)/|mean_true|``."""
        return (self.mean_est - self.mean_true) / max(abs(self.mean_true), 1e-300)


def cut_window(
    engagement: NDArray[np.float64] | None, n: int, trim: float = 0.2
) -> tuple[int, int]:
    """Longest run with ``engagement ≥ 0`` (whole record if None), trimmed at both ends."""
    if engagement is None:
        i0, i1 = 0, n
    else:
        cut = np.concatenate([[False], np.asarray(engagement) >= 0, [False]])
        edges = np.flatnonzero(np.diff(cut.astype(np.int8)))
        if len(edges) < 2:
            raise InputDataError("estimate vs truth: the recording never cuts")
        starts, stops = edges[0::2], edges[1::2]
        k = int(np.argmax(stops - starts))
        i0, i1 = int(starts[k]), int(stops[k])
    d = int(trim * (i1 - i0))
    return i0 + d, i1 - d


def harmonic_fit(
    x: NDArray[np.float64], fs: float, f0_hz: float, n_harm: int
) -> tuple[float, NDArray[np.complex128]]:
    """Mean and complex amplitudes (``a_k − j b_k``, |·| the amplitude) at ``k·f0``, k = 1…n."""
    t = np.arange(len(x)) / fs
    cols = [np.ones_like(t)]
    for k in range(1, n_harm + 1):
        w = 2 * np.pi * k * f0_hz * t
        cols += [np.cos(w), np.sin(w)]
    coef = np.linalg.lstsq(np.column_stack(cols), x, rcond=None)[0]
    return float(coef[0]), np.asarray(coef[1::2] - 1j * coef[2::2], dtype=np.complex128)


def compare(
    method: str,
    axis: str,
    estimate: NDArray[np.float64],
    truth: NDArray[np.float64],
    spindle_speed_rad_s: NDArray[np.float64],
    fs: float,
    flutes: int,
    *,
    delay_samples: int = 0,
    engagement: NDArray[np.float64] | None = None,
    n_harm: int = 6,
) -> HarmonicComparison:
    """Compare ``estimate`` (lagging by ``delay_samples``) with ``truth`` on the steady cut.

    Parameters
    ----------
    estimate, truth : load channels, N or N·m (same sign convention).
    spindle_speed_rad_s : measured spindle speed, rad/s.
    fs : sample rate, Hz.
    flutes : teeth on the cutter.
    delay_samples : the estimate at sample k + delay is of sample k.
    engagement : ``truth/process/engagement`` (−1 in air) or None.
    n_harm : harmonics compared.
    """
    n = len(truth)
    i0, i1 = cut_window(engagement, n)
    i1 = min(i1, n - delay_samples)
    if i1 - i0 < 10:
        raise InputDataError("estimate vs truth: steady cut too short to compare")
    est = np.asarray(estimate, dtype=float)[i0 + delay_samples : i1 + delay_samples]
    tru = np.asarray(truth, dtype=float)[i0:i1]
    omega = float(np.mean(spindle_speed_rad_s[i0:i1]))
    f_tooth = flutes * abs(omega) / (2 * np.pi)
    if not f_tooth > 0:
        raise InputDataError("estimate vs truth: spindle not turning in the cut window")
    me, ce = harmonic_fit(est, fs, f_tooth, n_harm)
    mt, ct = harmonic_fit(tru, fs, f_tooth, n_harm)
    ae, at = np.abs(ce), np.abs(ct)
    err = np.abs(ae - at) / np.maximum(at, 1e-300)
    return HarmonicComparison(
        method,
        axis,
        f_tooth,
        np.arange(1, n_harm + 1),
        ae,
        at,
        err,
        me,
        mt,
        (i0, i1),
    )
