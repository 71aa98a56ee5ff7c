"""Plan-driven virtual machine: plan format 2, PlanEngagement, vertex paths, ``simulate --plan``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from millsense.cli.main import main
from millsense.core.errors import InputDataError
from millsense.core.units import MM
from millsense.plan.gcode import interpret
from millsense.plan.path import vertex_path
from millsense.plan.plan_engagement import PlanEngagement, plan_path
from millsense.plan.stock import ZMapStock
from millsense.plan.virtual_plan import (
    LAYER_COLUMNS,
    META_KEY,
    PLAN_FORMAT_VERSION,
    VirtualPlan,
    coefficients_from_metadata,
    plan_program,
    tool_from_metadata,
)
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.validation import run_case, select_cases
from millsense.validation.cases.simulator_plan import SLOT_PROGRAM, SLOT_WINDOW, slot_run

TOOL = EndMill(20e-3, 2, helix_rad=math.radians(30), runout_offset_m=5e-6)
COEFFS = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)

# a slot entering the block, then a second slot crossing it (two intervals per layer there)
CROSS = (
    "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-15 Y20 Z5\nG1 Z-2 F400\nX45\nG0 Z5\n"
    "G0 X20 Y-15\nG1 Z-3 F400\nY30\nG0 Z5\nM30\n"
)


def _plan(text: str = CROSS) -> VirtualPlan:
    stock = ZMapStock.from_box([0.0, 0.0, -0.02], [0.04, 0.04, 0.0], 0.2e-3)
    return plan_program(interpret(text, source="t.nc"), stock, TOOL, COEFFS)


@pytest.fixture(scope="module")
def cross_plan() -> VirtualPlan:
    return _plan()


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_layer_columns_round_trip_and_readable_by_arrow(
    cross_plan: VirtualPlan, tmp_path: Path
) -> None:
    p = cross_plan.write(tmp_path / "p.parquet")
    table = pq.read_table(p)
    # plain Arrow list columns (duckdb/polars read them as LIST)
    assert table.schema.field("interval_counts").type == pa.list_(pa.int16())
    assert table.schema.field("intervals_rad").type == pa.list_(pa.float32())
    meta = json.loads(table.schema.metadata[META_KEY])
    assert meta["format_version"] == PLAN_FORMAT_VERSION == 2
    back = VirtualPlan.read(p)
    assert back.layers is not None and cross_plan.layers is not None
    m = back.layers.intervals_rad.shape[2]
    # exact: the float32 intervals are stored bit for bit
    assert np.array_equal(back.layers.counts, cross_plan.layers.counts)
    assert np.array_equal(back.layers.intervals_rad, cross_plan.layers.intervals_rad[:, :, :m])
    # the crossing gives two intervals in a layer somewhere (entry and exit of the first slot)
    assert int(back.layers.counts.max()) == 2
    # flattened length = 2 × Σ counts per row (independent count from the Arrow offsets)
    lengths = pa.compute.list_value_length(table.column("intervals_rad")).to_numpy()
    assert np.array_equal(lengths, 2 * cross_plan.layers.counts.sum(axis=1))


def test_tool_and_coefficients_from_metadata(cross_plan: VirtualPlan, tmp_path: Path) -> None:
    back = VirtualPlan.read(cross_plan.write(tmp_path / "p.parquet"))
    tool = tool_from_metadata(back.metadata)
    co = coefficients_from_metadata(back.metadata)
    # exactly the objects the plan was built with (JSON floats round-trip)
    assert tool.diameter_m == pytest.approx(TOOL.diameter_m, rel=1e-12)
    assert tool.n_flutes == 2 and tool.helix_rad == pytest.approx(TOOL.helix_rad, rel=1e-12)
    assert tool.runout_offset_m == pytest.approx(5e-6, rel=1e-9)
    for k in ("ktc", "krc", "kac", "kte", "kre", "kae"):
        assert getattr(co, k) == pytest.approx(getattr(COEFFS, k), rel=1e-12, abs=1e-9)
    assert back.metadata["n_discs"] == 20  # 2 × n_layers, predict_states' default
    with pytest.raises(InputDataError, match=r"'tool\.diameter_mm'"):
        tool_from_metadata({"tool": {"flutes": 2}})


def test_plan_engagement_follows_arc_length(cross_plan: VirtualPlan) -> None:
    src = PlanEngagement(cross_plan)
    assert src.exact and not src.notes
    s = src.row_s_m
    k = int(np.nonzero(src.row_index >= 0)[0][10])
    idx, dep = src.at(np.array([s[k], 0.5 * (s[k] + s[k + 1]), s[k + 1] - 1e-9, -1.0, s[-1] + 1]))
    # row k holds on [s_k, s_k+1); air before the path and after its end
    assert list(idx[:3]) == [src.row_index[k]] * 3 and list(idx[3:]) == [-1, -1]
    assert dep[0] == pytest.approx(cross_plan["axial_depth_mm"][k] * MM, rel=1e-12)
    # the table entry is the CWE's own intervals, layer by layer
    assert cross_plan.layers is not None
    eng = src.table[int(src.row_index[k])]
    for layer in range(eng.n_layers):
        n = int(cross_plan.layers.counts[k, layer])
        want = cross_plan.layers.intervals_rad[k, layer, :n].astype(float)
        assert np.allclose(np.array(eng.layers[layer]).reshape(-1, 2), want, atol=0)
    # arc length is the chord length of the rows: on these straight moves equal to s_mm
    # except across the corners of rapids (chords ≤ arc)
    assert np.all(s <= cross_plan["s_mm"] * MM + 1e-12)


def test_version1_plan_falls_back_to_widest_interval(
    cross_plan: VirtualPlan, tmp_path: Path
) -> None:
    v1 = VirtualPlan(dict(cross_plan.columns), dict(cross_plan.metadata))  # no layers
    p = v1.write(tmp_path / "v1.parquet")
    table = pq.read_table(p)
    assert not set(LAYER_COLUMNS) & set(table.column_names)
    back = VirtualPlan.read(p)
    assert back.layers is None and back.metadata["format_version"] == 1
    src = PlanEngagement(back)
    assert not src.exact and "widest interval" in src.notes[0]
    # in the steady first slot the widest interval is the whole slot (0, π) at every height
    k = int(np.argmin(np.abs(back["x_mm"] - 10.0) + 1e3 * (back["y_mm"] != 20.0)))
    eng = src.table[int(src.row_index[k])]
    assert eng.n_layers == 1
    assert eng.layers[0][0] == pytest.approx((0.0, math.pi), abs=1e-6)


def test_bad_plan_files_one_line_exit_2(
    cross_plan: VirtualPlan, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = cross_plan.write(tmp_path / "good.parquet")
    table = pq.read_table(good)
    not_parquet = tmp_path / "junk.parquet"
    not_parquet.write_text("x_mm,y_mm\n1,2\n")
    missing = tmp_path / "missing.parquet"
    pq.write_table(table.drop(["feed_mm_min"]), missing)
    wrong = tmp_path / "wrong.parquet"
    meta = json.loads(table.schema.metadata[META_KEY])
    meta["format_version"] = 99
    pq.write_table(table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()}), wrong)
    no_layers = tmp_path / "nolayers.parquet"
    pq.write_table(table.drop(["intervals_rad"]), no_layers)
    cases = [
        (not_parquet, "not a Parquet file"),
        (missing, "missing column 'feed_mm_min'"),
        (wrong, "format version 99"),
        (no_layers, "misses column 'intervals_rad'"),
    ]
    for path, text in cases:
        code, _, err = _run(["simulate", "--plan", str(path), "-o", str(tmp_path / "r.h5")], capsys)
        assert code == 2, path
        assert err.strip().count("\n") == 0 and text in err and path.name in err


def test_vertex_path_keeps_exact_corners_and_arcs() -> None:
    prog = (
        "G21 G90 G17\nS1000 M3\nG0 X0 Y0 Z5\nG1 Z0 F600\nX10\nG2 X20 Y-10 I0 J-10\nG1 Y-30\nM30\n"
    )
    tp = interpret(prog)
    vp = vertex_path(tp, chord_tol_m=1e-6)
    xy = np.column_stack([vp.x, vp.y]) / MM
    # the programmed vertices are points of the path (exact corners)
    for corner in ([0, 0], [10, 0], [20, -10], [20, -30]):
        assert np.min(np.hypot(*(xy - corner).T)) < 1e-9
    on_arc = vp.move == int(np.nonzero(tp.kind == 2)[0][0])
    r = np.hypot(xy[on_arc, 0] - 10, xy[on_arc, 1] + 10)
    assert np.allclose(r, 10.0, atol=1e-9)  # arc points on the circle
    # chord sagitta r (1 − cos(Δφ/2)) ≤ tolerance: Δφ from consecutive points
    pts = xy[np.nonzero(on_arc)[0][0] - 1 : np.nonzero(on_arc)[0][-1] + 1]
    ang = np.unwrap(np.arctan2(pts[:, 1] + 10, pts[:, 0] - 10))
    sag = 10e-3 * (1 - np.cos(np.abs(np.diff(ang)) / 2))
    assert sag.max() <= 1e-6 * (1 + 1e-9) and sag.max() > 0.5e-6  # not over-refined
    # each point carries the feed of the move leading to it; the first the first move's
    assert vp.rapid[0] and vp.rapid[1] and not vp.rapid[2:].any()
    assert np.all(vp.feed[2:] == pytest.approx(600 * MM / 60))
    # arc length at the end: 5 (G0) + 5 (plunge) + 10 + quarter circle R10 + 20, mm
    assert vp.s[-1] / MM == pytest.approx(40 + 10 * math.pi / 2, rel=1e-12)


def test_plan_path_segments_take_the_next_row(cross_plan: VirtualPlan) -> None:
    pp = plan_path(cross_plan)
    assert pp.path.shape == (len(cross_plan), 3)  # rows 0.4 mm apart: none dropped
    assert np.array_equal(pp.rapid, cross_plan["rapid"][1:].astype(bool))
    assert np.allclose(pp.feed_m_s[~pp.rapid], 400 * MM / 60, rtol=1e-12)
    assert np.allclose(pp.spindle_rad_s[~pp.rapid], 1000 * 2 * math.pi / 60, rtol=1e-12)


def test_a_rotary_only_move_turns_at_its_rate_on_a_five_axis_machine() -> None:
    """Decision 1743: ``G0 A30 C90`` holds no row of the plan; its rotation falls into the
    segment to the next row (a 5 mm rapid in Y), whose plan time holds the rotation's at the
    rotary rapid rate (20 rev/min: 90° in 0.75 s). That segment's feed is its length over the
    plan's time: C turns at 20 rev/min (1e-9), not 90° over the rapid's 15 ms. The other
    segments keep the rows' feeds."""
    from millsense.core.units import MM_PER_MIN
    from millsense.plan.path import DEFAULT_RAPID_ROTARY_RATE

    text = ("G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-15 Y20 Z5 A0 C0\nG0 A30 C90\nG0 Y25\n"
            "G1 Z-2 F400\nX10\nG0 Z5\nM30\n")  # fmt: skip
    plan = _plan(text)
    pp = plan_path(plan, five_axis=True)
    rot = np.linalg.norm(np.diff(pp.path[:, 3:], axis=0), axis=1)
    lin = np.linalg.norm(np.diff(pp.path[:, :3], axis=0), axis=1)
    turning = np.flatnonzero(rot > 1e-9)
    assert turning.size == 1
    j = int(turning[0])
    assert rot[j] == pytest.approx(math.hypot(math.radians(30), math.radians(90)), rel=1e-9)
    # the segment lasts the plan's time, the rotation's at the rotary rapid rate (the larger
    # axis turn, C's 90°, at 20 rev/min) and the rapid's few milliseconds
    duration = lin[j] / pp.feed_m_s[j]
    t = np.asarray(plan["t_s"])
    assert duration == pytest.approx(t[pp.rows[j + 1]] - t[pp.rows[j]], rel=1e-9)
    c_rate = math.radians(90) / duration
    assert 0.97 * DEFAULT_RAPID_ROTARY_RATE <= c_rate <= DEFAULT_RAPID_ROTARY_RATE
    others = np.delete(np.arange(len(pp.feed_m_s)), j)
    rows = pp.rows[1:][others]
    assert np.array_equal(pp.feed_m_s[others], np.asarray(plan["feed_mm_min"])[rows] * MM_PER_MIN)
    # a 3-axis machine's path keeps the rows' feed (no rotary columns)
    assert plan_path(plan).feed_m_s.min() > 0.9 * 400 * MM / 60


def test_quick_plan_cases_pass() -> None:
    ids = {c.id for c in select_cases("simulator.plan_*", quick_only=True)}
    assert ids == {"simulator.plan_slot_average_force", "simulator.plan_slot_peak_resultant"}
    for c in select_cases("simulator.plan_*", quick_only=True):
        res = run_case(c)
        assert res.passed, (c.id, res.measured, res.details, res.error)


def test_interpolator_keeps_the_feed_on_plan_rows() -> None:
    # 0.4 mm collinear rows must not slow the feed (decision "Interpolator junction speed"):
    # the interpolated feed in the steady window equals 400 mm/min
    run = slot_run()
    x = run.data["truth/x/position"]
    win = (x >= SLOT_WINDOW[0]) & (x < SLOT_WINDOW[1])
    feed = run.data["cnc/feed"][win]
    assert feed.min() == pytest.approx(400 * MM / 60, rel=1e-9)
    assert feed.max() == pytest.approx(400 * MM / 60, rel=1e-9)
    # and the simulated chip equals the plan's chip load (0.2 mm/tooth) within 0.1 %
    c = run.data["truth/process/feed_per_tooth"][win]
    assert c.mean() == pytest.approx(0.2e-3, rel=1e-3)


def test_cli_simulate_plan_uses_the_plan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.io import read_recording

    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], 0.2e-3)
    plan = plan_program(interpret(SLOT_PROGRAM, source="slot.nc"), stock, TOOL, COEFFS)
    pfile = plan.write(tmp_path / "slot.parquet")
    out = tmp_path / "run.h5"
    code, _, err = _run(
        ["simulate", "--machine", "quaser-ux600", "--plan", str(pfile), "-o", str(out),
         "--duration-s", "4.0"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    rec = read_recording(out)
    assert rec.metadata["plan"] == str(pfile)
    depth = rec.channel("truth/process/depth")
    # the slot is 2 mm deep: the plan's depth reaches the machine (tool from the plan)
    assert depth.max() == pytest.approx(2e-3, rel=1e-9)
    torque = rec.channel("truth/spindle/torque")[depth > 0]
    # in the full slot (x ≥ 0, by 4 s the tool is at x ≈ +2 mm) the torque averages about
    # the plan's 2.43 N·m; partial engagement before → mean below it but positive
    assert 0.3 < float(torque.mean()) < 2.6


@pytest.mark.parametrize("flutes", [3, 4])
def test_the_recordings_metadata_names_the_tools_flutes(tmp_path: Path, flutes: int) -> None:
    """Decision 1716: the virtual machine's recording says how many flutes its tool has, as
    `millsense example-data`'s does, so `monitor` and `estimate` without a plan judge it at
    the tool's tooth frequency, not the default 2 flutes' (found on a 3-flute run, where
    `monitor` placed the tooth line at 200 Hz instead of 300 Hz at 6000 rev/min)."""
    from millsense.cli.cmd_monitor import _flutes
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.simulator.plan_job import plan_job

    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], 0.5e-3)
    tool = EndMill(10e-3, flutes, helix_rad=math.radians(30))
    plan = plan_program(interpret(SLOT_PROGRAM, source="slot.nc"), stock, tool, COEFFS)
    _, _, meta, _ = plan_job(plan, load_preset(MachineConfig, "quaser-ux600"), "slot.parquet")
    assert meta["flutes"] == flutes

    class Rec:  # what `monitor` reads of a recording
        metadata = meta

    assert _flutes(None, Rec(), None) == flutes
