"""Recordings as users bring them (QA of the "real data in" path): column names carrying their
unit after an underscore (``x_current_A``, ``time_ms``), missing values, constant channels,
a second file at another rate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.io.importers import import_files, load_map

MAP = """[[channels]]
column = "x_current_A"
channel = "x/current_cmd"
unit = "header"

[[channels]]
column = "spindle_speed_rpm"
channel = "spindle/speed"
unit = "header"
"""


def _write(tmp_path: Path, name: str, text: str, mapping: str = MAP) -> tuple[Path, Path]:
    (tmp_path / name).write_text(text)
    (tmp_path / "m.toml").write_text(mapping)
    return tmp_path / name, tmp_path / "m.toml"


@pytest.mark.parametrize(("tname", "factor"), [("time_ms", 1e-3), ("t_us", 1e-6), ("Zeit_s", 1.0)])
def test_time_and_units_after_an_underscore_in_the_column_names(
    tmp_path: Path, tname: str, factor: float
) -> None:
    """``time_ms`` was not taken for the time column ("no time column and no sample rate"),
    and ``unit = "header"`` found no unit in ``x_current_A``: the part after the last
    underscore is the column's unit when it is a known one. 200 rows 0.2 ms apart are
    5000 Hz (1e-9), rev/min converted to rad/s (3000 rev/min = 314.159 rad/s, 1e-12)."""
    step = 0.2e-3 / factor
    rows = "".join(f"{k * step:.6g},{np.sin(k / 10):.6f},3000\n" for k in range(200))
    csv, m = _write(tmp_path, "a.csv", f"{tname},x_current_A,spindle_speed_rpm\n" + rows)
    res = import_files([csv], load_map(m))
    rec = res.recording
    assert rec.sample_rate_hz == pytest.approx(5000.0, rel=1e-9)
    assert rec.info("x/current_cmd").unit == "A"
    assert rec.channel("spindle/speed")[0] == pytest.approx(3000 * 2 * np.pi / 60, rel=1e-12)


def test_a_name_ending_in_no_unit_still_asks_for_one(tmp_path: Path) -> None:
    """``coolant_on`` ends in no unit: ``unit = "header"`` is still refused naming the column
    (the suffix is a unit only when it is one of the map's units)."""
    from millsense.core.errors import InputDataError

    rows = "".join(f"{k * 0.2:.1f},1\n" for k in range(20))
    mapping = '[[channels]]\ncolumn = "coolant_on"\nchannel = "cnc/coolant"\nunit = "header"\n'
    csv, m = _write(tmp_path, "a.csv", "time_ms,coolant_on\n" + rows, mapping)
    with pytest.raises(InputDataError, match="column 'coolant_on' has no unit in the file"):
        import_files([csv], load_map(m))


def test_no_mains_hum_on_a_constant_or_a_finely_quantised_channel() -> None:
    """A 10-minute import reported "60 Hz mains hum" on a constant 0.3 A channel (lines of
    5.7e-21 A standing 39 dB over a floor of rounding residue) and on a spindle speed written
    to 0.01 rev/min (2e-5 rad/s lines, 1/50 of one step of the file's resolution). A line
    below half the channel's quantisation step is the rounding pattern, not the mains; a
    constant channel has no spectrum. 60 s at 10 kHz of each; a real 0.05 A hum on a current
    written to 1e-5 A is still found with its amplitude (Hann window: 10 %)."""
    from millsense.io.quality import mains_hum

    fs = 10_000.0
    t = np.arange(int(60 * fs)) / fs
    assert mains_hum(np.full(t.size, 0.3), fs) is None
    speed = np.round(3000 + 2 * np.sin(t), 2) * 2 * np.pi / 60  # %.2f rev/min
    assert mains_hum(speed, fs) is None
    rng = np.random.default_rng(1)
    current = 2 * np.sin(2 * np.pi * 100 * t) + 0.05 * np.sin(2 * np.pi * 60 * t)
    current = np.round(current + 0.01 * rng.standard_normal(t.size), 5)
    hum = mains_hum(current, fs, rotation_hz=50.0)
    assert hum is not None and hum[0] == 60.0
    assert hum[1][0][1] == pytest.approx(0.05, rel=0.1)


def test_a_table_read_in_chunks_is_the_table_read_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A long file is parsed in chunks of its text (memory of a 10-minute 10 kHz file of
    290 MB: 2.8 GB read whole, 0.9 GB in chunks): with 1000-character chunks and a 5-line
    head, a 3000-row file with a header longer than the head, stamps and decimal commas reads
    exactly as whole (same floats), the stamps from the file's first one, and a bad cell in a
    late chunk is named at its line."""
    from millsense.core.errors import InputDataError
    from millsense.io.importers import delimited

    head = "".join(f"info {k}: x\n" for k in range(8)) + "Zeit;I;U\n"
    rows = [
        f"2026-11-29 10:15:{2 + k * 1e-3:09.6f};{k * 0.25:.2f};{np.sin(k):.6f}".replace(".", ",")
        for k in range(3000)
    ]
    rows = [r.replace(",", ".", 1) for r in rows]  # the stamp keeps its decimal point
    (tmp_path / "a.csv").write_text(head + "\n".join(rows) + "\n\n\n")
    whole = delimited.read_delimited(tmp_path / "a.csv", decimal=",")
    monkeypatch.setattr(delimited, "CHUNK_CHARS", 1000)
    monkeypatch.setattr(delimited, "HEAD_LINES", 5)
    done: list[tuple[int, int]] = []
    part = delimited.read_delimited(
        tmp_path / "a.csv", decimal=",", progress=lambda a, b: done.append((a, b))
    )
    assert len(done) > 50 and done[-1][0] == done[-1][1]
    assert part.n_rows == whole.n_rows == 3000 and part.first_line == whole.first_line == 10
    for c in ("Zeit", "I", "U"):
        np.testing.assert_array_equal(part.columns[c], whole.columns[c])
    assert part.columns["Zeit"][-1] == pytest.approx(2.999, abs=1e-9)
    rows[2500] = rows[2500].rsplit(";", 1)[0] + ";oops"
    (tmp_path / "a.csv").write_text(head + "\n".join(rows) + "\n")
    with pytest.raises(InputDataError, match=r"a.csv: line 2510, column 3 \('U'\)"):
        delimited.read_delimited(tmp_path / "a.csv", decimal=",")


def test_excel_unicode_text_export_is_read(tmp_path: Path) -> None:
    """Excel's "Unicode Text" (UTF-16 with a byte-order mark, tab-separated, CRLF) was read
    as cp1252 and refused ("no table of numbers found"); its 300 rows at 1 kHz read as the
    same table written in UTF-8."""
    text = "time\tI\r\n" + "".join(f"{k * 1e-3:.3f}\t{k % 7}\r\n" for k in range(300))
    (tmp_path / "u16.txt").write_bytes(text.encode("utf-16"))
    mapping = '[[channels]]\ncolumn = "I"\nchannel = "x/current_cmd"\nunit = "A"\n'
    (tmp_path / "m.toml").write_text(mapping)
    rec = import_files([tmp_path / "u16.txt"], load_map(tmp_path / "m.toml")).recording
    assert rec.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    np.testing.assert_array_equal(rec.channel("x/current_cmd"), np.arange(300) % 7)


@pytest.mark.parametrize("bad_row", [0, 1, 2])
def test_text_in_one_of_the_first_rows_is_named_at_its_line(tmp_path: Path, bad_row: int) -> None:
    """A cell of text in one of the first three data rows moved the table's start below it and
    took the bad row for the names: "no column 'I' ...; columns: '0.001', 'x'". It is named at
    its line and column like one further down."""
    from millsense.core.errors import InputDataError

    rows = [f"{k * 1e-3:.3f},{k}" for k in range(10)]
    rows[bad_row] = rows[bad_row].split(",")[0] + ",x"
    (tmp_path / "bad.csv").write_text("time,I\n" + "\n".join(rows) + "\n")
    mapping = '[[channels]]\ncolumn = "I"\nchannel = "x/current_cmd"\nunit = "A"\n'
    (tmp_path / "m.toml").write_text(mapping)
    with pytest.raises(InputDataError) as err:
        import_files([tmp_path / "bad.csv"], load_map(tmp_path / "m.toml"))
    assert f"bad.csv: line {bad_row + 2}, column 2 ('I'): 'x' is not a number" in str(err.value)


def test_a_slower_channel_merged_into_the_table_becomes_a_stream(tmp_path: Path) -> None:
    """A DAQ export with a 100 Hz temperature among 10 kHz currents (a value every 100th row,
    blank between) was refused: "channel 'thermal/temp' has 99 missing (NaN) samples in a
    row". It is the field 'temp' of the stream 'thermal' at 100 Hz: 50 rows at t = 0, 0.01
    ... s with their values (exact), the current untouched."""
    rows = []
    for k in range(5000):
        temp = f"{25 + k * 1e-4:.4f}" if k % 100 == 0 else ""
        rows.append(f"{k * 1e-4:.4f},{np.sin(k / 7):.5f},{temp}\n")
    mapping = (
        '[[channels]]\ncolumn = "x_current_A"\nchannel = "x/current_cmd"\nunit = "header"\n'
        '[[channels]]\ncolumn = "temp"\nchannel = "thermal/temp"\nunit = "1"\n'
    )
    csv, m = _write(tmp_path, "daq.csv", "time_s,x_current_A,temp\n" + "".join(rows), mapping)
    res = import_files([csv], load_map(m))
    rec = res.recording
    st = rec.stream("thermal")
    assert len(st) == 50
    np.testing.assert_allclose(st.time_s, np.arange(50) * 0.01, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(st["temp"], np.round(25 + np.arange(50) * 0.01, 4))
    assert rec.channel("x/current_cmd").size == 5000
    (f,) = res.report.of_kind("nan")
    assert "every 100 rows" in f.message and "100 Hz" in f.message


def test_no_mains_hum_on_the_harmonic_comb_of_a_periodic_motion() -> None:
    """A position reversing every 15 s (a sawtooth of 0.3 m) has harmonics every 1/15 Hz, one
    on 60 Hz: it was reported as "60 Hz mains hum 1e-4 m (174 dB)". Its neighbours are as
    strong: no hum. 10 minutes at 1 kHz; a 1e-5 m hum added on top of a noisy motion
    instead is still found (amplitude within 10 %, the Hann window's)."""
    from millsense.io.quality import mains_hum

    fs = 1000.0
    t = np.arange(int(600 * fs)) / fs
    saw = (0.02 * t) % 0.3
    assert mains_hum(saw, fs) is None
    rng = np.random.default_rng(2)
    moving = 0.1 * np.sin(2 * np.pi * 0.05 * t) + 1e-6 * rng.standard_normal(t.size)
    hum = mains_hum(moving + 1e-5 * np.sin(2 * np.pi * 60 * t), fs)
    assert hum is not None and hum[0] == 60.0
    assert hum[1][0][1] == pytest.approx(1e-5, rel=0.1)


def test_export_says_the_streams_it_does_not_write(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`export` of a recording with a stream wrote the channels and dropped the stream without
    a word, and `-c thermal/temp` said "not in r.h5" although `info` lists it. The note names
    the streams left out (exit 0); asking for one is one line saying it is a stream (exit 2).
    The 200 exported samples import back exactly."""
    from cli_run import run_cli
    from millsense.core.recording import Recording
    from millsense.io.recording_file import read_recording, write_recording

    rec = Recording(1000.0)
    rec.add_channel("x/current_cmd", np.sin(np.arange(200) / 5), "A")
    rec.add_stream("thermal", np.arange(20) / 100, {"temp": 25 + np.arange(20.0)}, {"temp": "1"})
    write_recording(tmp_path / "r.h5", rec)
    out = tmp_path / "r.csv"
    code, _, err = run_cli(["export", str(tmp_path / "r.h5"), "--format", "csv", "-o", str(out)],
                           capsys)  # fmt: skip
    assert code == 0 and "streams are not exported: thermal (temp)" in err
    code, _, _ = run_cli(["import", str(out), "--map", str(tmp_path / "r.map.toml"), "-o",
                          str(tmp_path / "b.h5")], capsys)  # fmt: skip
    assert code == 0
    back = read_recording(tmp_path / "b.h5").channel("x/current_cmd")
    np.testing.assert_array_equal(back, rec.channel("x/current_cmd"))
    args = ["export", str(tmp_path / "r.h5"), "--format", "csv", "-c", "thermal/temp"]
    code, _, err = run_cli([*args, "-o", str(tmp_path / "t.csv")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "'thermal/temp': a stream of" in err and "streams are not exported" in err


def test_a_refusal_is_one_line_on_stderr_also_outside_a_terminal(tmp_path: Path) -> None:
    """With the progress bar of `import` (and `plan`'s) the refusal of an empty file came
    after an empty line when stderr was a log or a pipe (rich's bar stopping): exactly one
    line now, exit status 2, as a script sees it (a subprocess, stderr a pipe)."""
    import os
    import subprocess
    import sys

    (tmp_path / "empty.csv").write_text("")
    (tmp_path / "m.toml").write_text(MAP)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    args = [sys.executable, "-m", "millsense", "import", str(tmp_path / "empty.csv")]
    args += ["--map", str(tmp_path / "m.toml"), "-o", str(tmp_path / "o.h5")]
    r = subprocess.run(args, capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("millsense: error: ")
    assert "empty.csv: no table of numbers found" in r.stderr
