"""Recording file throughput: 10 kHz x 16 channels x 60 s of noisy float64 signals.

Write goes through :class:`~millsense.io.RecordingWriter` with 1 s chunks (as a live recorder
would), close and consolidation included; read is :func:`~millsense.io.read_recording` of the
whole file. Figures are best of three runs (the machine is shared; the best run is the one
least disturbed by other processes).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from _harness import Metric, benchmark
from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter, read_recording
from millsense.io.recording_file import partial_dir

FS = 10_000.0
N_CHANNELS = 16
DURATION_S = 60.0


def _signals() -> dict[str, np.ndarray]:
    """Drive-like signals: a few harmonics of tooth and spindle frequency plus white noise."""
    n = int(FS * DURATION_S)
    t = np.arange(n) / FS
    rng = np.random.default_rng(2024)
    out: dict[str, np.ndarray] = {}
    axes = ["x", "y", "z", "s"]
    kinds = ["current_cmd", "current", "velocity", "position"]
    for i in range(N_CHANNELS):
        f0 = 40.0 + 7.3 * i  # Hz
        sig = (1.0 + 0.1 * i) * np.sin(2 * np.pi * f0 * t) + 0.3 * np.sin(2 * np.pi * 3 * f0 * t)
        out[f"{axes[i // 4]}/{kinds[i % 4]}"] = sig + 0.05 * rng.standard_normal(n)
    return out


def _write(path: Path, data: dict[str, np.ndarray]) -> float:
    chans = [ChannelInfo(k, "A") for k in data]
    step = int(FS)  # 1 s chunks
    n = next(iter(data.values())).shape[0]
    t0 = time.perf_counter()
    with RecordingWriter(path, FS, chans, {"source": "bench"}, flush_every_s=1.0) as w:
        for s in range(0, n, step):
            w.append({k: v[s : s + step] for k, v in data.items()})
    return time.perf_counter() - t0


def _h5py_baseline(path: Path, data: dict[str, np.ndarray]) -> tuple[float, float]:
    """Plain h5py, the way an engineer would store the same data in one go: one chunked
    dataset per channel, shuffle + gzip level 4 (h5py's default level). Write and read times."""
    import h5py

    t0 = time.perf_counter()
    with h5py.File(path, "w") as f:
        for k, v in data.items():
            f.create_dataset(k, data=v, chunks=(65536,), shuffle=True, compression="gzip")
    tw = time.perf_counter() - t0
    t0 = time.perf_counter()
    with h5py.File(path, "r") as f:
        back = {k: f[k][()] for k in data}
    tr = time.perf_counter() - t0
    if not np.array_equal(back["x/current_cmd"], data["x/current_cmd"]):
        raise AssertionError("baseline read back differs")
    return tw, tr


@benchmark("core.recording_throughput")
def _throughput() -> list[Metric]:
    data = _signals()
    n = next(iter(data.values())).shape[0]
    raw_mb = sum(v.nbytes for v in data.values()) / 1e6
    write_s, read_s = [], []
    base_w: list[float] = []
    base_r: list[float] = []
    size = 0
    with tempfile.TemporaryDirectory() as d:
        for run in range(3):
            path = Path(d) / f"r{run}.h5"
            write_s.append(_write(path, data))
            size = path.stat().st_size
            t0 = time.perf_counter()
            rec = read_recording(path)
            read_s.append(time.perf_counter() - t0)
            if not np.array_equal(rec["x/current_cmd"], data["x/current_cmd"]):
                raise AssertionError("read back differs from what was written")
            path.unlink()
            shutil.rmtree(partial_dir(path), ignore_errors=True)
            bw, br = _h5py_baseline(Path(d) / f"b{run}.h5", data)
            base_w.append(bw)
            base_r.append(br)
    tw, tr = min(write_s), min(read_s)
    bw, br = min(base_w), min(base_r)
    note = f"10 kHz x {N_CHANNELS} ch x {DURATION_S:g} s float64 ({raw_mb:.1f} MB), best of 3"
    return [
        Metric("write_x_realtime", DURATION_S / tw, "x", target=100.0, note=note + ", 1 s chunks"),
        Metric("read_x_realtime", DURATION_S / tr, "x", target=500.0, note=note),
        Metric(
            "write_speedup_vs_h5py_gzip",
            bw / tw,
            "x",
            baseline="h5py one-shot write, shuffle + gzip 4, same data, run alternately",
            note="crash-safe chunked writer including close, against a one-shot h5py write",
        ),
        Metric(
            "read_speedup_vs_h5py_gzip",
            br / tr,
            "x",
            baseline="h5py read of the shuffle + gzip 4 file, run alternately",
            note="read_recording (threaded chunk decode) against plain h5py dataset reads",
        ),
        Metric("write_samples_per_s", n * N_CHANNELS / tw, "samples/s", note="all channels"),
        Metric("read_samples_per_s", n * N_CHANNELS / tr, "samples/s", note="all channels"),
        Metric(
            "compression_ratio",
            raw_mb * 1e6 / size,
            "x",
            note="shuffle + deflate (random planes stored, rest Z_RLE)",
        ),
    ]
