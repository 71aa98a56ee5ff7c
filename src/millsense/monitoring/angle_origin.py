"""The tool's angle at a record's spindle-angle zero, from its cut's harmonics (decision 1738).

Lee's model (seed 004 Eqs. 2.2-2.12) puts flute 0 at θ = 0 of the spindle angle and the
entry and exit angles in the feed's frame. The chip h_s = c·sin θ makes the tooth harmonics'
magnitudes depend on where the window lies in that frame. A record whose angle zero lies φ₀
past flute 0 (a real spindle is not stopped at flute 0 when the trace starts) multiplies
harmonic k by e^{−ikφ₀}. The fit then absorbs that phase into wrong angles and depths. The
2-flute down-milling cut read 5.08 mm for 2 mm at σ 0.86 with φ₀ = 60°.

:func:`tool_angle_offset` turns a cut's averaged harmonics (revolutions of one steady cut, in
the record's frame) by candidate angles φ over one tooth pitch (the tooth harmonics repeat
there). It fits each candidate globally and keeps the φ whose relative misfit is smallest:
the grid of :data:`STEP_DEG`, then scipy's bounded scalar minimiser within a step. A record is
misaligned where that misfit is below :data:`ADOPT_RATIO` of its own frame's (φ = 0). The
offset fixes the depths only where the fit's notch lies within the fitted harmonics
(:meth:`ToolAngle.resolved`); beyond it an offset and a depth trade phase slopes, and a
sensorless slot at 1000 rev/min cropped at 1.2345 s read 0.32 mm for 3 mm at the offset found.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from millsense.monitoring import _spectrum_kernels as _sk
from millsense.monitoring.torque_spectrum import SpectrumIdentifier, ToolGeometry

#: Grid step of the candidate offsets over one tooth pitch, degrees.
STEP_DEG = 5.0
#: An offset is adopted where its misfit is below this share of the record's own frame's.
ADOPT_RATIO = 0.5


def _fit(
    geom: ToolGeometry, n_harmonics: int, edge: bool, max_depth_fraction: float,
    coeff: NDArray[np.complex128], feed_m: float, t0_net: float, mean_var: float,
) -> tuple[float, float]:  # fmt: skip
    """The relative misfit 2·cost/|x|² of a global fit to ``coeff`` ([k = 1, tooth
    harmonics]) and its notch index d_a,p/d_a."""
    ident = SpectrumIdentifier(geom, n_harmonics, edge, max_depth_fraction)
    x = np.ascontiguousarray(coeff[1:])
    out = ident.identify_array(x, complex(coeff[0]), feed_m, t0_net, mean_var)
    _, norm = _sk.normalised(x)
    misfit = 2.0 * float(out[_sk.EST_COST]) / norm if norm > 0 else math.inf
    return misfit, float(out[_sk.EST_NOTCH])


@dataclass(frozen=True)
class ToolAngle:
    """What :func:`tool_angle_offset` found: the best offset (rad), the relative misfits in
    the record's frame and at the offset, and the fit's notch index there."""

    offset_rad: float
    misfit_at_zero: float
    misfit: float
    notch_index: float

    @property
    def misaligned(self) -> bool:
        """An offset fits clearly better than the record's own frame (:data:`ADOPT_RATIO`)."""
        return self.misfit < ADOPT_RATIO * self.misfit_at_zero

    def resolved(self, n_harmonics: int) -> bool:
        """The depth at the offset is fixed by the harmonics' magnitudes: its notch lies
        within the ``n_harmonics`` fitted. Beyond it the phases' slope over the harmonics
        carries the depth, and an offset's slope trades for a depth's (−kNφ against
        −kN·d_a·tanβ/2r): only an angle reference separates them."""
        return bool(self.notch_index <= n_harmonics)


def tool_angle_offset(
    geom: ToolGeometry, n_harmonics: int, edge: bool, max_depth_fraction: float,
    orders: NDArray[np.float64], coeffs: Sequence[NDArray[np.complex128]],
    feeds: Sequence[float], t0s: Sequence[float], mean_vars: Sequence[float],
) -> ToolAngle:  # fmt: skip
    """The best offset φ₀ for the revolutions' coefficients ``coeffs`` (each at ``orders`` =
    [1, N, 2N, …]; module notes). Raises ValueError without revolutions."""
    if not coeffs:
        raise ValueError("tool_angle_offset: no revolution")
    fit = functools.partial(_fit, geom, n_harmonics, edge, max_depth_fraction)
    mean = np.mean(np.stack(coeffs), axis=0)
    feed = float(np.mean(feeds))
    t0 = float(np.mean(t0s)) if np.all(np.isfinite(t0s)) else math.nan
    var = float(np.mean(mean_vars))
    k = np.asarray(orders, dtype=np.float64)

    def cost(phi: float) -> float:
        return fit(mean * np.exp(-1j * k * phi), feed, t0, var)[0]

    pitch = 2.0 * math.pi / geom.n_flutes
    step = math.radians(STEP_DEG)
    grid = np.arange(0.0, pitch, step)
    costs = [cost(float(p)) for p in grid]
    at0 = costs[0]
    best = float(grid[int(np.argmin(costs))])
    res = optimize.minimize_scalar(cost, bounds=(best - step, best + step), method="bounded",
                                   options={"xatol": math.radians(0.01)})  # fmt: skip
    phi, found = (float(res.x), float(res.fun)) if res.fun < min(costs) else (best, min(costs))
    phi = float(phi % pitch)
    return ToolAngle(phi, at0, found, fit(mean * np.exp(-1j * k * phi), feed, t0, var)[1])
