"""PNG of a data-quality report (:mod:`millsense.io.quality`): where in time each finding is,
the first clipped flat top, the mains-hum spectrum and the drifting offset."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from millsense.core.recording import Recording
from millsense.io.quality import QualityReport
from millsense.report.plots import _save

__all__ = ["plot_quality"]

_COLOURS = {
    "gap": "tab:red",
    "repeated": "tab:orange",
    "clipped": "tab:purple",
    "nan": "tab:brown",
    "time": "tab:red",
}


def plot_quality(rec: Recording, report: QualityReport, path: str | Path) -> None:
    """Four panels: findings on a time line; the first clipped channel around its first flat
    top; the amplitude spectrum of the channel with the strongest mains hum; the channel with
    a drifting offset and its fitted drift. Panels without a finding say so."""
    fs, t0 = rec.sample_rate_hz, rec.t0_s
    fig, axes = plt.subplots(4, 1, figsize=(10, 11))
    ax = axes[0]
    rows: list[str] = []
    for f in report.findings:
        if f.kind not in _COLOURS:
            continue
        label = f"{f.kind}: {f.where}"[:60]
        if label not in rows:
            rows.append(label)
        y = rows.index(label)
        spans: list[tuple[float, float]] = []
        if f.kind == "repeated":
            spans = [(f.data["start"] / fs, f.data["length"] / fs)]
        elif f.kind == "clipped":
            spans = [(s / fs, n / fs) for s, n, _ in f.data["runs"]]
        elif f.kind == "gap":
            spans = [(f.data["t_s"] - t0, f.data["duration_s"])]
        elif f.kind == "nan":
            spans = [
                (s / fs, n / fs) for s, n in zip(f.data["starts"], f.data["lengths"], strict=True)
            ]
        for s, w in spans:
            ax.broken_barh([(t0 + s, max(w, 2.0 / fs))], (y - 0.35, 0.7), color=_COLOURS[f.kind])
    ax.set_yticks(range(len(rows)), rows, fontsize=7)
    ax.set_xlim(t0, t0 + rec.duration_s)
    ax.set_xlabel("time [s]")
    ax.set_title("findings in time" if rows else "findings in time: none")

    ax = axes[1]
    clip = report.of_kind("clipped")
    if clip:
        c = clip[0].where
        s, n, rail = clip[0].data["runs"][0]
        a, b = max(0, s - 20 * n), min(rec.n_samples, s + 21 * n)
        t = t0 + np.arange(a, b) / fs
        ax.plot(t, rec.channel(c)[a:b], lw=0.8)
        ax.axhline(rail, color="tab:purple", ls="--", lw=0.8, label=f"rail {rail:.4g}")
        ax.set_title(f"{c}: first flat top ({n} samples at t = {t0 + s / fs:.4g} s)")
        ax.set_ylabel(rec.info(c).unit)
        ax.legend(fontsize=8)
    else:
        ax.set_title("clipping: none found")

    ax = axes[2]
    hum = report.of_kind("hum")
    if hum:
        best = max(hum, key=lambda f: f.data["lines"][0][2])
        x = np.asarray(rec.channel(best.where), dtype=np.float64)
        hann = np.hanning(x.size)
        spec = np.abs(np.fft.rfft((x - x.mean()) * hann)) * 2 / hann.sum()
        freqs = np.fft.rfftfreq(x.size, 1 / fs)
        top = 6 * best.data["mains_hz"]
        sel = freqs <= top
        ax.semilogy(freqs[sel], spec[sel], lw=0.7)
        for f_line, amp, _ in best.data["lines"]:
            ax.plot(f_line, amp, "rv")
        ax.set_title(f"{best.where}: {best.data['mains_hz']:g} Hz mains hum")
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel(f"amplitude [{rec.info(best.where).unit}]")
    else:
        ax.set_title("mains hum: none found")

    ax = axes[3]
    drift = report.of_kind("drift")
    if drift:
        c = drift[0].where
        x = np.asarray(rec.channel(c), dtype=np.float64)
        t = t0 + np.arange(x.size) / fs
        ax.plot(t, x, lw=0.5)
        ax.set_title(
            f"{c}: offset drifting {drift[0].data['per_s']:+.3g} {rec.info(c).unit}/s at rest"
        )
        ax.set_ylabel(rec.info(c).unit)
        ax.set_xlabel("time [s]")
    else:
        ax.set_title("offset drift: none found")
    fig.tight_layout()
    _save(fig, path)
