"""``millsense monitor``: chatter on a recording, event log, plot, plan location, bad input.

The recordings are synthetic (tests/test_monitoring_chatter.py's signal: a 4-flute cut at
6000 rev/min, chatter at 937 Hz from 2.5 s) so the expected event is known exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from millsense.plan.virtual_plan import COLUMNS, VirtualPlan
from millsense.streaming import read_event_log
from test_monitoring_chatter import FS, _signal


def _recording(path: Path, *, speed: bool = True, zero_speed: bool = False,
               program: str = "part.nc") -> Path:  # fmt: skip
    x, spd = _signal()
    rec = Recording(FS, 0.0, {"program": program, "flutes": 4})
    rec.add_channel("mic/pressure", x, "Pa", "microphone")
    if speed:
        rec.add_channel("spindle/speed", 0.0 * spd if zero_speed else spd, "rad/s")
        nc = np.where(np.arange(len(x)) < 2.0 * FS, 10, 12)
        rec.add_channel("cnc/nc_line", nc.astype(np.float64), "1")
    write_recording(path, rec)
    return path


def _plan(path: Path, program: str = "part.nc") -> Path:
    n = 50
    cols: dict[str, np.ndarray] = {c: np.zeros(n) for c in COLUMNS}
    cols["t_s"] = np.linspace(0.0, 4.0, n)
    cols["x_mm"] = np.linspace(0.0, 40.0, n)
    cols["nc_line"] = np.where(cols["t_s"] < 2.0, 10, 12).astype(np.int64)
    for c in ("tool", "source_line", "n_intervals"):
        cols[c] = np.zeros(n, dtype=np.int64)
    cols["rapid"] = np.zeros(n, dtype=bool)
    cols["in_cut"] = np.ones(n, dtype=bool)
    VirtualPlan(cols, {"program": program}).write(path)
    return path


def test_monitor_microphone_only_with_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _recording(tmp_path / "run.h5", speed=False)
    out, png = tmp_path / "ev.parquet", tmp_path / "m.png"
    code, stdout, err = run_cli(["monitor", str(rec), "--spindle-rpm", "6000", "--methods",
                                 "chatter-comb,chatter-sdft", "-o", str(out), "--plot", str(png)],
                                capsys)  # fmt: skip
    assert code == 0, err
    ev = [e for e in read_event_log(out) if e.name == "chatter"]
    assert sorted(e.source for e in ev) == ["chatter-comb", "chatter-sdft"]
    for e in ev:
        assert e.value == pytest.approx(937.0, rel=0.005)  # the synthetic chatter frequency
        assert 2.5 < e.time_s <= 2.7
    assert png.stat().st_size > 10_000
    assert "chatter-comb: 1 chatter alarm" in stdout


def test_monitor_with_plan_locates_the_event(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _recording(tmp_path / "run.h5")
    plan = _plan(tmp_path / "plan.parquet")
    out = tmp_path / "ev.parquet"
    code, _, err = run_cli(["monitor", str(rec), "--plan", str(plan), "-o", str(out)], capsys)
    assert code == 0, err
    (e,) = [e for e in read_event_log(out) if e.name == "chatter"]
    assert e.nc_line == 12
    # nearest plan row in time of NC line 12: x = 10 mm/s × t (row spacing 0.82 mm)
    assert e.x_mm == pytest.approx(10.0 * e.time_s, abs=0.5)


@pytest.mark.parametrize(
    ("kind", "needle"),
    [
        ("no-speed", "spindle speed"),
        ("zero-speed", "zero throughout"),
        ("bad-channel", "--channel 'accel/x'"),
        ("other-plan", "other.nc"),
        ("bad-method", "unknown monitor 'chatter-fft'"),
    ],
)
def test_monitor_bad_input_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, needle: str
) -> None:
    rec = _recording(tmp_path / "run.h5", speed=kind != "no-speed", zero_speed=kind == "zero-speed")
    args = ["monitor", str(rec), "-o", str(tmp_path / "ev.parquet")]
    if kind == "bad-channel":
        args += ["--channel", "accel/x"]
    if kind == "other-plan":
        args += ["--plan", str(_plan(tmp_path / "p.parquet", program="other.nc"))]
    if kind == "bad-method":
        args += ["--methods", "chatter-fft"]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "ev.parquet").exists()
