"""Z-map (dexel) stock: a grid of material heights over XY, and material removal.

The stock is a regular grid of square cells of side h (default 0.1 mm). Each cell holds the
height [m] of the top of material at its centre; material fills the column from the stock
bottom up to it. A z-map cannot represent overhangs, which 3-axis milling never creates.

Heights are ``float32``: a 300 × 300 mm part at 0.1 mm is 9 M cells, 36 MB (float64 would be
72 MB). The float32 spacing near 0.3 m is 3e-8 m, far below any cutting tolerance; the
engagement compares heights with a 0.1 µm margin (:mod:`millsense.plan.cwe`).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.plan import _zmap_kernels as _k

FloatArray = NDArray[np.float64]

#: Largest grid accepted (cells); 2e8 float32 cells are 800 MB.
MAX_CELLS = 200_000_000


def _grid_shape(extent_x: float, extent_y: float, resolution_m: float) -> tuple[int, int]:
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise ConfigError(f"stock: resolution_m must be positive, got {resolution_m!r}")
    nx = max(math.ceil(extent_x / resolution_m - 1e-9), 1)
    ny = max(math.ceil(extent_y / resolution_m - 1e-9), 1)
    if nx * ny > MAX_CELLS:
        raise ConfigError(
            f"stock: {extent_x * 1e3:.4g} × {extent_y * 1e3:.4g} mm at a "
            f"{resolution_m * 1e3:g} mm resolution is {nx} × {ny} cells, beyond the ceiling "
            f"of {MAX_CELLS:.3g} (decision 0943); give a coarser --resolution-mm"
        )
    return nx, ny


@dataclass
class ZMapStock:
    """Material heights on a regular XY grid.

    Attributes
    ----------
    x0_m, y0_m : float
        Lower-left corner of the grid [m]; cell (iy, ix) has its centre at
        (x0 + (ix + ½) h, y0 + (iy + ½) h).
    resolution_m : float
        Cell side h [m].
    bottom_m : float
        Bottom of the stock [m]; a cell whose height is ≤ bottom holds no material.
    heights : (ny, nx) float32
        Top of material at every cell centre [m] (row iy, column ix).

    Notes
    -----
    Points outside the grid hold no material. Removal lowers heights to the lower envelope of
    the swept tool and never raises them (see :meth:`remove_path`).
    """

    x0_m: float
    y0_m: float
    resolution_m: float
    bottom_m: float
    heights: NDArray[np.float32]

    @classmethod
    def from_box(
        cls,
        min_xyz_m: Sequence[float],
        max_xyz_m: Sequence[float],
        resolution_m: float = 1e-4,
    ) -> ZMapStock:
        """A rectangular block.

        Parameters
        ----------
        min_xyz_m, max_xyz_m : (3,) float
            Opposite corners of the block [m].
        resolution_m : float
            Cell side [m]; the grid starts at the block's minimum corner and covers it with
            ⌈extent/h⌉ cells per axis (the last cell may overhang by less than h).
        """
        lo = np.asarray(min_xyz_m, dtype=float)
        hi = np.asarray(max_xyz_m, dtype=float)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo + hi)):
            raise ConfigError("stock: min_xyz_m and max_xyz_m must be three finite numbers each")
        if np.any(hi <= lo):
            raise ConfigError(f"stock: max_xyz_m {hi.tolist()} must exceed min_xyz_m {lo.tolist()}")
        nx, ny = _grid_shape(hi[0] - lo[0], hi[1] - lo[1], resolution_m)
        heights = np.full((ny, nx), hi[2], dtype=np.float32)
        return cls(float(lo[0]), float(lo[1]), float(resolution_m), float(lo[2]), heights)

    @classmethod
    def from_stl(
        cls,
        path: str | os.PathLike[str],
        resolution_m: float = 1e-4,
        scale_to_m: float = 1e-3,
    ) -> ZMapStock:
        """Top surface of an STL mesh (binary or ASCII), ray-cast at every cell centre.

        Parameters
        ----------
        path : path
            STL file.
        resolution_m : float
            Cell side [m].
        scale_to_m : float
            Metres per STL unit (STL has no units; CAM exports millimetres, the default).

        Notes
        -----
        The grid covers the mesh's XY bounding box; the bottom is the mesh's lowest z. Each
        cell centre takes the highest z where a vertical line through it crosses a
        triangle; cells the mesh does not cover hold no material. Only the top surface is
        kept (no overhangs, as any z-map).
        """
        tri = read_stl(path) * float(scale_to_m)
        lo = tri.reshape(-1, 3).min(axis=0)
        hi = tri.reshape(-1, 3).max(axis=0)
        if np.any(hi[:2] <= lo[:2]) or hi[2] <= lo[2]:
            raise InputDataError(f"{path}: STL mesh has no volume (extent {(hi - lo).tolist()})")
        nx, ny = _grid_shape(hi[0] - lo[0], hi[1] - lo[1], resolution_m)
        h64 = np.full((ny, nx), -np.inf)
        _k.top_surface_from_triangles(h64, float(lo[0]), float(lo[1]), float(resolution_m), tri)
        h64[~np.isfinite(h64)] = lo[2]
        return cls(
            float(lo[0]), float(lo[1]), float(resolution_m), float(lo[2]), h64.astype(np.float32)
        )

    @property
    def nx(self) -> int:
        """Number of cells along x."""
        return int(self.heights.shape[1])

    @property
    def ny(self) -> int:
        """Number of cells along y."""
        return int(self.heights.shape[0])

    @property
    def x_centres_m(self) -> FloatArray:
        """Cell-centre x coordinates [m], (nx,)."""
        return np.asarray(self.x0_m + (np.arange(self.nx) + 0.5) * self.resolution_m, np.float64)

    @property
    def y_centres_m(self) -> FloatArray:
        """Cell-centre y coordinates [m], (ny,)."""
        return np.asarray(self.y0_m + (np.arange(self.ny) + 0.5) * self.resolution_m, np.float64)

    @property
    def max_height_m(self) -> float:
        """Highest material top [m]."""
        return float(self.heights.max())

    def copy(self) -> ZMapStock:
        """Independent copy (heights copied)."""
        return ZMapStock(
            self.x0_m, self.y0_m, self.resolution_m, self.bottom_m, self.heights.copy()
        )

    def height_at(self, x_m: FloatArray, y_m: FloatArray) -> FloatArray:
        """Top of material [m] at points (x, y) (cell containing each point; NaN outside)."""
        x = np.asarray(x_m, dtype=float)
        y = np.asarray(y_m, dtype=float)
        fx = np.floor((x - self.x0_m) / self.resolution_m)
        fy = np.floor((y - self.y0_m) / self.resolution_m)
        ok = (fx >= 0) & (fy >= 0) & (fx < self.nx) & (fy < self.ny)
        out = np.full(np.broadcast(x, y).shape, np.nan)
        ix = np.where(ok, fx, 0).astype(np.int64)
        iy = np.where(ok, fy, 0).astype(np.int64)
        out[ok] = self.heights[iy[ok], ix[ok]]
        return out

    def material_volume_m3(self) -> float:
        """Volume of material [m³] (column heights above the bottom times the cell area)."""
        col = np.maximum(self.heights.astype(np.float64) - self.bottom_m, 0.0)
        return float(col.sum() * self.resolution_m**2)

    def remove_path(
        self,
        radius_m: float,
        shape: Literal["flat", "ball"],
        x_m: FloatArray,
        y_m: FloatArray,
        z_m: FloatArray,
        join: NDArray[np.bool_] | None = None,
    ) -> None:
        """Remove the material swept by a tool whose tip follows the polyline (x, y, z).

        Parameters
        ----------
        radius_m : float
            Tool radius R [m].
        shape : {"flat", "ball"}
            Flat end mill (lower envelope z_tip within R) or ball end mill
            (z_tip + R − √(R² − r²)).
        x_m, y_m, z_m : (n,) float
            Tool-tip positions [m].
        join : (n,) bool, optional
            ``join[k]`` False means step k is not connected to step k−1 (a new piece of
            path: only the tool at step k is stamped). Default: all connected.

        Notes
        -----
        Each segment between consecutive steps is swept exactly (not sub-stepped): every
        cell centre within R of the segment in XY is lowered to the minimum over the segment
        of the tool's lower envelope (closed forms in
        :func:`millsense.plan._zmap_kernels.sweep_segment`), so the result does not
        depend on the step length. The only discretisation is the grid: a cell is cut iff
        its centre is.
        """
        x, y, z, jn = _path_arrays(x_m, y_m, z_m, join)
        r = _check_radius(radius_m, shape)
        _k.sweep_path(
            self.heights,
            self.x0_m,
            self.y0_m,
            self.resolution_m,
            x,
            y,
            z,
            jn,
            r,
            shape == "ball",
            self.max_height_m,
        )


def _check_radius(radius_m: float, shape: str) -> float:
    if not (math.isfinite(radius_m) and radius_m > 0):
        raise ConfigError(f"tool: radius_m must be positive, got {radius_m!r}")
    if shape not in ("flat", "ball"):
        raise ConfigError(f"tool: shape must be 'flat' or 'ball', got {shape!r}")
    return float(radius_m)


def _path_arrays(
    x_m: FloatArray, y_m: FloatArray, z_m: FloatArray, join: NDArray[np.bool_] | None
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    x = np.ascontiguousarray(x_m, dtype=np.float64)
    y = np.ascontiguousarray(y_m, dtype=np.float64)
    z = np.ascontiguousarray(z_m, dtype=np.float64)
    if x.ndim != 1 or x.shape != y.shape or x.shape != z.shape:
        raise InputDataError(
            f"path: x, y, z must be 1-D of equal length, got {x.shape}, {y.shape}, {z.shape}"
        )
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
        bad = int(np.flatnonzero(~(np.isfinite(x) & np.isfinite(y) & np.isfinite(z)))[0])
        raise InputDataError(f"path: step {bad} has a non-finite coordinate")
    if join is None:
        jn = np.ones(x.size, dtype=np.bool_)
    else:
        jn = np.ascontiguousarray(join, dtype=np.bool_)
        if jn.shape != x.shape:
            raise InputDataError(f"path: join has shape {jn.shape}, expected {x.shape}")
    return x, y, z, jn


_STL_ASCII_VERTEX = re.compile(
    rb"vertex\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)", re.IGNORECASE
)


def read_stl(path: str | os.PathLike[str]) -> FloatArray:
    """Triangles of a binary or ASCII STL file as an (n, 3, 3) float64 array (file units).

    A file is binary when its size is 84 + 50 n for the triangle count n in its header
    (ASCII files may also start with ``solid``, so the size decides).
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputDataError(f"{path}: cannot read STL ({exc.strerror or exc})") from None
    if len(data) >= 84:
        n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) == 84 + 50 * n:
            rec = np.dtype(
                [("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")], align=False
            )
            arr = np.frombuffer(data, dtype=rec, count=n, offset=84)
            tri = arr["v"].astype(np.float64)
            return _check_triangles(tri, path)
    if not data.lstrip()[:5].lower() == b"solid":
        raise InputDataError(f"{path}: not an STL file (neither binary size nor 'solid' header)")
    vals = _STL_ASCII_VERTEX.findall(data)
    if not vals or len(vals) % 3:
        raise InputDataError(
            f"{path}: ASCII STL has {len(vals)} vertices, expected a positive multiple of 3"
        )
    try:
        tri = np.array(vals, dtype=np.float64).reshape(-1, 3, 3)
    except ValueError:
        raise InputDataError(f"{path}: ASCII STL has a malformed vertex line") from None
    return _check_triangles(tri, path)


def _check_triangles(tri: FloatArray, path: str | os.PathLike[str]) -> FloatArray:
    if tri.shape[0] == 0:
        raise InputDataError(f"{path}: STL has no triangles")
    if not np.all(np.isfinite(tri)):
        bad = int(np.flatnonzero(~np.isfinite(tri).all(axis=(1, 2)))[0])
        raise InputDataError(f"{path}: triangle {bad} has a non-finite vertex")
    return np.ascontiguousarray(tri)


def write_stl(path: str | os.PathLike[str], triangles: FloatArray) -> None:
    """Write triangles (n, 3, 3) as a binary STL (file units as given; normals computed)."""
    tri = np.asarray(triangles, dtype=np.float64)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 0, nrm / np.where(ln > 0, ln, 1.0), 0.0)
    rec = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")], align=False)
    arr = np.zeros(tri.shape[0], dtype=rec)
    arr["normal"] = nrm
    arr["v"] = tri
    header = b"millsense binary STL".ljust(80, b" ")
    from millsense.io.safe_output import write_bytes

    write_bytes(path, header + np.uint32(tri.shape[0]).tobytes() + arr.tobytes())
