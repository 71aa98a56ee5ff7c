"""Crash safety: a writer killed with SIGKILL loses nothing it reported as flushed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from millsense.io import read_recording, recording_status

FS = 2000.0

CHILD = r"""
import sys, time
import numpy as np
from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter

path, progress = sys.argv[1], sys.argv[2]

def signal_at(k):
    # Only correctly rounded IEEE + and * : identical in any process and any chunking.
    return k * 0.001 + ((k * 7919) % 1013) * 0.01 - 5.0

w = RecordingWriter(
    path, 2000.0,
    [ChannelInfo("x/current_cmd", "A", "command"), ChannelInfo("truth/x/force", "N")],
    metadata={"machine": "crash-test"},
    streams={"nc": [ChannelInfo("line", "1")]},
    flush_every_s=0.05,
)
k = 0
last = 0
while True:
    idx = np.arange(k, k + 37)
    w.append({"x/current_cmd": signal_at(idx), "truth/x/force": idx.astype(float)})
    w.append_stream("nc", [k / 2000.0], {"line": [k // 100]})
    k += 37
    if w.samples_written != last:
        last = w.samples_written
        with open(progress, "a") as fh:
            fh.write(f"{last}\n")
    time.sleep(0.003)
"""


def _signal_at(k: np.ndarray) -> np.ndarray:
    return k * 0.001 + ((k * 7919) % 1013) * 0.01 - 5.0


def _progress(path: Path) -> list[int]:
    if not path.exists():
        return []
    return [int(x) for x in path.read_text().split()]


def _wait_flushes(progress: Path, proc: subprocess.Popen[bytes], count: int) -> list[int]:
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        done = _progress(progress)
        if len(done) >= count:
            return done
        if proc.poll() is not None:
            raise AssertionError(
                f"writer exited early: {proc.stderr.read() if proc.stderr else ''}"
            )
        time.sleep(0.02)
    raise AssertionError("writer made no progress in 30 s")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX SIGKILL")
def test_sigkill_mid_recording_recovers_every_flushed_sample(tmp_path: Path) -> None:
    path = tmp_path / "crash.h5"
    progress = tmp_path / "progress.txt"
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(path), str(progress)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        # A reader while the writer is still running gets every sample reported flushed.
        seen = _wait_flushes(progress, proc, 4)
        live = read_recording(path)
        assert live.n_samples >= seen[-1]
        np.testing.assert_array_equal(
            live["x/current_cmd"], _signal_at(np.arange(live.n_samples, dtype=float))
        )
        # Kill it without warning after several more flushes.
        _wait_flushes(progress, proc, 10)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.stderr:
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    reported = _progress(progress)[-1]

    assert not path.exists()  # the final file is only made by close()
    rec = read_recording(path)
    assert rec.n_samples >= reported  # nothing reported flushed is lost
    k = np.arange(rec.n_samples, dtype=float)
    np.testing.assert_array_equal(rec["x/current_cmd"], _signal_at(k))  # bit-exact
    np.testing.assert_array_equal(rec["truth/x/force"], k)
    assert rec.info("x/current_cmd").unit == "A"
    assert rec.metadata["recovered"] is True and rec.metadata["machine"] == "crash-test"
    nc = rec.stream("nc")
    assert len(nc) > 0 and np.all(np.diff(nc.time_s) > 0)
    assert nc.time_s[-1] < rec.n_samples / FS  # stream rows flushed with their samples

    status = recording_status(path)
    assert not status.complete
    assert status.n_samples == rec.n_samples
    assert status.ends_at_s == pytest.approx(rec.n_samples / FS, abs=1e-12)  # t0 = 0
    assert status.message.startswith("incomplete: writer did not close; recovered")
    assert f"({rec.n_samples} samples)" in status.message
    assert f"data ends at t = {rec.n_samples / FS:.6g} s" in status.message
    assert status.message == rec.metadata["recovery_note"]
    assert "\n" not in status.message
    assert os.path.isdir(str(path) + ".partial")
