"""Phase-lag (synchronisation) compensation of drive signals: streaming pure delays.

Yamada §2.4 (digest C5): the current command reaches the motor after the amplifier dead time
T_s, the motor angle and the table position reach the CNC after their own dead times T_m and
T_t. Before a multi-encoder observer combines them, each is delayed so that the three paths
have the same total delay (Yamada Fig. 2-5, Table 3-3)::

    T_1 = T_s + T_m + T_2 = T_s + T_t + T_3,   T_1, T_2, T_3 ≥ 0 and minimal

i.e. ``T_1 = T_s + max(T_m, T_t)``: Machine A (0.35, 0.45, 0.1) ms → (0.8, 0, 0.35) ms,
Machine B (0.2, 0.2, 0.2) ms → (0.4, 0, 0) ms (Table 3-3; §2.4.2's "(0.2, 0, 0) ms" is a typo,
digest §7).

Delay realisation (decision docs/decisions/0068-fractional-delays-of-the-phase-lag-compensation.md):
a delay of D samples is a ring of whole samples plus, when D is not an integer, a first-order Thiran
allpass ``(a + z⁻¹)/(1 + a·z⁻¹)``, ``a = (1 − d)/(1 + d)``, whose phase delay is d samples at DC
(d ∈ [0.5, 1.5) where possible, so |a| ≤ 1/3). An allpass keeps the magnitude exactly 1 at every
frequency: the observers subtract large inertia terms from the thrust near the resonance, and the
magnitude droop of linear interpolation (cos(ωT/2) at half a sample) would leave a residue there.
The thesis' delays are whole samples at its sampling rates (0.4 ms at 10 kHz, 0.8/0.35 ms at 20
kHz), for which the ring alone is exact.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

_INT_TOL = 1e-9


def sync_delays(
    amplifier_s: float, motor_encoder_s: float, scale_s: float
) -> tuple[float, float, float]:
    """Compensation delays (T_1, T_2, T_3) for current, motor angle and scale position.

    Parameters
    ----------
    amplifier_s : T_s, dead time from current command to torque, s.
    motor_encoder_s : T_m, dead time of the motor angle, s.
    scale_s : T_t, dead time of the linear-scale position, s.

    Returns
    -------
    (T_1, T_2, T_3) in s: the smallest non-negative delays with equal totals
    ``T_1 = T_s + T_m + T_2 = T_s + T_t + T_3`` (Yamada §2.4, Table 3-3).
    """
    for name, v in (("T_s", amplifier_s), ("T_m", motor_encoder_s), ("T_t", scale_s)):
        if not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"dead time {name} must be finite and ≥ 0, got {v!r}")
    t1 = amplifier_s + max(motor_encoder_s, scale_s)
    return t1, t1 - amplifier_s - motor_encoder_s, t1 - amplifier_s - scale_s


def split_delay(delay_samples: float) -> tuple[int, float]:
    """Whole-sample part and Thiran fraction d of a delay (``N + d = D``; d = 0: no allpass).

    d ∈ [0.5, 1.5) when D ≥ 0.5, otherwise d = D (then the allpass pole is nearer 1 but
    still stable for D > 0).
    """
    if not (math.isfinite(delay_samples) and delay_samples >= 0.0):
        raise ValueError(f"delay must be finite and ≥ 0 samples, got {delay_samples!r}")
    n = round(delay_samples)
    if abs(delay_samples - n) <= _INT_TOL:
        return int(n), 0.0
    if delay_samples < 1.5:
        return 0, float(delay_samples)
    whole = math.floor(delay_samples)
    frac = delay_samples - whole
    d = frac + 1.0 if frac < 0.5 else frac
    return round(delay_samples - d), float(d)


def thiran1_coefficient(d: float) -> float:
    """First-order Thiran allpass coefficient ``a = (1 − d)/(1 + d)`` for a delay d > 0."""
    if not d > 0.0:
        raise ValueError(f"Thiran delay must be > 0, got {d!r}")
    return (1.0 - d) / (1.0 + d)


class StreamingDelay:
    """Delay a signal by ``delay_samples`` (any non-negative real) chunk by chunk.

    Parameters
    ----------
    delay_samples : D, samples (``delay_s · sample_rate``).

    Notes
    -----
    Before the first sample the signal is taken to have held its first value (no start-up
    step). Output is identical whatever the chunking (ring concatenation and ``lfilter`` state).
    """

    def __init__(self, delay_samples: float) -> None:
        self.delay_samples = float(delay_samples)
        self.whole, self.fraction = split_delay(self.delay_samples)
        self._a = thiran1_coefficient(self.fraction) if self.fraction > 0.0 else 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the history."""
        self._hist: NDArray[np.float64] | None = None
        self._zi: NDArray[np.float64] | None = None

    def frf(self, f_hz: ArrayLike, sample_rate_hz: float) -> NDArray[np.complex128]:
        """Frequency response of the delay at ``f_hz`` (Hz)."""
        w = 2.0 * np.pi * np.asarray(f_hz, dtype=float) / sample_rate_hz
        zi = np.exp(-1j * w)
        h = zi**self.whole
        if self.fraction > 0.0:
            h = h * (self._a + zi) / (1.0 + self._a * zi)
        return np.asarray(h, dtype=complex)

    def process(self, x: ArrayLike) -> NDArray[np.float64]:
        """Delay one chunk; returns an array of the same length."""
        arr = np.asarray(x, dtype=float)
        if arr.size == 0:
            return np.zeros(0)
        if self._hist is None:
            self._hist = np.full(self.whole, arr[0])
            if self.fraction > 0.0:
                self._zi = signal.lfilter_zi([self._a, 1.0], [1.0, self._a]) * arr[0]
        if self.whole > 0:
            ext = np.concatenate([self._hist, arr])
            out = ext[: len(arr)].copy()
            self._hist = ext[len(arr) :].copy()
        else:
            out = arr.copy()
        if self.fraction > 0.0:
            assert self._zi is not None
            out, self._zi = signal.lfilter([self._a, 1.0], [1.0, self._a], out, zi=self._zi)
        return np.asarray(out, dtype=float)
