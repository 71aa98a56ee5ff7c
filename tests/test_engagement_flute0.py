"""Decision 1694: an angle or index channel's own angle is the engagement monitor's frame, and
flute 0's angle at its zero can be given (``--flute0-deg``).

The block used only the angle channel's steps, so its frame started at the record's first
sample whatever the encoder read there. A record of an encoder whose zero is flute 0 (Lee's
setup) that started mid-revolution was then misaligned (decision 1738), although the channel
said where the tool was. Flute 0's angle at the encoder's zero is also a constant of the tool's
clamping: found once on a cut whose depth the harmonics fix, it serves the clamping's light cuts,
whose depths the search cannot fix.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from test_engagement_nyquist import FS, _band_limited_torque
from test_engagement_set_speed import _depths as _summary

RPM = 1000.0


def _encoder_record(path: Path, axial_m: float, zero_rad: float, start: int = 0) -> Path:
    """2 s of the 2-flute Ø20 mm down-milling cut (``axial_m`` deep, 5 mm radial) at 1000
    rev/min with a wrapped encoder angle that reads ``zero_rad`` where flute 0 is at 0, the
    record starting ``start`` samples into the stream."""
    data = _band_limited_torque(RPM, 2.0, 2, axial_m)
    ang = RPM * 2 * math.pi / 60 * np.arange(data["spindle/speed"].size) / FS
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("dynamometer/torque", data["spindle/torque_est"][start:], "N*m")
    rec.add_channel("spindle/angle", np.mod(ang + zero_rad, 2 * math.pi)[start:], "rad")
    write_recording(path, rec)
    return path


def _axial_mm(line: str) -> float:
    m = re.search(r"(?:median axial depth|averaged: axial depth) ([\d.]+) mm", line)
    assert m, line
    return float(m.group(1))


def test_an_encoder_whose_zero_is_flute_0_needs_no_search_from_any_start(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Lee's setup: the encoder reads 0 where flute 0 is. Records starting 123 and 475
    samples into the stream (74° and 285° into a revolution) read the 2 mm depth within 2 %
    and report no offset: the frame is the encoder's. (The frame from the first sample read
    them as misaligned, and "not determined": the 2 mm cut's notch lies beyond the fitted
    harmonics, decision 1738.)"""
    for start in (123, 475):
        rec = _encoder_record(tmp_path / f"r{start}.h5", 2e-3, 0.0, start)
        code, line = _summary(tmp_path, rec, capsys)
        assert code == 0, line
        assert _axial_mm(line) == pytest.approx(2.0, rel=0.02), line
        assert "flute 0 at" not in line


def test_flute_0_found_on_a_deep_cut_serves_the_clampings_light_cut(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The encoder reads 1 rad where flute 0 is: flute 0 is at −57.3° at its zero (122.7° a
    tooth pitch on). On the 8 mm cut, whose depth's notch lies within the fitted harmonics,
    the search finds that angle (within 0.5°) and the summary offers it as ``--flute0-deg``;
    the 2 mm cut of the same clamping is "not determined" alone and reads its 2 mm within 2 %
    with the angle given."""
    deep = _encoder_record(tmp_path / "deep.h5", 8e-3, 1.0, 300)
    code, line = _summary(tmp_path, deep, capsys)
    assert code == 0, line
    m = re.search(r"--flute0-deg (-?[\d.]+) gives it to the tool's other records", line)
    assert m, line
    found = float(m.group(1))
    # the tooth harmonics repeat every tooth pitch (180°): the angle is found within one
    assert (found + math.degrees(1.0) + 90.0) % 180.0 - 90.0 == pytest.approx(0.0, abs=0.5)
    assert _axial_mm(line) == pytest.approx(8.0, rel=0.02)
    light = _encoder_record(tmp_path / "light.h5", 2e-3, 1.0, 700)
    code, alone = _summary(tmp_path, light, capsys)
    assert code == 0, alone
    assert "engagement not determined" in alone and "--flute0-deg" in alone, alone
    code, given = _summary(tmp_path, light, capsys, "--flute0-deg", str(found))
    assert code == 0, given
    assert _axial_mm(given) == pytest.approx(2.0, rel=0.02), given
    assert f"flute 0 at {found:.1f}° where the spindle angle reads 0, as given" in given


def test_flute0_without_an_angle_reference_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With a speed channel only, the record's zero is wherever the spindle was: a given
    angle means nothing. One line naming the channels needed, exit 2, no event log."""
    data = _band_limited_torque(RPM, 1.0, 2)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("dynamometer/torque", data["spindle/torque_est"], "N*m")
    rec.add_channel("spindle/speed", data["spindle/speed"], "rad/s")
    write_recording(tmp_path / "r.h5", rec)
    code, err = _summary(tmp_path, tmp_path / "r.h5", capsys, "--flute0-deg", "30")
    assert code == 2
    msg = err.strip().splitlines()[-1]
    assert "--flute0-deg" in msg and "spindle/angle" in msg and "spindle/index" in msg
    assert not (tmp_path / "ev.parquet").exists()
