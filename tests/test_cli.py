"""CLI: user errors print one line and exit 2; info and plot work on a recording."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording


def small_recording(path: Path, **metadata: object) -> Path:
    rec = Recording(10000.0, metadata={"machine": "test", "source": str(path), **metadata})
    t = np.arange(2000) / 10000.0
    rec.add_channel("x/current_cmd", np.sin(2 * np.pi * 50 * t), "A", "current command")
    rec.add_channel("truth/x/force", -100 + 10 * np.sin(2 * np.pi * 100 * t), "N", "truth")
    rec.add_stream("tcp", t[::30], {"x": t[::30] * 0.02}, {"x": "m"})
    write_recording(path, rec)
    return path


def test_info_lists_channels_and_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = small_recording(tmp_path / "r.h5")
    code, out, _ = run_cli(["info", str(p)], capsys)
    assert code == 0
    assert "2000 samples at 10000 Hz" in out
    assert "x/current_cmd" in out and "truth/x/force" in out and "tcp" in out


def test_info_summarises_the_import_report_and_long_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An import's quality report (300 findings) is shown as its count per kind, another long
    value cut to 200 characters; the file keeps both whole."""
    import json

    from millsense.cli.cmd_recording import MAX_METADATA_CHARS, _metadata_text
    from millsense.io.recording_file import read_recording

    findings = [{"kind": "repeated", "message": f"run {i}"} for i in range(298)]
    findings += [{"kind": "hum", "message": "hum"}, {"kind": "gap", "message": "gap"}]
    quality = json.dumps({"findings": findings, "rates": {}})
    p = small_recording(tmp_path / "r.h5", quality_json=quality, notes="n" * 1000)
    code, out, _ = run_cli(["info", str(p)], capsys)
    assert code == 0
    flat = re.sub(r"[│\s]+", " ", out)  # the table wraps long cells over several lines
    assert "300 findings (gap 1, hum 1, repeated 298)" in flat
    assert "run 17" not in flat and "(1000 characters)" in flat
    cut = _metadata_text("notes", "n" * 1000, p)
    assert cut == "n" * (MAX_METADATA_CHARS - 40) + " … (1000 characters)"
    assert read_recording(p).metadata["quality_json"] == quality


def test_plot_writes_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = small_recording(tmp_path / "r.h5")
    png = tmp_path / "p.png"
    code, _, _ = run_cli(
        ["plot", str(p), "-c", "x/current_cmd", "-c", "truth/x/force", "-o", str(png)], capsys
    )
    assert code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["info", "{tmp}/missing.h5"], "missing.h5"),
        (["plot", "{rec}", "-c", "nope", "-o", "{tmp}/p.png"], "unknown channel 'nope'"),
        (["plot", "{rec}", "-c", "x/current_cmd", "-o", "{tmp}/p.pdf"], "give a .png"),
        (["validate", "--case", "no.such.case"], "no validation case matches"),
        (["info"], "Missing argument"),
        # numpy's seeds are ≥ 0: -1 was its "expected non-negative integer" traceback (exit 1)
        (
            ["simulate", "--seed", "-1", "-o", "{tmp}/s.h5"],
            "'--seed': Input should be greater than or equal to 0",
        ),
        (
            ["simulate-fleet", "--seed", "-1", "-o", "{tmp}/f"],
            "'--seed': Input should be greater than or equal to 0",
        ),
        (
            ["run", "--program", "{tmp}/x.nc", "--seed", "-1", "-o", "{tmp}/o.h5"],
            "'--seed': Input should be greater than or equal to 0",
        ),
        (
            ["serve-machine", "--seed", "-1"],
            "'--seed': Input should be greater than or equal to 0",
        ),
        (["demo", "--seed", "-1"], "'--seed': Input should be greater than or equal to 0"),
        (["frobnicate"], "No such command"),
    ],
)
def test_user_errors_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], expected: str
) -> None:
    rec = small_recording(tmp_path / "r.h5")
    args = [a.format(tmp=tmp_path, rec=rec) for a in args]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("millsense: error:")
    assert expected in lines[0]
    assert "Traceback" not in err


def test_truncated_file_is_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = small_recording(tmp_path / "r.h5")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    code, _, err = run_cli(["info", str(p)], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "r.h5" in err


@pytest.mark.parametrize(
    ("window", "held"),
    [(("5", "6"), "0 samples"), (("-3", "-1"), "0 samples"), (("0.01", "0.01005"), "1 sample")],
)
def test_plot_window_without_two_samples_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], window: tuple[str, str], held: str
) -> None:
    """A window outside the 0.2 s recording (5-6 s, before its start) or holding one sample
    at 10 kHz (50 µs) drew empty axes and said "wrote p.png" (exit 0): now one line giving
    the samples held and the recording's span, exit 2, no file."""
    rec = small_recording(tmp_path / "r.h5")
    png = tmp_path / "p.png"
    args = ["plot", str(rec), "-c", "x/current_cmd", "-o", str(png)]
    code, _, err = run_cli([*args, "--from-s", window[0], "--to-s", window[1]], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert held in err and "t = 0 to 0.2 s" in err
    assert not png.exists()


def test_plot_draws_stream_fields_beside_channels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording's slower streams (an imported 333 Hz file, the tcp stream here) were not
    drawable: `-c tcp/x` was "unknown channel". STREAM/FIELD and a whole STREAM are drawn; in
    the window 0.05-0.1 s the tcp rows are those of t ≥ 0.05 s and < 0.1 s (every 30th sample
    of 10 kHz: 17 rows), with their values (x = 0.02 t m, exact)."""
    from millsense.io.recording_file import read_recording
    from millsense.report.plots import recording_series

    p = small_recording(tmp_path / "r.h5")
    png = tmp_path / "p.png"
    args = ["plot", str(p), "-c", "x/current_cmd", "-c", "tcp/x", "-o", str(png)]
    code, _, err = run_cli([*args, "--from-s", "0.05", "--to-s", "0.1"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rec = read_recording(p)
    cur, tcp = recording_series(rec, ["x/current_cmd", "tcp/x"], (0.05, 0.1))
    assert cur.time_s.size == 500 and cur.unit == "A"
    assert tcp.unit == "m" and tcp.stream == "tcp" and tcp.time_s.size == 17
    assert tcp.time_s[0] == pytest.approx(0.051, abs=1e-12)  # first multiple of 3 ms ≥ 50 ms
    np.testing.assert_allclose(tcp.values, 0.02 * tcp.time_s, rtol=0, atol=1e-15)
    (whole,) = recording_series(rec, ["tcp"])
    assert whole.label == "tcp/x" and whole.time_s.size == 67  # ceil(2000 / 30)


def test_plot_unknown_name_lists_channels_and_stream_fields(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An unknown name (or field of a stream) is one line listing both kinds of names; a
    window holding one row of a stream is refused as for the channels, naming the stream."""
    p = small_recording(tmp_path / "r.h5")
    png = tmp_path / "p.png"
    code, _, err = run_cli(["plot", str(p), "-c", "tcp/y", "-o", str(png)], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "unknown channel 'tcp/y'" in err and "stream fields: tcp/x" in err
    args = ["plot", str(p), "-c", "tcp/x", "-o", str(png), "--from-s", "0.05", "--to-s", "0.053"]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "holds 1 row of stream 'tcp'" in err and "t = 0 to 0.198 s" in err
    assert not png.exists()


def test_info_shows_units_in_brackets_that_look_like_styles(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`info` printed an imported stream's fields as "a_position , c_position": rich took
    "[rad]" for a style and dropped it (also "[m]", "[bold]" in a description or a file
    name). The recording's text is escaped: the unit and the 100-row count are shown."""
    rec = Recording(1000.0, metadata={"source": "[bold] run"})
    t = np.arange(200) / 1000.0
    rec.add_channel("x/position_cmd", t, "m", "X [mm] of trace.csv")
    rec.add_stream("axes", t[::2], {"a_position": t[::2]}, {"a_position": "rad"})
    write_recording(tmp_path / "r.h5", rec)
    code, out, _ = run_cli(["info", str(tmp_path / "r.h5")], capsys)
    assert code == 0
    assert "stream axes: 100 rows, ~500 Hz: a_position [rad]" in out
    assert "X [mm] of trace.csv" in out and "[bold] run" in out
