"""Mechanistic milling forces: chip thickness with runout and pitch, linear edge-force model.

Sign convention: the forces are the forces **on the tool** in the feed frame (x along the
feed, z along the tool axis, see :mod:`millsense.process.geometry`). Torque is the cutting
torque the spindle must supply, positive when cutting (power = torque · Ω ≥ 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.geometry import Discs, EndMill

FloatArray = NDArray[np.float64]

_TWO_PI = 2.0 * math.pi


def previous_flute_table(tool: EndMill) -> tuple[NDArray[np.int64], FloatArray]:
    """Flutes that passed before each flute, and the angle since they passed.

    Returns
    -------
    prev : (N, N) int
        ``prev[j, m-1]`` is the flute m places ahead of flute j (m = 1 … N, m = N is flute j
        itself one revolution earlier).
    angle : (N, N) float
        Spindle rotation [rad] between that flute and flute j reaching the same immersion,
        (θ_j − θ_prev) mod 2π, with 2π for m = N.
    """
    n = tool.n_flutes
    theta = tool.flute_angles_rad
    j = np.arange(n)[:, None]
    m = np.arange(1, n + 1)[None, :]
    prev = (j - m) % n
    angle = np.mod(theta[j] - theta[prev], _TWO_PI)
    angle[:, -1] = _TWO_PI
    # Guard against round-off making a full turn look like zero.
    angle = np.where(angle <= 1e-12, _TWO_PI, angle)
    return prev.astype(np.int64), angle


def chip_thickness(
    tool: EndMill,
    engagement: Engagement,
    feed_per_tooth_m: float,
    spindle_angle_rad: FloatArray,
    discs: Discs,
) -> FloatArray:
    """Uncut chip thickness of every flute at every disc and spindle angle [m].

    Parameters
    ----------
    tool : EndMill
        Tool with pitch, helix and runout.
    engagement : Engagement
        Immersion intervals per layer.
    feed_per_tooth_m : float
        Feed per tooth c [m]; the feed per revolution is N c.
    spindle_angle_rad : (n_angles,) float
        Spindle angles φ [rad].
    discs : Discs
        Axial discretisation, from :meth:`EndMill.discs`.

    Returns
    -------
    (n_angles, N, n_discs) float
        h ≥ 0; zero outside the engagement and where the flute does not reach the material.

    Notes
    -----
    The surface at immersion φ was left by whichever earlier flute cut deepest, so
    (Lee Eq. 2.4 generalised to variable pitch and to flutes that leave the cut)

        h_j = sin κ · max(0, min_{m=1…N} [ N c Δθ_jm/(2π) sin φ_j + r_j − r_{j−m} ]),

    with Δθ_jm the rotation since flute j−m passed (the pitch p_j for m = 1) and r the flute
    radii of :meth:`EndMill.flute_radii_m`. With all flutes cutting this is
    h_j = c_j sin φ_j + r_j − r_{j−1}, c_j = N c p_j/(2π). Static feed only; the vibration
    is added by :mod:`millsense.stability.time_domain`.
    """
    phi = tool.immersion_angles(np.asarray(spindle_angle_rad, dtype=float), discs)
    radii = tool.flute_radii_m(discs)  # (N, d)
    prev, angle = previous_flute_table(tool)
    f_rev = tool.n_flutes * feed_per_tooth_m
    sin_phi = np.sin(phi)  # (a, N, d)
    h = None
    for m in range(tool.n_flutes):
        dr = radii - radii[prev[:, m], :]  # (N, d)
        cand = (f_rev * angle[:, m] / _TWO_PI)[None, :, None] * sin_phi + dr[None, :, :]
        h = cand if h is None else np.minimum(h, cand)
    assert h is not None
    h = np.maximum(h, 0.0) * np.sin(discs.kappa_rad)[None, None, :]
    inside = engagement.inside(phi, discs.axial_fraction)
    return np.where(inside, h, 0.0)


@dataclass(frozen=True)
class ToothStats:
    """Statistics of a force record over consecutive complete periods.

    Every array has one entry per complete period (a tooth period 2π/N or a revolution).
    Forces in N, torque in N·m, angles in rad.
    """

    start_angle_rad: FloatArray
    mean_fx_n: FloatArray
    mean_fy_n: FloatArray
    mean_fz_n: FloatArray
    mean_torque_nm: FloatArray
    peak_resultant_n: FloatArray
    mean_resultant_n: FloatArray
    peak_torque_nm: FloatArray


@dataclass
class CuttingForces:
    """Cutting forces on the tool versus spindle angle.

    Attributes
    ----------
    spindle_angle_rad : (n,) float
        Spindle angle φ [rad].
    fx_n, fy_n, fz_n : (n,) float
        Force on the tool [N] along the feed (x), normal to it (y), along the tool axis (z).
    torque_nm : (n,) float
        Cutting torque the spindle supplies [N·m].
    n_flutes : int
        Number of flutes (tooth period 2π/N for the statistics).
    """

    spindle_angle_rad: FloatArray
    fx_n: FloatArray
    fy_n: FloatArray
    fz_n: FloatArray
    torque_nm: FloatArray
    n_flutes: int = 1

    def power_w(self, spindle_speed_rad_s: float) -> FloatArray:
        """Cutting power P = T Ω [W] at spindle speed Ω [rad/s]."""
        return self.torque_nm * float(spindle_speed_rad_s)

    def resultant_n(self, include_z: bool = False) -> FloatArray:
        """Resultant force [N]: √(F_x² + F_y²) (Aslan Eq. 5.33), or with F_z if asked."""
        r2 = self.fx_n**2 + self.fy_n**2
        if include_z:
            r2 = r2 + self.fz_n**2
        return np.sqrt(r2)

    def average(self) -> tuple[float, float, float, float]:
        """Mean (F_x, F_y, F_z [N], torque [N·m]) over all samples."""
        return (
            float(np.mean(self.fx_n)),
            float(np.mean(self.fy_n)),
            float(np.mean(self.fz_n)),
            float(np.mean(self.torque_nm)),
        )

    def rms(self) -> tuple[float, float, float]:
        """Root mean square of F_x, F_y, F_z [N] over all samples."""
        return (
            float(np.sqrt(np.mean(self.fx_n**2))),
            float(np.sqrt(np.mean(self.fy_n**2))),
            float(np.sqrt(np.mean(self.fz_n**2))),
        )

    def _stats(self, period_rad: float) -> ToothStats:
        phi = np.asarray(self.spindle_angle_rad, dtype=float)
        if phi.size < 2 or np.any(np.diff(phi) <= 0):
            raise InputDataError("forces: spindle_angle_rad must be increasing for statistics")
        k = np.floor((phi - phi[0]) / period_rad + 1e-9).astype(np.int64)
        step = float(np.median(np.diff(phi)))
        # A period is complete if samples cover it up to one step short of its end.
        n_complete = int(np.floor((phi[-1] - phi[0] + step) / period_rad + 1e-9))
        keep = k < n_complete
        if n_complete == 0:
            empty = np.zeros(0)
            return ToothStats(empty, empty, empty, empty, empty, empty, empty, empty)
        k = k[keep]
        counts = np.bincount(k, minlength=n_complete).astype(float)
        res = self.resultant_n()[keep]

        def mean(v: FloatArray) -> FloatArray:
            return np.bincount(k, weights=v[keep], minlength=n_complete) / counts

        peak = np.full(n_complete, -np.inf)
        np.maximum.at(peak, k, res)
        peak_t = np.full(n_complete, -np.inf)
        np.maximum.at(peak_t, k, self.torque_nm[keep])
        return ToothStats(
            start_angle_rad=phi[0] + period_rad * np.arange(n_complete),
            mean_fx_n=mean(self.fx_n),
            mean_fy_n=mean(self.fy_n),
            mean_fz_n=mean(self.fz_n),
            mean_torque_nm=mean(self.torque_nm),
            peak_resultant_n=peak,
            mean_resultant_n=np.bincount(k, weights=res, minlength=n_complete) / counts,
            peak_torque_nm=peak_t,
        )

    def per_tooth_period(self) -> ToothStats:
        """Statistics over each complete tooth period 2π/N from the first sample."""
        return self._stats(_TWO_PI / self.n_flutes)

    def per_revolution(self) -> ToothStats:
        """Statistics over each complete revolution from the first sample."""
        return self._stats(_TWO_PI)


def edge_forces(
    tool: EndMill,
    coeffs: CuttingCoefficients,
    engagement: Engagement,
    feed_per_tooth_m: float,
    spindle_angle_rad: FloatArray,
    discs: Discs,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Tangential, radial, axial force of every flute in every disc, and the chip thickness.

    Returns
    -------
    dft, dfr, dfa, h : (n_angles, N, n_discs) float
        Elemental forces [N] and chip thickness [m]. Edge terms act only where h > 0.
    """
    h = chip_thickness(tool, engagement, feed_per_tooth_m, spindle_angle_rad, discs)
    cutting = h > 0.0
    db = discs.edge_length_m[None, None, :]
    hb = h * db
    eb = np.where(cutting, db, 0.0)
    dft = coeffs.ktc * hb + coeffs.kte * eb
    dfr = coeffs.krc * hb + coeffs.kre * eb
    dfa = coeffs.kac * hb + coeffs.kae * eb
    return dft, dfr, dfa, h


def milling_forces(
    tool: EndMill,
    coeffs: CuttingCoefficients,
    engagement: Engagement,
    feed_per_tooth_m: float,
    axial_depth_m: float,
    spindle_angle_rad: FloatArray,
    n_discs: int = 20,
) -> CuttingForces:
    """Cutting forces and torque on a milling tool versus spindle angle (sliced model).

    Parameters
    ----------
    tool : EndMill
        Geometry (flutes, pitch, helix, shape, runout).
    coeffs : CuttingCoefficients
        Linear edge-force coefficients [N/m², N/m].
    engagement : Engagement
        Immersion intervals per axial layer.
    feed_per_tooth_m : float
        Feed per tooth c [m] (≥ 0).
    axial_depth_m : float
        Axial depth of cut a [m].
    spindle_angle_rad : (n,) float
        Spindle angles φ [rad] at which to evaluate.
    n_discs : int
        Number of axial discs.

    Returns
    -------
    CuttingForces
        Forces on the tool [N] and torque [N·m].

    Notes
    -----
    Per flute and disc (Altintas ch. 2; Aslan Eq. 5.32; Ilme Eqs. 2.2–2.5, 2.33):
    dF_t = K_tc h db + K_te dS, dF_r = K_rc h db + K_re dS, dF_a = K_ac h db + K_ae dS with
    db = dS = dz / sin κ, and on the tool

        dF_x = −dF_t cos φ − dF_r sin κ sin φ + dF_a cos κ sin φ
        dF_y = +dF_t sin φ − dF_r sin κ cos φ + dF_a cos κ cos φ
        dF_z = +dF_r cos κ + dF_a sin κ,      dT = r_j dF_t.

    For a flat end mill (κ = π/2) the slot averages are those of benchmarks.md §3. The ball
    end axial sign is chosen so that κ = π/2 reduces to the flat case
    (docs/decisions/0012-ball-end-force-directions.md).
    """
    if not (feed_per_tooth_m >= 0 and math.isfinite(feed_per_tooth_m)):
        raise ConfigError(f"cut: feed_per_tooth_m must be ≥ 0, got {feed_per_tooth_m!r}")
    phi_s = np.atleast_1d(np.asarray(spindle_angle_rad, dtype=float))
    discs = tool.discs(axial_depth_m, n_discs)
    dft, dfr, dfa, _ = edge_forces(tool, coeffs, engagement, feed_per_tooth_m, phi_s, discs)
    phi = tool.immersion_angles(phi_s, discs)
    s, c = np.sin(phi), np.cos(phi)
    sk = np.sin(discs.kappa_rad)[None, None, :]
    ck = np.cos(discs.kappa_rad)[None, None, :]
    radial_out = dfa * ck - dfr * sk  # force component along the outward radius u(φ)
    fx = np.sum(-dft * c + radial_out * s, axis=(1, 2))
    fy = np.sum(dft * s + radial_out * c, axis=(1, 2))
    fz = np.sum(dfr * ck + dfa * sk, axis=(1, 2))
    radii = tool.flute_radii_m(discs)
    torque = np.sum(dft * radii[None, :, :], axis=(1, 2))
    return CuttingForces(
        spindle_angle_rad=phi_s,
        fx_n=fx,
        fy_n=fy,
        fz_n=fz,
        torque_nm=torque,
        n_flutes=tool.n_flutes,
    )
