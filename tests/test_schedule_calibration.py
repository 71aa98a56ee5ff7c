"""Feed scheduling (re-plan holds the limit) and K_tc calibration round trip."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.plan.calibration import calibrate_ktc, rescale_plan, steady_window
from millsense.plan.gcode import interpret, interpret_file
from millsense.plan.schedule import AT_LIMIT, AT_MAX, schedule_feed, write_scheduled_program
from millsense.plan.stock import ZMapStock
from millsense.plan.virtual_plan import VirtualPlan, plan_program
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill

TOOL = EndMill(20e-3, 2, helix_rad=math.radians(30.0))
PROGRAM = """%
G21 G90 G94 G17
S1000 M3
G0 X-15. Y20. Z5.
G1 Z-1. F400.
X25.
G0 Z5.
G0 X-15. Y20.
G1 Z-3. F400.
X45.
G2 X55. Y30. I0. J10.
G1 Y50.
G0 Z20.
M30
%
"""


def _coeffs(ktc: float) -> CuttingCoefficients:
    return CuttingCoefficients(ktc * 1e6, 0.5 * ktc * 1e6, 0.0, 25e3, 35e3)


def _plan(text: str, ktc: float = 758.0) -> VirtualPlan:
    stock = ZMapStock.from_box((0, 0, -0.02), (0.06, 0.06, 0.0), 1e-4)
    return plan_program(interpret(text, source="s.nc"), stock, TOOL, _coeffs(ktc))


def test_schedule_replan_holds_force_limit(tmp_path: Path) -> None:
    plan = _plan(PROGRAM)
    limit = 325.0
    sched = schedule_feed(plan, limit, max_feed_m_s=800 / 60e3, accel_m_s2=1.0)
    out = tmp_path / "opt.nc"
    added = write_scheduled_program(PROGRAM, interpret(PROGRAM), plan, sched, out)
    assert added > 0  # the slot with its depth step needs a split
    again = plan_program(
        interpret_file(out),
        ZMapStock.from_box((0, 0, -0.02), (0.06, 0.06, 0.0), 1e-4),
        TOOL,
        _coeffs(758.0),
    )
    assert len(again) == len(plan)  # same geometry: split points lie on the path
    free = (sched.status == AT_LIMIT) | (sched.status == AT_MAX)
    f = again["fres_peak_n"]
    # ≤ limit (1 %: F words rounded down to 0.1 mm/min, positions to 0.01 µm) where free
    assert np.all(f[free] <= limit * 1.01)
    at = sched.status == AT_LIMIT
    assert at.sum() > 20
    # runs share their smallest feed within 2 % (merge tolerance): force ≥ 0.97 limit
    assert np.all(f[at] >= limit * 0.97)


@pytest.mark.parametrize("end", ["45.2", "45.3"])
def test_a_moves_last_row_keeps_the_feed_of_its_cut(end: str, tmp_path: Path) -> None:
    """Decision 1744: the 3 mm slot ends at X45.2 (or X45.3) and a G2 turns back from there; its
    last row (X45.105) faces the arc (decision 0066) and read out of the cut (X45.2) or at a
    third of the slot's engagement (X45.3): its feed, from it to the slot's end, was the
    programmed 400 mm/min or 626.5 mm/min where the slot holds 325 N at 162 mm/min. Now the
    slot's block is written at one feed, the slot's."""
    prog = PROGRAM.replace("X45.\nG2 X55. Y30. I0. J10.",
                           f"X{end}\nG2 X{float(end) + 10:.2f} Y30. I0. J10.")  # fmt: skip
    plan = _plan(prog)
    sched = schedule_feed(plan, 325.0, max_feed_m_s=800 / 60e3, accel_m_s2=1.0)
    line = np.asarray(plan["source_line"])
    rows = np.flatnonzero(line == 10)
    slot = rows[np.asarray(plan["in_cut"])[rows]]
    assert sched.feed_m_s[rows[-1]] == sched.feed_m_s[slot[-2]]
    assert sched.feed_m_s[rows[-1]] * 60e3 == pytest.approx(162.0, rel=0.01)
    out = tmp_path / "opt.nc"
    write_scheduled_program(prog, interpret(prog), plan, sched, out)
    text = out.read_text().splitlines()
    # the slot's end at the slot's feed (no block split 1 µm before its last row), and the
    # arc's last block without a leading blank
    assert f"X{end} F162." in text, text
    assert not [ln for ln in text if ln.startswith(" ")]


def test_schedule_power_limit_closed_form() -> None:
    # mean power is linear in the feed: P = Ω (s c T_shear + T_edge) → exact at the limit
    plan = _plan(PROGRAM)
    sched = schedule_feed(plan, 300.0, kind="power", max_feed_m_s=2000 / 60e3)
    at = sched.status == AT_LIMIT
    c = sched.feed_m_s[at] * 60e3 / (2 * 1000) / 1e3  # m per tooth at 1000 rev/min
    t = plan["torque_avg_shear_nm"][at] / 0.2e-3 * c + (
        plan["torque_avg_nm"][at] - plan["torque_avg_shear_nm"][at]
    )
    assert at.sum() > 0
    np.testing.assert_allclose(t * 1000 * 2 * math.pi / 60, 300.0, rtol=0.021)


def test_calibration_round_trip(tmp_path: Path) -> None:
    # plan with 758 N/mm², "measure" the mean torque of a plan made with 900 → 900 (1 %)
    plan = _plan(PROGRAM, 758.0)
    truth = _plan(PROGRAM, 900.0)
    start = int(np.flatnonzero(plan["in_cut"] & (plan["source_line"] == 10))[5])
    rows = steady_window(plan, start, 10)
    assert rows.size >= 5
    measured = float(np.mean(truth["torque_avg_nm"][rows]))
    cal = calibrate_ktc(plan, rows, measured_torque_nm=measured)
    assert cal.ktc_n_mm2 == pytest.approx(900.0, rel=0.01)
    # tangential force form, T = F_t R
    cal2 = calibrate_ktc(plan, rows, measured_tangential_force_n=measured / 0.01)
    assert cal2.ktc_n_mm2 == pytest.approx(cal.ktc_n_mm2, rel=1e-12)
    # rescaled plan equals the plan made with 900: in memory exactly, from a file the
    # means exactly and the peaks at the stored angle (≤ 0.5 %)
    mem = rescale_plan(plan, cal.ktc_n_mm2)
    plan.write(tmp_path / "p.parquet")
    disk = rescale_plan(VirtualPlan.read(tmp_path / "p.parquet"), cal.ktc_n_mm2)
    cut = truth["in_cut"] & (truth["ktc_n_mm2"] > 0)
    for col in ("torque_avg_nm", "fx_avg_n", "fres_peak_n", "power_w"):
        np.testing.assert_allclose(mem[col][cut], truth[col][cut], rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(disk["torque_avg_nm"][cut], truth["torque_avg_nm"][cut], rtol=1e-3)
    np.testing.assert_allclose(disk["fres_peak_n"][cut], truth["fres_peak_n"][cut], rtol=5e-3)


def test_scheduled_words_stay_outside_semicolon_comments(tmp_path: Path) -> None:
    """A ';' comment runs to the end of the line: the scheduled F (and a split arc's end point
    and centre) were appended after it, inside the comment, so the CNC ran the block at the
    previous modal feed (above the limit) and the arc lost its end. With ';' comments on every
    feed block the rewritten program has exactly the feeds and path of the program without
    them (the same toolpath, move for move)."""
    commented = "\n".join(
        ln + " ; cut" if ln.startswith(("G1", "X", "G2", "G1 Y")) else ln
        for ln in PROGRAM.splitlines()
    )
    plan = _plan(PROGRAM)
    sched = schedule_feed(plan, 325.0, max_feed_m_s=800 / 60e3, accel_m_s2=1.0)
    plain_out, comm_out = tmp_path / "plain.nc", tmp_path / "comm.nc"
    write_scheduled_program(PROGRAM, interpret(PROGRAM), plan, sched, plain_out)
    added = write_scheduled_program(commented, interpret(commented), plan, sched, comm_out)
    assert added > 0 and comm_out.read_text().count("; cut") == commented.count("; cut")
    a, b = interpret_file(plain_out), interpret_file(comm_out)
    assert b.kind.size == a.kind.size
    np.testing.assert_allclose(b.end, a.end, atol=1e-12)
    np.testing.assert_allclose(b.feed, a.feed, rtol=1e-12)
    assert float(np.nanmin(b.feed)) * 60e3 < 800.0  # some block slowed below the maximum


def test_scheduled_feed_of_an_inch_program_is_in_inch_per_minute(tmp_path: Path) -> None:
    """A G20 program's F words are inch/min: the scheduler wrote its mm/min numbers into
    them, 25.4 times the feed that holds the limit (F 850 in/min = 21.6 m/min where
    33.5 in/min was meant). The inch program (PROGRAM with every length and feed / 25.4, not
    split: each block takes the lowest feed of its rows) now runs each block at that feed,
    within the 0.01 in/min the F words are rounded down to."""
    import re

    from millsense.core.units import MM_PER_MIN

    def inch(m: re.Match[str]) -> str:
        return f"{m.group(1)}{float(m.group(2)) / 25.4:.6f}"

    text = re.sub(r"([XYZIJF])(-?\d+\.?\d*)", inch, PROGRAM).replace("G21", "G20")
    plan = _plan(text)
    sched = schedule_feed(plan, 325.0, max_feed_m_s=800 / 60e3, accel_m_s2=1.0)
    out = tmp_path / "inch.nc"
    write_scheduled_program(text, interpret(text), plan, sched, out)
    again = interpret_file(out)
    rows = ~plan["rapid"].astype(bool) & (plan["source_line"] > 0)
    checked = 0
    for line in sorted({int(v) for v in plan["source_line"][rows]}):
        want = float(sched.feed_m_s[rows & (plan["source_line"] == line)].min()) / MM_PER_MIN
        got = again.feed[again.source_line == line] / MM_PER_MIN
        assert np.all(got <= want + 1e-6) and np.all(got >= want - 0.254), (line, got, want)
        checked += 1
    assert checked >= 5 and float(np.nanmax(again.feed)) / MM_PER_MIN <= 800.0 + 1e-6
