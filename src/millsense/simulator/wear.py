"""Tool flank wear of the virtual machine (truth): worn-tool cutting coefficients and the
growth of the flank wear land over a tool's life (issue 20, item 2; decision 2001).

The seeds leave wear as future work (Aslan ch. 7). The virtual machine follows the
mechanistic worn-tool literature (Smithey, Kapoor & DeVor, *Machining Science and Technology*
5(1), 2001: the worn-tool force is the sharp-tool force plus a force on the flank wear land):

* **Flank land force.** A land of width VB rubs the machined surface with a normal stress σ
  and a friction coefficient μ; per unit length of cutting edge in contact it adds a radial
  (normal) force σ·VB and a tangential force μ·σ·VB — exactly the form of the edge
  coefficients of the linear model (Altintas ch. 2), so ΔK_re = σ·VB_eff, ΔK_te = μ·σ·VB_eff.
  Beyond a critical land width the stress near the trailing edge of the land relaxes
  (Smithey's plastic/elastic split); the truth uses a piecewise-linear effective land
  VB_eff = VB for VB ≤ VB*, VB* + ρ (VB − VB*) beyond (ρ < 1).
* **Edge rounding.** The worn edge also cuts with a blunter effective rake: the shear
  coefficients grow by a fraction per millimetre of VB (``shear_growth_per_mm``).
* **Growth.** VB against the cutting time at the reference speed follows the three stages
  of every wear curve (break-in, steady, accelerated): VB(t) = VB_b (1 − e^{−t/τ_b}) + r t
  + VB_c (e^{t/τ_c} − 1), with Taylor's speed dependence (V Tⁿ = C) folded into an
  equivalent time t = t_cut (V/V_ref)^{1/n}.

The monitor (:mod:`millsense.monitoring.wear`) never reads this module: it believes a
linear land model with its own generic parameters, so the simulated wear is a plant the
monitor's model does not share (decision 2001).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from millsense.core.errors import ConfigError
from millsense.process.coefficients import CuttingCoefficients

__all__ = ["FlankWearModel"]


@dataclass(frozen=True)
class FlankWearModel:
    """Truth flank-wear model of the virtual machine (SI; module docstring, decision 2001).

    Attributes
    ----------
    contact_stress_n_m2 : σ, normal stress on the flank wear land (160 N/mm², a fraction of
        the flow stress of a 7xxx aluminium alloy).
    flank_friction : μ, tangential over normal force on the land.
    critical_land_m : VB*, land width beyond which the land's stress relaxes.
    relaxed_fraction : ρ, share of the land beyond VB* that still carries σ.
    shear_growth_per_mm : fractional growth of K_tc, K_rc, K_ac per mm of VB.
    breakin_vb_m, breakin_time_s : VB_b, τ_b of the break-in stage.
    steady_rate_m_s : r, VB growth rate of the steady stage.
    accel_vb_m, accel_time_s : VB_c, τ_c of the accelerated stage.
    reference_speed_m_s : V_ref, cutting speed at which the times above hold.
    taylor_n : Taylor's exponent n (V Tⁿ = C) for other speeds.
    """

    contact_stress_n_m2: float = 160e6
    flank_friction: float = 0.45
    critical_land_m: float = 0.2e-3
    relaxed_fraction: float = 0.6
    shear_growth_per_mm: float = 0.25
    breakin_vb_m: float = 0.05e-3
    breakin_time_s: float = 300.0
    steady_rate_m_s: float = 0.002e-3 / 60.0
    accel_vb_m: float = 0.005e-3
    accel_time_s: float = 1800.0
    reference_speed_m_s: float = 60.0 / 60.0
    taylor_n: float = 0.3

    def __post_init__(self) -> None:
        for name in ("contact_stress_n_m2", "critical_land_m", "breakin_time_s", "accel_time_s",
                     "reference_speed_m_s", "taylor_n"):  # fmt: skip
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"wear model: {name} must be > 0, got {v!r}")
        for name in ("flank_friction", "shear_growth_per_mm", "breakin_vb_m",
                     "steady_rate_m_s", "accel_vb_m"):  # fmt: skip
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"wear model: {name} must be ≥ 0, got {v!r}")
        if not 0.0 <= self.relaxed_fraction <= 1.0:
            raise ConfigError("wear model: relaxed_fraction must be in [0, 1]")

    def effective_land_m(self, vb_m: float) -> float:
        """VB_eff: the land width carrying the full stress σ (piecewise linear, module doc)."""
        vb = _check_vb(vb_m)
        vs = self.critical_land_m
        return vb if vb <= vs else vs + self.relaxed_fraction * (vb - vs)

    def coefficients(self, sharp: CuttingCoefficients, vb_m: float) -> CuttingCoefficients:
        """The worn tool's coefficients: ΔK_re = σ VB_eff, ΔK_te = μ σ VB_eff, and the shear
        coefficients × (1 + g VB) (module docstring). VB = 0 returns ``sharp`` unchanged."""
        vb = _check_vb(vb_m)
        if vb == 0.0:
            return sharp
        land = self.effective_land_m(vb)
        grow = 1.0 + self.shear_growth_per_mm * vb * 1e3
        return replace(
            sharp,
            ktc=sharp.ktc * grow,
            krc=sharp.krc * grow,
            kac=sharp.kac * grow,
            kte=sharp.kte + self.flank_friction * self.contact_stress_n_m2 * land,
            kre=sharp.kre + self.contact_stress_n_m2 * land,
        )

    def equivalent_time_s(self, cutting_time_s: ArrayLike, cutting_speed_m_s: float) -> np.ndarray:
        """Cutting time at ``cutting_speed_m_s`` as time at the reference speed (Taylor)."""
        t = np.asarray(cutting_time_s, dtype=np.float64)
        v = float(cutting_speed_m_s)
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"wear model: cutting speed must be > 0, got {v!r}")
        if np.any(~np.isfinite(t)) or np.any(t < 0):
            raise ConfigError("wear model: cutting times must be finite and ≥ 0")
        return t * (v / self.reference_speed_m_s) ** (1.0 / self.taylor_n)

    def vb_at(self, equivalent_time_s: ArrayLike) -> np.ndarray:
        """VB [m] after ``equivalent_time_s`` of cutting at the reference speed (three stages)."""
        t = np.asarray(equivalent_time_s, dtype=np.float64)
        if np.any(~np.isfinite(t)) or np.any(t < 0):
            raise ConfigError("wear model: equivalent times must be finite and ≥ 0")
        return (
            self.breakin_vb_m * -np.expm1(-t / self.breakin_time_s)
            + self.steady_rate_m_s * t
            + self.accel_vb_m * np.expm1(t / self.accel_time_s)
        )


def _check_vb(vb_m: float) -> float:
    vb = float(vb_m)
    if not (math.isfinite(vb) and 0.0 <= vb <= 2e-3):
        raise ConfigError(f"flank wear VB must be in [0, 2] mm, got {vb * 1e3:g} mm")
    return vb
