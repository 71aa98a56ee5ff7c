"""``millsense recover`` and ``info`` turn a killed recording into a plain HDF5 file (decision
0922): readable by h5py and pandas without millsense, with a note of what was lost."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter
from millsense.io.recording_file import partial_dir

FS = 1000.0
FLUSH_S = 0.02

WRITER = r"""
import sys, time
import numpy as np
from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter

w = RecordingWriter(
    sys.argv[1], 1000.0, [ChannelInfo("x/current_cmd", "A", "command")],
    metadata={"machine": "kill-test"}, flush_every_s=0.02,
)
k = 0
while True:
    w.append({"x/current_cmd": np.arange(k, k + 10, dtype=float)})
    k += 10
    time.sleep(0.002)
"""

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX SIGKILL")


def _killed_recording(path: Path, tmp: Path) -> None:
    """A recording whose writer got SIGKILL after several flushes."""
    script = tmp / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60.0
        while len(list(partial_dir(path).glob("seg-*.bin"))) < 5:
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stderr:
            proc.stderr.close()


def _check_plain(path: Path) -> int:
    """Open ``path`` with h5py and pandas only; the data are the writer's ramp, bit-exact."""
    with h5py.File(path, "r") as f:
        data = f["channels/x/current_cmd"][()]
        assert f["channels/x/current_cmd"].attrs["unit"] == "A"
        assert bool(f.attrs["recovered"]) is True
        lost = str(f.attrs["recovery_lost"])
        assert f.attrs["machine"] == "kill-test"
        assert float(f.attrs["sample_rate_hz"]) == FS
    n = len(data)
    assert n >= 50  # five segments of >= 20 samples each
    np.testing.assert_array_equal(data, np.arange(n, dtype=float))
    try:  # pandas is not a dependency of millsense; where it is installed, through h5py
        import pandas as pd
    except ImportError:
        pass
    else:
        frame = pd.DataFrame({"x/current_cmd": data})
        np.testing.assert_array_equal(frame["x/current_cmd"].to_numpy(), data)
    # what was lost is said with the writer's own flush interval (0.02 s) and where data end
    assert lost.startswith("lost: at most 0.02 s of signal") and f"t = {n / FS:.6g} s" in lost
    return n


def test_recover_writes_a_plain_hdf5_file_with_a_loss_note(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.h5"
    _killed_recording(path, tmp_path)
    assert not path.exists() and partial_dir(path).is_dir()
    code, out, err = run_cli(["recover", str(path)], capsys)
    assert code == 0, err
    n = _check_plain(path)
    assert f"({n} samples)" in out and "lost: at most 0.02 s" in out
    assert not partial_dir(path).exists()  # every sample is in the plain file
    # nothing left to recover: one line, exit 2
    code, _, err = run_cli(["recover", str(path)], capsys)
    assert code == 2 and "nothing to recover" in err and len(err.splitlines()) == 1


def test_info_on_a_killed_recording_writes_the_plain_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.h5"
    _killed_recording(path, tmp_path)
    code, out, err = run_cli(["info", str(path)], capsys)
    assert code == 0, err
    assert "recovered" in out and "plain HDF5" in out and "lost:" in out
    _check_plain(path)


def test_recover_beside_an_earlier_recording_and_messages_name_no_function(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.h5"
    _killed_recording(path, tmp_path)
    # a new writer on that name is refused with the command that helps, not a function name
    with pytest.raises(Exception) as exc:
        RecordingWriter(path, FS, [ChannelInfo("a", "A")])
    assert f"millsense recover {path}" in str(exc.value)
    assert "read_recording" not in str(exc.value) and "()" not in str(exc.value)
    code, _, err = run_cli(["recover", str(path), "-o", str(path)], capsys)
    assert code == 2 and "an input" in err  # -o is the recording itself: the default
    other = tmp_path / "kept.h5"
    code, out, err = run_cli(["recover", str(path), "-o", str(other)], capsys)
    assert code == 0, err
    _check_plain(other)
    assert partial_dir(path).is_dir()  # written elsewhere: the folder stays
    assert f"kept {path}.partial/" in out


def test_a_running_writer_is_not_recovered(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "live.h5"
    w = RecordingWriter(path, FS, [ChannelInfo("a", "A")])
    w.append({"a": np.zeros(5)})
    w.flush()
    code, _, err = run_cli(["recover", str(path)], capsys)
    assert code == 2 and "still being written" in err
    w.close()
    assert path.is_file()


@pytest.mark.parametrize(
    ("content", "why"),
    [
        (b"", "not a readable HDF5 file"),
        (b"time,x\n0,1\n", "not a readable HDF5 file"),
        (None, "HDF5 file but not a millsense recording"),
    ],
)
def test_recover_of_a_file_that_is_no_recording_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes | None, why: str
) -> None:
    """An empty file, a CSV named .h5 and a foreign HDF5 file were each called "a complete
    recording; nothing to recover": the message says what the file is (as info's does) and
    that there is no .partial folder to recover from; exit 2, one line, the file untouched."""
    path = tmp_path / "run.h5"
    if content is None:
        with h5py.File(path, "w") as f:
            f["x"] = np.arange(3.0)
    else:
        path.write_bytes(content)
    before = path.read_bytes()
    code, _, err = run_cli(["recover", str(path)], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert why in err and "no run.h5.partial folder" in err and "complete recording" not in err
    assert path.read_bytes() == before
