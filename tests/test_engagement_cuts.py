"""Decision 1739: the engagement monitor's record is judged cut by cut.

`millsense monitor` pooled every revolution of a record into one verdict. A program's record of
a 3 mm slot and a 1.5 mm pass on the virtual machine read "not determined" over the 139
revolutions of both, where each alone reads its own depth. The steady cuts
(:func:`~millsense.monitoring.steady_cuts.steady_cuts`) are now judged apart: a summary line
and an event-log row each.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from millsense.monitoring.steady_cuts import MERGE_GAP, STEADY_BAND, steady_cuts, steady_rows
from millsense.streaming import read_event_log

FS = 10000.0


def _coeffs(levels: list[float | None]) -> list[np.ndarray | None]:
    """Revolutions whose first tooth harmonic has the magnitude of ``levels`` (None: not
    evaluated)."""
    return [None if m is None else np.array([0.1, m, 0.3 * m], dtype=np.complex128)
            for m in levels]  # fmt: skip


def test_cuts_split_where_the_level_steps_and_where_no_revolution_is_evaluated() -> None:
    """Ten revolutions at 1.0, ten at 1.4 (beyond the ±15 % band), air, twelve at 1.0: three
    cuts, each its own revolutions."""
    levels: list[float | None] = [1.0] * 10 + [1.4] * 10 + [None] * 3 + [1.0] * 12
    cuts = steady_cuts(_coeffs(levels), min_revolutions=8)
    assert cuts == [list(range(10)), list(range(10, 20)), list(range(23, 35))]


def test_a_lone_revolution_outside_the_band_does_not_split_a_cut() -> None:
    """A noise spike (one revolution at 2×) in 30 revolutions at one level: one cut of the 29
    others (the runs around it are MERGE_GAP or fewer apart at one level); two spikes in a row
    are within MERGE_GAP too, three are not."""
    assert MERGE_GAP == 2
    for spikes, n_cuts in ((1, 1), (2, 1), (3, 2)):
        levels: list[float | None] = [1.0] * 15 + [2.0] * spikes + [1.0] * 15
        cuts = steady_cuts(_coeffs(levels), min_revolutions=8)
        assert len(cuts) == n_cuts, (spikes, cuts)
        assert sum(len(c) for c in cuts) == 30
        assert all(levels[i] == 1.0 for c in cuts for i in c)


def test_the_mean_torque_splits_cuts_whose_tooth_harmonic_is_alike() -> None:
    """The 3 mm slot and the 1.5 mm half-immersion pass of the module's record: first tooth
    harmonics 0.86 and 1.0 (16 % apart, at the band's edge), mean cutting torques 3.3 and
    1.4 N·m. With a tooth harmonic alike (0.9 and 0.95) the mean torque still splits them."""
    levels: list[float | None] = [0.9] * 12 + [0.95] * 12
    means = [3.3] * 12 + [1.4] * 12
    assert len(steady_cuts(_coeffs(levels), min_revolutions=8)) == 1
    assert steady_cuts(_coeffs(levels), means, 8) == [list(range(12)), list(range(12, 24))]
    assert abs(0.95 / 0.9 - 1.0) < STEADY_BAND


def test_short_runs_are_no_cut_and_the_longest_run_is_decision_1738s() -> None:
    """An entry's rising revolutions (each > 15 % above the last) form no cut of 8; the
    longest run is the one decision 1738 places flute 0 with; one revolution not evaluated
    between two runs at one level does not part them, three do."""
    levels: list[float | None] = [0.2, 0.4, 0.6, 0.8] + [1.0] * 9 + [None] * 3 + [1.0] * 20
    cuts = steady_cuts(_coeffs(levels), min_revolutions=8)
    assert cuts == [list(range(4, 13)), list(range(16, 36))]
    assert steady_rows(_coeffs(levels)) == list(range(16, 36))
    levels[13:16] = [1.0, None, 1.0]
    assert steady_cuts(_coeffs(levels), min_revolutions=8) == [[*range(4, 14), *range(15, 36)]]


def _two_cut_recording(path: Path) -> Path:
    """A Ø20 mm 2-flute 30° cut at 1000 rev/min, 0.2 mm a tooth, down milling 5 mm wide: air to
    0.5 s, 2 mm deep to 4 s, air to 4.5 s, 4 mm deep to 8 s; 0.05 N·m of noise; no plan."""
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    n = int(8.0 * FS)
    t = np.arange(n) / FS
    om = 1000 * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    phi = 2 * math.pi * np.arange(600) / 600
    ang = np.mod(om * t, 2 * math.pi)
    eng = Engagement.radial(5e-3, 20e-3, "down")
    shallow, deep = (np.interp(ang, phi, milling_forces(tool, co, eng, 0.2e-3, d, phi).torque_nm,
                               period=2 * math.pi) for d in (2e-3, 4e-3))  # fmt: skip
    tq = np.where((t >= 0.5) & (t < 4.0), shallow, np.where(t >= 4.5, deep, 0.0))
    tq = tq + 0.05 * np.random.default_rng(3).standard_normal(n)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("spindle/torque_est", tq, "N*m")
    rec.add_channel("spindle/speed", np.full(n, om), "rad/s")
    rec.add_channel("cnc/nc_line", np.where(t < 4.25, 12.0, 15.0), "1")
    write_recording(path, rec)
    return path


def test_monitor_reports_each_cut_of_a_record_apart(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The two cuts of :func:`_two_cut_recording` read 2 and 4 mm (each within 5 %: the
    revolutions' medians of this clean synthetic torque) on lines of their own, with their NC
    lines, and the event log holds one ``engagement`` row per cut with its depth as the value."""
    rec = _two_cut_recording(tmp_path / "run.h5")
    out = tmp_path / "ev.parquet"
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                                 "aslan-d20-2flute", "--feed-per-tooth-mm", "0.2", "-o",
                                 str(out)], capsys)  # fmt: skip
    assert code == 0, err
    assert "engagement: 2 steady cuts, each judged apart (decision 1739)" in stdout, stdout
    cut_lines = [ln.strip() for ln in stdout.splitlines() if ln.strip().startswith("cut ")]
    assert len(cut_lines) == 2, stdout
    depths = []
    for line, nc in zip(cut_lines, (12, 15), strict=True):
        assert f"NC line {nc}" in line, line
        m = re.search(r"median axial depth ([\d.]+) mm", line)
        assert m, line
        depths.append(float(m.group(1)))
    assert depths == pytest.approx([2.0, 4.0], rel=0.05)
    events = [e for e in read_event_log(out) if e.name == "engagement"]
    assert [e.nc_line for e in events] == [12, 15]
    assert [e.value for e in events] == pytest.approx(depths, abs=5e-4)  # the lines' rounding
    assert events[0].values["last_s"] < 4.0 < 4.5 < events[1].values["first_s"]
    assert all(e.values["revolutions"] >= 8 for e in events)


def test_plan_locator_reads_the_source_line_where_the_program_has_no_n_words() -> None:
    """The CNC (and the virtual machine) name a block by its N word, else its line in the
    program; a plan of a program without N words has nc_line −1 and the line in source_line.
    The locator matched only nc_line: every event fell back to the nearest planned time and
    reported NC line −1 (the 1.5 mm pass's cut at z 5 mm, a retract)."""
    from millsense.monitoring.locate import PlanLocator

    cols = {
        "t_s": np.array([0.0, 1.0, 2.0, 3.0]),
        "nc_line": np.full(4, -1),
        "source_line": np.array([5, 5, 6, 6]),
        "x_mm": np.array([0.0, 10.0, 20.0, 30.0]),
        "y_mm": np.zeros(4),
        "z_mm": np.array([-3.0, -3.0, 5.0, 5.0]),
    }
    plan = type("P", (), {"columns": cols, "__getitem__": lambda self, k: cols[k]})()
    locate = PlanLocator(plan)  # type: ignore[arg-type]
    assert locate(2.6, 5) == (5, 10.0, 0.0, -3.0)  # line 5's nearest row in planned time
    assert locate(0.2, 6) == (6, 20.0, 0.0, 5.0)
    assert locate(2.6, None) == (6, 30.0, 0.0, 5.0)


@pytest.mark.parametrize("width_deg, why", [(0.0, "collapse to no engagement window"),
                                            (40.0, "lies inside the half-turn")])  # fmt: skip
def test_a_cut_whose_fits_collapse_says_its_harmonics_are_in_the_noise(
    width_deg: float, why: str
) -> None:
    """The shop pocket's 3 mm cuts at 8000 rev/min on the sensorless estimate: every fit's
    window shrank to nothing (median 42° to 42°), and the summary blamed a misaligned spindle
    angle (decision 1738's words for windows inside the half-turn). A median window narrower
    than 5° is the fits' collapse in the noise, and is said so; a real window inside the
    half-turn keeps decision 1738's words."""
    from types import SimpleNamespace

    from millsense.cli.monitor_engagement import EngagementCut, engagement_lines, engagement_verdict

    entry = math.radians(42.0)
    revs = [SimpleNamespace(reliability=-0.5, kt_n_m2=8e8, edge_n_m=1e4, entry_rad=entry,
                            exit_rad=entry + math.radians(width_deg), axial_depth_m=1e-3)
            for _ in range(4)]  # fmt: skip
    block = SimpleNamespace(name="engagement", estimates=[(0.1 * (k + 1), e)
                                                          for k, e in enumerate(revs)])  # fmt: skip
    v = engagement_verdict(block)
    assert v.kind == "undetermined"
    line = engagement_lines(block, [EngagementCut(0.1, 0.4, v)], 1e4)[0]
    assert why in line, line
