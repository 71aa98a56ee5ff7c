"""Z-map stock: construction, STL top surface, exact swept removal."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core.errors import ConfigError, InputDataError
from millsense.plan.stock import ZMapStock, read_stl, write_stl

H = 1e-4  # 0.1 mm cells


def _brute_envelope(
    stock: ZMapStock, p0: np.ndarray, p1: np.ndarray, radius: float, ball: bool, n: int = 4001
) -> np.ndarray:
    """Lower envelope of the tool sampled at n points along the segment (independent check)."""
    xc, yc = np.meshgrid(stock.x_centres_m, stock.y_centres_m)
    out = np.full(xc.shape, np.inf)
    for t in np.linspace(0.0, 1.0, n):
        p = p0 + t * (p1 - p0)
        r2 = (xc - p[0]) ** 2 + (yc - p[1]) ** 2
        inside = r2 <= radius**2
        env = p[2] + (radius - np.sqrt(np.maximum(radius**2 - r2, 0.0)) if ball else 0.0)
        out = np.where(inside, np.minimum(out, env), out)
    return out


def test_box_grid_and_memory_bound() -> None:
    s = ZMapStock.from_box((0, 0, -0.05), (0.3, 0.3, 0.0), H)
    # 300 mm / 0.1 mm = 3000 cells per axis; float32 heights: 9e6 × 4 B = 36 MB
    assert (s.ny, s.nx) == (3000, 3000)
    assert s.heights.dtype == np.float32 and s.heights.nbytes == 36_000_000
    assert s.x_centres_m[0] == pytest.approx(0.5 * H) and s.bottom_m == -0.05
    # volume of the block, exact for a block whose sides are whole cells
    assert s.material_volume_m3() == pytest.approx(0.3 * 0.3 * 0.05, rel=1e-6)


def test_box_rejects_bad_corners() -> None:
    with pytest.raises(ConfigError, match="max_xyz_m"):
        ZMapStock.from_box((0, 0, 0), (0.1, -0.1, 0.02))
    with pytest.raises(ConfigError, match="resolution_m"):
        ZMapStock.from_box((0, 0, 0), (0.1, 0.1, 0.02), 0.0)


@pytest.mark.parametrize("ball", [False, True])
def test_segment_sweep_matches_dense_sampling(ball: bool) -> None:
    # Exact closed-form envelope vs the tool stamped at n = 2001 points along a 3-D segment.
    # The exact minimum is never above the sampled one. It is below it by at most
    # |Δz|/(n − 1) for the flat end (z linear in t, the minimum at an end of the t-interval);
    # for the ball the envelope is convex in t and the sampled minimum is off by at most
    # f'' Δt²/8 < 3e-8 m where r ≤ 0.9 R (f'' ≤ |d|²/(0.083 R)), compared there.
    rng = np.random.default_rng(3)
    n = 2001
    for _ in range(2):
        s = ZMapStock.from_box((0, 0, 0), (0.03, 0.03, 0.02), 2e-4)
        p0 = np.array([0.008, 0.01, 0.012]) + rng.uniform(-2e-3, 2e-3, 3)
        p1 = np.array([0.021, 0.019, 0.016]) + rng.uniform(-2e-3, 2e-3, 3)
        if rng.uniform() < 0.5:
            p0, p1 = p1, p0  # descending as well as ascending
        r = 4e-3
        s.remove_path(r, "ball" if ball else "flat", *np.stack([p0, p1]).T)
        ref = np.minimum(_brute_envelope(s, p0, p1, r, ball, n), 0.02)
        both = np.isfinite(ref) & (ref < 0.02 - 1e-6)
        if ball:
            xc, yc = np.meshgrid(s.x_centres_m, s.y_centres_m)
            d = p1[:2] - p0[:2]
            t = np.clip(((xc - p0[0]) * d[0] + (yc - p0[1]) * d[1]) / (d @ d), 0, 1)
            dist = np.hypot(xc - p0[0] - t * d[0], yc - p0[1] - t * d[1])
            both &= dist <= 0.9 * r
            tol = 1e-7
        else:
            tol = abs(p1[2] - p0[2]) / (n - 1) + 1e-7
        got = s.heights.astype(float)
        assert np.all(got[both] <= ref[both] + 1e-7)  # float32 rounding of heights
        assert np.max(ref[both] - got[both]) <= tol
        # cells cut by the exact sweep but missed by the sampling lie on the boundary
        missed = (got < 0.02 - 1e-6) & ~np.isfinite(ref)
        assert missed.sum() <= 0.002 * both.sum()


def test_sweep_independent_of_step_length() -> None:
    # Exact swept footprint: one long segment or 0.4 mm or 0.05 mm steps give the same cells
    # (flat level move; differences only from round-off exactly at the boundary).
    ref = None
    for step in (None, 0.4e-3, 0.05e-3):
        s = ZMapStock.from_box((0, 0, 0), (0.04, 0.03, 0.02), H)
        x = np.array([0.005, 0.0353]) if step is None else np.arange(0.005, 0.0353 + 1e-9, step)
        if step is not None:
            x[-1] = 0.0353
        s.remove_path(5e-3, "flat", x, np.full(x.size, 0.0151), np.full(x.size, 0.018))
        if ref is None:
            ref = s.heights.copy()
        else:
            assert np.count_nonzero(s.heights != ref) <= 4


def test_slot_volume_equals_stadium() -> None:
    # Removed volume = (2 R L + π R²) × depth; the grid error is at most one cell along the
    # perimeter: |ΔV| ≤ perimeter × h × depth.
    s = ZMapStock.from_box((0, 0, 0), (0.06, 0.04, 0.02), H)
    v0 = s.material_volume_m3()
    r, depth, length = 6e-3, 3e-3, 0.03
    x = np.arange(0.015, 0.015 + length + 1e-9, 0.4e-3)
    s.remove_path(r, "flat", x, np.full(x.size, 0.02), np.full(x.size, 0.02 - depth))
    removed = v0 - s.material_volume_m3()
    exact = (2 * r * length + math.pi * r**2) * depth
    assert abs(removed - exact) <= (2 * length + 2 * math.pi * r) * H * depth


def test_ball_stamp_profile() -> None:
    # Ball plunge: height = z_tip + R − √(R² − r²) at every cell centre within R.
    s = ZMapStock.from_box((0, 0, 0), (0.02, 0.02, 0.02), H)
    r, zt = 5e-3, 0.016
    s.remove_path(r, "ball", np.array([0.01]), np.array([0.01]), np.array([zt]))
    xc, yc = np.meshgrid(s.x_centres_m, s.y_centres_m)
    rr = np.hypot(xc - 0.01, yc - 0.01)
    env = zt + r - np.sqrt(np.maximum(r**2 - rr**2, 0.0))
    sel = (rr < r) & (env < 0.02)
    assert np.max(np.abs(s.heights[sel] - env[sel])) < 1e-7  # float32 rounding
    assert np.all(s.heights[rr > r] == np.float32(0.02))


def test_diagonal_ramp_flat_lowest_point() -> None:
    # Flat tool ramping down along a diagonal: each cell goes to the lowest tip height that
    # still covers it, i.e. z at the far end of its t-interval (linear z). Cell at the end
    # point: z_end; cell on the path beyond the end: not cut deeper than z_end.
    s = ZMapStock.from_box((0, 0, 0), (0.04, 0.04, 0.02), H)
    s.remove_path(3e-3, "flat", np.array([0.01, 0.03]), np.array([0.01, 0.03]),
                  np.array([0.019, 0.015]))  # fmt: skip
    assert float(s.height_at(np.array([0.03005]), np.array([0.03005]))[0]) == pytest.approx(
        0.015, abs=1e-7
    )
    # the cell centre (20.05, 20.05) mm lies on the path at t_c = 0.5 + 0.05√2/(20√2); the
    # tool covers it until t = t_c + R/|d|, |d| = 20√2 mm: z = 19 − 4 (t_c + 3/(20√2)) mm
    t_end = 0.5 + 0.05 / 20 + 3 / (20 * math.sqrt(2))
    zc = 0.019 - 4e-3 * t_end
    assert float(s.height_at(np.array([0.02005]), np.array([0.02005]))[0]) == pytest.approx(
        zc,
        abs=1e-7,  # float32 heights
    )


def _box_triangles(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    c = np.array(
        [[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], hi[1], lo[2]], [lo[0], hi[1], lo[2]],
         [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], hi[1], hi[2]], [lo[0], hi[1], hi[2]]]
    )  # fmt: skip
    faces = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
             (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]  # fmt: skip
    return c[np.array(faces)]


def test_stl_box_equals_from_box(tmp_path: Path) -> None:
    # A 12-triangle box in mm read from binary STL: same grid and heights as from_box.
    path = tmp_path / "box.stl"
    write_stl(path, _box_triangles(np.array([0.0, 0.0, -10.0]), np.array([20.0, 15.0, 5.0])))
    s = ZMapStock.from_stl(path, resolution_m=H)
    b = ZMapStock.from_box((0, 0, -0.01), (0.02, 0.015, 0.005), H)
    assert s.heights.shape == b.heights.shape and s.bottom_m == pytest.approx(-0.01)
    assert np.max(np.abs(s.heights - b.heights)) < 1e-7  # no pin-holes on the diagonal edges


def test_ascii_stl_pyramid_heights(tmp_path: Path) -> None:
    # Square pyramid, base 20 × 20 mm at z = 0, apex (10, 10, 10): top z = 10 − max(|x−10|,
    # |y−10|) in mm at every cell centre (planar faces, exact up to float32).
    base = np.array([[0, 0, 0], [20, 0, 0], [20, 20, 0], [0, 20, 0]], dtype=float)
    apex = np.array([10.0, 10.0, 10.0])
    tris = [np.array([base[i], base[(i + 1) % 4], apex]) for i in range(4)]
    tris += [np.array([base[0], base[2], base[1]]), np.array([base[0], base[3], base[2]])]
    lines = ["solid pyramid"]
    for t in tris:
        lines += ["facet normal 0 0 0", " outer loop"]
        lines += [f"  vertex {v[0]:.6e} {v[1]:.6e} {v[2]:.6e}" for v in t]
        lines += [" endloop", "endfacet"]
    lines.append("endsolid pyramid")
    path = tmp_path / "pyr.stl"
    path.write_text("\n".join(lines))
    assert read_stl(path).shape == (6, 3, 3)
    s = ZMapStock.from_stl(path, resolution_m=0.5e-3)
    xc, yc = np.meshgrid(s.x_centres_m, s.y_centres_m)
    ref = 0.01 - np.maximum(np.abs(xc - 0.01), np.abs(yc - 0.01))
    assert np.max(np.abs(s.heights - ref)) < 1e-7


def test_stl_errors_name_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "junk.stl"
    bad.write_bytes(b"this is not a mesh at all, not even close" * 3)
    with pytest.raises(InputDataError, match=r"junk\.stl"):
        ZMapStock.from_stl(bad)
    with pytest.raises(InputDataError, match=r"missing\.stl"):
        read_stl(tmp_path / "missing.stl")
    flat = tmp_path / "flat.stl"
    write_stl(flat, np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float))
    with pytest.raises(InputDataError, match=r"flat\.stl: STL mesh has no volume"):
        ZMapStock.from_stl(flat)


def test_path_shape_errors() -> None:
    s = ZMapStock.from_box((0, 0, 0), (0.01, 0.01, 0.01), H)
    with pytest.raises(InputDataError, match="equal length"):
        s.remove_path(1e-3, "flat", np.zeros(3), np.zeros(2), np.zeros(3))
    with pytest.raises(InputDataError, match="step 1"):
        s.remove_path(1e-3, "flat", np.array([0.0, np.nan]), np.zeros(2), np.zeros(2))
    with pytest.raises(ConfigError, match="shape"):
        s.remove_path(1e-3, "bull", np.zeros(1), np.zeros(1), np.zeros(1))  # type: ignore[arg-type]
