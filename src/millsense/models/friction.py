"""Friction models of feed drives (motor side: rad, rad/s, N·m).

Pure model functions, shared by the simulator and by the estimators that compensate friction
(the estimators depend on these models, never on the simulator).

The static Coulomb + viscous model here is the rigid-body part of Aslan's LuGre model
(Eq. 3.2 with the bristle state at steady sliding, Eq. 3.4 at |v| ≫ v_s):
``τ_f = τ_coul·sgn(ω) + σ2·ω``, with separate parameters for positive and negative motion
(Aslan Table 3.2 gives them per direction). The dynamic LuGre model belongs to the full
drive simulator (issue 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from millsense.core.config import FrictionConfig


@dataclass(frozen=True)
class CoulombViscous:
    """Direction-dependent Coulomb + viscous friction, motor side.

    Attributes
    ----------
    coulomb_pos, coulomb_neg : Coulomb torque for positive / negative speed, N·m (≥ 0).
    viscous_pos, viscous_neg : viscous coefficient σ2 for positive / negative speed, N·m·s/rad.
    smoothing_rad_s : speed over which sgn(ω) is smoothed as tanh(ω/ω_s), rad/s. A regularised
        sign keeps the simulated plant well posed at rest; 0 gives the discontinuous sign.
    """

    coulomb_pos: float
    coulomb_neg: float
    viscous_pos: float
    viscous_neg: float
    smoothing_rad_s: float = 1e-3

    @classmethod
    def from_config(cls, cfg: FrictionConfig, smoothing_rad_s: float = 1e-3) -> CoulombViscous:
        return cls(
            coulomb_pos=cfg.coulomb_nm[0],
            coulomb_neg=cfg.coulomb_nm[1],
            viscous_pos=cfg.viscous_nm_s_rad[0],
            viscous_neg=cfg.viscous_nm_s_rad[1],
            smoothing_rad_s=smoothing_rad_s,
        )

    def as_array(self) -> np.ndarray:
        """Parameters packed for the numba kernels: [c+, c−, v+, v−, ω_s]."""
        return np.array(
            [
                self.coulomb_pos,
                self.coulomb_neg,
                self.viscous_pos,
                self.viscous_neg,
                self.smoothing_rad_s,
            ]
        )

    def torque(self, speed_rad_s: np.ndarray) -> np.ndarray:
        """Friction torque opposing motion, N·m, for motor speeds in rad/s (vectorised)."""
        w = np.asarray(speed_rad_s, dtype=float)
        if self.smoothing_rad_s > 0:
            sgn = np.tanh(w / self.smoothing_rad_s)
        else:
            sgn = np.sign(w)
        cp, cn, vp, vn = self.coulomb_pos, self.coulomb_neg, self.viscous_pos, self.viscous_neg
        if _same(cp, cn) and _same(vp, vn):  # one direction's coefficients for every sample
            return cp * sgn + vp * w
        pos = w >= 0.0
        coul = np.where(pos, cp, cn)
        visc = np.where(pos, vp, vn)
        return coul * sgn + visc * w


def _same(a: float, b: float) -> bool:
    """``a`` and ``b`` the same number, sign of zero included (then the scalar gives the same
    products as the per-sample selection between them)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


@numba.njit(cache=True)
def coulomb_viscous_torque(speed: float, p: np.ndarray) -> float:
    """Scalar kernel of :meth:`CoulombViscous.torque` for numba loops (``p`` from as_array)."""
    if speed >= 0.0:
        coul, visc = p[0], p[2]
    else:
        coul, visc = p[1], p[3]
    sgn = np.tanh(speed / p[4]) if p[4] > 0.0 else np.sign(speed)
    return coul * sgn + visc * speed
