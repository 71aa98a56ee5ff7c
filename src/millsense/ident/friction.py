"""Friction identification from constant-velocity moves (Aslan C1, Ch. 3.2.1).

At constant speed the torque balance (Aslan Eq. 3.1) has no inertia term, so the mean motor
torque ``K_t·ī`` of an air move equals the friction torque at that speed. Fitting
``τ = τ_coul + σ2·ω`` per direction by least squares over several speeds gives the Coulomb and
viscous parameters of the static friction model (the LuGre static parameters of issue 6 extend
this with the Stribeck term).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from millsense.core.errors import InputDataError
from millsense.machine.friction import CoulombViscous


@dataclass(frozen=True)
class LineFit:
    """``τ = intercept + slope·|ω|`` for one direction, with the RMS residual (N·m)."""

    intercept: float
    slope: float
    rms_residual: float


def fit_line(speed_rad_s: np.ndarray, torque_nm: np.ndarray) -> LineFit:
    """Least-squares Coulomb (intercept) and viscous (slope) torque for one direction.

    Parameters
    ----------
    speed_rad_s : mean motor speeds of the moves, rad/s, all of one sign (at least two).
    torque_nm : mean motor torques ``K_t·ī`` of the same moves, N·m.
    """
    w = np.abs(np.asarray(speed_rad_s, dtype=float))
    tau = np.abs(np.asarray(torque_nm, dtype=float))
    if len(w) < 2 or np.ptp(w) <= 0:
        raise InputDataError("friction fit needs constant-velocity moves at two speeds or more")
    a = np.column_stack([np.ones_like(w), w])
    coef, *_ = np.linalg.lstsq(a, tau, rcond=None)
    res = tau - a @ coef
    return LineFit(float(coef[0]), float(coef[1]), float(np.sqrt(np.mean(res**2))))


def coulomb_viscous_from_moves(
    speed_rad_s: np.ndarray, torque_nm: np.ndarray, smoothing_rad_s: float = 1e-3
) -> CoulombViscous:
    """Direction-dependent Coulomb + viscous friction from moves in both directions.

    Moves with positive mean speed give the positive-direction parameters, negative ones the
    negative-direction parameters. With moves in one direction only, both directions get the
    same values (stated in the returned model by equal fields).
    """
    w = np.asarray(speed_rad_s, dtype=float)
    tau = np.asarray(torque_nm, dtype=float)
    pos, neg = w > 0, w < 0
    fits = {}
    for name, sel in (("pos", pos), ("neg", neg)):
        if sel.sum() >= 2:
            fits[name] = fit_line(w[sel], tau[sel])
    if not fits:
        raise InputDataError("friction fit needs constant-velocity moves at two speeds or more")
    p = fits.get("pos", fits.get("neg"))
    n = fits.get("neg", p)
    assert p is not None and n is not None
    return CoulombViscous(p.intercept, n.intercept, p.slope, n.slope, smoothing_rad_s)
