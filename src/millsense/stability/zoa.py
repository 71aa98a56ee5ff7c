"""Frequency-domain stability: Altintas–Budak zero-order approximation and Tlusty's closed form.

Both reduce to the characteristic equation, per eigenvalue branch λ(ω) of the oriented FRF,

    1 + g · b · (1 − e^{−iωT}) · λ(iω) = 0,

with ``b`` the depth, ``T`` the delay and ``g`` a gain: ``g = K_f`` for orthogonal cutting
(λ the oriented FRF), ``g = −N K_t / (4π)`` for milling (λ an eigenvalue of ``[α][Φ]``,
Altintas & Budak 1995). Writing ``Z = −1/(g λ) = b (1 − e^{−iωT})``::

    b = |Z|² / (2 Re Z)          (Re Z > 0),
    ω T = π − 2 arctan(Im Z / Re Z) + 2 k π,   k = 0, 1, 2, ...

which is Altintas' ``a_lim = −(2π Λ_R / (N K_t)) (1 + κ²)``, ``ε = π − 2 arctan κ`` and, for
orthogonal cutting, Tlusty's ``b_lim = −1 / (2 K_f Re G)``. Spindle speed ``n = 60/(N T)``
(milling, N teeth) or ``60/T`` (turning). Each lobe ``k`` is a curve over the chatter
frequency; the diagram at a speed is the lower envelope of all lobes and branches.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.stability.lobes import LobeResult
from millsense.stability.modal import ModalModel

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def directional_factors(phi_st: float, phi_ex: float, kr_ratio: float) -> FloatArray:
    """Altintas–Budak integrated directional factors [[α_xx, α_xy], [α_yx, α_yy]] [-].

    Parameters
    ----------
    phi_st, phi_ex : engagement window [rad] (clockwise from +y).
    kr_ratio : K_r / K_t [-].

    Notes
    -----
    benchmarks.md §3, evaluated between φ_st and φ_ex:
    α_xx = ½[cos2φ − 2k_rφ + k_r sin2φ], α_xy = ½[−sin2φ − 2φ + k_r cos2φ],
    α_yx = ½[−sin2φ + 2φ + k_r cos2φ], α_yy = ½[−cos2φ − 2k_rφ − k_r sin2φ].
    The mean directional matrix over a tooth period is ``(N/2π)[α]``.
    """
    k = kr_ratio

    def prim(p: float) -> FloatArray:
        c2, s2 = math.cos(2 * p), math.sin(2 * p)
        return 0.5 * np.array(
            [
                [c2 - 2 * k * p + k * s2, -s2 - 2 * p + k * c2],
                [-s2 + 2 * p + k * c2, -c2 - 2 * k * p - k * s2],
            ]
        )

    return prim(phi_ex) - prim(phi_st)


@dataclass(frozen=True)
class LobeCurves:
    """Lobes as curves over the chatter frequency, one row per (lobe k, branch).

    Attributes
    ----------
    rpm, depth_m, chatter_hz : (K, F) spindle speed [rev/min], limiting depth [m] (NaN where
        no chatter is possible) and chatter frequency [Hz].
    """

    rpm: FloatArray
    depth_m: FloatArray
    chatter_hz: FloatArray

    def min_depth(self, rpm_min: float = 0.0, rpm_max: float = math.inf) -> tuple[float, float]:
        """Lowest depth [m] on the curves within a speed range, and its speed [rev/min]."""
        ok = np.isfinite(self.depth_m) & (self.rpm >= rpm_min) & (self.rpm <= rpm_max)
        if not ok.any():
            return math.inf, math.nan
        d = np.where(ok, self.depth_m, np.inf)
        i = np.unravel_index(np.argmin(d), d.shape)
        return float(d[i]), float(self.rpm[i])

    def at_speeds(self, rpm: Sequence[float] | FloatArray) -> LobeResult:
        """Lower envelope at the given speeds (linear interpolation along each curve)."""
        speeds = np.asarray(rpm, dtype=float)
        best = np.full(speeds.shape, np.inf)
        best_f = np.full(speeds.shape, np.nan)
        for n_k, a_k, f_k in zip(self.rpm, self.depth_m, self.chatter_hz, strict=True):
            n0, n1 = n_k[:-1], n_k[1:]
            a0, a1 = a_k[:-1], a_k[1:]
            seg = np.isfinite(a0) & np.isfinite(a1)
            if not seg.any():
                continue
            idx = np.flatnonzero(seg)
            n0, n1, a0, a1 = n0[idx], n1[idx], a0[idx], a1[idx]
            f0, f1 = f_k[idx], f_k[idx + 1]
            lo, hi = np.minimum(n0, n1), np.maximum(n0, n1)
            for j, n in enumerate(speeds):
                hit = np.flatnonzero((lo <= n) & (n <= hi) & (hi > lo))
                if hit.size == 0:
                    continue
                t = (n - n0[hit]) / (n1[hit] - n0[hit])
                a = a0[hit] + t * (a1[hit] - a0[hit])
                q = int(np.argmin(a))
                if a[q] < best[j]:
                    best[j] = a[q]
                    best_f[j] = f0[hit[q]] + t[q] * (f1[hit[q]] - f0[hit[q]])
        return LobeResult(
            speeds, best, best_f, ["hopf" if np.isfinite(b) else "none" for b in best]
        )


def lobe_curves(
    lam: ComplexArray, freq_hz: FloatArray, gain: float, periods_per_rev: int, lobes: int
) -> LobeCurves:
    """Lobe curves from the eigenvalue branches λ (B, F) at frequencies ``freq_hz`` (F,).

    Parameters
    ----------
    lam : eigenvalue branches of the oriented FRF [m/N], shape (B, F).
    freq_hz : chatter frequencies [Hz].
    gain : g of the characteristic equation [N/m²] (module docstring).
    periods_per_rev : delays per revolution (N teeth for milling, 1 for turning).
    lobes : number of lobes k = 0 .. lobes − 1.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = -1.0 / (gain * lam)
        depth = np.abs(Z) ** 2 / (2.0 * Z.real)
        depth = np.where((Z.real > 0) & np.isfinite(depth), depth, np.nan)
        eps = math.pi - 2.0 * np.arctan(Z.imag / Z.real)
    w = 2 * math.pi * freq_hz
    ks = np.arange(lobes)
    T = (eps[None, :, :] + 2 * math.pi * ks[:, None, None]) / w[None, None, :]  # (K, B, F)
    rpm = 60.0 / (periods_per_rev * T)
    Kb = lobes * lam.shape[0]
    return LobeCurves(
        rpm.reshape(Kb, -1),
        np.broadcast_to(depth, T.shape).reshape(Kb, -1).copy(),
        np.broadcast_to(freq_hz, T.shape).reshape(Kb, -1).copy(),
    )


def default_frequency_grid(
    natural_frequencies_hz: Sequence[float], points: int = 6000
) -> FloatArray:
    """Chatter-frequency grid [Hz] from 0.5× the lowest to 2× the highest natural frequency."""
    fn = np.asarray(natural_frequencies_hz, dtype=float)
    return np.linspace(0.5 * fn.min(), 2.0 * fn.max(), points)


def milling_eigen_branches(
    structure: ModalModel, alpha: FloatArray, freq_hz: FloatArray
) -> ComplexArray:
    """Eigenvalues (B, F) of ``[α][Φ(iω)]`` over the flexible directions (B = 1 or 2)."""
    dirs = list(structure.directions)
    Phi = structure.frf(freq_hz)[:, dirs][:, :, dirs]  # (F, d, d)
    P = np.einsum("ab,fbc->fac", alpha[np.ix_(dirs, dirs)], Phi)
    if len(dirs) == 1:
        return P[:, 0, 0][None, :]
    tr = P[:, 0, 0] + P[:, 1, 1]
    det = P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] * P[:, 1, 0]
    root = np.sqrt(tr * tr - 4 * det + 0j)
    return np.stack([(tr + root) / 2, (tr - root) / 2])


def zoa_milling_curves(
    structure: ModalModel,
    flutes: int,
    kt: float,
    kr: float,
    phi_st: float,
    phi_ex: float,
    rpm_min: float,
    freq_hz: FloatArray | None = None,
) -> LobeCurves:
    """ZOA lobe curves of milling (Altintas & Budak 1995) reaching down to ``rpm_min``.

    Parameters
    ----------
    structure : modes in x and y.
    flutes : N.
    kt, kr : cutting coefficients [N/m²].
    phi_st, phi_ex : engagement window [rad].
    rpm_min : lowest speed the lobes must cover [rev/min] (sets the number of lobes).
    freq_hz : chatter-frequency grid [Hz] (default :func:`default_frequency_grid`).
    """
    fn = [md.natural_frequency_hz for md in structure.modes]
    f = default_frequency_grid(fn) if freq_hz is None else np.asarray(freq_hz, dtype=float)
    alpha = directional_factors(phi_st, phi_ex, kr / kt)
    lam = milling_eigen_branches(structure, alpha, f)
    lobes = int(60.0 * f.max() / (flutes * rpm_min)) + 2
    return lobe_curves(lam, f, -flutes * kt / (4 * math.pi), flutes, lobes)


def zoa_lobes(
    structure: ModalModel,
    flutes: int,
    kt: float,
    kr: float,
    phi_st: float,
    phi_ex: float,
    rpm: Sequence[float] | FloatArray,
) -> LobeResult:
    """ZOA lobe diagram at the given speeds [rev/min] (lower envelope of the lobe curves)."""
    speeds = np.asarray(rpm, dtype=float)
    curves = zoa_milling_curves(structure, flutes, kt, kr, phi_st, phi_ex, float(speeds.min()))
    return curves.at_speeds(speeds)


def orthogonal_curves(
    frf: ComplexArray, freq_hz: FloatArray, kf: float, rpm_min: float
) -> LobeCurves:
    """Lobe curves of orthogonal cutting / turning (Tlusty), one delay per revolution.

    Parameters
    ----------
    frf : oriented FRF G(iω) [m/N] at ``freq_hz``.
    freq_hz : [Hz].
    kf : cutting-force coefficient K_f [N/m²].
    rpm_min : lowest speed to cover [rev/min].
    """
    lobes = int(60.0 * np.max(freq_hz) / rpm_min) + 2
    return lobe_curves(np.asarray(frf)[None, :], np.asarray(freq_hz, dtype=float), kf, 1, lobes)


def tlusty_limit(frf: ComplexArray, freq_hz: FloatArray, kf: float) -> tuple[float, float]:
    """Absolute (speed-independent) limit ``b = −1/(2 K_f min Re G)`` [m] and its frequency [Hz].

    Notes
    -----
    benchmarks.md §3 (Tlusty/Tobias): for one mode ``min Re G = −1/(4kζ(1+ζ))`` at
    ``ω = ω_n √(1+2ζ)``.
    """
    i = int(np.argmin(np.real(frf)))
    re = float(np.real(frf[i]))
    if re >= 0:
        return math.inf, math.nan
    return -1.0 / (2.0 * kf * re), float(freq_hz[i])


#: Engaged fraction of the tooth period at or below which flip lobes are expected (0909).
FLIP_ENGAGED_FRACTION = 0.5


def engaged_fraction(flutes: int, phi_st: float, phi_ex: float) -> float:
    """Fraction of each tooth period during which a tooth cuts: N (φ_ex − φ_st) / 2π."""
    return flutes * (phi_ex - phi_st) / (2 * math.pi)


def flip_lobes_expected(flutes: int, phi_st: float, phi_ex: float) -> bool:
    """True when cutting is interrupted enough for period-doubling (flip) lobes (decision 0909).

    ZOA averages the directional matrix over the tooth period and so has only Hopf lobes. The
    time-varying part that creates flip lobes grows as the engaged fraction shrinks
    (Insperger et al. 2003, Merdol & Altintas 2004); for the Insperger 1-DOF benchmark SDM
    charts (5000–25000 rev/min) flip points appear on the lower envelope from a/D = 0.5
    (engaged fraction 0.5 with 2 flutes) down, so the warning starts at an engaged fraction
    of 0.5.
    """
    return engaged_fraction(flutes, phi_st, phi_ex) <= FLIP_ENGAGED_FRACTION + 1e-12
