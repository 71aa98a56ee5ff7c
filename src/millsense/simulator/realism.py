"""Realism the estimators' models lack: switchable, seeded departures from the identified model.

Estimators are built on the identified models (Aslan Table 3.2 friction, Table 3.4 modes,
App. E spindle modes); the virtual machine departs from them in ways the seeds report:

- **position-dependent modes** (Aslan App. C: the drive FRFs change with axis position and are
  coupled): the natural frequencies of an axis' disturbance modes scale by
  ``1 + δ·u`` with ``u = clip((q − q_c)/q_h, −1, 1)`` the normalised position of that axis
  (δ seeded in ±[2, 6] %; decision "Realism magnitudes"), realised as a table of 9
  discretisations switched per block;
- **friction drift**: Coulomb, static and viscous friction scale by
  ``(1 − k_T·T)·(1 + r·sin(2π q/λ + ψ))`` with a first-order temperature ``T`` (K above
  ambient) heated by the friction power (time constant 600 s), k_T = 0.4 %/K, a position
  ripple r seeded in [1, 3] % with λ = 10 screw revolutions;
- **modes above the identified band**: one or two seeded modes per axis between 1.5 and 3 times
  the highest identified frequency, residues scaled to 2 % of the static gain;
- **tool/spindle modes that change with speed and load** (Aslan Ch. 4: 980 → 800 Hz under
  load): the tool-mode frequencies of the chatter model scale by
  ``1 − 0.184·min(1, |T|/T_ref)`` (T the cutting torque, T_ref = 10 N·m; 0.184 = 1 − 800/980)
  and by ``1 − 0.03·(Ω/Ω_max)²`` (decision "Realism magnitudes"), updated in 1 % steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError

#: Tool-mode frequency drop under full load, 1 − 800/980 (Aslan Ch. 4).
LOAD_SHIFT = 1.0 - 800.0 / 980.0


@dataclass(frozen=True)
class RealismOptions:
    """Switches of the realism layer (all on when ``enabled``; on by default, decision 0976)."""

    enabled: bool = True
    position_modes: bool = True
    friction_drift: bool = True
    high_modes: bool = True
    spindle_load: bool = True
    torque_ref_nm: float = 10.0
    thermal_time_constant_s: float = 600.0
    thermal_resistance_k_w: float = 0.5
    friction_temp_coeff_1_k: float = 0.004

    def __post_init__(self) -> None:
        if not (self.torque_ref_nm > 0 and self.thermal_time_constant_s > 0):
            raise ConfigError("realism: torque_ref_nm and thermal_time_constant_s must be > 0")


def high_modes(
    axis: FeedAxisConfig, rng: np.random.Generator
) -> tuple[list[float], list[float], list[float], list[float]]:
    """Seeded modes above the identified band of an axis: (f Hz, ζ, α, β) lists.

    Residues are chosen so that each mode's static contribution α/ω² is 2 % of the
    identified static gain's magnitude (at least 0.01).
    """
    dm = axis.disturbance_modes
    if dm is None:
        return [], [], [], []
    f_top = max(dm.natural_frequency_hz)
    w = 2 * np.pi * np.asarray(dm.natural_frequency_hz)
    g0 = abs(float(np.sum(np.asarray(dm.alpha) / w**2)))
    count = int(rng.integers(1, 3))
    f = sorted(float(x) for x in rng.uniform(1.5 * f_top, 3.0 * f_top, count))
    zeta = [float(x) for x in rng.uniform(0.02, 0.05, count)]
    alpha = [0.02 * max(g0, 0.01) * (2 * math.pi * fi) ** 2 for fi in f]
    return f, zeta, alpha, [0.0] * count


@dataclass
class AxisRealism:
    """Per-axis seeded parameters of the position and friction departures."""

    mode_shift: float  #: δ, fraction of frequency change at the travel end
    centre: float  #: q_c, m or rad
    half_range: float  #: q_h, m or rad
    ripple: float  #: r, fraction
    ripple_wavelength: float  #: λ, m or rad of axis travel
    ripple_phase: float  #: ψ, rad
    temperature_k: float = 0.0

    @classmethod
    def seeded(
        cls, rng: np.random.Generator, centre: float, half_range: float, transmission: float
    ) -> AxisRealism:
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return cls(
            mode_shift=sign * float(rng.uniform(0.02, 0.06)),
            centre=centre,
            half_range=max(half_range, 1e-6),
            ripple=float(rng.uniform(0.01, 0.03)),
            ripple_wavelength=10 * 2 * math.pi * transmission,
            ripple_phase=float(rng.uniform(0, 2 * math.pi)),
        )

    def mode_scale(self, q: float) -> float:
        """Frequency scale of the disturbance modes at axis position q."""
        u = min(max((q - self.centre) / self.half_range, -1.0), 1.0)
        return 1.0 + self.mode_shift * u

    def friction_scale(
        self, q: float, friction_power_w: float, dt_s: float, opts: RealismOptions
    ) -> float:
        """Advance the temperature by ``dt_s`` and return the friction scale at q."""
        t_ss = opts.thermal_resistance_k_w * friction_power_w
        a = math.exp(-dt_s / opts.thermal_time_constant_s)
        self.temperature_k = t_ss + (self.temperature_k - t_ss) * a
        ripple = 1.0 + self.ripple * math.sin(
            2 * math.pi * q / self.ripple_wavelength + self.ripple_phase
        )
        return (1.0 - opts.friction_temp_coeff_1_k * self.temperature_k) * ripple


def tool_mode_scale(
    torque_nm: float, speed_rad_s: float, max_speed_rad_s: float, opts: RealismOptions
) -> float:
    """Frequency scale of the tool modes under load and speed, rounded to 1 % steps."""
    load = min(1.0, abs(torque_nm) / opts.torque_ref_nm)
    sp = min(1.0, abs(speed_rad_s) / max_speed_rad_s) if max_speed_rad_s > 0 else 0.0
    s = (1.0 - LOAD_SHIFT * load) * (1.0 - 0.03 * sp**2)
    return round(s * 100.0) / 100.0


def friction_columns(kind: str) -> list[int]:
    """Indices of the friction parameter array that scale with the drift (force levels)."""
    if kind == "lugre":  # σ0±, σ1±, σ2±, τ_s±, τ_c±, v_s±
        return [4, 5, 6, 7, 8, 9]
    return [0, 1, 2, 3]  # Coulomb±, viscous±
