"""Closed-form slot-milling average forces and the average-force coefficient identification."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import InputDataError
from millsense.process.coefficients import CuttingCoefficients

FloatArray = NDArray[np.float64]


def slot_average_forces(
    n_flutes: int, axial_depth_m: float, feed_per_tooth_m: ArrayLike, coeffs: CuttingCoefficients
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Average forces on the tool in slot milling (flat end mill, any helix).

    Parameters
    ----------
    n_flutes : int
        Number of flutes N (uniform pitch).
    axial_depth_m : float
        Axial depth of cut a [m].
    feed_per_tooth_m : float or array
        Feed per tooth c [m].
    coeffs : CuttingCoefficients
        Cutting and edge coefficients [N/m², N/m].

    Returns
    -------
    Fx, Fy, Fz : float arrays [N]
        Mean forces on the tool, same shape as ``feed_per_tooth_m``.

    Notes
    -----
    benchmarks.md §3 (Altintas, *Manufacturing Automation* ch. 2):
    F̄x = −(N a K_rc/4) c − N a K_re/π,  F̄y = (N a K_tc/4) c + N a K_te/π,
    F̄z = (N a K_ac/π) c + N a K_ae/2.
    """
    c = np.asarray(feed_per_tooth_m, dtype=float)
    na = n_flutes * axial_depth_m
    fx = -(na * coeffs.krc / 4.0) * c - na * coeffs.kre / math.pi
    fy = (na * coeffs.ktc / 4.0) * c + na * coeffs.kte / math.pi
    fz = (na * coeffs.kac / math.pi) * c + na * coeffs.kae / 2.0
    return fx, fy, fz


@dataclass(frozen=True)
class SlotFit:
    """Result of the average-force identification.

    Attributes
    ----------
    coefficients : CuttingCoefficients
        Identified coefficients [N/m², N/m].
    slopes_n_per_m : (3,) float
        Fitted dF̄/dc for x, y, z [N/m].
    intercepts_n : (3,) float
        Fitted F̄ at c = 0 for x, y, z [N].
    r_squared : (3,) float
        Coefficient of determination of each straight-line fit (x, y, z); NaN when an axis
        has no variation.
    residual_rms_n : (3,) float
        RMS residual of each fit [N].
    std_errors : (6,) float
        Standard errors of (ktc, krc, kac, kte, kre, kae) from the fit residuals
        (NaN with only two feeds).
    """

    coefficients: CuttingCoefficients
    slopes_n_per_m: FloatArray
    intercepts_n: FloatArray
    r_squared: FloatArray
    residual_rms_n: FloatArray
    std_errors: FloatArray


def fit_slot_coefficients(
    feeds_per_tooth_m: ArrayLike,
    fx_avg: ArrayLike,
    fy_avg: ArrayLike,
    fz_avg: ArrayLike,
    n_flutes: int,
    axial_depth_m: float,
) -> SlotFit:
    """Identify the six coefficients from slot average forces at several feeds per tooth.

    Parameters
    ----------
    feeds_per_tooth_m : (n,) float
        Feeds per tooth c_i [m], at least two distinct values.
    fx_avg, fy_avg, fz_avg : (n,) float
        Measured average forces on the tool [N] in the sign convention of
        :func:`slot_average_forces`.
    n_flutes : int
        Number of flutes N.
    axial_depth_m : float
        Axial depth of cut a [m].

    Returns
    -------
    SlotFit

    Notes
    -----
    Each axis is a straight line F̄ = F̄_c c + F̄_e fitted by least squares; inverting the
    closed forms of :func:`slot_average_forces` (Altintas ch. 2):
    K_tc = 4 F̄_yc/(N a), K_te = π F̄_ye/(N a), K_rc = −4 F̄_xc/(N a), K_re = −π F̄_xe/(N a),
    K_ac = π F̄_zc/(N a), K_ae = 2 F̄_ze/(N a).
    """
    c = np.asarray(feeds_per_tooth_m, dtype=float)
    ys = [np.asarray(v, dtype=float) for v in (fx_avg, fy_avg, fz_avg)]
    if c.ndim != 1 or any(y.shape != c.shape for y in ys):
        raise InputDataError("slot identification: feeds and forces must be 1-D, same length")
    if np.unique(c).size < 2:
        raise InputDataError("slot identification: needs at least two distinct feeds per tooth")
    if not all(np.all(np.isfinite(y)) for y in [c, *ys]):
        raise InputDataError("slot identification: feeds and forces must be finite")
    n = c.size
    design = np.column_stack([c, np.ones(n)])
    xtx_inv = np.linalg.inv(design.T @ design)
    slopes = np.zeros(3)
    intercepts = np.zeros(3)
    r2 = np.zeros(3)
    rms = np.zeros(3)
    se_slope = np.zeros(3)
    se_icpt = np.zeros(3)
    for i, y in enumerate(ys):
        beta, *_ = np.linalg.lstsq(design, y, rcond=None)
        resid = y - design @ beta
        slopes[i], intercepts[i] = beta
        ss_res = float(resid @ resid)
        ss_tot = float(np.sum((y - y.mean()) ** 2))
        r2[i] = 1.0 - ss_res / ss_tot if ss_tot > 0 else math.nan
        rms[i] = math.sqrt(ss_res / n)
        if n > 2:
            s2 = ss_res / (n - 2)
            se_slope[i] = math.sqrt(s2 * xtx_inv[0, 0])
            se_icpt[i] = math.sqrt(s2 * xtx_inv[1, 1])
        else:
            se_slope[i] = se_icpt[i] = math.nan
    na = n_flutes * axial_depth_m
    coeffs = CuttingCoefficients(
        ktc=4.0 * slopes[1] / na,
        krc=-4.0 * slopes[0] / na,
        kac=math.pi * slopes[2] / na,
        kte=math.pi * intercepts[1] / na,
        kre=-math.pi * intercepts[0] / na,
        kae=2.0 * intercepts[2] / na,
    )
    std = np.array(
        [
            4.0 * se_slope[1] / na,
            4.0 * se_slope[0] / na,
            math.pi * se_slope[2] / na,
            math.pi * se_icpt[1] / na,
            math.pi * se_icpt[0] / na,
            2.0 * se_icpt[2] / na,
        ]
    )
    return SlotFit(coeffs, slopes, intercepts, r2, rms, std)


def identify_coefficients_from_slot(
    feeds_per_tooth_m: ArrayLike,
    fx_avg: ArrayLike,
    fy_avg: ArrayLike,
    fz_avg: ArrayLike,
    n_flutes: int,
    axial_depth_m: float,
) -> CuttingCoefficients:
    """The six coefficients from slot average forces (see :func:`fit_slot_coefficients`).

    Use :func:`fit_slot_coefficients` for the goodness of fit (R², residuals, standard errors).
    """
    return fit_slot_coefficients(
        feeds_per_tooth_m, fx_avg, fy_avg, fz_avg, n_flutes, axial_depth_m
    ).coefficients
