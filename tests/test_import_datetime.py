"""Delimited recordings whose time column is an ISO-8601 date and time (data loggers, PC DAQ
software, CNC exports with a wall clock): read as seconds from the first sample.

Scenario: a 1 kHz current column stamped ``2026-11-29T10:15:02.123456`` (``T`` or a space
between date and time, with or without a zone offset); bad clocks are refused with one line
naming the file and the line (exit status 2) and nothing is written.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.io import read_recording
from millsense.io.importers import import_files, load_map

MAP_I = '[[channels]]\ncolumn = "I"\nchannel = "x/current_cmd"\nunit = "A"\n'
T0 = datetime(2026, 11, 29, 10, 15, 2, 123456)


def _stamps(n: int, step_s: float, sep: str = "T", tz: timezone | None = None) -> list[str]:
    out = []
    for k in range(n):
        t = T0 + timedelta(seconds=k * step_s)
        if tz is not None:
            t = t.replace(tzinfo=UTC).astimezone(tz)
        out.append(t.isoformat(sep=sep, timespec="microseconds"))
    return out


def _csv(stamps: list[str], d: str = ",", name: str = "timestamp") -> str:
    rows = [f"{s}{d}{k % 7 * 0.5}" for k, s in enumerate(stamps)]
    return f"{name}{d}I\n" + "\n".join(rows) + "\n"


def _import(tmp_path: Path, text: str, mapping: str = MAP_I):
    (tmp_path / "log.csv").write_text(text)
    (tmp_path / "m.toml").write_text(mapping)
    return import_files([tmp_path / "log.csv"], load_map(tmp_path / "m.toml"))


@pytest.mark.parametrize("sep", ["T", " "])
def test_iso_datetime_time_column_read_as_seconds_from_the_first_sample(
    tmp_path: Path, sep: str
) -> None:
    """200 rows 1 ms apart stamped to the µs: the rate is 1000 Hz (exact to the µs stamps'
    rounding of float steps, 1e-9), the recording starts at 0 s, the values are the column's
    and the wall-clock time of the first sample is kept in the metadata."""
    res = _import(tmp_path, _csv(_stamps(200, 1e-3, sep)))
    rec = res.recording
    assert rec.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    assert rec.t0_s == 0.0
    assert rec.n_samples == 200
    np.testing.assert_array_equal(rec.channel("x/current_cmd"), np.arange(200) % 7 * 0.5)
    assert rec.metadata["time_origin"] == f"2026-11-29{sep}10:15:02.123456"


def test_zone_offsets_across_a_clock_change_are_one_utc_time_base(tmp_path: Path) -> None:
    """Stamps with their zone offset through the end of summer time (CEST +02:00 → CET
    +01:00, 2026-10-25 03:00 local): the local clock goes back an hour, the UTC one does not;
    read on UTC, 100 rows 10 ms apart are 100 Hz (1e-9) with no gap and no refusal."""
    cest = timezone(timedelta(hours=2))
    cet = timezone(timedelta(hours=1))
    t_utc = datetime(2026, 10, 25, 0, 59, 59, 500000, tzinfo=UTC)
    stamps = []
    for k in range(100):
        t = t_utc + timedelta(seconds=k * 0.01)
        local = t.astimezone(cest if t < datetime(2026, 10, 25, 1, tzinfo=UTC) else cet)
        stamps.append(local.isoformat(timespec="milliseconds"))
    assert stamps[50].startswith("2026-10-25T02:00:00.000+01:00")  # local time went back
    res = _import(tmp_path, _csv(stamps))
    assert res.recording.sample_rate_hz == pytest.approx(100.0, rel=1e-9)
    assert res.recording.n_samples == 100
    assert not res.report.of_kind("gap")
    assert res.recording.metadata["time_origin"] == "2026-10-25T02:59:59.500+02:00"


def test_utc_designator_semicolons_and_decimal_commas(tmp_path: Path) -> None:
    """A German-locale export: ``;``, decimal comma in the values, stamps ending in ``Z``;
    the rate and the values read as in the plain case."""
    stamps = [s + "Z" for s in _stamps(50, 2e-3)]
    rows = [f"{s};{k},25" for k, s in enumerate(stamps)]
    mapping = '[[files]]\ndecimal = ","\n\n' + MAP_I
    res = _import(tmp_path, "Zeitstempel;I\n" + "\n".join(rows) + "\n", mapping)
    rec = res.recording
    assert rec.sample_rate_hz == pytest.approx(500.0, rel=1e-9)
    np.testing.assert_allclose(rec.channel("x/current_cmd"), np.arange(50) + 0.25, rtol=0)


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str) -> str:
    (tmp_path / "log.csv").write_text(text)
    (tmp_path / "m.toml").write_text(MAP_I)
    out = tmp_path / "o.h5"
    code, _, err = run_cli(
        ["import", str(tmp_path / "log.csv"), "--map", str(tmp_path / "m.toml"), "-o", str(out)],
        capsys,
    )
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert not out.exists()
    return lines[0]


def test_datetime_going_backwards_refused_naming_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Rows 0..9 then row 10 stamped 5 ms before row 9: line 12 of the file (names row + 11)."""
    stamps = _stamps(20, 1e-3)
    stamps[10] = (T0 + timedelta(seconds=4e-3)).isoformat(timespec="microseconds")
    msg = _refused(tmp_path, capsys, _csv(stamps))
    assert "log.csv" in msg and "line 12" in msg and "time does not increase" in msg


def test_stamps_coarser_than_the_sampling_refused_naming_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """10 kHz rows stamped to the millisecond: ten rows share a stamp, so time stands still
    from line 3 on; refused (not read as a 1 kHz record with repeats)."""
    stamps = [s[:-3] for s in _stamps(100, 1e-4)]  # µs cut to ms
    msg = _refused(tmp_path, capsys, _csv(stamps))
    assert "log.csv" in msg and "line 3" in msg and "time does not increase" in msg


def test_mixed_zone_offsets_refused_naming_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The first stamps with an offset, line 7 without: which clock is it? Refused."""
    stamps = [s + "+01:00" for s in _stamps(20, 1e-3)]
    stamps[5] = stamps[5][:-6]
    msg = _refused(tmp_path, capsys, _csv(stamps))
    assert "log.csv" in msg and "line 7" in msg and "zone offset" in msg


def test_irregular_time_beyond_tolerance_refused_naming_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 1 kHz log whose row 29 (line 31) comes 0.2 ms after row 28 (a step of a fifth of the 1 ms
    median, two samples in one sample period): refused naming line 31, for a datetime and
    for a numeric time column alike; a jitter of ±0.2 ms (steps 0.6-1.4 ms) is still resampled
    (accepted; its rate within 1 %: the end stamps' ±0.2 ms over 59 ms, 0.7 %)."""
    stamps = _stamps(60, 1e-3)
    stamps[29] = (T0 + timedelta(seconds=28.2e-3)).isoformat(timespec="microseconds")
    msg = _refused(tmp_path, capsys, _csv(stamps))
    assert "log.csv" in msg and "line 31" in msg and "irregular" in msg
    t = np.arange(60) * 1e-3
    t[29] = 28.2e-3
    text = "time,I\n" + "".join(f"{v:.7f},{k % 3}\n" for k, v in enumerate(t))
    msg = _refused(tmp_path, capsys, text)
    assert "log.csv" in msg and "line 31" in msg and "irregular" in msg
    rng = np.random.default_rng(0)
    t = np.arange(60) * 1e-3 + rng.uniform(-0.2e-3, 0.2e-3, 60)
    res = _import(tmp_path, "time,I\n" + "".join(f"{v:.7f},{k % 3}\n" for k, v in enumerate(t)))
    assert res.recording.sample_rate_hz == pytest.approx(1000.0, rel=0.01)
    assert res.report.of_kind("time")  # the resampling is reported


def test_datetime_refused_in_a_numeric_column_naming_line_and_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stamp where a current is expected is not a number: line and column named."""
    text = _csv(_stamps(10, 1e-3)).replace(",3.0\n", ",2026-11-29T10:15:02\n", 1)
    msg = _refused(tmp_path, capsys, text)
    assert "log.csv: line 8, column 2 ('I')" in msg and "not a number" in msg


def test_written_recording_keeps_the_time_origin(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Through the command: the written recording is 1000 Hz and knows its wall clock."""
    (tmp_path / "log.csv").write_text(_csv(_stamps(300, 1e-3, " ")))
    (tmp_path / "m.toml").write_text(MAP_I)
    out = tmp_path / "o.h5"
    code, _, err = run_cli(
        ["import", str(tmp_path / "log.csv"), "--map", str(tmp_path / "m.toml"), "-o", str(out)],
        capsys,
    )
    assert code == 0, err
    rec = read_recording(out)
    assert rec.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    assert rec.metadata["time_origin"] == "2026-11-29 10:15:02.123456"


def test_time_column_ignored_when_the_map_says_so(tmp_path: Path) -> None:
    """The refusal's remedy: ``time_column = ""`` with a stated rate reads the same irregular
    file as evenly sampled at 1000 Hz (exactly the stated rate: no time column measures it)."""
    t = np.arange(60) * 1e-3
    t[29] = 28.2e-3
    text = "time,I\n" + "".join(f"{v:.7f},{k % 3}\n" for k, v in enumerate(t))
    mapping = '[[files]]\ntime_column = ""\nsample_rate_hz = 1000\n\n' + MAP_I
    rec = _import(tmp_path, text, mapping).recording
    assert rec.sample_rate_hz == 1000.0
    assert rec.n_samples == 60


def test_files_stamped_with_the_wall_clock_are_laid_on_one_clock(tmp_path: Path) -> None:
    """A 1 kHz drive trace from 10:15:02.123456 and a 10 Hz temperature log from 0.5 s
    earlier (with a space for the T): each was read from its own first row, the log laid
    0.5 s late. The log's rows start at -0.5 s on the trace's clock (1e-9 s: µs stamps)."""
    (tmp_path / "log.csv").write_text(_csv(_stamps(1000, 1e-3)))
    t_log = [
        (T0 + timedelta(seconds=-0.5 + 0.1 * k)).isoformat(sep=" ", timespec="microseconds")
        for k in range(20)
    ]
    (tmp_path / "temp.csv").write_text(
        "stamp,temp\n" + "".join(f"{s},{20 + k}\n" for k, s in enumerate(t_log))
    )
    mapping = MAP_I + '\n[[channels]]\ncolumn = "temp"\nchannel = "thermal/temp"\nunit = "1"\n'
    (tmp_path / "m.toml").write_text(mapping)
    rec = import_files(
        [tmp_path / "log.csv", tmp_path / "temp.csv"], load_map(tmp_path / "m.toml")
    ).recording
    st = rec.stream("thermal")
    np.testing.assert_allclose(st.time_s, -0.5 + 0.1 * np.arange(20), rtol=0, atol=1e-9)
    assert rec.t0_s == 0.0 and rec.metadata["time_origin"] == "2026-11-29T10:15:02.123456"


def test_files_on_a_zoned_and_an_unzoned_clock_refused(tmp_path: Path) -> None:
    """One file's stamps carry +01:00, the other's none: no common clock, one line naming
    both first stamps."""
    from millsense.core.errors import InputDataError

    (tmp_path / "log.csv").write_text(_csv(_stamps(100, 1e-3)))
    zoned = [s + "+01:00" for s in _stamps(10, 0.1)]
    (tmp_path / "temp.csv").write_text("stamp,temp\n" + "".join(f"{s},20\n" for s in zoned))
    mapping = MAP_I + '\n[[channels]]\ncolumn = "temp"\nchannel = "thermal/temp"\nunit = "1"\n'
    (tmp_path / "m.toml").write_text(mapping)
    with pytest.raises(InputDataError, match=r"temp\.csv: its first stamp .* no common clock"):
        import_files([tmp_path / "log.csv", tmp_path / "temp.csv"], load_map(tmp_path / "m.toml"))
