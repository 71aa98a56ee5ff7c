"""PNG of load estimates against truth: time trace, zoom, amplitudes at tooth harmonics."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from millsense.report.estimate_metrics import HarmonicComparison
from millsense.report.plots import _save, plt

#: Percentiles of the samples the whole-record panel's y-axis spans: the inertia term makes the
#: estimate spike at rapid-move accelerations (truth is zero there), and a scale set by those
#: spikes flattens the cut itself; the clipped samples are counted in the legend.
FULL_PERCENTILES = (0.05, 99.95)


def value_limits(
    series: Sequence[NDArray[np.float64]], percentiles: tuple[float, float] = (0.0, 100.0)
) -> tuple[float, float]:
    """y-limits spanning ``percentiles`` of all finite samples of ``series``, 5 % margin.

    Returns (-1, 1) when there is no finite sample; a constant signal gets ±1 around it.
    """
    finite = [x[np.isfinite(x)] for x in series if len(x)]
    values = np.concatenate(finite) if finite else np.empty(0)
    if values.size == 0:
        return -1.0, 1.0
    lo, hi = (float(v) for v in np.percentile(values, percentiles))
    if hi <= lo:
        return lo - 1.0, hi + 1.0
    pad = 0.05 * (hi - lo)
    return lo - pad, hi + pad


def plot_estimates(
    path: str | Path,
    fs: float,
    truth: Mapping[str, NDArray[np.float64]],
    estimates: Mapping[tuple[str, str], tuple[NDArray[np.float64], int]],
    comparisons: Sequence[HarmonicComparison],
    units: Mapping[str, str],
) -> None:
    """One row per axis: whole trace, zoom of three tooth periods ×4, harmonic amplitudes.

    Parameters
    ----------
    path : PNG to write (atomically).
    fs : sample rate, Hz.
    truth : axis → ``truth/{axis}/load``.
    estimates : (method, axis) → (estimate, delay samples); plotted shifted back by the delay.
    comparisons : results of :func:`millsense.report.estimate_metrics.compare`.
    units : axis → unit of its load.
    """
    axes = list(truth)
    fig, grid = plt.subplots(
        len(axes),
        3,
        figsize=(15, 3.0 * len(axes) + 0.8),
        squeeze=False,
        gridspec_kw={"width_ratios": [2.2, 1.6, 1.2]},
    )
    for row, ax_name in enumerate(axes):
        tru = truth[ax_name]
        t = np.arange(len(tru)) / fs
        comps = [c for c in comparisons if c.axis == ax_name]
        a_full, a_zoom, a_spec = grid[row]
        a_full.plot(t, tru, "k", lw=0.8, label="truth")
        a_zoom.plot(t, tru, "k", lw=1.2, label="truth")
        shown: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = [(t, tru)]
        for (method, axis), (est, delay) in estimates.items():
            if axis != ax_name:
                continue
            te = (np.arange(len(est)) - delay) / fs
            a_full.plot(te, est, lw=0.6, alpha=0.8, label=method)
            a_zoom.plot(te, est, lw=0.9, label=method)
            shown.append((te, est))
        unit = units.get(ax_name, "")
        what = (
            f"tool force {ax_name.removeprefix('tool_')}"
            if ax_name.startswith("tool_")
            else f"{ax_name} load"
        )
        a_full.set_ylabel(f"{what} [{unit}]")
        lo, hi = value_limits([y for _, y in shown], FULL_PERCENTILES)
        a_full.set_ylim(lo, hi)
        clipped = sum(int(np.count_nonzero((y < lo) | (y > hi))) for _, y in shown)
        if clipped:
            a_full.plot([], [], " ", label=f"{clipped} samples off scale")
        a_full.legend(loc="upper right", fontsize=7)
        if comps:
            c0 = comps[0]
            mid = 0.5 * (c0.window[0] + c0.window[1]) / fs
            span = 12.0 / c0.tooth_hz
            a_zoom.set_xlim(mid - span / 2, mid + span / 2)
            inside = [y[(x >= mid - span / 2) & (x <= mid + span / 2)] for x, y in shown]
            a_zoom.set_ylim(*value_limits(inside))
            a_full.axvspan(c0.window[0] / fs, c0.window[1] / fs, color="0.9", zorder=0)
            h = c0.harmonics
            width = 0.8 / (len(comps) + 1)
            a_spec.bar(h - 0.4 + width / 2, c0.true_amp, width, color="k", label="truth")
            for j, c in enumerate(comps, start=1):
                a_spec.bar(h - 0.4 + width * (j + 0.5), c.est_amp, width, label=c.method)
            a_spec.set_xticks(h)
            a_spec.set_xticklabels([f"{k}×\n{k * c0.tooth_hz:.0f}" for k in h], fontsize=7)
            a_spec.set_ylabel(f"amplitude [{unit}]")
            a_spec.legend(fontsize=7)
        a_zoom.set_title("zoom (12 tooth periods)", fontsize=8)
        a_spec.set_title("tooth harmonics [Hz]", fontsize=8)
    grid[-1][0].set_xlabel("time [s]")
    grid[-1][1].set_xlabel("time [s]")
    fig.tight_layout()
    _save(fig, path)
