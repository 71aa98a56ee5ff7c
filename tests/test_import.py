"""``millsense import / check / export / example-data`` (issue 17): real files in.

Scenario: ``millsense example-data`` simulates a slot on the virtual quaser-ux600 (Ø20 mm
2-flute, Al7050, 4 mm deep at 1200 mm/min and 3000 rev/min, 6 mm of air first, 1.3 s at
10 kHz) and writes it as a Servo-Trace-like CSV (``;``, decimal comma, ``key: value`` header,
units row, field units) with flaws injected: header rate 10100 Hz (data at 10 kHz), three
runs of repeated rows, the spindle current clipped at 90 % of its in-cut peak, 30 rows
dropped, +15 N/s drift of the Y dynamometer, 0.5 A of 60 Hz hum (and a 3rd harmonic) on the
X current. The same simulation (``native.h5``) is exported to every format and imported back.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_run import run_cli
from millsense.cli.main import main
from millsense.io import read_recording
from millsense.io.importers import import_files, load_map
from millsense.io.importers.delimited import write_delimited
from millsense.io.importers.export import export_recording

COMMISSIONED = str(
    Path(__file__).resolve().parents[1] / "examples/walkthrough/quaser-ux600-commissioned.toml"
)


@pytest.fixture(scope="module")
def example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("example")
    try:
        main(["example-data", "-o", str(d)])
    except SystemExit as exc:
        assert not exc.code
    return d


# ------------------------------------------------------------------------------ round trip
#: format → (relative tolerance to each channel's peak, reason)
ROUND_TRIP = {
    "csv": (0.0, "17 significant digits: exact"),
    "tsv": (0.0, "17 significant digits: exact"),
    "mat": (0.0, "float64 vectors"),
    "mat73": (0.0, "float64 HDF5 datasets"),
    "tdms": (0.0, "float64 channels"),
    "wav": (1e-15, "64-bit float scaled to the peak and back: one rounding"),
    "parquet": (0.0, "float64 columns"),
}


@pytest.mark.parametrize("fmt", list(ROUND_TRIP))
def test_round_trip_every_format(example: Path, tmp_path: Path, fmt: str) -> None:
    rec = read_recording(example / "native.h5")
    chans = rec.measured_channel_names()
    suffix = ".mat" if fmt == "mat73" else f".{fmt}"
    out = tmp_path / f"run{suffix}"
    (tmp_path / "map.toml").write_text(export_recording(rec, out, fmt, chans))
    back = import_files([out], load_map(tmp_path / "map.toml")).recording
    tol, _reason = ROUND_TRIP[fmt]
    assert back.sample_rate_hz == pytest.approx(rec.sample_rate_hz, rel=1e-12)
    assert back.channel_names == chans
    for c in chans:
        ref = np.asarray(rec.channel(c), dtype=float)
        peak = max(float(np.max(np.abs(ref))), 1e-300)
        assert np.max(np.abs(back.channel(c) - ref)) <= tol * peak, c
        assert back.info(c).unit == rec.info(c).unit
    if fmt == "mat73":  # a MATLAB v7.3 file: HDF5 with the MATLAB header
        assert out.read_bytes()[:10] == b"MATLAB 7.3"
        with h5py.File(out) as f:
            assert f["x_current_cmd"].attrs["MATLAB_class"] == b"double"


def test_round_trip_flac_within_24_bits(example: Path, tmp_path: Path) -> None:
    rec = read_recording(example / "native.h5")
    chans = ["x/current_cmd", "spindle/current", "spindle/speed"]
    out = tmp_path / "run.flac"
    (tmp_path / "map.toml").write_text(export_recording(rec, out, "flac", chans))
    back = import_files([out], load_map(tmp_path / "map.toml")).recording
    for c in chans:
        ref = np.asarray(rec.channel(c))
        peak = float(np.max(np.abs(ref)))
        # 24-bit PCM: half a step of 2^-23 of full scale (the peak), plus the top code
        assert np.max(np.abs(back.channel(c) - ref)) <= 2.0**-23 * peak * 1.01, c


def test_mp3_read_where_libsndfile_reads_it(tmp_path: Path) -> None:
    """A 1 kHz tone at 44.1 kHz through MP3: lossy, so the tone's amplitude within 5 %."""
    sf = pytest.importorskip("soundfile")
    if "MP3" not in sf.available_formats():
        pytest.skip("this libsndfile has no MP3")
    fs = 44100
    t = np.arange(fs) / fs
    sf.write(str(tmp_path / "tone.mp3"), 0.5 * np.sin(2 * np.pi * 1000 * t), fs, format="MP3")
    (tmp_path / "map.toml").write_text(
        '[[channels]]\ncolumn = "0"\nchannel = "mic/pressure"\nunit = "Pa"\nscale = 2.0\n'
    )
    rec = import_files([tmp_path / "tone.mp3"], load_map(tmp_path / "map.toml")).recording
    x = np.asarray(rec.channel("mic/pressure"))[4410:-4410]
    assert rec.sample_rate_hz == fs
    assert np.sqrt(2 * np.mean(x**2)) == pytest.approx(1.0, rel=0.05)


# ------------------------------------------------------------------------------ quirks
def test_every_injected_quirk_found_with_its_numbers(example: Path) -> None:
    truth = json.loads((example / "quirks.json").read_text())
    res = import_files([example / "trace.csv"], load_map(example / "map.toml"))
    rec, rep = res.recording, res.report
    # rate: measured from the time column, within 0.1 % of the true 10 kHz; stated 10100 Hz
    (rate,) = rep.of_kind("rate")
    assert rate.data["stated_hz"] == truth["stated_rate_hz"]
    assert rate.data["measured_hz"] == pytest.approx(truth["true_rate_hz"], rel=1e-3)
    assert rec.sample_rate_hz == pytest.approx(truth["true_rate_hz"], rel=1e-3)
    # the gap: 30 samples after the right time, filled (the recording has every sample back)
    (gap,) = rep.of_kind("gap")
    assert gap.data["missing"] == truth["gap"]["missing"]
    assert gap.data["t_s"] == pytest.approx(truth["gap"]["t_s"], abs=1e-9)
    assert rec.n_samples == read_recording(example / "native.h5").n_samples
    # every repeated run, with its start and length
    found = sorted((f.data["start"], f.data["length"]) for f in rep.of_kind("repeated"))
    assert found == sorted(tuple(r) for r in truth["repeated"])
    # every clipped run (>= 2 samples at the rail), with its start and length
    (clip,) = rep.of_kind("clipped")
    assert clip.where == truth["clipped"]["channel"]
    assert [tuple(r[:2]) for r in clip.data["runs"]] == [
        tuple(r[:2]) for r in truth["clipped"]["runs"]
    ]
    # the drift: rate within 2 % (0.5 N noise on 0.6 s of air)
    (drift,) = rep.of_kind("drift")
    assert drift.where == truth["drift"]["channel"]
    assert drift.data["per_s"] == pytest.approx(truth["drift"]["per_s"], rel=0.02)
    # hum: 60 Hz on the X current, amplitude within 10 % (the Hann window's amplitude at a
    # line between bins is at most 15 % low; 60 Hz is 78 bins of 1/1.3 s exactly: on a bin;
    # the rest is the cut's own spectrum under the line), third harmonic listed
    (hum,) = rep.of_kind("hum")
    assert hum.where == truth["hum"]["channel"]
    assert hum.data["mains_hz"] == 60.0
    lines = {round(f): a for f, a, _ in hum.data["lines"]}
    assert lines[60] == pytest.approx(truth["hum"]["amplitude"], rel=0.1)
    assert lines[180] == pytest.approx(truth["hum"]["amplitude"] / 3, rel=0.1)
    # field units converted to SI: spindle speed in rev/min -> rad/s, positions mm -> m
    native = read_recording(example / "native.h5")
    assert rec.info("spindle/speed").unit == "rad/s"
    i = slice(5000, 5100)
    assert np.allclose(rec.channel("spindle/speed")[i], native.channel("spindle/speed")[i])
    assert np.allclose(rec.channel("x/position_cmd")[i], native.channel("x/position_cmd")[i])


def test_clean_simulation_has_no_false_findings(example: Path) -> None:
    """On the simulator's own channels: only constant channels (axes that do not move)."""
    from millsense.io.quality import check_recording

    rep = check_recording(read_recording(example / "native.h5"))
    assert {f.kind for f in rep.findings} <= {"constant"}
    rates = [m for k, (s, m) in rep.rates.items() if "motor_angle" in k]
    assert rates and all(abs(m / 1e4 - 1) < 1e-9 for m in rates)


def test_chance_repeats_of_a_16_bit_microphone_are_not_reported() -> None:
    """A 16-bit microphone at 44.1 kHz repeats a sample by chance (≈ 2e-3 of its steps here):
    the quantisation's chance of a zero step is estimated within 20 % of the count in a clean
    signal (an independent count; ≈ 400 zero and 800 one-quantum steps, so 20 % is about 3σ of
    their Poisson scatter), no chance repeat is reported, and three runs of 4 held rows
    (up-sampling by hold) injected into it are found exactly (decision 1703)."""
    from millsense.io.quality import chance_repeat_probability, repeated_rows

    fs, n = 44100, 5 * 44100
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    x = 0.05 * np.sin(2 * np.pi * 400 * t) + 0.02 * np.sin(2 * np.pi * 1000 * t)
    x = np.round((x + 0.005 * rng.standard_normal(n)) * 32767) / 32767  # 16-bit PCM
    zero_steps = np.count_nonzero(np.diff(x) == 0) / (n - 1)
    assert 1e-3 < zero_steps < 3e-3  # the chance repeats this test is about exist
    assert chance_repeat_probability(x) == pytest.approx(zero_steps, rel=0.2)
    starts, lengths, used = repeated_rows({"mic/pressure": x})
    assert used == ["mic/pressure"] and starts.size == 0
    held = x.copy()
    for s in (20000, 90000, 170000):
        held[s + 1 : s + 4] = held[s]
    starts, lengths, _ = repeated_rows({"mic/pressure": held})
    assert starts.tolist() == [20000, 90000, 170000] and lengths.tolist() == [4, 4, 4]


def test_many_findings_of_one_kind_are_counted_not_listed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Eight repeated runs and one hum: five repeats printed, the other three counted in one
    line, the hum printed; the report keeps all nine."""
    from millsense.cli.cmd_import import MAX_PRINTED_PER_KIND, _print_report
    from millsense.io.quality import Finding, QualityReport

    rep = QualityReport()
    for i in range(8):
        rep.add(Finding("repeated", "f.csv", f"f.csv: run {i}", data={"start": i}))
    rep.add(Finding("hum", "x/current", "f.csv: hum"))
    _print_report(rep)
    lines = capsys.readouterr().err.splitlines()
    assert MAX_PRINTED_PER_KIND == 5
    assert [ln for ln in lines if "run " in ln] == [
        f"millsense: warning: f.csv: run {i}" for i in range(5)
    ]
    assert "... and 3 more 'repeated' findings" in lines[-1]
    assert "millsense: warning: f.csv: hum" in lines
    assert len(rep.findings) == 9


def test_rate_measured_without_time_column(example: Path, tmp_path: Path) -> None:
    """No time column, a stated rate 1 % high: the encoder angle/speed pairs give 10 kHz
    within 0.1 %, and the recording uses it."""
    rec = read_recording(example / "native.h5")
    cols = {
        c: np.asarray(rec.channel(c))
        for c in ("x/motor_angle", "x/motor_speed", "x/current_cmd", "spindle/speed")
    }
    write_delimited(tmp_path / "t.csv", cols, {}, ",", {"Sample rate": "10100 Hz"})
    lines = [
        f'[[channels]]\ncolumn = "{c}"\nchannel = "{c}"\nunit = "{rec.info(c).unit}"\n'
        for c in cols
    ]
    (tmp_path / "m.toml").write_text("\n".join(lines))
    res = import_files([tmp_path / "t.csv"], load_map(tmp_path / "m.toml"))
    assert res.recording.sample_rate_hz == pytest.approx(1e4, rel=1e-3)
    (rate,) = res.report.of_kind("rate")
    assert rate.data["stated_hz"] == 10100.0


def test_slower_file_becomes_a_stream(example: Path, tmp_path: Path) -> None:
    rec = read_recording(example / "native.h5")
    fast = {"x/current_cmd": np.asarray(rec.channel("x/current_cmd"))}
    write_delimited(tmp_path / "fast.csv", fast, {}, ",", {"Sample rate": "10000 Hz"})
    st = rec.stream("cnc")
    write_delimited(
        tmp_path / "slow.csv",
        {"time": st.time_s, "tcp_x": st["tcp_x"] * 1e3},
        {"time": "s", "tcp_x": "mm"},
        ",",
    )
    (tmp_path / "m.toml").write_text(
        '[[channels]]\ncolumn = "x/current_cmd"\nchannel = "x/current_cmd"\nunit = "A"\n\n'
        '[[channels]]\ncolumn = "tcp_x"\nchannel = "cnc/tcp_x"\nunit = "header"\n'
    )
    out = import_files(
        [tmp_path / "fast.csv", tmp_path / "slow.csv"], load_map(tmp_path / "m.toml")
    ).recording
    assert out.sample_rate_hz == 1e4
    s = out.stream("cnc")
    assert np.allclose(s["tcp_x"], st["tcp_x"], rtol=1e-12, atol=1e-15)
    assert np.allclose(s.time_s, st.time_s, rtol=0, atol=1e-9)  # 333 Hz rows kept as rows


# ------------------------------------------------------------------------------ CLI
def test_cli_import_check_plot_json(
    example: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "imp.h5"
    code, _, err = run_cli(
        [
            "import",
            str(example / "trace.csv"),
            "--map",
            str(example / "map.toml"),
            "-o",
            str(out),
            "--plot",
            str(tmp_path / "q.png"),
        ],
        capsys,
    )
    assert code == 0, err
    assert "60 Hz mains hum" in err and "stated rate 10100 Hz" in err
    assert (tmp_path / "q.png").stat().st_size > 10_000
    code, stdout, err = run_cli(["check", str(out), "--json", "-"], capsys)
    assert code == 0, err
    rep = json.loads(stdout)
    kinds = {f["kind"] for f in rep["findings"]}
    assert {"gap", "rate", "repeated", "clipped", "drift", "hum"} <= kinds


def test_cli_export_round_trip(
    example: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(
        [
            "export",
            str(example / "native.h5"),
            "--format",
            "parquet",
            "-o",
            str(tmp_path / "n.parquet"),
        ],
        capsys,
    )
    assert code == 0, err
    code, _, err = run_cli(
        [
            "import",
            str(tmp_path / "n.parquet"),
            "--map",
            str(tmp_path / "n.map.toml"),
            "-o",
            str(tmp_path / "n.h5"),
        ],
        capsys,
    )
    assert code == 0, err
    a, b = read_recording(example / "native.h5"), read_recording(tmp_path / "n.h5")
    assert np.array_equal(a.channel("truth/x/load"), b.channel("truth/x/load"))


# ------------------------------------------------------------------------------ bad files
MAP_I = '[[channels]]\ncolumn = "I"\nchannel = "x/current_cmd"\nunit = "A"\n'


def _bad(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    csv: str,
    mapping: str,
    name: str = "bad.csv",
) -> str:
    (tmp_path / name).write_text(csv)
    (tmp_path / "m.toml").write_text(mapping)
    code, _, err = run_cli(
        [
            "import",
            str(tmp_path / name),
            "--map",
            str(tmp_path / "m.toml"),
            "--rate-hz",
            "1000",
            "-o",
            str(tmp_path / "o.h5"),
        ],
        capsys,
    )
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert not (tmp_path / "o.h5").exists()
    return lines[0]


def test_bad_wrong_delimiter(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = "t;I\n0;1\n0.001;2\n0.002;3\n"
    m = '[[files]]\ndelimiter = ","\n\n' + MAP_I
    msg = _bad(tmp_path, capsys, csv, m)
    assert "bad.csv" in msg and "delimiter ','" in msg and "split on ';'" in msg


def test_bad_missing_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    msg = _bad(tmp_path, capsys, "t,J\n0,1\n0.001,2\n0.002,3\n", MAP_I)
    assert "bad.csv" in msg and "no column 'I'" in msg and "'J'" in msg


def test_bad_text_in_numeric_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = "t,I\n0,1\n0.001,2\n0.002,3\n0.003,oops\n0.004,5\n"
    msg = _bad(tmp_path, capsys, csv, MAP_I)
    assert "bad.csv: line 5, column 2 ('I'): 'oops' is not a number" in msg


def test_bad_channel_named_twice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    msg = _bad(tmp_path, capsys, "t,I\n0,1\n0.001,2\n0.002,3\n", MAP_I + "\n" + MAP_I)
    assert "m.toml" in msg and "'x/current_cmd' is named twice" in msg
    assert "channels[0]" in msg and "channels[1]" in msg


def test_time_unit_from_the_file_when_the_map_names_the_time_column(tmp_path: Path) -> None:
    """A map naming the time column without time_unit read a Servo Trace's ms as seconds (the
    default "s" won over the file's units row): 1 ms steps gave 1 Hz and a 1000 times longer
    record. The file's unit is used when the map gives none; 1 ms steps are 1000 Hz."""
    csv = "Zeit;I\n[ms];[A]\n" + "".join(f"{k};{k % 3}\n" for k in range(50))
    (tmp_path / "t.csv").write_text(csv)
    (tmp_path / "m.toml").write_text('[[files]]\ntime_column = "Zeit"\n' + MAP_I)
    rec = import_files([tmp_path / "t.csv"], load_map(tmp_path / "m.toml")).recording
    assert rec.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    assert rec.duration_s == pytest.approx(0.05, rel=1e-9)


@pytest.mark.parametrize(
    ("header", "files", "message"),
    [
        ("t;I\n[s];[A]\n", 'time_column = "t"\ntime_unit = "A"\n', "time_unit: unit 'A' is not a"),
        ("t;I\n[mm];[A]\n", 'time_column = "t"\n', "time column 't': unit 'mm' is not a"),
    ],
)
def test_bad_time_unit_not_a_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], header: str, files: str, message: str
) -> None:
    """A time column in amperes (the map) or in mm (the file's units row) was read as
    seconds times the unit's factor: refused in one line naming the map key or the column."""
    csv = header + "".join(f"{k};{k % 3}\n" for k in range(50))
    msg = _bad(tmp_path, capsys, csv, "[[files]]\n" + files + MAP_I)
    assert message in msg and "time unit (s, ms, us)" in msg


@pytest.mark.parametrize(
    ("header", "mapping", "message"),
    [
        ("t;I\n", MAP_I.replace('"A"', '"mm"'), "channels[0] ('I'): unit 'mm' is m"),
        ("t;I\n[s];[mm]\n", MAP_I.replace('"A"', '"header"'), "channel 'x/current_cmd': unit"),
        ("t;I\n", MAP_I.replace("x/current_cmd", "spindle/speed"), "unit 'A' is A"),
    ],
)
def test_bad_unit_of_another_quantity_than_the_channel(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], header: str, mapping: str, message: str
) -> None:
    """Decision 1668: a current column mapped in mm (in the map or the file's units row)
    became x/current_cmd in metres, which every estimator reads as amperes (a 1000 A command
    per mm), and a current as spindle/speed in "A": refused in one line naming the map entry
    or the channel, the unit's SI quantity and the one the channel holds."""
    csv = header + "".join(f"{k * 0.001};{k % 3}\n" for k in range(50))
    msg = _bad(tmp_path, capsys, csv, mapping)
    assert message in msg and "holds" in msg


@pytest.mark.parametrize(
    ("variables", "column", "message"),
    [
        ({"v": np.arange(100.0)}, "v", "a.mat: 'v' (100 samples) is not a column"),
        ({"M": np.ones((10, 10))}, "M", "a.mat: 'M' (10×10) is not a column"),
        ({"fs": 0.0}, "I", "a.mat: the file states a sample rate of 0 Hz"),
        ({"fs": -5.0}, "I", "a.mat: the file states a sample rate of -5 Hz"),
    ],
)
def test_bad_mat_variables_named_for_what_they_are(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    variables: dict[str, object],
    column: str,
    message: str,
) -> None:
    """A .mat file beside a 1000-sample column 'I': a 100-sample vector or a 10×10 matrix
    mapped as a channel was reported as "no column 'v' ... (one column only: is the delimiter
    right?)" although the variable is there (and a .mat has no delimiter); fs = 0 or -5 was
    "sample_rate_hz must be finite and > 0, got 0.0" naming no file. Each is now one line
    naming the file and what is wrong, exit 2, nothing written."""
    from scipy.io import savemat

    savemat(str(tmp_path / "a.mat"), {"I": np.sin(np.arange(1000) * 0.01), **variables})
    (tmp_path / "m.toml").write_text(MAP_I.replace('"I"', f'"{column}"'))
    rate = [] if "fs" in variables else ["--rate-hz", "1000"]  # --rate-hz wins over fs
    code, _, err = run_cli(
        ["import", str(tmp_path / "a.mat"), "--map", str(tmp_path / "m.toml"), *rate,
         "-o", str(tmp_path / "r.h5")], capsys)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert message in err and "delimiter" not in err
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize(
    ("extra", "meta", "message"),
    [
        (["--flutes", "0"], "", "--flutes 0: must be a whole number ≥ 1"),
        (["--flutes", "-2"], "", "--flutes -2: must be a whole number ≥ 1"),
        (["--spindle-rpm", "-100"], "", "--spindle-rpm -100: must be finite and > 0"),
        (["--spindle-rpm", "nan"], "", "--spindle-rpm nan: must be finite and > 0"),
        (["--feed-mm-min", "-5"], "", "--feed-mm-min -5: must be finite and > 0"),
        (["--rate-hz", "inf"], "", "--rate-hz inf: must be finite and > 0"),
        ([], "[metadata]\nflutes = 2.5\n", "m.toml: [metadata] flutes = 2.5: must be a whole"),
        ([], "[metadata]\nspindle_rpm = 0\n", "m.toml: [metadata] spindle_rpm = 0: must be"),
    ],
)
def test_bad_process_metadata_refused(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    meta: str,
    message: str,
) -> None:
    """The tool's teeth, spindle speed and feed an import stores are what the monitors divide
    by (tooth frequency = flutes × rev/min / 60): --flutes 0 or -2, --spindle-rpm -100 and
    --feed-mm-min -5 were written as metadata (exit 0), nan was "metadata key 'spindle_rpm':
    nan is not representable in JSON" naming no option, --rate-hz inf named no option. Each
    is one line naming the option or the map key, exit 2, nothing written."""
    (tmp_path / "t.csv").write_text("t,I\n" + "".join(f"{k * 0.001},{k % 3}\n" for k in range(50)))
    (tmp_path / "m.toml").write_text(meta + MAP_I)
    code, _, err = run_cli(
        ["import", str(tmp_path / "t.csv"), "--map", str(tmp_path / "m.toml"), *extra,
         "-o", str(tmp_path / "r.h5")], capsys)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert message in err and not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("files", ['[[files]]\ndelimiter = " "\n', ""])
def test_whitespace_aligned_columns(tmp_path: Path, files: str) -> None:
    """Instrument and MATLAB fprintf exports align columns with runs of spaces: with the
    map's own delimiter = " " every extra space was an empty (NaN) cell, so a row with a
    negative number had a field less ("line 13: 9 fields, the table has 10"), and without a
    delimiter no table was found. Runs of blanks are one separator: 200 rows at 1 kHz, the
    50 Hz sine exact to the 5 printed digits."""
    t = np.arange(200) / 1000.0
    x = np.sin(2 * np.pi * 50 * t)
    text = "time        I\n" + "".join(f"{a:10.4f}  {b:10.5f}\n" for a, b in zip(t, x, strict=True))
    (tmp_path / "aligned.txt").write_text(text)
    (tmp_path / "m.toml").write_text(files + MAP_I)
    rec = import_files([tmp_path / "aligned.txt"], load_map(tmp_path / "m.toml")).recording
    assert rec.n_samples == 200 and rec.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    np.testing.assert_allclose(rec.channel("x/current_cmd"), x, atol=0.5e-5)


def test_export_of_a_channel_named_twice_imports_back(tmp_path: Path) -> None:
    """``export -c x/current_cmd -c x/current_cmd`` wrote the column once but listed it twice in
    the map, which import then refused ("channel 'x/current_cmd' is named twice"): the map
    that comes with an export must import it back. Once each: the 2000 samples exactly."""
    from millsense.core.recording import Recording

    rec = Recording(1e4, metadata={})
    x = np.sin(np.arange(2000) * 0.01)
    rec.add_channel("x/current_cmd", x, "A")
    text = export_recording(rec, tmp_path / "d.csv", "csv", ["x/current_cmd", "x/current_cmd"])
    (tmp_path / "d.map.toml").write_text(text)
    back = import_files([tmp_path / "d.csv"], load_map(tmp_path / "d.map.toml")).recording
    assert back.channel_names == ["x/current_cmd"]
    np.testing.assert_array_equal(back.channel("x/current_cmd"), x)


def test_bad_parquet_text_column_named_for_what_it_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A Parquet column of text mapped as a channel was "no column 'label' ... columns: 'time',
    'I'" although it is in the file: it is named with its type, one line, exit 2."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(100) / 1000.0
    pq.write_table(
        pa.table({"time": t, "I": np.sin(t), "label": ["a"] * 100}), tmp_path / "p.parquet"
    )
    (tmp_path / "m.toml").write_text(MAP_I.replace('"I"', '"label"'))
    code, _, err = run_cli(
        ["import", str(tmp_path / "p.parquet"), "--map", str(tmp_path / "m.toml"), "-o",
         str(tmp_path / "r.h5")], capsys)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "p.parquet: 'label' (string) is not a column for channel 'x/current_cmd'" in err
    assert not (tmp_path / "r.h5").exists()


def test_bad_unknown_unit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    m = MAP_I.replace('unit = "A"', 'unit = "furlong"')
    msg = _bad(tmp_path, capsys, "t,I\n0,1\n0.001,2\n0.002,3\n", m)
    assert "m.toml" in msg and "channels[0]" in msg and "unknown unit 'furlong'" in msg


def test_bad_time_going_backwards_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    msg = _bad(tmp_path, capsys, "time,I\n0,1\n0.001,2\n0.0005,3\n0.002,4\n", MAP_I)
    assert "bad.csv" in msg and "time does not increase at row 3" in msg


def test_time_standing_still_refused_without_a_numpy_warning(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A time column stuck at 0 s (a trace export whose clock did not run) was refused, but
    numpy's "invalid value encountered in scalar divide" (0 steps / 0 s) reached the user
    first: the refusal now returns before any rate is measured (the message names the row)."""
    import warnings

    from millsense.io.quality import QualityReport, rate_from_time

    report = QualityReport()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rate_from_time(np.zeros(5), None, "stuck.csv", report)
    assert [f.message for f in report.refusals] == [
        "stuck.csv: time does not increase at row 2 of the table (0 s then 0 s; 4 such steps)"
    ]
    msg = _bad(tmp_path, capsys, "time,I\n0,1\n0,2\n0,3\n0,4\n", MAP_I)
    assert "bad.csv: time does not increase at row 2" in msg


# ------------------------------------------------------------------------------ workflow
def test_estimate_on_imported_csv_with_dynamometer_reproduces_native(
    example: Path, tmp_path: Path
) -> None:
    """The simulator recording exported to CSV with its X load as a dynamometer column
    (``dynamometer/x/force``), imported and estimated: the same figures as the native
    recording compared with its truth (within 1 %; they are the same numbers here because
    the CSV is exact and the force-found cut window equals the engagement window)."""
    from millsense.cli.cmd_estimate import run_estimate

    native = read_recording(example / "native.h5")
    chans = [*native.measured_channel_names(), "truth/x/load"]
    text = export_recording(native, tmp_path / "run.csv", "csv", chans)
    text = text.replace('channel = "truth/x/load"', 'channel = "dynamometer/x/force"')
    (tmp_path / "run.map.toml").write_text(text)
    imp = import_files([tmp_path / "run.csv"], load_map(tmp_path / "run.map.toml")).recording
    assert not imp.truth_channel_names()
    from millsense.io import write_recording

    write_recording(tmp_path / "imp.h5", imp)
    kw = dict(machine=COMMISSIONED, method="feed", axes="x")
    a = run_estimate(recording=example / "native.h5", out=tmp_path / "ea.h5", **kw)
    b = run_estimate(recording=tmp_path / "imp.h5", out=tmp_path / "eb.h5", **kw)
    assert b["references"] == {"x": "dynamometer/x/force"}
    (ca,), (cb,) = a["comparisons"], b["comparisons"]
    assert cb.mean_est == pytest.approx(ca.mean_est, rel=0.01)
    assert cb.mean_true == pytest.approx(ca.mean_true, rel=0.01)
    big = ca.true_amp >= 0.01 * ca.true_amp.max()
    assert np.allclose(cb.est_amp[big], ca.est_amp[big], rtol=0.01)
    assert np.allclose(cb.true_amp[big], ca.true_amp[big], rtol=0.01)
    # the monitors run on the imported recording (no truth) as on the native one
    from millsense.cli.cmd_monitor import run_monitor

    ev = [run_monitor(recording=r, out=tmp_path / f"{r.stem}.events.parquet",
                      methods="chatter-comb,chatter-sdft", machine=COMMISSIONED)["events"]
          for r in (example / "native.h5", tmp_path / "imp.h5")]  # fmt: skip
    assert [(e.name, e.sample) for e in ev[1]] == [(e.name, e.sample) for e in ev[0]]


def test_identify_friction_on_imported_air_moves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Air moves of the Z drive (simulator file's model) exported as a Servo-Trace-like CSV
    and imported through a map: ``identify friction`` gives the same Coulomb and viscous
    friction as on the native recording (the CSV is exact: within 1e-9)."""
    import tomllib

    from millsense.io import write_recording
    from millsense.simulator import commissioning as cm
    from millsense.simulator.machine_file import simulator_machine, simulator_machine_path

    cfg = simulator_machine("quaser-ux600")
    sp = np.geomspace(0.3, 30.0, 5)
    moves = cm.friction_test(cfg, "z", np.ravel(np.column_stack([sp, -sp])), hold_s=0.4, ideal=True)
    write_recording(tmp_path / "native.h5", moves)
    (tmp_path / "air.map.toml").write_text(export_recording(moves, tmp_path / "air.csv", "csv"))
    code, _, err = run_cli(
        [
            "import",
            str(tmp_path / "air.csv"),
            "--map",
            str(tmp_path / "air.map.toml"),
            "-o",
            str(tmp_path / "imp.h5"),
        ],
        capsys,
    )
    assert code == 0, err
    sim = str(simulator_machine_path("quaser-ux600"))
    got = []
    for rec in ("native.h5", "imp.h5"):
        out = tmp_path / f"fr_{rec}.toml"
        code, _, err = run_cli(
            [
                "identify",
                "friction",
                str(tmp_path / rec),
                "--axis",
                "z",
                "--machine",
                sim,
                "-o",
                str(out),
            ],
            capsys,
        )
        assert code == 0, err
        got.append(tomllib.loads(out.read_text())["axes"]["z"]["friction"])
    assert np.allclose(got[1]["coulomb_nm"], got[0]["coulomb_nm"], rtol=1e-9)
    assert np.allclose(got[1]["viscous_nm_s_rad"], got[0]["viscous_nm_s_rad"], rtol=1e-9)


def test_identify_drive_on_an_imported_sweep(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The drive model (ball screw, inertia, dead time; Yamada Table 3-3) identified from a
    drive sweep exported as CSV and imported through its map (with the test's description in
    the map's [metadata]) equals the native recording's (the CSV keeps every digit: 1e-9)."""
    import tomllib

    from millsense.io import write_recording
    from millsense.simulator import commissioning as cm
    from millsense.simulator.machine_file import simulator_machine, simulator_machine_path

    sweep = cm.drive_sweep(simulator_machine("yamada-b"), "x")
    write_recording(tmp_path / "native.h5", sweep)
    # what the test was, as the user states it in the map (a trace export does not carry it)
    stated = "\n[metadata]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in
                                           sweep.metadata.items() if k != "source")  # fmt: skip
    (tmp_path / "s.map.toml").write_text(export_recording(sweep, tmp_path / "s.csv", "csv")
                                         + stated)  # fmt: skip
    code, _, err = run_cli(["import", str(tmp_path / "s.csv"), "--map",
                            str(tmp_path / "s.map.toml"), "-o", str(tmp_path / "imp.h5")],
                           capsys)  # fmt: skip
    assert code == 0, err
    sim = str(simulator_machine_path("yamada-b"))
    frags = []
    for rec in ("native.h5", "imp.h5"):
        out = tmp_path / f"d_{rec}.toml"
        code, _, err = run_cli(["identify", "drive", str(tmp_path / rec), "--machine", sim,
                                "-o", str(out)], capsys)  # fmt: skip
        assert code == 0, err
        frags.append(tomllib.loads(out.read_text())["axes"]["x"])
    for key in ("inertia_kg_m2", "dead_time_motor_encoder_ms"):
        assert frags[1][key] == pytest.approx(frags[0][key], rel=1e-9), key
    for key in ("axial_stiffness_n_um", "table_mass_kg"):
        assert frags[1]["ball_screw"][key] == pytest.approx(frags[0]["ball_screw"][key],
                                                           rel=1e-9), key  # fmt: skip


def test_tncscope_like_export_units_in_names_and_sample_time(tmp_path: Path) -> None:
    """Tab-separated, decimal comma, units in the column names, the rate stated as a sample
    time in ms: 3 ms → 333.33 Hz; position in µm → m, speed in mm/min → m/s."""
    rows = "\n".join(
        f"{k * 3};{k * 1.5:.1f};{600 + k}".replace(".", ",").replace(";", "\t") for k in range(6)
    )
    text = (
        "TNCscope export\nAbtastzeit: 3 ms\nDatum: 27.11.2026\n"
        "t [ms]\tX-Ist [um]\tVorschub [mm/min]\n" + rows + "\n"
    )
    (tmp_path / "scope.txt").write_text(text, encoding="cp1252")
    from millsense.io.importers.delimited import read_delimited

    t = read_delimited(tmp_path / "scope.txt", decimal=",")
    assert t.stated_rate_hz == pytest.approx(1000 / 3, rel=1e-12)
    assert t.units == {"t": "ms", "X-Ist": "um", "Vorschub": "mm/min"}
    assert t.first_line == 5
    (tmp_path / "m.toml").write_text(
        '[[files]]\ndecimal = ","\n\n'
        '[[channels]]\ncolumn = "X-Ist"\nchannel = "x/position"\nunit = "header"\n\n'
        '[[channels]]\ncolumn = "Vorschub"\nchannel = "cnc/feed"\nunit = "header"\n'
    )
    res = import_files([tmp_path / "scope.txt"], load_map(tmp_path / "m.toml"))
    rec = res.recording
    assert rec.sample_rate_hz == pytest.approx(1000 / 3, rel=1e-9)  # from the time column
    assert rec.channel("x/position")[2] == pytest.approx(3.0e-6, rel=1e-12)
    assert rec.channel("cnc/feed")[0] == pytest.approx(0.01, rel=1e-12)  # 600 mm/min


def test_temperatures_in_celsius_and_fahrenheit_become_kelvin(tmp_path: Path) -> None:
    """A trace's motor temperatures in °C (unit row) and °F (map): kelvin inside, by the
    affine conversions (0 °C = 273.15 K; 212 °F = 373.15 K, the boiling point both ways), and
    exported as K they import back unchanged; a temperature channel given in amperes is
    refused, naming the channel."""
    rows = "\n".join(f"{k * 0.001:.3f};{20.0 + k};{32.0 + 180.0 * k}" for k in range(3))
    (tmp_path / "t.csv").write_text("t;T_x [°C];T_s\n" + rows + "\n", encoding="utf-8")
    (tmp_path / "m.toml").write_text(
        '[[channels]]\ncolumn = "T_x"\nchannel = "x/temperature"\nunit = "header"\n\n'
        '[[channels]]\ncolumn = "T_s"\nchannel = "spindle/temperature"\nunit = "°F"\n',
        encoding="utf-8",
    )
    rec = import_files([tmp_path / "t.csv"], load_map(tmp_path / "m.toml")).recording
    assert rec.info("x/temperature").unit == "K"
    np.testing.assert_allclose(rec.channel("x/temperature"), [293.15, 294.15, 295.15], rtol=1e-15)
    np.testing.assert_allclose(rec.channel("spindle/temperature"), [273.15, 373.15, 473.15],
                               rtol=1e-14)  # fmt: skip
    chans = ["x/temperature", "spindle/temperature"]
    (tmp_path / "back.toml").write_text(export_recording(rec, tmp_path / "back.csv", "csv", chans))
    back = import_files([tmp_path / "back.csv"], load_map(tmp_path / "back.toml")).recording
    np.testing.assert_array_equal(back.channel("spindle/temperature"),
                                  rec.channel("spindle/temperature"))  # fmt: skip
    (tmp_path / "bad.toml").write_text(
        '[[channels]]\ncolumn = "T_s"\nchannel = "spindle/temperature"\nunit = "A"\n'
    )
    with pytest.raises(Exception, match=r"spindle/temperature.*K"):
        load_map(tmp_path / "bad.toml")


@pytest.mark.parametrize(
    ("fmt", "rate_hz", "message"),
    [
        ("mp3", 10_000.0, "MP3 holds only the MPEG rates"),
        ("flac", 1_000_000.0, "libsndfile cannot write"),
    ],
)
def test_export_audio_at_a_rate_the_format_lacks_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, rate_hz: float, message: str
) -> None:
    """MP3 has the nine MPEG rates (8-48 kHz) and FLAC at most 655 350 Hz: a 10 kHz drive
    recording to MP3 (and a 1 MHz one to FLAC) was libsndfile's traceback (exit 1), and the
    channel-count error named the temporary file. Now exit 2, one line naming the output,
    nothing left behind (no output, no map, no temporary file)."""
    from millsense.core.recording import Recording
    from millsense.io import write_recording

    sf = pytest.importorskip("soundfile")
    if fmt.upper() not in sf.available_formats():
        pytest.skip(f"this libsndfile has no {fmt}")
    rec = Recording(rate_hz, 0.0, {})
    rec.add_channel("x/current", np.sin(np.arange(2000) * 0.1), "A")
    write_recording(tmp_path / "r.h5", rec)
    out = tmp_path / f"r.{fmt}"
    code, _, err = run_cli(
        ["export", str(tmp_path / "r.h5"), "--format", fmt, "-o", str(out)], capsys
    )
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and message in err
    assert f"{out}:" in err and ".tmp" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]


@pytest.mark.parametrize("fmt", ["mat", "mat73"])
def test_mat_export_of_channels_named_like_the_rate_and_units(tmp_path: Path, fmt: str) -> None:
    """Channels named ``fs`` and ``units`` (a spectrum rig's names) were written as the file's
    rate and units variables, which they then overwrote (found by exploratory QA): they take
    ``_channel``, and the file imports back with its rate and both channels exact."""
    from millsense.core.recording import Recording

    rec = Recording(2500.0)
    rec.add_channel("fs", np.linspace(0.0, 1.0, 500), "V")
    rec.add_channel("units", np.cos(np.arange(500) * 0.1), "Pa")
    out = tmp_path / "r.mat"
    (tmp_path / "map.toml").write_text(export_recording(rec, out, fmt, ["fs", "units"]))
    back = import_files([out], load_map(tmp_path / "map.toml")).recording
    assert back.sample_rate_hz == pytest.approx(2500.0, rel=1e-12)
    for c in ("fs", "units"):
        assert np.array_equal(back.channel(c), rec.channel(c)), c
        assert back.info(c).unit == rec.info(c).unit
