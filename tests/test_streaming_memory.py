"""Streaming with constant memory (issue 21 item 5, decision 0961).

``estimate`` replays a recording from windows of the file and computes its estimate-vs-truth
table and plot from chunks; the results must equal the whole-record computations and the peak
resident memory must not grow with the recording's length.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter, read_recording
from millsense.io.recording_reader import RecordingReader, open_recording
from millsense.report.estimate_metrics import compare, harmonic_fit
from millsense.report.estimate_stream import (
    Envelope,
    StreamedComparison,
    StreamedEstimate,
    scan_cut_window,
    window_mean,
)
from millsense.simulator.machine_file import simulator_machine, simulator_machine_path
from millsense.streaming.engine import Pipeline, run
from millsense.streaming.sources import RecordingSource

FS = 10_000.0
RPM = 6000.0
OMEGA = RPM * 2 * np.pi / 60  # rad/s
TOOTH_HZ = 2 * RPM / 60  # 2 flutes: 200 Hz
#: Channels not read by `estimate --method raw --axes x`: a whole-record read loads them.
FILLERS = 16


def _chunks(n: int, seed: int) -> list[int]:
    """Uneven chunk boundaries covering ``n`` samples (1, 7, 997-sample chunks mixed)."""
    rng = np.random.default_rng(seed)
    cuts, k = [0], 0
    while k < n:
        k = min(n, k + int(rng.choice([1, 7, 997, 4096])))
        cuts.append(k)
    return cuts


def _signals(n: int, seed: int = 1) -> dict[str, np.ndarray]:
    k = np.arange(n)
    t = k / FS
    rng = np.random.default_rng(seed)
    truth = (
        100.0 + 40.0 * np.cos(2 * np.pi * TOOTH_HZ * t) + 15.0 * np.sin(4 * np.pi * TOOTH_HZ * t)
    )
    est = np.roll(truth, 12) * 1.03 + rng.normal(0.0, 2.0, n)  # lags by 12 samples, 3 % high
    eng = np.where((k > n // 10) & (k < n - n // 20), 0.5, -1.0)
    speed = OMEGA * (1.0 + 1e-4 * np.sin(2 * np.pi * 0.5 * t))
    return {"truth": truth, "est": est, "eng": eng, "speed": speed}


def test_streamed_comparison_equals_the_whole_record_fit() -> None:
    # compare() fits lstsq to the whole arrays; the streamed normal equations over uneven
    # chunks (1 to 4096 samples) must give the same means and amplitudes to 1e-9 relative
    n = 60_000
    s = _signals(n)
    delay = 12
    whole = compare(
        "raw",
        "x",
        s["est"],
        s["truth"],
        s["speed"],
        FS,
        2,
        delay_samples=delay,
        engagement=s["eng"],
    )

    def rd(name: str):
        return lambda a, b: s[name][a:b]

    window = scan_cut_window(rd("eng"), n, block=777)
    sc = StreamedComparison(
        [StreamedEstimate("raw", "x", "est", delay, "truth")],
        FS,
        n,
        window,
        lambda i0, i1: window_mean(rd("speed"), i0, i1, block=555),
        2,
    )
    cuts = _chunks(n, 3)
    for a, b in itertools.pairwise(cuts):
        sc.add(a, {"est": s["est"][a:b], "truth": s["truth"][a:b]})
    (got,) = sc.results()
    assert got.window == whole.window
    assert got.tooth_hz == pytest.approx(whole.tooth_hz, rel=1e-12)
    assert got.mean_est == pytest.approx(whole.mean_est, rel=1e-9)
    assert got.mean_true == pytest.approx(whole.mean_true, rel=1e-9)
    np.testing.assert_allclose(got.true_amp, whole.true_amp, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.est_amp, whole.est_amp, rtol=1e-9, atol=1e-9)
    # and the truth's amplitudes are the synthesised 40 N and 15 N at 1× and 2× (closed form)
    assert got.true_amp[:2] == pytest.approx([40.0, 15.0], rel=1e-3)
    _, direct = harmonic_fit(s["truth"][whole.window[0] : whole.window[1]], FS, got.tooth_hz, 6)
    np.testing.assert_allclose(got.true_amp, np.abs(direct), rtol=1e-9, atol=1e-9)


def test_cut_window_scan_matches_whole_array_rule() -> None:
    # longest run of engagement >= 0 (first of equal length), trimmed by 20 %, across blocks
    eng = -np.ones(10_000)
    eng[100:1100] = 0.2  # 1000 samples
    eng[3000:5000] = 0.0  # 2000 samples: the longest
    eng[7000:9000] = 1.0  # 2000 samples: equal, later
    for block in (1, 13, 999, 65536):
        assert scan_cut_window(lambda a, b: eng[a:b], len(eng), block=block) == (3400, 4600)


def test_envelope_is_chunk_invariant_and_keeps_every_peak() -> None:
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 1.0, 123_457)
    x[[17, 50_001, 123_456]] = [40.0, -55.0, 33.0]  # isolated peaks
    whole = Envelope(len(x), bins=1000)
    whole.add(0, x)
    parts = Envelope(len(x), bins=1000)
    cuts = _chunks(len(x), 9)
    for a, b in itertools.pairwise(cuts):
        parts.add(a, x[a:b])
    np.testing.assert_array_equal(parts.lo, whole.lo)
    np.testing.assert_array_equal(parts.hi, whole.hi)
    assert np.nanmax(whole.hi) == 40.0 and np.nanmin(whole.lo) == -55.0
    w = whole.width
    assert whole.hi[123_456 // w] == 33.0
    for b in range(len(whole.lo)):  # each bin spans exactly its samples' range
        seg = x[b * w : (b + 1) * w]
        assert whole.lo[b] == seg.min() and whole.hi[b] == seg.max()


def _write_run(path: Path, seconds: float, fillers: int = FILLERS) -> None:
    """A drive-like recording for `estimate --method raw --axes x` with truth and fillers."""
    n = int(seconds * FS)
    step = int(FS)
    infos = [
        ChannelInfo("x/current_cmd", "A"),
        ChannelInfo("x/motor_speed", "rad/s"),
        ChannelInfo("spindle/speed", "rad/s"),
        ChannelInfo("truth/x/load", "N"),
        ChannelInfo("truth/process/engagement", "1"),
    ] + [ChannelInfo(f"fill/c{i}", "1") for i in range(fillers)]
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 1, (fillers, step))  # the same second of noise in every second
    with RecordingWriter(path, FS, infos, {"flutes": 2}, flush_every_s=1.0) as w:
        for a in range(0, n, step):
            k = np.arange(a, min(n, a + step))
            t = k / FS
            load = 100.0 + 40.0 * np.cos(2 * np.pi * TOOTH_HZ * t)
            data = {
                "x/current_cmd": 0.5 + 0.004 * load + rng.normal(0, 0.01, len(k)),
                "x/motor_speed": 20.0 + 0.1 * np.sin(2 * np.pi * 3 * t),
                "spindle/speed": np.full(len(k), OMEGA),
                "truth/x/load": load,
                "truth/process/engagement": np.where(k > n // 10, 0.5, -1.0),
            }
            data.update({f"fill/c{i}": noise[i, : len(k)] for i in range(fillers)})
            w.append(data)


def test_windowed_replay_equals_the_in_memory_replay(tmp_path: Path) -> None:
    # the raw estimator run from file windows in 333-sample chunks (read-ahead 16384) and from
    # the recording in memory in one chunk: the same samples in, so the same numbers out
    from millsense.estimation.from_config import raw_estimator

    path = tmp_path / "run.h5"
    _write_run(path, 3.0, fillers=1)
    machine = simulator_machine("quaser-ux600")
    rec = read_recording(path)
    whole = run(RecordingSource(rec), Pipeline([raw_estimator("x", machine, 600.0)]), 10**9)
    with open_recording(path) as reader:
        assert isinstance(reader, RecordingReader)
        src = RecordingSource(reader, channels=["x/current_cmd", "x/motor_speed"])
        assert src.channel_names == ["x/current_cmd", "x/motor_speed"]
        got = run(src, Pipeline([raw_estimator("x", machine, 600.0)]), 333)
    ch = "est/raw/x/load"
    assert len(got.channels[ch]) == rec.n_samples == 30_000
    np.testing.assert_allclose(got.channels[ch], whole.channels[ch], rtol=0, atol=1e-9)
    assert np.ptp(whole.channels[ch]) > 1.0  # a signal, not zeros


def test_reader_window_and_errors(tmp_path: Path) -> None:
    from millsense.core.errors import RecordingError

    path = tmp_path / "run.h5"
    _write_run(path, 1.0, fillers=1)
    rec = read_recording(path)
    with RecordingReader(path) as r:
        assert r.n_samples == rec.n_samples and r.sample_rate_hz == FS
        np.testing.assert_array_equal(
            r.window("truth/x/load", 9990, 20_000), rec.channel("truth/x/load")[9990:]
        )
        with pytest.raises(RecordingError, match="unknown channel 'nope'"):
            r.window("nope", 0, 1)
    with pytest.raises(RecordingError, match="no such recording"):
        RecordingReader(tmp_path / "missing.h5")


def _peak_rss_mb(args: list[str]) -> float:
    """Peak resident memory (MB) of ``millsense ARGS`` run in a fresh process."""
    code = (
        "import resource, sys; from millsense.cli.main import main\n"
        "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "print('RSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, check=True
    ).stdout
    line = [x for x in out.splitlines() if x.startswith("RSS ")][-1]
    return int(line.split()[1]) / 1024.0  # ru_maxrss is in KiB on Linux


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in KiB on Linux")
def test_estimate_peak_memory_does_not_grow_with_the_recording(tmp_path: Path) -> None:
    # 20 s and 80 s of 21 channels at 10 kHz (the 80 s file holds 134 MB of samples): a
    # whole-record estimate grows by more than that (read, outputs, comparison copies), the
    # streamed one must stay within 20 % + 20 MB
    peaks = {}
    for seconds in (20, 80):
        rec = tmp_path / f"run{seconds}.h5"
        _write_run(rec, seconds)
        summary = tmp_path / f"s{seconds}.json"
        peaks[seconds] = _peak_rss_mb(
            [
                "estimate",
                str(rec),
                "--machine",
                str(simulator_machine_path("quaser-ux600")),
                "--method",
                "raw",
                "--axes",
                "x",
                "-o",
                str(tmp_path / f"e{seconds}.h5"),
                "--plot",
                str(tmp_path / f"e{seconds}.png"),
                "--json",
                str(summary),
                "--chunk",
                "5000",
            ]
        )
        comp = json.loads(summary.read_text())["comparisons"][0]
        assert comp["amplitude_truth"][0] == pytest.approx(40.0, rel=1e-6)  # closed form
        est = read_recording(tmp_path / f"e{seconds}.h5")
        assert est.n_samples == seconds * FS
    assert peaks[80] <= 1.2 * peaks[20] + 20.0, peaks


def test_air_window_scan_is_block_invariant_and_closed_form(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # feed 0 until sample 1000, then 1200 mm/min (0.02 m/s); the stock at 20.001 mm of path:
    # the path reaches it at sample 11000 and the guard (0.5 mm before) at 10750; the steady
    # run starts at 1000, plus 0.05 s of settling: slice(1500, 10750), whatever the blocks
    from millsense.core.recording import Recording
    from millsense.estimation.feed import idle_compensation as ic

    n = 20_000
    rec = Recording(FS, 0.0, {ic.FIRST_ENGAGEMENT_KEY: 0.020001})
    rec.add_channel("cnc/feed", np.where(np.arange(n) >= 1000, 0.02, 0.0), "m/s")
    rec.add_channel("spindle/speed_cmd", np.full(n, OMEGA), "rad/s")
    rec.add_channel("spindle/speed", np.full(n, OMEGA), "rad/s")
    for block in (65536, 7, 1000):
        monkeypatch.setattr(ic, "SCAN_BLOCK", block)
        assert ic.find_air_window(rec, "run.h5") == slice(1500, 10750)
