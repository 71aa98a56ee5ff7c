"""Linear edge-force cutting coefficients (mechanistic model, Altintas ch. 2)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from millsense.core.config import MaterialConfig
from millsense.core.errors import ConfigError


@dataclass(frozen=True)
class CuttingCoefficients:
    """Six coefficients of the linear edge-force model.

    dF_t = K_tc h db + K_te dS,  dF_r = K_rc h db + K_re dS,  dF_a = K_ac h db + K_ae dS
    (Altintas, *Manufacturing Automation* ch. 2; Aslan Eq. 5.32; Ilme Eq. 2.33).

    Parameters
    ----------
    ktc, krc, kac : float
        Cutting (shear) coefficients, tangential, radial, axial [N/m²].
    kte, kre, kae : float
        Edge (ploughing) coefficients, tangential, radial, axial [N/m].
    """

    ktc: float
    krc: float
    kac: float = 0.0
    kte: float = 0.0
    kre: float = 0.0
    kae: float = 0.0

    def __post_init__(self) -> None:
        for name in ("ktc", "krc", "kac", "kte", "kre", "kae"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ConfigError(f"cutting coefficients: {name} must be finite, got {v!r}")

    @classmethod
    def from_config(cls, material: MaterialConfig) -> CuttingCoefficients:
        """From a material configuration (field units converted to SI there)."""
        return cls(
            ktc=material.ktc,
            krc=material.krc,
            kac=material.kac,
            kte=material.kte,
            kre=material.kre,
            kae=material.kae,
        )

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        """(ktc, krc, kac, kte, kre, kae) in SI."""
        return (self.ktc, self.krc, self.kac, self.kte, self.kre, self.kae)
