"""The spindle's actual speed from a torque record's own revolutions (decision 1737).

Seed 004's engagement monitor sums each revolution's samples against the spindle angle. A cut
at a set speed recorded with a dynamometer alone has no speed channel, and the set speed is
not the angle: 0.02 % off, the angle slips 2.4° at the fundamental over 33 revolutions (57° at
the 24th order), and the 2 mm depth of a 2-flute cut read 2.10 mm.

The cutting torque repeats every revolution. Demodulated at order h of the set speed, each
revolution of the record (of the set speed's period) gives a phase; where the spindle turns a
fraction ε faster than set, that phase advances by 2π·h·ε a revolution. The slope of the
unwrapped phases over the record (least squares, each revolution weighted by its amplitude
squared) gives ε. h is the order with the largest h × mean amplitude over the revolutions (the
phase's resolution of ε grows with h), among those a 1 % error cannot turn by more than a
quarter turn a revolution. Two passes: the second demodulates at the first pass's speed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: The largest difference between the actual and the set speed searched (1 %).
MAX_SPEED_ERROR = 0.01
#: Samples of a record read at most (the first ones): 1 M samples bound the cost.
MAX_SAMPLES = 1 << 20
#: Fewest whole revolutions a record needs for a slope.
MIN_REVOLUTIONS = 4


def _revolution_phasors(
    x: NDArray[np.float64], period: float, order: int, revs: int
) -> NDArray[np.complex128]:
    """Per revolution r (samples [r·period, (r+1)·period), rounded):
    Σ x(t) e^{−i2π·order·t/period}."""
    t = np.arange(x.shape[0], dtype=np.float64)
    z = x * np.exp(-2j * math.pi * order * t / period)
    edges = np.rint(np.arange(revs + 1) * period).astype(np.int64)
    return np.add.reduceat(z[: edges[-1]], edges[:-1])


def _order(x: NDArray[np.float64], period: float, revs: int) -> int:
    """The order h of the set speed's revolution with the largest h × mean |coefficient|
    over the revolutions (each revolution's own spectrum, so a speed error does not smear it),
    h ≤ 1/(4·MAX_SPEED_ERROR) and below the revolution's Nyquist order."""
    m = int(period)
    spec = np.abs(np.fft.rfft(x[: revs * m].reshape(revs, m), axis=1)).mean(axis=0)
    top = min(int(0.25 / MAX_SPEED_ERROR), spec.shape[0] - 2)
    if top < 1:
        return 0
    h = np.arange(1, top + 1)
    return int(h[np.argmax(h * spec[1 : top + 1])])


def refined_speed_rpm(
    torque: NDArray[np.float64], sample_rate_hz: float, set_rpm: float
) -> float | None:
    """The spindle's speed (rev/min) from ``torque``'s own revolutions near ``set_rpm``, or
    None where the record holds fewer than :data:`MIN_REVOLUTIONS` revolutions, shows no
    revolution (flat), or gives a speed more than :data:`MAX_SPEED_ERROR` off the set one."""
    if not (set_rpm > 0 and sample_rate_hz > 0):
        raise ValueError(
            f"refined_speed_rpm: need a positive speed and rate, got {set_rpm}, {sample_rate_hz}"
        )
    x = np.asarray(torque, dtype=np.float64)[:MAX_SAMPLES]
    if not np.isfinite(x).all():
        return None
    rpm = float(set_rpm)
    for _ in range(2):
        period = sample_rate_hz * 60.0 / rpm
        revs = int(x.shape[0] // period)
        if revs < MIN_REVOLUTIONS:
            return None
        y = x[: int(revs * period)] - float(np.mean(x[: int(revs * period)]))
        h = _order(y, period, revs)
        if h < 1:
            return None
        c = _revolution_phasors(y, period, h, revs)
        w = np.abs(c) ** 2
        if not float(w.sum()) > 0.0:
            return None
        phase = np.unwrap(np.angle(c))
        r = np.arange(revs, dtype=np.float64)
        rm = float(np.sum(w * r) / w.sum())
        slope = float(np.sum(w * (r - rm) * phase) / np.sum(w * (r - rm) ** 2))
        rpm *= 1.0 + slope / (2.0 * math.pi * h)
    if abs(rpm / set_rpm - 1.0) > MAX_SPEED_ERROR:
        return None
    return rpm
