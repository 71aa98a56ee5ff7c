"""Virtual plan: predictions vs the sliced force model, file round trip, match, look-ahead."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.plan.cwe import compute_engagement
from millsense.plan.gcode import interpret
from millsense.plan.predict import predict_states
from millsense.plan.stock import ZMapStock
from millsense.plan.virtual_plan import VirtualPlan, plan_program
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.validation import run_case, select_cases

TOOL = EndMill(20e-3, 2, helix_rad=math.radians(30.0))
COEFFS = CuttingCoefficients(758e6, 379e6, 100e6, 25e3, 35e3, 5e3)
FEED = 400.0 / 60e3
OMEGA = 1000.0 * 2 * math.pi / 60


def test_prediction_equals_sliced_model_in_machine_frame() -> None:
    # Independent computation: milling_forces per step (20 discs, 360 angles over a tooth
    # period = the basis' grid), rotated by the feed angle by hand. Round-off agreement.
    stock = ZMapStock.from_box((0, 0, 0), (0.06, 0.04, 0.02), 1e-4)
    x = np.arange(-0.015, 0.045, 0.4e-3)
    y = 0.03 + 0.002 * np.sin(x * 200)
    eng = compute_engagement(stock, TOOL, x, y, np.full(x.size, 0.017))
    n = x.size
    pred = predict_states(eng, COEFFS, np.full(n, FEED), np.full(n, OMEGA))
    assert pred.basis.n_signatures < pred.active.sum()  # grouping happened
    phi = np.arange(360) * math.pi / 360
    for k in np.flatnonzero(pred.active)[::15]:
        f = milling_forces(TOOL, COEFFS, eng.engagement(k), 0.2e-3, eng.axial_depth_m[k], phi, 20)
        th = eng.feed_angle_rad[k]
        fx = f.fx_n * math.cos(th) - f.fy_n * math.sin(th)
        fy = f.fx_n * math.sin(th) + f.fy_n * math.cos(th)
        assert pred.stats["fx_avg"][k] == pytest.approx(fx.mean(), rel=1e-9, abs=1e-9)
        assert pred.stats["fy_avg"][k] == pytest.approx(fy.mean(), rel=1e-9, abs=1e-9)
        assert pred.stats["fres_peak"][k] == pytest.approx(np.hypot(fx, fy).max(), rel=1e-9)
        assert pred.stats["torque_avg"][k] == pytest.approx(f.torque_nm.mean(), rel=1e-9)
        assert abs(pred.stats["fz_peak"][k]) == pytest.approx(np.abs(f.fz_n).max(), rel=1e-9)
        # chip load c = v_f/(N n) = 400/(2·1000) mm; MRR = v_f × engaged area
        assert pred.chip_load_m[k] == pytest.approx(0.2e-3, rel=1e-12)
        assert pred.mrr_m3_s[k] == pytest.approx(FEED * eng.engaged_area_m2[k], rel=1e-12)
        assert pred.power_w[k] == pytest.approx(f.torque_nm.mean() * OMEGA, rel=1e-9)


def test_runout_tool_uses_revolution_period_and_matches_model() -> None:
    # With runout the force repeats once per revolution and h is not linear in c; the
    # feed-binned signature must still equal the direct model at the bin's feed (≤ 0.5 %).
    tool = EndMill(20e-3, 2, runout_offset_m=20e-6)
    stock = ZMapStock.from_box((0, 0, 0), (0.06, 0.04, 0.02), 1e-4)
    x = np.arange(-0.015, 0.045, 0.4e-3)
    eng = compute_engagement(stock, tool, x, np.full(x.size, 0.02), np.full(x.size, 0.017))
    pred = predict_states(eng, COEFFS, np.full(x.size, FEED), np.full(x.size, OMEGA))
    assert pred.basis.period_rad == pytest.approx(2 * math.pi)
    k = int(np.argmin(np.abs(x - 0.03)))
    phi = np.arange(720) * math.pi / 360
    f = milling_forces(tool, COEFFS, eng.engagement(k), 0.2e-3, eng.axial_depth_m[k], phi, 20)
    assert pred.stats["torque_avg"][k] == pytest.approx(f.torque_nm.mean(), rel=5e-3)
    assert pred.stats["fres_peak"][k] == pytest.approx(f.resultant_n().max(), rel=5e-3)


def test_quick_validation_cases_pass() -> None:
    for c in select_cases("plan.plan_*"):
        assert run_case(c).passed, c.id


PROGRAM = """%
G21 G90 G94 G17
T1 M6
S1000 M3
G0 X-15. Y20. Z5.
G1 Z-2. F400.
X25.
G0 Z5.
G0 X-15. Y20.
G1 Z-3. F400.
X75.
G0 Z20.
M30
%
"""


def _plan(text: str = PROGRAM) -> VirtualPlan:
    stock = ZMapStock.from_box((0, 0, -0.02), (0.06, 0.04, 0.0), 1e-4)
    return plan_program(interpret(text, source="t.nc"), stock, TOOL, COEFFS)


def test_plan_columns_and_parquet_round_trip(tmp_path: Path) -> None:
    plan = _plan()
    out = plan.write(tmp_path / "p.parquet")
    back = VirtualPlan.read(out)
    assert len(back) == len(plan)
    for name in ("x_mm", "fres_peak_n", "torque_avg_nm", "in_cut", "nc_line"):
        np.testing.assert_array_equal(back[name], plan[name])  # lossless
    assert back.metadata["material"]["ktc_n_mm2"] == pytest.approx(758.0)
    assert back.metadata["step_mm"] == pytest.approx(0.4)
    # the first slot is 2 mm deep (stock top z = 0), the second 1 mm below it
    cut = plan["in_cut"] & (plan["source_line"] == 7)
    assert np.median(plan["axial_depth_mm"][cut]) == pytest.approx(2.0, abs=1e-6)
    # field-unit columns: 400 mm/min, 1000 rev/min → 0.2 mm/tooth, K_tc 758 N/mm²
    assert np.all(plan["feed_mm_min"][cut] == pytest.approx(400.0))
    assert np.all(plan["chip_load_mm"][cut] == pytest.approx(0.2))
    assert np.all(plan["ktc_n_mm2"][cut] == pytest.approx(758.0))
    # pyarrow reads it as a plain table with unit-named columns
    import pyarrow.parquet as pq

    table = pq.read_table(out, columns=["x_mm", "feed_mm_min"])
    assert table.num_rows == len(plan)


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    plan = _plan()
    target = tmp_path / "p.parquet"
    plan.write(target)
    before = target.read_bytes()
    import pyarrow.parquet as pq

    def boom(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", boom)
    with pytest.raises(OSError):
        plan.write(target)
    assert target.read_bytes() == before  # old file untouched
    assert [p.name for p in tmp_path.iterdir()] == ["p.parquet"]  # no temporary left
    with pytest.raises(OSError):
        plan.write(tmp_path / "new.parquet")
    assert not (tmp_path / "new.parquet").exists()


def test_read_rejects_other_files(tmp_path: Path) -> None:
    bad = tmp_path / "x.parquet"
    bad.write_text("not parquet")
    with pytest.raises(InputDataError, match=r"x\.parquet"):
        VirtualPlan.read(bad)


def test_match_forward_with_tolerance() -> None:
    plan = _plan()
    rng = np.random.default_rng(1)
    # TCP at 333 Hz on the second slot (400 mm/min → 20 µm per sample), ±5 µm noise
    rows = np.flatnonzero(plan["source_line"] == 11)
    xs = np.arange(plan["x_mm"][rows[0]], plan["x_mm"][rows[-1]], 0.02) * 1e-3
    tcp = np.column_stack((xs, np.full(xs.size, 0.02), np.full(xs.size, -0.003)))
    tcp += rng.uniform(-5e-6, 5e-6, tcp.shape)
    got = plan.match(tcp, from_row=0)
    assert np.all(got >= 0) and np.all(np.diff(got) >= 0)
    # row r holds x_r ≤ x < x_r + 0.4 mm (± noise): independent floor computation
    expect = rows[0] + np.floor((tcp[:, 0] * 1e3 - plan["x_mm"][rows[0]]) / 0.4 + 1e-9)
    assert np.max(np.abs(got - expect)) <= 1  # within one row where noise crosses a row
    # the first slot passes the same XY 1 mm higher: never matched when searching from it
    assert np.all(got >= rows[0])
    # 15 µm off in z is outside ±10 µm → no match
    off = plan.match(tcp[:5] + np.array([0, 0, 15e-6]), from_row=int(rows[0]))
    assert np.all(off == -1)


def test_look_ahead_flags() -> None:
    plan = _plan()
    rows = np.flatnonzero((plan["source_line"] == 11) & plan["in_cut"])
    # second slot: depth 1 mm inside the first slot (its end at X25), 3 mm beyond →
    # engaged area triples at X25: flag 1 within 0.5 s (3.3 mm at 400 mm/min)
    x = plan["x_mm"]
    # engaged area a·D: 1 × 20 and 3 × 20 mm², within one engagement layer (3/10 mm × 20)
    area = plan["engaged_area_mm2"]
    assert area[rows[np.argmin(np.abs(x[rows] - 15.0))]] == pytest.approx(20.0, abs=6.0)
    assert area[rows[np.argmin(np.abs(x[rows] - 40.0))]] == pytest.approx(60.0, abs=6.0)
    before_step = rows[np.argmin(np.abs(x[rows] - 23.0))]
    la = plan.look_ahead(int(before_step), 0.5)
    assert la.flag == 1 and la.rising
    # at x = 10 the shallow cut does not reach the step within 0.5 s: flag 0
    far = rows[np.argmin(np.abs(x[rows] - 10.0))]
    assert plan.look_ahead(int(far), 0.5).flag == 0
    # near the end of the slot (the tool leaves the 60 mm block at X70): leaving → flag 2
    last = rows[-1]
    la2 = plan.look_ahead(int(last - 3), 0.5)
    assert la2.flag == 2 and la2.leaving_cut
    # a 200 % override covers twice the path: the step is seen from further away
    earlier = rows[np.argmin(np.abs(x[rows] - 20.4))]
    assert plan.look_ahead(int(earlier), 0.5, 1.0).flag == 0
    assert plan.look_ahead(int(earlier), 0.5, 2.0).flag == 1


def _look_ahead_by_masks(
    t: np.ndarray,
    cut_col: np.ndarray,
    area_col: np.ndarray,
    chip_col: np.ndarray,
    row: int,
    span_s: float,
    rise: float,
) -> tuple[int, bool, bool, bool, int, int]:
    """Decision 0063's verdict written with whole-window masks (the form the compiled
    one-pass kernel replaced), as an independent computation."""
    n = t.size
    end = max(min(int(np.searchsorted(t, t[row] + span_s, side="right")), n), row + 1)
    sl = slice(row + 1, end)
    cut, area, cl = cut_col[sl].astype(bool), area_col[sl], chip_col[sl]
    now = bool(cut_col[row])
    a0, c0 = float(area_col[row]), float(chip_col[row])
    rising_m = cut & ((area >= (1 + rise) * a0) | (cl >= (1 + rise) * c0)) if now else cut
    leaving_m = np.zeros(cut.size, bool)
    cavity_m = np.zeros(cut.size, bool)
    if now and cut.size:
        later = np.flip(np.maximum.accumulate(np.flip(cut)))
        leaving_m = ~later
        cavity_m = ((~cut) | (area <= (1 - rise) * a0)) & later
    rising, leaving, cavity = bool(rising_m.any()), bool(leaving_m.any()), bool(cavity_m.any())
    flag = 2 if (leaving or cavity) else (1 if rising else 0)
    mask = (leaving_m | cavity_m) if flag == 2 else rising_m
    return flag, rising, leaving, cavity, int(row + 1 + np.argmax(mask)) if flag else -1, end


def test_look_ahead_kernel_equals_the_mask_form_on_random_paths() -> None:
    """The one-pass kernel (``_plan_kernels.look_ahead_flags``) gives the mask form's verdict,
    event row and horizon on 3000 random windows: cuts with gaps, area and chip-load jumps
    around the ±15 % bounds, rows at the path's end, overrides."""
    from millsense.plan import _plan_kernels as k

    rng = np.random.default_rng(7)
    for trial in range(3000):
        n = int(rng.integers(1, 60))
        t = np.cumsum(rng.uniform(0.0, 0.05, n))
        cut = (rng.random(n) < rng.uniform(0.2, 1.0)).astype(float)
        area = np.round(rng.uniform(0.5, 1.5, n) * 20.0, 1) * cut
        chip = np.round(rng.uniform(0.7, 1.3, n) * 0.1, 3) * cut
        row = int(rng.integers(0, n))
        span, rise = float(rng.uniform(0.0, 1.0)), float(rng.choice([0.0, 0.15]))
        got = k.look_ahead_flags(t, cut, area, chip, row, span, rise)
        assert tuple(got) == _look_ahead_by_masks(t, cut, area, chip, row, span, rise), trial


def test_engagement_faces_the_next_motion_at_a_reversal() -> None:
    # A slot runs into the block to X30 and comes back along itself. Leaving X30 the tool
    # moves back through cut material: the step at the vertex meets nothing
    # (docs/decisions/0066-engagement-faces-the-next-motion.md); reading the incoming tangent
    # would see the uncut wall ahead and predict a full-slot force there.
    text = """G21 G90 G17
S1000 M3
G0 X-15. Y20. Z5.
G1 Z-2. F400.
X30.
X-15.
G0 Z5.
M30
"""
    plan = _plan(text)
    x = plan["x_mm"]
    vertex = int(np.argmax(x))
    assert x[vertex] == pytest.approx(30.0, abs=0.4)  # the sample nearest the vertex
    assert not plan["in_cut"][vertex]
    assert plan["fres_peak_n"][vertex] == 0.0
    # the steps just before the vertex are still in a full slot
    assert plan["in_cut"][vertex - 3] and plan["fres_peak_n"][vertex - 3] > 100.0


def test_a_retract_along_the_axis_cuts_nothing_a_plunge_still_does() -> None:
    """Decision 1544: the module's program retracts with G0 Z5. at X25, inside the block, after
    its 2 mm slot. Moving up the tool leaves the slot's end wall: none of the retract's steps
    is in cut and none carries a force (the z-map's edge cells of that wall read as a half-slot
    all the way up before). A plunge into the block at X30 keeps its engagement."""
    plan = _plan()
    x, z = plan["x_mm"], plan["z_mm"]
    retract = (np.abs(x - 25.0) < 1e-9) & (z > -2.0 + 1e-9) & (z < 0.0)
    assert retract.sum() >= 4  # 0.4 mm steps from Z-2 to the top face
    assert not plan["in_cut"][retract].any()
    assert not np.any(plan["fres_peak_n"][retract])
    plunge = _plan("""G21 G90 G17
S1000 M3
G0 X30. Y20. Z5.
G1 Z-2. F100.
X45. F400.
G0 Z5.
M30
""")
    x, z = plunge["x_mm"], plunge["z_mm"]
    down = (np.abs(x - 30.0) < 1e-9) & (z < -0.5) & (z > -2.0)
    assert down.any() and plunge["in_cut"][down].all()


def test_ramps_and_plunges_cut_the_feed_across_the_tool_axis() -> None:
    """Decision 1673: the flutes' chip is the feed per tooth across the tool axis. A 45° ramp
    (X30 → X31.5, Z−1.5 → Z−3) has the chip of cos 45° of the feed per tooth (0.2 mm at F400,
    1000 rev/min, 2 flutes: 0.1414 mm), a plunge none (its torque is the edge part alone), the
    horizontal cut after them the whole 0.2 mm (each step the tangent of its move)."""
    plan = _plan("""G21 G90 G17
S1000 M3
G0 X30. Y20. Z5.
G1 Z-1.5 F400.
X31.5 Z-3.
X45.
G0 Z5.
M30
""")
    x, z = plan["x_mm"], plan["z_mm"]
    cut = plan["in_cut"]
    chip = plan["chip_load_mm"]
    ramp = cut & (x > 30.05) & (x < 31.45)
    plunge = cut & (np.abs(x - 30.0) < 1e-9) & (z < -0.05) & (z > -1.05)
    flat = cut & (x > 35.0) & (x < 44.0)
    assert ramp.sum() >= 3 and plunge.any() and flat.sum() >= 10
    assert chip[flat] == pytest.approx(0.2, rel=1e-9)
    assert chip[ramp] == pytest.approx(0.2 * math.cos(math.pi / 4), rel=1e-6)
    assert chip[plunge] == pytest.approx(0.0, abs=1e-12)
    tq, shear = plan["torque_avg_nm"], plan["torque_avg_shear_nm"]
    assert shear[plunge] == pytest.approx(0.0, abs=1e-12)
    assert tq[plunge] == pytest.approx(tq[plunge] - shear[plunge], abs=1e-12)
