"""Cutter–workpiece engagement (CWE) along a tool path on a z-map stock.

For every path step the tool sweeps from the previous step to the current one (material
removal, :meth:`ZMapStock.remove_path`), then the engagement at the current position is read
from the stock as left by everything before: that is the material the cutting edges meet as
the tool feeds on from this position. One compiled call handles the whole path (or a chunk of
it, resumable with ``previous_xyz_m``).

Engagement criterion (decision docs/decisions/0042-z-map-engagement-criterion.md)
------------------------------------------------------------------------------
Tool feed frame: x along the XY feed direction f, y = z × f, so immersion φ (clockwise from
+y, :mod:`millsense.process.geometry`) puts an edge point at P + r (sin φ f + cos φ (z × f)).
Axial layers: L equal layers from the tool tip to the axial depth a; layer ℓ has centre
height z_ℓ = (ℓ + ½) a/L and edge radius r_ℓ (R, or √(R² − (R − z_ℓ)²) on a ball).
The front half φ ∈ [0, π] is split into bins of ``angle_step_rad``; bin i of layer ℓ is
engaged iff the cell containing the point at radius r_ℓ + δ (δ = one cell) and bin-centre
angle has material above the layer centre (height > z_tip + z_ℓ + 0.1 µm, and z_tip + z_ℓ
above the stock bottom). δ = h guarantees the sampled cell's centre lies outside the tool
(its distance is ≥ r + h − h/√2), so material the tool has just removed is never counted.
Runs of engaged bins give the intervals (entry, exit) at bin edges; runs separated by a gap
narrower than one cell at the sampling radius are joined (grid staircase of slanted walls).

Grazing filter: a wall left by an earlier pass of the same radius parallel to the feed is
tangent to the tool at φ = 0 or π; the sample at r + δ reads it up to
φ_g = arccos((r − h/2)/(r + δ)) (9.9° for R = 10 mm, h = 0.1 mm), although the edges never
reach it. Intervals lying entirely within [0, φ_g] or [π − φ_g, π] are therefore dropped.
Consequence: a radial depth of cut below about 1.5 cells (R (1 − cos φ_g)) is not resolved
and reads as no engagement; intervals reaching beyond φ_g are kept whole.

Axial depth a: the highest material top just outside the tool (radius R + δ) over the front
half, measured from the tool tip, or from the stock bottom where the tip is below it (a cut
through a plate: the flutes below the bottom cut nothing, and the layers split only the part of
the flutes inside the stock; ``layer_base_m`` is that bottom's height above the tip); if no
bin of the top layer is engaged, a is lowered once to the highest material seen by engaged
bins and the layers are recomputed (a tall wall beside the tool does not make the cut
deeper). Material below the tool tip (plunging, ramping) is not
represented: the criterion is the XY feed over the periphery, which is where the force model
(:mod:`millsense.process.forces`) cuts.

Accuracy (stated tolerances of the tests): an entry or exit angle away from 0 and π is
within one bin plus ≈ 1.5 h/(r |sin φ|) (boundary quantised to cells plus δ); 0 and π are
found exactly when the material is there (first pass of a slot), grazing walls as above. An
axial step in the material lying on a cell edge shows when the tool's front edge is one cell
before it (the sample at r + h lands in the first cell beyond the step), i.e. within one
cell; a step inside a cell is itself quantised to the cell edge (± h/2 more).

Limits: the top of material is sampled at the full radius only (a rib inside a ball's
footprint, above the ring at R + h, is not seen); one tool per call (split a path at tool
changes); clockwise spindle (M3). At the last step of an earlier cut the look-ahead sees the
uncut material beyond it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.plan import _zmap_kernels as _k
from millsense.plan.stock import ZMapStock, _path_arrays
from millsense.process.engagement import Engagement
from millsense.process.geometry import EndMill

FloatArray = NDArray[np.float64]

#: Height margin [m] for "material above this level" (float32 heights near 0.3 m: 3e-8 m).
EPS_Z_M = 1e-7

#: Aslan Eq. 5.34: K_rc = 0.5 K_tc, the ratio under which Gain_CWE is defined (V9).
GAIN_RADIAL_RATIO = 0.5


@dataclass
class EngagementResult:
    """Engagement at every path step (arrays over steps).

    Attributes
    ----------
    axial_depth_m : (n,) float
        Axial depth of cut a [m]: the part of the flutes inside the stock, from the tool tip
        or from the stock bottom when the tip is below it (0 out of cut); the layers split it.
    intervals_rad : (n, L, M, 2) float32
        (entry, exit) immersion angles [rad] in the tool feed frame, per layer (tip upwards);
        only the first ``n_intervals[k, ℓ]`` rows of each layer are valid.
    n_intervals : (n, L) int16
        Number of intervals per step and layer.
    gain_cwe_m : (n,) float
        Gain_CWE [m]: peak over spindle angle of the resultant XY force divided by K_tc c,
        for K_rc = 0.5 K_tc and no edge forces (Aslan V9, Eq. 5.34), with this tool's flutes,
        pitch and helix. F_res,peak = K_tc c Gain_CWE.
    engaged_area_m2 : (n,) float
        Projected engaged area [m²]: Σ_ℓ Δz r_ℓ Σ (cos entry − cos exit), the area of the
        engaged cut normal to the feed (a D for a slot); material removal rate = v_f × it.
    contact_area_m2 : (n,) float
        Area of the tool envelope in contact [m²]: Σ_ℓ (Δz / sin κ_ℓ) r_ℓ Σ (exit − entry).
    feed_angle_rad : (n,) float
        Direction of the XY feed used for the tool frame [rad], atan2(f_y, f_x).
    tool : EndMill
        Tool used.
    layer_base_m : (n,) float
        Height of the first layer's bottom above the tool tip [m]: 0, or the stock bottom's
        height above a tip below it. The force models (:func:`millsense.process.forces.
        milling_forces`, the plan's prediction, the virtual machine) put the layers from the tip
        up: for a flat end mill that is the same cut with the helix phase shifted by
        k_β · layer_base (an offset of the spindle angle); a ball's layers keep the radii of
        their heights above the tip only here (Gain_CWE, areas).
    n_overflow : int
        Steps where a layer had more intervals than M (closest ones merged).
    """

    axial_depth_m: FloatArray
    intervals_rad: NDArray[np.float32]
    n_intervals: NDArray[np.int16]
    gain_cwe_m: FloatArray
    engaged_area_m2: FloatArray
    contact_area_m2: FloatArray
    feed_angle_rad: FloatArray
    tool: EndMill
    layer_base_m: FloatArray
    n_overflow: int = 0

    def __len__(self) -> int:
        return int(self.axial_depth_m.size)

    @classmethod
    def concatenate(cls, parts: list[EngagementResult]) -> EngagementResult:
        """Join results of consecutive chunks of one path (same tool and settings)."""
        if not parts:
            raise InputDataError("engagement: nothing to concatenate")
        shapes = {p.intervals_rad.shape[1:] for p in parts}
        if len(shapes) != 1 or any(p.tool != parts[0].tool for p in parts):
            raise InputDataError("engagement: chunks differ in tool, layers or interval count")
        return cls(
            axial_depth_m=np.concatenate([p.axial_depth_m for p in parts]),
            intervals_rad=np.concatenate([p.intervals_rad for p in parts]),
            n_intervals=np.concatenate([p.n_intervals for p in parts]),
            gain_cwe_m=np.concatenate([p.gain_cwe_m for p in parts]),
            engaged_area_m2=np.concatenate([p.engaged_area_m2 for p in parts]),
            contact_area_m2=np.concatenate([p.contact_area_m2 for p in parts]),
            feed_angle_rad=np.concatenate([p.feed_angle_rad for p in parts]),
            tool=parts[0].tool,
            layer_base_m=np.concatenate([p.layer_base_m for p in parts]),
            n_overflow=sum(p.n_overflow for p in parts),
        )

    @property
    def n_layers(self) -> int:
        """Number of axial layers L."""
        return int(self.n_intervals.shape[1])

    @property
    def in_cut(self) -> NDArray[np.bool_]:
        """Whether any layer is engaged, per step."""
        return np.asarray(self.n_intervals.sum(axis=1) > 0)

    @property
    def gain_cwe_mm(self) -> FloatArray:
        """Gain_CWE in mm, the unit of Aslan's virtual file (V9)."""
        return self.gain_cwe_m * 1e3

    def layer_radii_m(self, k: int) -> FloatArray:
        """Edge radius r_ℓ [m] at the centre of every layer of step k."""
        a = float(self.axial_depth_m[k])
        zc = self.layer_base_m[k] + (np.arange(self.n_layers) + 0.5) * a / self.n_layers
        return _layer_radius(self.tool, zc)

    def intervals(self, k: int) -> list[list[tuple[float, float]]]:
        """Intervals (entry, exit) [rad] of step k, one list per layer (tip upwards)."""
        if not (-len(self) <= k < len(self)):
            raise IndexError(f"step {k} out of range for {len(self)} steps")
        out: list[list[tuple[float, float]]] = []
        for layer in range(self.n_layers):
            m = int(self.n_intervals[k, layer])
            iv = self.intervals_rad[k, layer, :m].astype(np.float64)
            out.append([(float(a), float(b)) for a, b in iv])
        return out

    def engagement(self, k: int) -> Engagement:
        """Step k as a :class:`millsense.process.engagement.Engagement`.

        Use it with ``axial_depth_m[k]`` in :func:`millsense.process.forces.milling_forces`
        (the layers split that depth; any number of discs).
        """
        return Engagement.from_intervals(self.intervals(k))


def _layer_radius(tool: EndMill, z_m: FloatArray) -> FloatArray:
    r = tool.radius_m
    if tool.shape == "ball":
        zc = np.minimum(z_m, r)
        return np.asarray(np.sqrt(np.maximum(r**2 - (r - zc) ** 2, 0.0)), dtype=np.float64)
    return np.full(np.shape(z_m), r)


def _feed_directions(
    x: FloatArray, y: FloatArray, feed_dir: FloatArray | None
) -> tuple[FloatArray, FloatArray]:
    n = x.size
    if feed_dir is None:
        d = np.zeros((n, 2))
        if n > 1:
            d[1:, 0] = np.diff(x)
            d[1:, 1] = np.diff(y)
            d[0] = d[1]
    else:
        fd = np.asarray(feed_dir, dtype=float)
        if fd.ndim != 2 or fd.shape[0] != n or fd.shape[1] not in (2, 3):
            raise InputDataError(f"path: feed_dir must be (n, 2) or (n, 3), got {fd.shape}")
        if not np.all(np.isfinite(fd)):
            raise InputDataError("path: feed_dir has a non-finite value")
        d = fd[:, :2].copy()
    norm = np.hypot(d[:, 0], d[:, 1])
    valid = norm > 1e-9
    # Plunges and pure z moves keep the last XY direction (the first valid one before it, +x).
    idx = np.where(valid, np.arange(n), -1)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(valid)) if valid.any() else -1
    idx = np.where(idx < 0, first, idx)
    ux = np.ones(n)
    uy = np.zeros(n)
    if first >= 0:
        ux = d[idx, 0] / norm[idx]
        uy = d[idx, 1] / norm[idx]
    return np.ascontiguousarray(ux), np.ascontiguousarray(uy)


def compute_engagement(
    stock: ZMapStock,
    tool: EndMill,
    x_m: FloatArray,
    y_m: FloatArray,
    z_m: FloatArray,
    feed_dir: FloatArray | None = None,
    *,
    join: NDArray[np.bool_] | None = None,
    previous_xyz_m: tuple[float, float, float] | None = None,
    n_layers: int = 10,
    angle_step_rad: float = math.radians(0.5),
    max_intervals: int = 6,
    gain_angles_per_rev: int = 720,
) -> EngagementResult:
    """Remove material along a path and return the engagement at every step.

    The stock is modified in place (it ends as left by the whole path).

    Parameters
    ----------
    stock : ZMapStock
        Stock, cut in place.
    tool : EndMill
        Flat or ball end mill (radius, flutes, pitch and helix for Gain_CWE). Clockwise
        spindle rotation (M3), as :mod:`millsense.process` assumes.
    x_m, y_m, z_m : (n,) float
        Tool-tip positions [m] in the stock's frame.
    feed_dir : (n, 2) or (n, 3) float, optional
        Feed (tangent) directions; only the XY part is used and normalised. Default: the
        direction from the previous step. Steps without XY motion keep the last direction.
    join : (n,) bool, optional
        ``join[k]`` False: step k does not continue from step k−1 (only stamped).
    previous_xyz_m : (x, y, z) [m], optional
        Tool position before step 0 (to continue a path cut in chunks).
    n_layers : int
        Axial layers L.
    angle_step_rad : float
        Angular bin width over the front half [rad] (π must be a whole number of bins).
    max_intervals : int
        Intervals kept per layer (closest ones merged beyond it; counted in n_overflow).
    gain_angles_per_rev : int
        Spindle angles per revolution for the peak of Gain_CWE.

    Returns
    -------
    EngagementResult

    Notes
    -----
    Criterion, filter, axial depth and tolerances: module docstring. Gain_CWE (Aslan V9,
    F_res = K_tc c Gain_CWE; docs/decisions/0043-gain-cwe-definition.md): with chip thickness
    h = c sin φ_j(z) sin κ and chip width Δz/sin κ, dF_t = K_tc c sin φ Δz and
    dF_r = 0.5 K_tc c sin φ Δz; F_x = Σ −dF_t cos φ − dF_r sin κ sin φ,
    F_y = Σ dF_t sin φ − dF_r sin κ cos φ over flutes and layers in the engagement (the
    formulas of :func:`millsense.process.forces.milling_forces` with one disc per layer),
    and Gain_CWE = max_φ √(F_x² + F_y²)/(K_tc c). For one straight tooth in a slot of depth
    a this is a √1.25.
    """
    x, y, z, jn = _path_arrays(x_m, y_m, z_m, join)
    if n_layers < 1 or int(n_layers) != n_layers:
        raise ConfigError(f"engagement: n_layers must be an integer ≥ 1, got {n_layers!r}")
    n_bins = round(math.pi / angle_step_rad) if angle_step_rad > 0 else 0
    if n_bins < 4 or abs(n_bins * angle_step_rad - math.pi) > 1e-9:
        raise ConfigError(
            f"engagement: angle_step_rad must divide π into ≥ 4 bins, got {angle_step_rad!r}"
        )
    if max_intervals < 1:
        raise ConfigError(f"engagement: max_intervals must be ≥ 1, got {max_intervals!r}")
    if gain_angles_per_rev < 8:
        raise ConfigError(
            f"engagement: gain_angles_per_rev must be ≥ 8, got {gain_angles_per_rev!r}"
        )
    ux, uy = _feed_directions(x, y, feed_dir)
    n = x.size
    iv = np.zeros((n, n_layers, max_intervals, 2), dtype=np.float32)
    nv = np.zeros((n, n_layers), dtype=np.int16)
    depth = np.zeros(n)
    base = np.zeros(n)
    gain = np.zeros(n)
    eng_area = np.zeros(n)
    contact = np.zeros(n)
    uniform = tool.pitch_angles_rad is None
    period = 2 * math.pi / tool.n_flutes if uniform else 2 * math.pi
    n_gain = max(round(gain_angles_per_rev * period / (2 * math.pi)), 1)
    has_prev = previous_xyz_m is not None
    px, py, pz = (float(v) for v in previous_xyz_m) if previous_xyz_m is not None else (0, 0, 0)
    n_ovf = _k.cut_and_engage(
        stock.heights,
        stock.x0_m,
        stock.y0_m,
        stock.resolution_m,
        stock.bottom_m,
        stock.max_height_m,
        x,
        y,
        z,
        ux,
        uy,
        jn,
        has_prev,
        px,
        py,
        pz,
        tool.radius_m,
        tool.shape == "ball",
        int(n_layers),
        int(n_bins),
        stock.resolution_m,
        EPS_Z_M,
        np.ascontiguousarray(tool.flute_angles_rad),
        tool.lag_per_m,
        GAIN_RADIAL_RATIO,
        n_gain,
        period,
        iv,
        nv,
        depth,
        base,
        gain,
        eng_area,
        contact,
    )
    return EngagementResult(
        axial_depth_m=depth,
        intervals_rad=iv,
        n_intervals=nv,
        gain_cwe_m=gain,
        engaged_area_m2=eng_area,
        contact_area_m2=contact,
        feed_angle_rad=np.arctan2(uy, ux),
        tool=tool,
        layer_base_m=base,
        n_overflow=int(n_ovf),
    )
