"""Benchmark of the run report (issue 19): a 60-minute 10 kHz recording → ``run.html`` in
under 60 s, the file under 20 MB, every force peak of the recording on the page.

The recording is synthesised cheaply (vectorised, in blocks) with the channels a session
records and the report reads: a raster of the 100 × 80 mm demo part at 1000 rev/min, 2 flutes
(tooth-periodic forces and torque with noise), the adaptive feed override, the breakage
residual and threshold, the tool-centre point, and :data:`N_PEAKS` single-sample force peaks
well above the cutting force at known samples. The report time is the wall time of
:func:`millsense.report.run_report.write_report` (reading the 15 channels once, envelopes,
harmonics, HTML); tests/test_run_report.py runs the same synthesis for 3 minutes and checks the
peaks through the same envelope code.
"""

from __future__ import annotations

import itertools
import tempfile
import time
from pathlib import Path

import numpy as np

from _harness import Metric, benchmark

FS = 10000.0
SPINDLE_RAD_S = 1000 * 2 * np.pi / 60
#: Single-sample force peaks injected, at evenly spread pseudo-random samples.
N_PEAKS = 8
BLOCK = 1 << 20


def peak_samples(n: int, n_peaks: int = N_PEAKS, seed: int = 19) -> tuple[np.ndarray, np.ndarray]:
    """Samples and heights (N, 2000–3500: above the cut's ≈ 700 N) of the injected peaks."""
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, n, n_peaks + 1).astype(np.int64)
    at = np.array([rng.integers(a + 1, b - 1) for a, b in itertools.pairwise(edges)])
    return at, rng.uniform(2000.0, 3500.0, n_peaks)


def synthesise(path: Path, seconds: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Write a synthetic run of ``seconds`` at 10 kHz to ``path``; the peaks' samples and
    heights (on ``truth/tool/force_x``)."""
    from millsense.core.recording import ChannelInfo
    from millsense.io import RecordingWriter

    n = int(seconds * FS)
    at, height = peak_samples(n)
    names = {
        "truth/tool/force_x": "N", "truth/tool/force_y": "N", "truth/spindle/torque": "N*m",
        "est/spindle/spindle/load": "N*m", "spindle/speed": "rad/s", "cnc/feed_override": "1",
        "supervisor/feed_override": "1", "adaptive_feed/peak": "W",
        "adaptive_feed/reference": "W", "breakage/residual1": "N*m", "breakage/limit1": "N*m",
        "tcp/x": "m", "tcp/y": "m", "plan/cutting_torque": "N*m",
        "truth/process/engagement": "1",
    }  # fmt: skip
    rng = np.random.default_rng(seed)
    meta = {"source": "benchmarks/bench_report.py (synthetic)", "machine": "quaser-ux600"}
    w = RecordingWriter(path, FS, [ChannelInfo(k, u, k) for k, u in names.items()],
                        metadata=meta, flush_every_s=60.0)  # fmt: skip
    pass_s = 12.0  # one 100 mm pass at 500 mm/min
    for a in range(0, n, BLOCK):
        b = min(n, a + BLOCK)
        t = np.arange(a, b) / FS
        phase = 2 * SPINDLE_RAD_S * t  # tooth phase, 2 flutes
        tooth = np.maximum(np.sin(phase), 0.0) ** 1.5
        noise = rng.standard_normal((4, b - a))
        fx = 600.0 * tooth + 20.0 * noise[0]
        fy = 250.0 * tooth + 20.0 * noise[1]
        k = (at >= a) & (at < b)
        fx[at[k] - a] = height[k]
        torque = 4.0 * tooth + 0.05 * noise[2]
        u = 1.0 + 0.2 * np.sin(2 * np.pi * t / 300.0)
        k_pass = np.floor(t / pass_s)
        frac = t / pass_s - k_pass
        x = np.where(k_pass % 2 == 0, frac, 1.0 - frac) * 0.1
        y = (k_pass % 80) * 1e-3
        w.append({
            "truth/tool/force_x": fx, "truth/tool/force_y": fy, "truth/spindle/torque": torque,
            "est/spindle/spindle/load": torque + 0.3 * noise[3],
            "spindle/speed": np.full(b - a, SPINDLE_RAD_S), "cnc/feed_override": u,
            "supervisor/feed_override": u, "adaptive_feed/peak": 400.0 * u,
            "adaptive_feed/reference": np.full(b - a, 420.0),
            "breakage/residual1": 0.1 * noise[2], "breakage/limit1": np.full(b - a, 1.8),
            "tcp/x": x, "tcp/y": y, "plan/cutting_torque": torque,
            "truth/process/engagement": np.ones(b - a),
        })  # fmt: skip
    w.close()
    return at, height


@benchmark("report.hour")
def _report() -> list[Metric]:
    from millsense.report.run_report import write_report

    with tempfile.TemporaryDirectory() as tmp:
        rec, html = Path(tmp) / "hour.h5", Path(tmp) / "hour.html"
        t0 = time.perf_counter()
        at, height = synthesise(rec, 3600.0)
        synth_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = write_report(html, rec)
        wall = time.perf_counter() - t0
        size = html.stat().st_size / 1e6
    note = (
        f"60 min at 10 kHz, 15 channels (synthesised in {synth_s:.0f} s), {N_PEAKS} "
        "single-sample force peaks; one read of each channel, 5000 min/max bins per trace"
    )
    return [
        Metric("report_wall_s_60min", wall, "s", target=60.0, higher_is_better=False, note=note),
        Metric("report_size_mb_60min", size, "MB", target=20.0, higher_is_better=False,
               note=note),
        Metric("report_peaks_on_page_60min", float(_peaks_on_page(rep, at, height)), "peaks",
               target=float(N_PEAKS), note=note + " (peaks whose height the page's envelope "
               "of the true resultant force reaches, to 0.1 %)"),
    ]  # fmt: skip


def _peaks_on_page(rep: object, at: np.ndarray, height: np.ndarray) -> int:
    """How many peaks the drawn envelope of the true |F_xy| (adaptive-control figure) reaches
    at the peak's time."""
    return int(np.sum(peaks_drawn(rep, at, height)))


def peaks_drawn(rep: object, at: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Per peak: does the drawn trace ``true |F_xy|`` reach the peak's |F_xy| (≥ its x-force
    height, to 0.1 %) within one bin of its time?"""
    fig = rep.figures["control"]  # type: ignore[attr-defined]
    tr = next(t for t in fig.data if t.name == "true |F_xy|")
    x, y = np.asarray(tr.x, dtype=float), np.asarray(tr.y, dtype=float)
    width = x[2] - x[0]
    out = []
    for s, h in zip(at, height, strict=True):
        near = np.abs(x - s / FS) <= width
        out.append(bool(near.any() and y[near].max() >= 0.999 * h))
    return np.array(out)
