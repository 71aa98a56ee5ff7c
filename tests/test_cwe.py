"""Cutter–workpiece engagement on the z-map: analytic cases, Gain_CWE, Aslan V9.

Tolerances (module docstring of millsense.plan.cwe): grid h = 0.1 mm, bins of 0.5°, tool
radius R = 10 mm. An entry/exit angle at a straight material boundary is within one bin plus
1.5 h/(R |sin φ|) rad (boundary on a cell edge, sample one cell outside the tool); 0 and π
are exact when the material is there.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError, InputDataError
from millsense.plan.cwe import EngagementResult, compute_engagement
from millsense.plan.stock import ZMapStock
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.validation import run_case, select_cases

H = 1e-4
R = 10e-3
BIN = math.radians(0.5)
TOOL = EndMill(2 * R, 2)  # straight 2-flute Ø20 (seed 000 tool without helix)
TOP = 0.02


def _tol(phi: float) -> float:
    """Angle tolerance [rad] at a boundary crossing the periphery at φ (see module doc)."""
    return BIN + 1.5 * H / (R * abs(math.sin(phi)))


def _line(
    start: tuple[float, float], direction_deg: float, length: float, step: float = 0.4e-3
) -> tuple[np.ndarray, np.ndarray]:
    s = np.arange(0.0, length + 1e-12, step)
    d = math.radians(direction_deg)
    return start[0] + s * math.cos(d), start[1] + s * math.sin(d)


def _run(
    stock: ZMapStock,
    tool: EndMill,
    x: np.ndarray,
    y: np.ndarray,
    z: float,
    **kw: object,
) -> EngagementResult:
    return compute_engagement(stock, tool, x, y, np.full(x.size, z), **kw)  # type: ignore[arg-type]


def _step_at(x: np.ndarray, y: np.ndarray, px: float, py: float) -> int:
    return int(np.argmin(np.hypot(x - px, y - py)))


def _block(lx: float = 0.06, ly: float = 0.04) -> ZMapStock:
    return ZMapStock.from_box((0, 0, 0), (lx, ly, TOP), H)


@pytest.mark.parametrize("direction_deg", [0.0, 30.0])
def test_slot_full_immersion(direction_deg: float) -> None:
    # First pass through a block: material on the whole front half, φ ∈ [0, π] exactly, in
    # every layer, for a feed along x and along a 30° diagonal (frame rotation).
    stock = _block(0.08, 0.08)
    d = math.radians(direction_deg)
    start = (0.04 - 0.045 * math.cos(d), 0.04 - 0.045 * math.sin(d))
    x, y = _line(start, direction_deg, 0.06)
    res = _run(stock, TOOL, x, y, TOP - 2e-3)
    k = _step_at(x, y, 0.04, 0.04)
    for layer in res.intervals(k):
        assert layer == [(0.0, pytest.approx(math.pi, abs=1e-6))]  # float32 storage
    assert res.axial_depth_m[k] == pytest.approx(2e-3, abs=1e-8)
    # engaged (projected) area of a slot = a D; contact area = a π R
    assert res.engaged_area_m2[k] == pytest.approx(2e-3 * 2 * R, rel=1e-6)
    assert res.contact_area_m2[k] == pytest.approx(2e-3 * math.pi * R, rel=1e-6)
    # one straight tooth in a slot: peak resultant K_tc c a √(1 + 0.5²)
    # (docs/decisions/0015-aslan-v9-shape-check.md)
    assert res.gain_cwe_m[k] == pytest.approx(2e-3 * math.sqrt(1.25), rel=1e-6)
    assert res.feed_angle_rad[k] == pytest.approx(d)


@pytest.mark.parametrize(
    ("mode", "y_centre", "expected"),
    [
        ("down", 0.04, (math.pi / 2, math.pi)),  # material below the centre line (φ > 90°)
        ("up", 0.0, (0.0, math.pi / 2)),  # material above it
        ("down", 0.045, (2 * math.pi / 3, math.pi)),  # a_e = D/4: arccos(2·¼ − 1) = 120°
        ("up", -0.005, (0.0, math.pi / 3)),  # a_e = D/4: arccos(1 − 2·¼) = 60°
    ],
)
def test_partial_immersion(mode: str, y_centre: float, expected: tuple[float, float]) -> None:
    # Block y ∈ [0, 40] mm, tool centre on a cell edge: closed-form entry/exit
    # (benchmarks.md §1, Engagement.radial) within the stated tolerance.
    stock = _block()
    x, y = _line((-0.015, y_centre), 0.0, 0.06)
    res = _run(stock, TOOL, x, y, TOP - 3e-3)
    k = _step_at(x, y, 0.03, y_centre)
    a_e = {0.04: R, 0.0: R, 0.045: R / 2, -0.005: R / 2}[y_centre]
    ref = Engagement.radial(a_e, 2 * R, mode).layers[0][0]  # type: ignore[arg-type]
    assert ref == pytest.approx(expected)
    for layer in res.intervals(k):
        assert len(layer) == 1
        (entry, exit_), = layer  # fmt: skip
        assert entry == pytest.approx(expected[0], abs=_tol(expected[0]) if entry > 0 else 1e-6)
        assert exit_ == pytest.approx(expected[1], abs=_tol(expected[1]) if exit_ < 3 else 1e-6)
    assert res.axial_depth_m[k] == pytest.approx(3e-3, abs=1e-8)


def test_ball_end_at_known_depth() -> None:
    # Ball Ø10 slotting 3 mm deep: engaged height = 3 mm, every layer φ ∈ [0, π], layer radii
    # √(R² − (R − z)²) at the layer centres, and the projected area Σ 2 r_ℓ Δz.
    rb = 5e-3
    ball = EndMill(2 * rb, 2, shape="ball")
    stock = _block()
    x, y = _line((-0.01, 0.02), 0.0, 0.05)
    res = _run(stock, ball, x, y, TOP - 3e-3)
    k = _step_at(x, y, 0.03, 0.02)
    assert res.axial_depth_m[k] == pytest.approx(3e-3, abs=1e-8)
    for layer in res.intervals(k):
        assert layer == [(0.0, pytest.approx(math.pi, abs=1e-6))]
    zc = (np.arange(10) + 0.5) * 0.3e-3
    r_ref = np.sqrt(rb**2 - (rb - zc) ** 2)
    assert res.layer_radii_m(k) == pytest.approx(r_ref, rel=1e-6)  # depth from float32 top
    assert res.engaged_area_m2[k] == pytest.approx(np.sum(2 * r_ref * 0.3e-3), rel=1e-6)
    # The swept slot profile in the stock is the ball: its cross-section area equals the
    # circular segment ∫ 2√(R² − (R − z)²) dz within one cell of width along its edge.
    col = np.asarray(stock.heights[:, 300], dtype=float)
    removed = np.sum(TOP - col) * H
    u0 = rb - 3e-3
    seg = 2 * (
        rb**2 * math.pi / 4 - (u0 / 2 * math.sqrt(rb**2 - u0**2) + rb**2 / 2 * math.asin(u0 / rb))
    )
    assert removed == pytest.approx(seg, abs=2 * H * 3e-3)


def test_second_pass_has_no_engagement() -> None:
    # The same tool along the same line at the same depth meets no material: no step in cut,
    # no height changes. (The second pass stays 20 mm inside the first: at the end of a cut
    # the look-ahead reads the uncut material beyond it.)
    stock = _block()
    x, y = _line((-0.015, 0.02), 0.0, 0.075)
    _run(stock, TOOL, x, y, TOP - 2e-3)
    before = stock.heights.copy()
    x2, y2 = _line((-0.015, 0.02), 0.0, 0.055)
    res = _run(stock, TOOL, x2, y2, TOP - 2e-3)
    assert not res.in_cut.any()
    assert np.array_equal(stock.heights, before)


def test_depth_step_position() -> None:
    # Material top rises from 20 to 23 mm at X_s = 30 mm (a cell edge); the axial depth of a
    # tool at z = 17 mm jumps from 3 to 6 mm when its front edge reaches X_s: the first step
    # with the deeper cut has |x + R − X_s| ≤ h (fine 0.05 mm steps resolve it).
    stock = _block()
    stock.heights[:, 300:] = np.float32(0.023)
    x, y = _line((-0.015, 0.02), 0.0, 0.04, step=0.05e-3)
    res = _run(stock, TOOL, x, y, 0.017)
    deep = np.flatnonzero(res.axial_depth_m > 4.5e-3)
    first = int(deep[0])
    assert abs(x[first] + R - 0.03) <= H
    assert res.axial_depth_m[first - 1] == pytest.approx(3e-3, abs=1e-8)
    assert res.axial_depth_m[first] == pytest.approx(6e-3, abs=1e-8)


def test_crossing_an_existing_slot_gives_two_intervals() -> None:
    # Slot along y at X0 = 30 mm, then a cut along +x at the same depth: with the centre
    # 1.5 R before X0 the material ends where R sin φ = 0.5 R, φ ∈ [0, 30°] ∪ [150°, 180°].
    tool = EndMill(2 * R, 2, helix_rad=math.radians(30.0))
    stock = _block(0.06, 0.06)
    xs, ys = _line((0.03, -0.015), 90.0, 0.09)
    _run(stock, tool, xs, ys, TOP - 3e-3)
    x, y = _line((-0.015, 0.03), 0.0, 0.09)
    res = _run(stock, tool, x, y, TOP - 3e-3)
    k = _step_at(x, y, 0.03 - 1.5 * R, 0.03)
    for layer in res.intervals(k):
        assert len(layer) == 2
        (a0, b0), (a1, b1) = layer
        assert a0 == pytest.approx(0.0, abs=1e-6) and b1 == pytest.approx(math.pi, abs=1e-6)
        assert b0 == pytest.approx(math.pi / 6, abs=_tol(math.pi / 6))
        assert a1 == pytest.approx(5 * math.pi / 6, abs=_tol(5 * math.pi / 6))
    # Gain_CWE is the peak resultant of the sliced model for K_tc = 1, K_rc = 0.5, c = 1
    # (one disc per layer, same angle grid): identical up to round-off.
    eng = res.engagement(k)
    phi = np.arange(360) * math.pi / 360  # one tooth period, as compute_engagement
    f = milling_forces(
        tool, CuttingCoefficients(1.0, 0.5), eng, 1.0, float(res.axial_depth_m[k]), phi, 10
    )
    assert res.gain_cwe_m[k] == pytest.approx(float(f.resultant_n().max()), rel=1e-9)


def test_ball_gain_matches_sliced_model() -> None:
    # Ball end, helix 30°, half immersion: Gain_CWE = peak resultant of milling_forces with
    # the same layers and angles (κ-dependent radial projection), up to round-off.
    ball = EndMill(10e-3, 3, helix_rad=math.radians(30.0), shape="ball")
    stock = _block()
    x, y = _line((-0.01, 0.04), 0.0, 0.05)
    res = _run(stock, ball, x, y, TOP - 2e-3)
    k = _step_at(x, y, 0.03, 0.04)
    phi = np.arange(240) * (2 * math.pi / 3) / 240
    f = milling_forces(
        ball, CuttingCoefficients(1.0, 0.5), res.engagement(k), 1.0,
        float(res.axial_depth_m[k]), phi, 10,
    )  # fmt: skip
    assert res.gain_cwe_m[k] > 0
    assert res.gain_cwe_m[k] == pytest.approx(float(f.resultant_n().max()), rel=1e-9)


def test_aslan_v9_slot_step() -> None:
    # Seed 000 V9: F_res = K_tc c Gain_CWE, 758 N/mm² × 0.2 mm × 0.976 mm = 147.96 N. A slot
    # of depth 0.976/√1.25 mm with the straight 2-flute Ø20 gives Gain_CWE = 0.976 mm on the
    # z-map, and the sliced force model on that engagement gives the same peak resultant.
    stock = _block()
    depth = 0.976e-3 / math.sqrt(1.25)
    x, y = _line((-0.015, 0.02), 0.0, 0.06)
    res = _run(stock, TOOL, x, y, TOP - depth)
    k = _step_at(x, y, 0.03, 0.02)
    assert res.gain_cwe_mm[k] == pytest.approx(0.976, rel=1e-5)
    ktc = 758e6
    f = milling_forces(
        TOOL, CuttingCoefficients(ktc, 0.5 * ktc), res.engagement(k), 0.2e-3,
        float(res.axial_depth_m[k]), np.arange(720) * math.pi / 360, 20,
    )  # fmt: skip
    peak = float(f.resultant_n().max())
    assert peak == pytest.approx(ktc * 0.2e-3 * res.gain_cwe_m[k], rel=1e-6)
    assert peak == pytest.approx(147.96, rel=1e-3)


def test_chunked_call_equals_one_call() -> None:
    # previous_xyz_m continues a path: two chunks give the same engagement and stock.
    x, y = _line((-0.015, 0.03), 10.0, 0.06)
    z = np.full(x.size, TOP - 2e-3)
    s1, s2 = _block(), _block()
    one = compute_engagement(s1, TOOL, x, y, z)
    m = x.size // 2
    a = compute_engagement(s2, TOOL, x[:m], y[:m], z[:m])
    b = compute_engagement(
        s2, TOOL, x[m:], y[m:], z[m:], previous_xyz_m=(x[m - 1], y[m - 1], z[m - 1])
    )
    assert np.array_equal(s1.heights, s2.heights)
    both = EngagementResult.concatenate([a, b])
    assert np.array_equal(one.intervals_rad, both.intervals_rad)
    assert np.array_equal(one.gain_cwe_m, both.gain_cwe_m)
    assert np.array_equal(one.engaged_area_m2, both.engaged_area_m2)
    assert one.in_cut.sum() > 100  # the comparison is not vacuous


def test_out_of_cut_and_engagement_object() -> None:
    # Above the stock nothing is engaged and the Engagement has only empty layers.
    stock = _block()
    x, y = _line((0.0, 0.02), 0.0, 0.02)
    res = _run(stock, TOOL, x, y, TOP + 1e-3, n_layers=4)
    assert not res.in_cut.any() and np.all(res.gain_cwe_m == 0)
    eng = res.engagement(3)
    assert eng.n_layers == 4 and eng.max_intervals() == 0


def test_bad_arguments() -> None:
    stock = _block()
    x = np.zeros(3)
    with pytest.raises(ConfigError, match="n_layers"):
        compute_engagement(stock, TOOL, x, x, x, n_layers=0)
    with pytest.raises(ConfigError, match="angle_step_rad"):
        compute_engagement(stock, TOOL, x, x, x, angle_step_rad=0.3)
    with pytest.raises(InputDataError, match="feed_dir"):
        compute_engagement(stock, TOOL, x, x, x, feed_dir=np.zeros((2, 2)))


def test_virtual_quick_cases_pass() -> None:
    # The registered acceptance figures of this package (each with its own reference).
    cases = select_cases("plan.cwe*", quick_only=True) + select_cases(
        "plan.aslan*", quick_only=True
    )
    assert len(cases) >= 6
    for c in cases:
        r = run_case(c)
        assert r.passed, (c.id, r.measured, r.reference, r.error)


@pytest.mark.parametrize("slope_deg", [20.0, 35.0, 50.0])
def test_slanted_edge_gives_one_clean_interval(slope_deg: float) -> None:
    # Material below a line through (30, 20) mm at slope angle α, staircased by the grid;
    # tool centre on the line feeding along +x: material where R cos φ < tan α R sin φ, i.e.
    # φ ∈ [90° − α, 180°]. One interval per layer (staircase gaps narrower than a cell are
    # joined), entry within the stated tolerance.
    stock = _block()
    t = math.tan(math.radians(slope_deg))
    xc, yc = np.meshgrid(stock.x_centres_m, stock.y_centres_m)
    stock.heights[yc > 0.02 + t * (xc - 0.03)] = np.float32(0.0)
    x, y = np.array([0.03]), np.array([0.02])
    res = compute_engagement(stock, TOOL, x, y, np.full(1, TOP - 3e-3), feed_dir=np.array([[1, 0]]))
    entry = math.radians(90.0 - slope_deg)
    for layer in res.intervals(0):
        assert len(layer) == 1
        assert layer[0][0] == pytest.approx(entry, abs=_tol(entry))
        assert layer[0][1] == pytest.approx(math.pi, abs=1e-6)
