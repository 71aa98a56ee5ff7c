"""End-mill geometry: flutes, pitch, helix, ball end, runout, axial discs.

Angle convention (used by every module of :mod:`millsense.process` and by
:mod:`millsense.stability.time_domain`; Altintas, *Manufacturing Automation*, ch. 2):

* the feed is along +x, the tool axis along +z, the tool turns clockwise seen from +z;
* an immersion angle φ is measured clockwise from +y, so an edge point at immersion φ and
  radius r sits at (r sin φ, r cos φ) from the spindle axis; the chip thickness of a flat end
  mill is h = c sin φ;
* the spindle angle φ is the immersion of flute 0 at the tool tip (z = 0);
* flute j trails flute j-1 by the pitch angle p_j; its cumulative angle is θ_j = p_1 + … + p_j
  (θ_0 = 0) and its immersion at height z is φ_j(z) = φ − θ_j − ψ(z), where
  ψ(z) = z tan(β)/R is the helix lag (constant lead, β the helix angle at the nominal radius).

Runout: the cutter axis is offset from the spindle axis by ρ (``runout_offset_m``) in the
direction of a virtual flute at cumulative angle λ (``runout_angle_rad``), i.e. the offset
turns with the spindle at immersion φ − λ. To first order in ρ/R the radius of flute j at
height z, measured from the spindle axis, is (Lee Eq. 2.3, rewritten in this convention)

    r_j(z) = R(z) + ρ cos(θ_j + ψ(z) − λ).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from millsense.core.config import ToolConfig
from millsense.core.errors import ConfigError

FloatArray = NDArray[np.float64]

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Discs:
    """Axial discretisation of the engaged part of the tool.

    Attributes
    ----------
    z_m : (n,) float
        Height of each disc centre above the tool tip [m].
    dz_m : (n,) float
        Axial thickness of each disc [m].
    radius_m : (n,) float
        Local nominal radius of the edge at the disc centre [m] (R for a flat end mill).
    kappa_rad : (n,) float
        Axial immersion angle κ [rad] between the tool axis and the surface normal
        (π/2 on the cylinder, 0 at the ball tip).
    lag_rad : (n,) float
        Helix lag angle ψ(z) = z tan β / R at the disc centre [rad].
    edge_length_m : (n,) float
        Length of cutting edge in the disc, dz / sin κ [m] (chip width b of Altintas).
    axial_fraction : (n,) float
        Disc centre height divided by the axial depth, in (0, 1); used to pick the
        engagement layer of the disc.
    """

    z_m: FloatArray
    dz_m: FloatArray
    radius_m: FloatArray
    kappa_rad: FloatArray
    lag_rad: FloatArray
    edge_length_m: FloatArray
    axial_fraction: FloatArray

    @property
    def n(self) -> int:
        """Number of discs."""
        return int(self.z_m.size)


@dataclass(frozen=True)
class EndMill:
    """A flat or ball end mill with N flutes, any pitch, a helix and radial runout.

    Parameters
    ----------
    diameter_m : float
        Nominal diameter D [m].
    n_flutes : int
        Number of flutes N ≥ 1.
    pitch_angles_rad : tuple of float, optional
        Pitch p_j [rad] from flute j-1 to flute j, j = 0 … N-1 (p_0 is from flute N-1 round
        to flute 0). ``None`` means uniform pitch 2π/N. Must be positive and sum to 2π.
    helix_rad : float
        Helix angle β [rad] at the nominal radius, 0 ≤ β < π/2.
    shape : {"flat", "ball"}
        Flat end mill or ball end mill (ball radius = D/2).
    runout_offset_m : float
        Radial offset ρ ≥ 0 [m] of the cutter axis from the spindle axis.
    runout_angle_rad : float
        Angle λ [rad] of the offset, measured like the flute angles θ_j (see module notes).

    Notes
    -----
    Helix lag ψ(z) = z tan β / R (constant lead, as Altintas ch. 2 and Ilme Eq. 2.16 with
    b_h = R / tan α). For a ball end mill the local radius is R(z) = √(R² − (R − z)²) for
    z < R and κ(z) = arcsin(R(z)/R); above z = R the tool is cylindrical.
    """

    diameter_m: float
    n_flutes: int
    pitch_angles_rad: tuple[float, ...] | None = None
    helix_rad: float = 0.0
    shape: Literal["flat", "ball"] = "flat"
    runout_offset_m: float = 0.0
    runout_angle_rad: float = 0.0

    @classmethod
    def from_config(cls, tool: ToolConfig) -> EndMill:
        """From a tool configuration (field units converted to SI there)."""
        return cls(
            diameter_m=tool.diameter_m,
            n_flutes=tool.flutes,
            pitch_angles_rad=tool.pitch_rad,
            helix_rad=tool.helix_rad,
            shape=tool.shape,
            runout_offset_m=tool.runout_m,
            runout_angle_rad=tool.runout_angle_rad,
        )

    def __post_init__(self) -> None:
        if not (math.isfinite(self.diameter_m) and self.diameter_m > 0):
            raise ConfigError(f"tool: diameter_m must be positive, got {self.diameter_m!r}")
        if int(self.n_flutes) != self.n_flutes or self.n_flutes < 1:
            raise ConfigError(f"tool: n_flutes must be an integer ≥ 1, got {self.n_flutes!r}")
        if self.pitch_angles_rad is not None:
            p = self.pitch_angles_rad
            if len(p) != self.n_flutes:
                raise ConfigError(
                    f"tool: pitch_angles_rad has {len(p)} values for {self.n_flutes} flutes"
                )
            if min(p) <= 0 or abs(sum(p) - _TWO_PI) > 1e-6:
                raise ConfigError(
                    f"tool: pitch_angles_rad must be positive and sum to 2π, sum is {sum(p)!r}"
                )
        if not (0.0 <= self.helix_rad < 0.5 * math.pi):
            raise ConfigError(f"tool: helix_rad must be in [0, π/2), got {self.helix_rad!r}")
        if self.shape not in ("flat", "ball"):
            raise ConfigError(f"tool: shape must be 'flat' or 'ball', got {self.shape!r}")
        if not (self.runout_offset_m >= 0 and self.runout_offset_m < 0.5 * self.diameter_m):
            raise ConfigError(
                f"tool: runout_offset_m must be in [0, D/2), got {self.runout_offset_m!r}"
            )

    @property
    def radius_m(self) -> float:
        """Nominal radius R = D/2 [m]."""
        return 0.5 * self.diameter_m

    @property
    def pitches_rad(self) -> FloatArray:
        """Pitch angle p_j of every flute [rad], (N,), summing to 2π."""
        if self.pitch_angles_rad is None:
            return np.full(self.n_flutes, _TWO_PI / self.n_flutes)
        p = np.asarray(self.pitch_angles_rad, dtype=float)
        return p * (_TWO_PI / p.sum())

    @property
    def flute_angles_rad(self) -> FloatArray:
        """Cumulative angle θ_j of flute j behind flute 0 [rad], (N,), θ_0 = 0."""
        p = self.pitches_rad
        return np.concatenate(([0.0], np.cumsum(p[1:])))

    @property
    def lag_per_m(self) -> float:
        """Helix lag rate k_β = tan β / R [rad/m]."""
        return math.tan(self.helix_rad) / self.radius_m

    def discs(self, axial_depth_m: float, n_discs: int = 20) -> Discs:
        """Split the axial depth of cut into ``n_discs`` equal discs from the tip.

        Parameters
        ----------
        axial_depth_m : float
            Axial depth of cut a [m], measured from the tool tip.
        n_discs : int
            Number of discs.

        Returns
        -------
        Discs
            Disc centres, thicknesses, local radius, κ, helix lag and edge length.
        """
        if not (axial_depth_m > 0 and math.isfinite(axial_depth_m)):
            raise ConfigError(f"cut: axial_depth_m must be positive, got {axial_depth_m!r}")
        if n_discs < 1:
            raise ConfigError(f"cut: n_discs must be ≥ 1, got {n_discs!r}")
        dz = axial_depth_m / n_discs
        z: FloatArray = (np.arange(n_discs, dtype=np.float64) + 0.5) * dz
        r_nom = self.radius_m
        if self.shape == "ball":
            zc = np.minimum(z, r_nom)
            radius = np.sqrt(np.maximum(r_nom**2 - (r_nom - zc) ** 2, 0.0))
            kappa = np.arcsin(np.clip(radius / r_nom, 0.0, 1.0))
        else:
            radius = np.full(n_discs, r_nom)
            kappa = np.full(n_discs, 0.5 * math.pi)
        return Discs(
            z_m=z,
            dz_m=np.full(n_discs, dz),
            radius_m=radius,
            kappa_rad=kappa,
            lag_rad=np.asarray(z * self.lag_per_m, dtype=np.float64),
            edge_length_m=dz / np.sin(kappa),
            axial_fraction=np.asarray(z / axial_depth_m, dtype=np.float64),
        )

    def immersion_angles(self, spindle_angle_rad: FloatArray, discs: Discs) -> FloatArray:
        """Immersion angle of every flute edge point, φ_j(z) = φ − θ_j − ψ(z) [rad].

        Parameters
        ----------
        spindle_angle_rad : (n_angles,) float
            Spindle angle φ [rad] (immersion of flute 0 at the tip).
        discs : Discs
            From :meth:`discs`.

        Returns
        -------
        (n_angles, N, n_discs) float
            Immersion angles, not wrapped.
        """
        phi = np.asarray(spindle_angle_rad, dtype=float)
        return (
            phi[:, None, None] - self.flute_angles_rad[None, :, None] - discs.lag_rad[None, None, :]
        )

    def flute_radii_m(self, discs: Discs) -> FloatArray:
        """Radius of every flute at every disc, measured from the spindle axis [m].

        r_j(z) = R(z) + ρ cos(θ_j + ψ(z) − λ) (first order in ρ/R, Lee Eq. 2.3).

        Returns
        -------
        (N, n_discs) float
        """
        arg = self.flute_angles_rad[:, None] + discs.lag_rad[None, :] - self.runout_angle_rad
        return discs.radius_m[None, :] + self.runout_offset_m * np.cos(arg)
