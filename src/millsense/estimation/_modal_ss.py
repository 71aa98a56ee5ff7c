"""Minimal modal state-space realisation for the estimation examples (private).

``machine/modal_ss.py`` (another helper) is the project's modal realisation; this one exists
only so the Kalman toolkit's worked examples and tests do not depend on it, and can be swapped
for it. Aslan Eq. 3.13: ``Φ(s) = Σ_k (α_k + β_k s) / (s² + 2ζ_k ω_k s + ω_k²)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from millsense.estimation.kalman import StateSpaceModel

#: Aslan Table 3.4 (digest P5): per axis (f_n [Hz], ζ [-], α, β). ζ is printed in % for X, Y, Z
#: and as a fraction for A and C (digest P5: the A1 row of Appendix A equals −Σ2ζω_n only so).
ASLAN_TABLE_3_4: dict[str, tuple[tuple[float, float, float, float], ...]] = {
    "x": (
        (36.1, 0.047, 3042.0, 38.1),
        (40.2, 0.0214, 9413.0, 47.1),
        (42.0, 0.035, -292.0, 86.8),
        (62.5, 0.05, 24575.0, 152.5),
        (145.0, 0.05, 34073.0, -18.7),
        (179.0, 0.0423, 195281.0, -99.0),
    ),
    "y": (
        (16.3, 0.0496, 518.0, 1.3),
        (31.0, 0.029, 2719.0, 7.1),
        (36.0, 0.033, 6183.0, 7.8),
        (47.0, 0.028, 2673.0, -10.2),
        (52.0, 0.05, 15591.0, 9.98),
        (63.5, 0.06, 8849.0, 21.1),
        (71.0, 0.022, 11459.0, 3.9),
        (77.5, 0.03, 57547.0, 96.1),
        (85.0, 0.022, 16125.0, 17.4),
        (102.0, 0.012, 5831.0, -10.0),
        (130.0, 0.098, 22339.0, 115.6),
        (180.0, 0.039, -108153.0, -158.2),
    ),
    "z": (
        (39.0, 0.07, -1913.0, 43.1),
        (43.0, 0.0381, 3980.0, -3.3),
        (63.74, 0.0497, 29270.0, 55.8),
        (86.0, 0.004, 852.0, -1.5),
        (89.0, 0.062, 109192.0, 185.1),
        (92.5, 0.03, -38413.0, 10.1),
        (150.5, 0.018, 30800.0, 34.9),
        (183.3, 0.0031, 11631.0, 4.7),
    ),
    "a": (
        (19.9, 0.69, -8053.0, -26.2),
        (50.0, 0.47, -123072.0, 263.9),
        (63.86, 0.22, 105425.0, -132.0),
        (81.31, 0.16, 14992.0, -115.0),
        (167.8, 0.122, 140159.0, -44.6),
        (176.34, 0.13, -116470.0, 74.6),
    ),
    "c": (
        (45.3, 0.14, -11820.0, -244.0),
        (52.6, 0.086, 70505.0, 453.6),
        (66.3, 0.035, 30915.0, 16.6),
        (75.2, 0.022, 9365.0, 6.44),
        (98.9, 0.052, -1126.0, -65.5),
    ),
}

#: Aslan Eq. 3.30 (digest P4): per axis (R, Q).
ASLAN_EQ_3_30: dict[str, tuple[float, float]] = {
    "x": (0.0776, 200.0),
    "y": (0.1159, 700.0),
    "z": (0.6665, 2000.0),
    "a": (1.0235, 800.0),
    "c": (1.4903, 10000.0),
}

ASLAN_C_AXIS_MODES = ASLAN_TABLE_3_4["c"]


def modal_state_space(modes: Sequence[tuple[float, float, float, float]]) -> StateSpaceModel:
    """Continuous realisation of Eq. 3.13 in 2×2 blocks, one per mode.

    Parameters
    ----------
    modes : (f_n [Hz], ζ [-], α [1/s²], β [1/s]) per mode.

    Notes
    -----
    Mode k has states ``z₁ = ω_k·ξ``, ``z₂ = ξ̇`` with ``ξ̈ + 2ζω ξ̇ + ω² ξ = u``:
    ``ż₁ = ω z₂``, ``ż₂ = −ω z₁ − 2ζω z₂ + u``, ``y = (α/ω) z₁ + β z₂``; the scaling by ω keeps
    both states of the same magnitude. D = 0 (Eq. 3.13 is strictly proper).
    """
    n = 2 * len(modes)
    a = np.zeros((n, n))
    b = np.zeros((n, 1))
    c = np.zeros((1, n))
    for k, (fn, zeta, alpha, beta) in enumerate(modes):
        w = 2 * np.pi * fn
        i = 2 * k
        a[i, i + 1] = w
        a[i + 1, i] = -w
        a[i + 1, i + 1] = -2 * zeta * w
        b[i + 1, 0] = 1.0
        c[0, i] = alpha / w
        c[0, i + 1] = beta
    return StateSpaceModel(a, b, c, np.zeros((1, 1)))
