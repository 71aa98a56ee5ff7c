"""Spindle-drive data of the Quaser UX600 (Aslan Ch. 5, Table 5.1/5.2, Eq. 5.7, 5.8, App. E).

Pure data and transfer-function helpers; :mod:`millsense.simulator.spindle` builds the drive.
Mode tables are ``[f_n (Hz), ζ (fraction), α, β]`` per row; Appendix E prints ζ in %.
"""

from __future__ import annotations

import numpy as np

#: Appendix E, range 1 (0–3300 rev/min): ω_n Hz / ζ % / α / β (ζ converted to a fraction).
MODES_RANGE1 = np.array(
    [
        [21.9, 0.83, 8.6e1, -9.1e-1],
        [66.8, 0.94, -9.1e1, -2.9e2],
        [258.8, 0.50, 1.8e1, 6.4e1],
        [457.9, 0.50, -8.9, -1e1],
        [640.0, 0.15, -1.7, 4.4],
        [875.0, 0.12, -4.9e-1, -1.8],
        [1050.0, 0.12, 6.1e-1, 1.0],
        [1350.0, 0.04, -3.5e-1, -9.9e-1],
        [1800.0, 0.03, -2.5e-1, 1.3e-2],
        [2417.0, 0.05, -4.3e-1, 5.4e-1],
    ]
)

#: Appendix E, range 2 (3300–24000 rev/min).
MODES_RANGE2 = np.array(
    [
        [21.4, 0.77, 8.5e1, -1.7e1],
        [232.7, 0.60, -9.1e1, 7.7e1],
        [445.9, 0.35, 4.4, -5.5],
        [666.5, 0.20, -3.6e1, 4.9],
        [843.8, 0.25, 2.7e1, -3.8e1],
        [1157.7, 0.15, 1.7e1, 1.1e1],
        [1355.6, 0.054, -2.3, 3.9e-1],
        [1659.8, 0.109, 8.3, 2.0],
        [1766.2, 0.08, -6.2, 2.2],
        [2415.7, 0.047, -1.0, 2.3],
    ]
)

#: Eq. 5.7 motor admittance I/V = 1/(a·s² + b·s + c): (a, b, c) per range.
ADMITTANCE_RANGE1 = (1.658e-7, 0.002008, 0.7521)
ADMITTANCE_RANGE2 = (5.968e-8, 0.0003651, 0.2106)

#: Eq. 5.8 closed current loop as printed: numerator and denominators (descending powers).
GM_NUM = (0.0093, 3.185, 50.5)
GM_DEN_RANGE1 = (4.973e-10, 6.033e-6, 0.01166, 3.38, 50.5)
GM_DEN_RANGE2 = (1.79e-10, 1.098e-6, 0.00995, 3.353, 50.5)

#: Attenuation of G_dτ in range 1 stated by Aslan Ch. 5.4: (Hz, dB).
ATTENUATION_RANGE1 = (
    (457.0, -32.0),
    (945.0, -39.0),
    (1380.0, -31.0),
    (1811.0, -35.0),
    (2320.0, -29.0),
)


def modal_sum_frf(modes: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Σ_k (α_k + β_k·s)/(s² + 2ζ_k·ω_k·s + ω_k²) at complex ``s`` (rad/s), Aslan Eq. 5.10."""
    out = np.zeros_like(s, dtype=complex)
    for f_n, zeta, alpha, beta in modes:
        w = 2.0 * np.pi * f_n
        out += (alpha + beta * s) / (s * s + 2.0 * zeta * w * s + w * w)
    return out


def printed_current_loop_frf(range_index: int, s: np.ndarray) -> np.ndarray:
    """G_m(s) of Aslan Eq. 5.8 as printed (range 1 or 2)."""
    den = GM_DEN_RANGE1 if range_index == 1 else GM_DEN_RANGE2
    return np.polyval(GM_NUM, s) / np.polyval(den, s)
