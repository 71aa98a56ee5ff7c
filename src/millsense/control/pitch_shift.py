"""Chatter avoidance in parallel turning by a pitch shift of the two tools (seed 001 C15).

Yamada §6 (digest §2.11): two turrets cut the same workpiece with nominally opposed tools. The
regenerative waves left by the two tools cancel when their phase difference is an odd multiple
of π, Δε = 2π(m + ½) (Eq. 6-1). With the phase per revolution φ = 2π f_c / (S/60) (Eq. 6-2),
a change Δθ of the central angle between the tools changes the phase difference by

    Δε = (60 / S) f_c Δθ                                   (Eq. 6-9)

so the pitch shift that cancels chatter at f_c is

    Δθ = 2π (m + ½) S / (60 f_c)                           (Eq. 6-10)

with S the spindle speed in min⁻¹ (rev/min), f_c the chatter frequency in Hz and m = 0, 1, 2, …
(the thesis uses m = 0: a large m tilts the tool to a large negative rake; it computes with the
largest chatter frequency seen, so that Δε ≤ π for the others). Only turret 1 moves, by Δθ/2
around the workpiece axis, keeping its posture; its tool tip moves in the X₁Y′₁ plane by

    Δx₁ = d/2 (1 − cos(Δθ/2))   (radial),   Δy′₁ = d/2 sin(Δθ/2)   (tangential)

with d the current workpiece diameter (the digest's derivation, which reproduces Table 6-4).
No modal model or stability chart is needed. The digest lists no erratum for Eqs. 6-9/6-10.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError

FloatArray = NDArray[np.float64]


def _check(chatter_hz: ArrayLike, spindle_rpm: ArrayLike) -> tuple[FloatArray, FloatArray]:
    f = np.asarray(chatter_hz, dtype=float)
    s = np.asarray(spindle_rpm, dtype=float)
    if np.any(~(f > 0)) or np.any(~(s > 0)):
        raise ConfigError("pitch shift: chatter frequency and spindle speed must be > 0")
    return f, s


def pitch_shift_rad(chatter_hz: ArrayLike, spindle_rpm: ArrayLike, m: int = 0) -> FloatArray:
    """Pitch shift Δθ between the two tools that cancels chatter at ``chatter_hz``, rad.

    Parameters
    ----------
    chatter_hz : chatter frequency f_c, Hz.
    spindle_rpm : spindle speed S, rev/min (min⁻¹).
    m : order, m ≥ 0 (the thesis: 0).

    Returns
    -------
    Δθ = 2π (m + ½) S / (60 f_c), rad (Yamada Eq. 6-10).

    References
    ----------
    Yamada (2017), §6, Eqs. 6-1, 6-9, 6-10; 5.52° at 1200 min⁻¹ and 652 Hz.

    See Also
    --------
    phase_difference_rad, turret_offsets_m
    """
    if m < 0:
        raise ConfigError(f"pitch shift: m = {m} must be ≥ 0")
    f, s = _check(chatter_hz, spindle_rpm)
    return np.asarray(2.0 * math.pi * (m + 0.5) * s / (60.0 * f), dtype=np.float64)


def phase_difference_rad(
    pitch_shift: ArrayLike, chatter_hz: ArrayLike, spindle_rpm: ArrayLike
) -> FloatArray:
    """Phase difference Δε of the regenerative waves for a pitch shift Δθ [rad], rad.

    Δε = (60 / S) f_c Δθ (Yamada Eq. 6-9); S in rev/min, f_c in Hz.
    """
    f, s = _check(chatter_hz, spindle_rpm)
    return np.asarray(60.0 / s * f * np.asarray(pitch_shift, dtype=float), dtype=np.float64)


def turret_offsets_m(
    pitch_shift: ArrayLike, diameter_m: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Tool-tip move of turret 1 turned by Δθ/2 about the workpiece axis, m.

    Parameters
    ----------
    pitch_shift : Δθ, rad (turret 1 moves by half of it).
    diameter_m : current workpiece diameter d, m.

    Returns
    -------
    (Δx₁, Δy′₁): radial d/2 (1 − cos(Δθ/2)) and tangential d/2 sin(Δθ/2), m (digest §2.11,
    derived; reproduces Yamada Table 6-4).
    """
    half = 0.5 * np.asarray(pitch_shift, dtype=float)
    r = 0.5 * np.asarray(diameter_m, dtype=float)
    if np.any(~(r > 0)):
        raise ConfigError("pitch shift: workpiece diameter must be > 0")
    return (
        np.asarray(r * (1.0 - np.cos(half)), dtype=np.float64),
        np.asarray(r * np.sin(half), dtype=np.float64),
    )
