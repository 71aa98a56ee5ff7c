"""Decision 1738: a record's spindle-angle zero is not the tool's. `monitor` finds flute 0's
angle from the steady cut's harmonics, and no revolution whose window is no steady side cut's
is reported."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from millsense.monitoring.engagement import SIDE_CUT_TOL_RAD, side_cut_window
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from test_engagement_nyquist import FS, _band_limited_torque, _tool

RPM = 1002.0


def test_side_cut_window() -> None:
    """Down milling ends at π, up milling starts at 0, a slot does both, within 10°; a window
    inside the half-turn is none of them."""
    assert side_cut_window(2.09, math.pi)
    assert side_cut_window(0.0, 1.02)
    assert side_cut_window(0.0, math.pi)
    assert side_cut_window(0.9 * SIDE_CUT_TOL_RAD, 1.5)
    assert not side_cut_window(0.98, 1.88)
    assert not side_cut_window(1.1 * SIDE_CUT_TOL_RAD, math.pi - 1.1 * SIDE_CUT_TOL_RAD)


def _monitor(tmp_path: Path, capsys: pytest.CaptureFixture[str], torque: np.ndarray,
             speed: np.ndarray) -> str:  # fmt: skip
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("dynamometer/torque", torque, "N*m")
    rec.add_channel("spindle/speed", speed, "rad/s")
    path = tmp_path / "r.h5"
    write_recording(path, rec)
    code, stdout, err = run_cli(["monitor", str(path), "--methods", "engagement", "--channel",
                                 "dynamometer/torque", "--tool", str(_tool(tmp_path / "t.toml", 2)),
                                 "--feed-per-tooth-mm", "0.1", "-o",
                                 str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    return next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))


@pytest.mark.parametrize("start", [0, 100, 275])
@pytest.mark.parametrize("axial_mm", [2.0, 8.0])
def test_a_recording_whose_angle_zero_is_not_the_tools(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], start: int, axial_mm: float
) -> None:
    """The 2-flute down-milling cut (5 mm radial: window 120° to 180°; 598.8 samples a
    revolution) recorded from sample ``start`` of its stream, so that the record's zero lies
    0°, 60° or 165° of the tool's turn (mod a pitch) past flute 0. In the record's frame the
    fit read the 2 mm cut as 5.08 and 5.38 mm at σ ≥ 0.8. At 8 mm the depth's notch (harmonic
    54.4/8 = 6.8) lies within the 12 fitted: the offset is found and the depth is read within
    1 % from every start, with flute 0's angle within 0.5°. At 2 mm the notch (harmonic 27)
    lies beyond them, where an offset and a depth trade phase: the misaligned records report
    no depth and say why."""
    data = _band_limited_torque(RPM, 2.0, 2, 1e-3 * axial_mm)
    line = _monitor(tmp_path, capsys, data["spindle/torque_est"][start:],
                    data["spindle/speed"][start:])  # fmt: skip
    if start and axial_mm == 2.0:
        assert "engagement not determined: the record's spindle-angle zero is not flute 0's" in line
        assert "decision 1738" in line
        return
    words = line.replace(",", "").replace(";", "").split()
    assert float(words[words.index("axial") + 2]) == pytest.approx(axial_mm, rel=0.01)
    turned = math.degrees(2 * math.pi * RPM / 60 * start / FS) % 180.0
    if start == 0:
        assert "flute 0 at" not in line
    else:
        got = float(line.split("flute 0 at ")[1].split("°")[0])
        assert min(abs(got - turned), 180.0 - abs(got - turned)) <= 0.5


def test_a_window_inside_the_half_turn_is_not_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A cut whose window lies at 60° to 120° of the feed's frame (no steady side cut: an
    entry's, a corner's): no depth is reported, and the summary names decision 1738 (the
    window inside the half-turn, or a frame turned to fit it better whose depth the phases
    alone would carry)."""
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    m = 720
    phi = 2 * math.pi * np.arange(m) / m
    eng = Engagement(layers=(((math.radians(60), math.radians(120)),),))
    rev = milling_forces(tool, co, eng, 0.1e-3, 2e-3, phi).torque_nm
    coeff = np.fft.rfft(rev) / m
    omega = RPM * 2 * math.pi / 60
    ang = omega * np.arange(int(2 * FS)) / FS
    tq = np.full(ang.size, coeff[0].real)
    for h in range(1, coeff.size):
        if h * omega / (2 * math.pi) >= 0.5 * FS:
            break
        tq += 2.0 * (coeff[h] * np.exp(1j * h * ang)).real
    line = _monitor(tmp_path, capsys, tq, np.full(ang.size, omega))
    assert "engagement not determined" in line and "decision 1738" in line
    assert "median axial depth" not in line
