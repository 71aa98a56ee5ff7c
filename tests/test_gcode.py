"""G-code interpreter: corpus, analytic geometry, modal state and one-line errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core.errors import ProgramError
from millsense.core.units import DEG, MM, MM_PER_MIN, RPM
from millsense.plan.gcode import interpret, interpret_file
from millsense.plan.path import ARC, DWELL, LINE, PLANE_YZ, PLANE_ZX, RAPID, sample_path

CORPUS = Path(__file__).resolve().parents[1] / "examples" / "gcode"
OFFSETS = {"G55": (100.0, 50.0, -20.0), "G56": (10.0, 10.0, 0.0)}
INCH = 25.4 * MM


def _run(body: str, **kw: object) -> object:
    return interpret("G21 G90 G17\n" + body + "\nM30\n", source="t.nc", **kw)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- corpus


@pytest.mark.parametrize("name", sorted(p.name for p in CORPUS.glob("*.nc")))
def test_corpus_parses_and_is_continuous(name: str) -> None:
    tp = interpret_file(CORPUS / name, home_mm=(0.0, 0.0, 0.0), work_offsets_mm=OFFSETS)
    # Every move starts where the previous one ended (exact by construction).
    assert np.array_equal(tp.start[1:], tp.end[:-1])
    # Arc end points lie on their circle within the RS274 tolerance (0.002 mm / 0.0002 in).
    arc = tp.kind == ARC
    assert np.all(np.abs(tp.radius_start[arc] - tp.radius_end[arc]) <= 0.0002 * INCH)
    assert len(sample_path(tp)) > 100  # every file holds at least 40 mm of path


def test_corpus_count() -> None:
    # Five post styles: Fanuc/Fusion, LinuxCNC inch, Heidenhain ISO A/C, Mastercam, G91.
    assert len(list(CORPUS.glob("*.nc"))) >= 5


def test_fanuc_fusion_pocket() -> None:
    tp = interpret_file(CORPUS / "fanuc_fusion_pocket.nc", home_mm=(-300.0, -200.0, 0.0))
    nc = list(tp.nc_line)
    # N75: helical turn r = 2 mm, dz = -1 mm: L = sqrt((2π·2)² + 1²) mm (closed form).
    i = nc.index(75)
    assert tp.source_line[i] == 21 and tp.kind[i] == ARC
    assert tp.lengths()[i] == pytest.approx(math.hypot(4 * math.pi, 1.0) * MM, rel=1e-12)
    assert tp.sweep[i] == pytest.approx(2 * math.pi)
    # N255: full circle r = 23 around (20, 15), clockwise, tool 2 at 12000 rev/min.
    j = nc.index(255)
    assert tp.direction[j] == -1 and tp.tool[j] == 2
    assert tp.centre[j, :2] == pytest.approx(np.array([20.0, 15.0]) * MM)
    assert tp.spindle_speed[j] == pytest.approx(12000 * RPM)
    assert tp.feed[j] == pytest.approx(700 * MM_PER_MIN)
    # Tool 1 before the second M6; G28 G91 Z0. goes to home Z, then X Y home at the end.
    assert tp.tool[nc.index(100)] == 1
    assert tp.end[-1, :3] == pytest.approx(np.array([-300.0, -200.0, 0.0]) * MM)
    assert any("M1" in n for n in tp.notes)


def test_linuxcnc_inch_r_arcs() -> None:
    tp = interpret_file(CORPUS / "linuxcnc_inch_r_arcs.nc")
    arcs = np.flatnonzero(tp.kind == ARC)
    # g3 r0.25 from (1, 0) to (1, 0.5): semicircle about (1, 0.25) in (G20).
    assert tp.centre[arcs[0], :2] == pytest.approx(np.array([1.0, 0.25]) * INCH)
    assert tp.sweep[arcs[0]] == pytest.approx(math.pi)
    # g2 r-0.25 from (0, 0.5) to (-0.25, 0.25): R < 0 picks the 270° arc about (0, 0.25).
    assert tp.centre[arcs[1], :2] == pytest.approx(np.array([0.0, 0.25]) * INCH, abs=1e-12)
    assert tp.sweep[arcs[1]] == pytest.approx(1.5 * math.pi)
    # centre-format full circle, and the P2 helix: two turns (4π).
    assert tp.sweep[arcs[2]] == pytest.approx(2 * math.pi)
    assert tp.sweep[arcs[3]] == pytest.approx(4 * math.pi)
    assert tp.lengths()[arcs[3]] == pytest.approx(
        math.hypot(4 * math.pi * 0.1, 0.1) * INCH, rel=1e-12
    )
    # F30 inch/min on the slot; dwell 0.5 s.
    assert tp.feed[arcs[0]] == pytest.approx(30 * 25.4 * MM_PER_MIN)
    assert tp.dwell[tp.kind == DWELL] == pytest.approx([0.5])
    # Block delete: the "/ g1 ... z-0.08" line is skipped by default and runs when off.
    assert not np.any(np.isclose(tp.end[:, 2], -0.08 * INCH))
    tp2 = interpret_file(CORPUS / "linuxcnc_inch_r_arcs.nc", block_delete=False)
    assert len(tp2) == len(tp) + 1
    assert np.any(np.isclose(tp2.end[:, 2], -0.08 * INCH))


def test_heidenhain_iso_rotary_axes() -> None:
    tp = interpret_file(CORPUS / "heidenhain_iso_ac.nc")
    i = list(tp.nc_line).index(80)
    assert tp.end[i, 3:] == pytest.approx([30 * DEG, 90 * DEG])
    # N130 G03 quarter circle about (40, 20), r = 10 mm.
    k = list(tp.nc_line).index(130)
    assert tp.lengths()[k] == pytest.approx(0.5 * math.pi * 10 * MM)
    # N260 G01 C+90 F3600: rotary only, 60° at 3600 deg/min = 1 s (LinuxCNC semantics).
    r = list(tp.nc_line).index(260)
    assert tp.lengths()[r] == 0.0
    assert tp.durations()[r] == pytest.approx(1.0)
    # A, C are interpolated along N230 (A 5→10°, C 10→20°) at mid-length.
    sp = sample_path(tp, step=0.1 * MM)
    on = sp.move == list(tp.nc_line).index(230)
    frac = (sp.x[on] - 10 * MM) / (10 * MM)  # x is linear in the path parameter on a line
    assert np.max(np.abs(sp.a[on] - (5 + 5 * frac) * DEG)) < 1e-12
    assert np.max(np.abs(sp.c[on] - (10 + 10 * frac) * DEG)) < 1e-12


def test_mastercam_planes_and_offsets() -> None:
    tp = interpret_file(
        CORPUS / "mastercam_planes_g55.nc", work_offsets_mm=OFFSETS, home_mm=(0, 0, 0)
    )
    off = np.array(OFFSETS["G55"]) * MM
    nc = list(tp.nc_line)
    # N122 G18 G90.1: centre absolute (X15, Z0) in G55; semicircle of r = 10 dipping to Z-10.
    i = nc.index(122)
    assert tp.plane[i] == PLANE_ZX
    assert tp.centre[i] == pytest.approx(off + np.array([15.0, 0.0, 0.0]) * MM)
    sp = sample_path(tp, step=0.05 * MM)
    on = sp.move == i
    # G2 about +Y passes below; samples every 0.05 mm miss the bottom by ≤ (h/2)²/(2r) ≈ 3.1e-8 m
    assert sp.z[on].min() == pytest.approx(off[2] - 10 * MM, abs=5e-8)
    # N134 G19 incremental J5 K0: centre (Y10, Z-10); G2 about +X from Y5 bulges up to Z-5.
    j = nc.index(134)
    assert tp.plane[j] == PLANE_YZ
    assert tp.centre[j, 1:] == pytest.approx(off[1:] + np.array([10.0, -10.0]) * MM)
    on = sp.move == j
    assert sp.z[on].max() == pytest.approx(off[2] - 5 * MM, abs=5e-8)


def test_incremental_pattern_sums() -> None:
    tp = interpret_file(CORPUS / "incremental_pattern.nc", work_offsets_mm=OFFSETS)
    off = np.array(OFFSETS["G56"]) * MM
    # Three slots at pitch 20 mm, each 10 + 10 mm of line and two half circles of r = 3 mm.
    cut = (
        (tp.kind != RAPID)
        & (tp.end[:, 2] < off[2] - 0.5 * MM)
        & (tp.start[:, 2] < off[2] - 0.5 * MM)
    )
    assert tp.lengths()[cut].sum() == pytest.approx(3 * (20 + 2 * math.pi * 3) * MM, rel=1e-12)
    # The last slot ends back at its start: X = 2 x 20 mm in G56.
    last = np.flatnonzero(tp.kind == ARC)[-1]
    assert tp.end[last, :3] == pytest.approx(off + np.array([40.0, 0.0, -1.0]) * MM)


# ---------------------------------------------------------------------------- analytic


def test_helix_length_and_time() -> None:
    tp = _run("G0 X10 Y0 Z0\nG1 F600\nG3 X10 Y0 Z-5 I-10 J0")
    # Helix r = 10, one turn, pitch 5: L = sqrt((2π·10)² + 5²) mm, t = L/F.
    length = math.hypot(20 * math.pi, 5.0) * MM
    assert tp.lengths()[-1] == pytest.approx(length, rel=1e-13)
    sp = sample_path(tp)
    t_rapid = math.hypot(10, 0) * MM / (20_000 * MM_PER_MIN)
    assert sp.t[-1] == pytest.approx(t_rapid + length / (600 * MM_PER_MIN), rel=1e-12)
    assert sp.xyz[-1] == pytest.approx(np.array([10, 0, -5]) * MM, abs=1e-15)


def test_full_circle_ends_at_start() -> None:
    tp = _run("G0 X5 Y5\nG2 X5 Y5 I3 J4 F100")
    assert tp.sweep[-1] == pytest.approx(2 * math.pi)
    assert tp.radius_start[-1] == pytest.approx(5 * MM)
    sp = sample_path(tp, step=0.01 * MM)
    # The last sample is the start point; the circle's points are 5 mm from (8, 9).
    assert sp.xyz[-1, :2] == pytest.approx(np.array([5, 5]) * MM, abs=1e-15)
    d = np.hypot(sp.x[sp.move == 1] - 8 * MM, sp.y[sp.move == 1] - 9 * MM)
    assert np.max(np.abs(d - 5 * MM)) < 1e-15


@pytest.mark.parametrize(
    ("code", "r", "centre", "sweep_deg"),
    [
        ("G2", 10.0, (10.0, 0.0), 90.0),  # R > 0: the short (≤ 180°) arc
        ("G2", -10.0, (0.0, 10.0), 270.0),  # R < 0: the long arc, other centre (RS274 §3.5.3.1)
        ("G3", 10.0, (0.0, 10.0), 90.0),
        ("G3", -10.0, (10.0, 0.0), 270.0),
    ],
)
def test_r_form_centre(code: str, r: float, centre: tuple[float, float], sweep_deg: float) -> None:
    tp = _run(f"G0 X0 Y0\n{code} X10 Y10 R{r} F100")
    assert tp.centre[-1, :2] == pytest.approx(np.array(centre) * MM, abs=1e-15)
    assert math.degrees(tp.sweep[-1]) == pytest.approx(sweep_deg)


def test_g20_scaling_and_feed() -> None:
    tp = interpret("G20 G90\nG1 X1 Y2 F10\nM2", source="t.nc")
    assert tp.end[0, :3] == pytest.approx(np.array([1.0, 2.0, 0.0]) * INCH)
    assert tp.feed[0] == pytest.approx(10 * INCH / 60)  # 10 inch/min in m/s


def test_g91_incremental_sums() -> None:
    tp = _run("G91\nG1 X1.5 Y-2 F100\nX1.5 Y-2\nZ-0.25\nG90\nG1 X0")
    assert tp.end[2, :3] == pytest.approx(np.array([3.0, -4.0, -0.25]) * MM)
    assert tp.end[3, :3] == pytest.approx(np.array([0.0, -4.0, -0.25]) * MM)


def test_work_offsets_translate() -> None:
    tp = _run("G55 G0 X1 Y2 Z3\nG54 X1\nG56 G1 X0 F10", work_offsets_mm={"G55": (10, 20, 30)})
    assert tp.end[0, :3] == pytest.approx(np.array([11.0, 22.0, 33.0]) * MM)
    # G54 is zero unless given; Y, Z keep their machine positions.
    assert tp.end[1, :3] == pytest.approx(np.array([1.0, 22.0, 33.0]) * MM)
    assert tp.end[2, 0] == pytest.approx(0.0)


def test_g18_g19_arc_direction() -> None:
    # G18: G2 is clockwise seen from +Y, i.e. a negative rotation about +Y. From X0 about
    # (X5, Z0) the start vector is -X; rotating it by -90° about Y gives -Z, so the arc passes
    # Z = -5 (x' = x cosθ + z sinθ, z' = -x sinθ + z cosθ with θ = -90°).
    tp = _run("G18 G0 X0 Y0 Z0\nG2 X10 Z0 I5 K0 F100")
    sp = sample_path(tp, step=0.1 * MM)
    # the sample nearest the bottom misses it by ≤ (h/2)²/(2r) = 2.5e-7 m
    assert sp.z.min() == pytest.approx(-5 * MM, abs=2.6e-7)
    assert sp.z.max() < 1e-12
    # G19: G2 is a negative rotation about +X. From Y0 about (Y5, Z0) the start vector is -Y;
    # rotating it by -90° about X gives +Z (z' = y sinθ + z cosθ), so the arc passes Z = +5.
    tp = _run("G19 G0 X0 Y0 Z0\nG2 Y10 Z0 J5 K0 F100")
    sp = sample_path(tp, step=0.1 * MM)
    assert sp.z.max() == pytest.approx(5 * MM, abs=2.6e-7)
    assert sp.z.min() > -1e-12


def test_spiral_within_tolerance_ends_on_programmed_point() -> None:
    # End 0.0015 mm off the radius (inside 0.002 mm): accepted, ends exactly on the end point.
    tp = _run("G0 X10 Y0\nG3 X0 Y10.0015 I-10 J0 F100")
    assert tp.radius_end[-1] - tp.radius_start[-1] == pytest.approx(0.0015 * MM)
    sp = sample_path(tp, step=0.05 * MM)
    assert sp.xyz[-1] == pytest.approx(np.array([0, 10.0015, 0]) * MM, abs=1e-15)


def test_modal_state_spindle_tool_dwell() -> None:
    tp = _run("T7 M6\nS1200 M4\nG0 X1\nM5\nG4 P2.5\nG0 X2\nT3\nG0 X3")
    assert tp.tool.tolist() == [7, 7, 7, 7]  # T3 without M6 only selects
    assert tp.spindle_dir.tolist() == [-1, 0, 0, 0]
    assert tp.spindle_speed[0] == pytest.approx(1200 * RPM)
    assert tp.kind[1] == DWELL and tp.durations()[1] == pytest.approx(2.5)


def test_comments_and_line_numbers() -> None:
    tp = _run("N0010 G1 X1 (move; not a comment end) Y2 F100 ; trailing (text\n( whole line )")
    assert tp.nc_line[0] == 10 and tp.source_line[0] == 2
    assert tp.end[0, :2] == pytest.approx(np.array([1.0, 2.0]) * MM)
    assert tp.kind[0] == LINE


def test_m30_stops_reading() -> None:
    tp = interpret("G21 G0 X1\nM30\nG0 X2\nthis is not read", source="t.nc")
    assert len(tp) == 1


# ---------------------------------------------------------------------------- errors

BAD = [
    ("G0 X0 Y0\nG2 X10 Y0.2 I5 J0 F100", 3, "off its radius"),  # 0.004 mm > 0.002 mm
    ("G1 X1", 2, "no feed rate"),
    ("G1 X1 F0", 2, "feed rate F is zero"),
    ("G1 X1 F10\nG5.1 X2", 3, "unknown G code G5.1"),
    ("G0 G1 X1 F10", 2, "motion group"),
    ("G20 G21", 2, "units group"),
    ("G0 X1 ?", 2, "unexpected character"),
    ("G0 X1.2.3", 2, "unexpected character"),
    ("G0 X", 2, "letter X without a number"),
    ("G0 X0 Y0\nG2 Z-1 R5 F100", 3, "without an end point"),
    ("G0 X0 Y0\nG2 X0 Y0 R5 F100", 3, "ending at its start"),
    ("G0 X0 Y0\nG2 X20 Y0 R5 F100", 3, "smaller than half the chord"),
    ("G0 X0 Y0\nG2 X20 Y0 F100", 3, "centre offsets or R"),
    ("G0 X0 Y0\nG2 X10 Y0 I5 K1 F100", 3, "K word on an arc in the XY plane"),
    ("G41 D1", 2, "G41 is not supported"),
    ("G42 D1", 2, "G42 is not supported"),
    ("G93", 2, "inverse-time"),
    ("G83 X0 Y0 Z-5 R1 Q1 F100", 2, "canned cycle G83"),
    ("M98 P100", 2, "unknown M code M98"),
    ("M3 M4", 2, "same modal group"),
    ("G0 X1 X2", 2, "word X appears twice"),
    ("G0 X1 I2", 2, "word I is not used"),
    ("X1", 2, "without a motion mode"),
    ("G28 G91 Z0", 2, "G28 needs the machine reference position"),
    ("G0 X1 (open comment", 2, "unbalanced"),
    ("#1 = 5", 2, "parameters"),
    ("G0 X[1+2]", 2, "expressions"),
    ("G0 B10", 2, "word B is not supported"),
    ("G4", 2, "G4 dwell needs a time P"),
]


@pytest.mark.parametrize(("body", "line", "reason"), BAD, ids=[b[2] for b in BAD])
def test_bad_program_one_line_error(body: str, line: int, reason: str) -> None:
    text = "G21 G90 G17\n" + body + "\nM30\n"
    with pytest.raises(ProgramError) as exc:
        interpret(text, source="bad.nc")
    msg = str(exc.value)
    bad_line = text.splitlines()[line - 1].strip()
    assert "\n" not in msg
    assert msg.startswith(f"bad.nc:{line}: ")
    assert reason in msg
    assert msg.endswith(f"'{bad_line}'")


def test_percent_needs_closing_line_and_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ProgramError, match=r"^p\.nc: program opened with % has no closing %"):
        interpret("%\nG0 X1\n", source="p.nc")
    with pytest.raises(ProgramError, match="no moves"):
        interpret("G21\nM30\n", source="e.nc")
    with pytest.raises(ProgramError, match="cannot read program"):
        interpret_file(tmp_path / "missing.nc")


def test_g53_g28_and_g80_line() -> None:
    # G55 at (100, 50, -20); G53 Z0 is machine Z0 for one block; G28 G91 Z0 goes straight to
    # home Z (intermediate point = current); G28 X5 (G90) goes via X5 in G55 to home X.
    tp = _run(
        "G0 G17 G40 G49 G80 G90\nG55 G0 X1 Y2 Z3\nG53 G0 Z0\nG0 Z3\nG28 G91 Z0\nG90 G28 X5",
        work_offsets_mm={"G55": (100, 50, -20)},
        home_mm=(-400.0, -300.0, 10.0),
    )
    assert tp.end[1, 2] == pytest.approx(0.0)  # G53 Z0: machine zero
    assert tp.end[2, 2] == pytest.approx(-17 * MM)  # back in G55
    assert tp.end[3, :3] == pytest.approx(np.array([101.0, 52.0, 10.0]) * MM)  # home Z only
    assert tp.end[4, 0] == pytest.approx(105 * MM)  # intermediate X5 in G55
    assert tp.end[5, :3] == pytest.approx(np.array([-400.0, 52.0, 10.0]) * MM)
    assert (tp.kind == RAPID).all()


def test_fast_path_matches_explicit_blocks() -> None:
    # Modal continuation lines (fast path) give the same moves as fully written blocks.
    a = _run("G1 X1 Y1 F100\nX2\nY3 Z-1\nG0 X0\nY0")
    b = _run("G1 X1 Y1 F100\nG1 X2 Y1\nG1 X2 Y3 Z-1\nG0 X0 Y3 Z-1\nG0 X0 Y0 Z-1")
    assert np.array_equal(a.end, b.end) and np.array_equal(a.kind, b.kind)
    assert np.array_equal(a.feed, b.feed, equal_nan=True)


def test_utf8_bom_is_not_part_of_the_first_block(tmp_path: Path) -> None:
    """Windows editors (Notepad) save UTF-8 with a byte-order mark: the first block was
    refused ("unexpected character '\\ufeff'"). The same program with and without it gives the
    same path: the walkthrough slot's lowest point Z -2 mm and its 40 mm cut to X 40 mm."""
    text = (CORPUS.parent / "walkthrough" / "slot.nc").read_text()
    (tmp_path / "bom.nc").write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "plain.nc").write_text(text)
    a, b = interpret_file(tmp_path / "plain.nc"), interpret_file(tmp_path / "bom.nc")
    np.testing.assert_array_equal(b.end, a.end)
    assert float(b.end[:, 2].min()) == pytest.approx(-2e-3, abs=1e-12)
    assert float(b.end[:, 0].max()) == pytest.approx(40e-3, abs=1e-12)
