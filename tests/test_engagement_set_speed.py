"""Decision 1737: the engagement monitor takes the spindle speed from a channel in rad/s or
rev/min, or, for a cut at a set speed recorded without one (a dynamometer alone, as Lee's),
from ``--spindle-rpm`` or the recording's metadata."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from test_engagement_nyquist import FS, _band_limited_torque, _tool

ACTUAL_RPM = 1002.0


def _recording(path: Path, rpm: float, speed: str | None, **metadata: object) -> Path:
    """2 s of a 2-flute Ø20 mm cut (2 mm axial, 5 mm radial, 0.1 mm a tooth) turning at
    ``rpm``; its speed channel in ``speed`` units (None: no speed channel)."""
    data = _band_limited_torque(rpm, 2.0, 2)
    rec = Recording(FS, 0.0, {"program": "part.nc", **metadata})
    rec.add_channel("dynamometer/torque", data["spindle/torque_est"], "N*m")
    if speed in ("index", "ttl"):  # a mark at each revolution's start: 0/1, or 0/5 V 1 ms wide
        turns = np.cumsum(data["spindle/speed"]) / FS / (2 * math.pi)
        width = 1 if speed == "index" else 10
        start = np.flatnonzero(np.diff(np.floor(turns)) > 0) + 1
        mark = np.zeros(turns.size)
        for i in start:
            mark[i : i + width] = 1.0 if speed == "index" else 5.0
        rec.add_channel("spindle/index", mark, "1" if speed == "index" else "V")
    elif speed == "angle":  # a rotary encoder's angle, wrapped into [0, 2π) as one records it
        ang = np.cumsum(data["spindle/speed"]) / FS
        rec.add_channel("spindle/angle", np.mod(ang + 1.0, 2 * math.pi), "rad")
    elif speed == "rad/s":
        rec.add_channel("spindle/speed", data["spindle/speed"], "rad/s")
    elif speed == "rev/min":
        rec.add_channel("spindle/speed", data["spindle/speed"] * 60 / (2 * math.pi), "rev/min")
    write_recording(path, rec)
    return path


def _depths(tmp_path: Path, rec: Path, capsys: pytest.CaptureFixture[str],
            *extra: str) -> tuple[int, str]:  # fmt: skip
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--channel",
                                 "dynamometer/torque", "--tool", str(_tool(tmp_path / "t.toml", 2)),
                                 "--feed-per-tooth-mm", "0.1", *extra, "-o",
                                 str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    if code != 0:
        return code, err
    return code, next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))


def _axial_mm(line: str) -> float:
    words = line.replace(",", "").split()
    return float(words[words.index("axial") + 2])


@pytest.mark.parametrize("unit", ["rad/s", "rev/min"])
def test_the_speed_channel_in_either_unit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], unit: str
) -> None:
    """A speed channel in rev/min (a CNC trace's) gives the depth as one in rad/s: 2 mm
    within 2 %."""
    code, line = _depths(tmp_path, _recording(tmp_path / "r.h5", 1000.0, unit), capsys)
    assert code == 0, line
    assert _axial_mm(line) == pytest.approx(2.0, rel=0.02)
    assert "no speed channel" not in line


@pytest.mark.parametrize("source", ["option", "metadata"])
def test_a_cut_at_a_set_speed_without_a_speed_channel(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], source: str
) -> None:
    """A dynamometer's torque alone, the set speed from --spindle-rpm or the recording's
    metadata, the spindle turning 0.2 % faster than set (1002 rev/min): the monitor refines
    the speed from the torque's own revolutions, the depth is within 2 % of 2 mm, and the
    summary says where the angle came from. (At the set speed itself, 0.02 % off already read
    2.10 mm: decision 1737.)"""
    meta = {"spindle_rpm": 1000.0} if source == "metadata" else {}
    rec = _recording(tmp_path / "r.h5", ACTUAL_RPM, None, **meta)
    extra = ("--spindle-rpm", "1000") if source == "option" else ()
    code, line = _depths(tmp_path, rec, capsys, *extra)
    assert code == 0, line
    assert _axial_mm(line) == pytest.approx(2.0, rel=0.02)
    assert "the set 1000 rev/min refined from the torque's own revolutions" in line


def test_no_speed_at_all_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Neither a speed channel nor a set speed: one line naming both ways, exit 2."""
    code, err = _depths(tmp_path, _recording(tmp_path / "r.h5", 1000.0, None), capsys)
    assert code == 2
    msg = err.strip().splitlines()[-1]
    assert "spindle/speed" in msg and "--spindle-rpm" in msg
    assert not (tmp_path / "ev.parquet").exists()


@pytest.mark.parametrize("actual", [1000.0, 1002.0, 1009.0])
def test_the_speed_from_the_torques_own_revolutions(actual: float) -> None:
    """2 s of the cut (33 revolutions) with 0.05 N·m of noise, set to 1000 rev/min: the
    speed within 10 ppm (the phase slope at the strongest order over the record; a 1 % error
    is the range searched)."""
    from millsense.monitoring.revolution_period import refined_speed_rpm

    x = _band_limited_torque(actual, 2.0, 2)["spindle/torque_est"]
    x = x + 0.05 * np.random.default_rng(3).standard_normal(x.size)
    rpm = refined_speed_rpm(x, FS, 1000.0)
    assert rpm is not None
    assert rpm == pytest.approx(actual, rel=1e-5)


def test_no_refined_speed_without_revolutions() -> None:
    """A flat record, fewer than 4 revolutions, or a speed beyond the 1 % searched: None."""
    from millsense.monitoring.revolution_period import refined_speed_rpm

    assert refined_speed_rpm(np.zeros(20000), FS, 1000.0) is None
    short = _band_limited_torque(1000.0, 0.2, 2)["spindle/torque_est"]  # 3.3 revolutions
    assert refined_speed_rpm(short, FS, 1000.0) is None
    far = _band_limited_torque(1030.0, 2.0, 2)["spindle/torque_est"]  # 3 % faster
    assert refined_speed_rpm(far, FS, 1000.0) is None


def test_the_spindle_angle_channel(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dynamometer's torque with the spindle encoder's wrapped angle (Lee's revolution
    reference), the spindle at 1002 rev/min, no speed channel and no set speed: the depth
    within 2 % of 2 mm, the summary naming the angle channel. The encoder reads 1 rad and a
    sample's turn (its angle is the speed's running sum to the sample) where flute 0 is at 0:
    at its zero flute 0 is at −57.9° (decision 1694), which ``--flute0-deg`` gives."""
    rec = _recording(tmp_path / "r.h5", 1002.0, "angle")
    zero = -math.degrees(1.0 + 1002.0 * 2 * math.pi / 60 / FS)
    code, line = _depths(tmp_path, rec, capsys, "--flute0-deg", f"{zero!r}")
    assert code == 0, line
    assert _axial_mm(line) == pytest.approx(2.0, rel=0.02)
    assert "the spindle angle from the channel spindle/angle" in line


def test_an_angle_channel_is_an_angle() -> None:
    """The import map refuses a spindle angle in a length unit (one-line ConfigError)."""
    from millsense.core.errors import ConfigError
    from millsense.io.importers.mapfile import check_channel_unit

    check_channel_unit("spindle/angle", "deg", "rad", "map")
    with pytest.raises(ConfigError, match="spindle/angle"):
        check_channel_unit("spindle/angle", "mm", "m", "map")


def test_the_angle_channel_is_chunk_invariant() -> None:
    """The speed from the angle's steps carries the last angle across chunks: 10 ms and 0.1 s
    chunks give the same estimates, bit for bit."""
    from millsense.monitoring.engagement import EngagementBlock
    from millsense.streaming.block import Chunk

    data = _band_limited_torque(1002.0, 1.0, 2)
    n = data["spindle/speed"].size
    angle = np.mod(np.cumsum(data["spindle/speed"]) / FS, 2 * math.pi)
    feed = {"spindle/torque_est": data["spindle/torque_est"], "spindle/angle": angle}
    got = []
    for chunk in (100, 1000):
        block = EngagementBlock(2, 20.0, 30.0, feed_per_tooth_mm=0.1,
                                angle_channel="spindle/angle")  # fmt: skip
        block.reset(FS)
        for a in range(0, n, chunk):
            block.process(Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in feed.items()}))
        got.append([(t, None if e is None else e.axial_depth_m) for t, e in block.estimates])
    assert len(got[0]) >= 15
    assert got[0] == got[1]


@pytest.mark.parametrize("kind", ["index", "ttl"])
def test_the_index_pulse(tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    """A once-per-revolution mark (0/1, or a 5 V pulse 1 ms wide) with the dynamometer's
    torque and nothing else, the spindle at 1000 rev/min (600 samples a revolution, so each
    mark falls on a revolution's first sample): the depth within 2 % of 2 mm, the summary
    naming the pulse. (At a period of 598.8 samples the marks' sample quantisation is
    :func:`test_the_index_pulses_angle`'s; the depth then moves with where the revolutions'
    boundaries fall between samples, as it does with an exact angle: decision 1737.)"""
    code, line = _depths(tmp_path, _recording(tmp_path / "r.h5", 1000.0, kind), capsys)
    assert code == 0, line
    assert _axial_mm(line) == pytest.approx(2.0, rel=0.02)
    assert "the spindle angle from the index pulse spindle/index" in line


def test_the_index_pulses_angle() -> None:
    """Marks every 598.8 samples (1002 rev/min at 10 kHz), each on the first sample at or
    after a revolution's start: NaN until the second mark; from the 8th on (the line's
    marks) the true angle to within half a sample's turn (2π/598.8 per sample; a single
    mark is up to one sample late), and within 0.2 of one in the mean square (a mark's
    lateness is uniform over a sample, s.d. 0.29; the line over 8 marks, extrapolated up to a
    revolution ahead, keeps about 0.7 of it); the same whatever the chunking."""
    from millsense.monitoring.index_pulse import FIT_MARKS, index_angle, index_state

    period = FS * 60.0 / 1002.0
    turns = np.arange(30000) / period
    mark = np.zeros(turns.size)
    at = np.flatnonzero(np.diff(np.floor(turns)) > 0) + 1
    mark[at] = 1.0
    got = []
    for chunk in (1, 100, 30000):
        state, out = index_state(), np.empty(turns.size)
        for a in range(0, turns.size, chunk):
            index_angle(mark[a : a + chunk], 0.5, state, out[a : a + chunk])
        got.append(out)
    assert np.array_equal(got[0], got[1], equal_nan=True)
    assert np.array_equal(got[0], got[2], equal_nan=True)
    assert np.isnan(got[0][: at[1]]).all()
    # the angle counts turns from the first mark, which lies on revolution floor(turns[at[0]])
    true = 2 * math.pi * (turns - np.floor(turns[at[0]]))
    one = 2 * math.pi / period
    err = (got[0] - true)[at[FIT_MARKS - 1] :]
    # a constant offset (the marks' mean lateness) is the angle's reference, not an error
    err = err - np.mean(err)
    assert np.max(np.abs(err)) <= 0.5 * one
    assert np.sqrt(np.mean(err**2)) <= 0.2 * one
