"""PNG of load estimates against truth: time trace, zoom, amplitudes at tooth harmonics."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from millsense.report.estimate_metrics import HarmonicComparison
from millsense.report.plots import _save, plt

if TYPE_CHECKING:
    from millsense.report.estimate_stream import PlotTraces

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

    The whole arrays are passed through the same min/max envelopes as a streamed run
    (:func:`plot_traces`), so both draw the same figure.
    """
    from millsense.report.estimate_stream import PlotTraces, StreamedEstimate

    n = max((len(v) for v in truth.values()), default=0)
    est = [
        StreamedEstimate(m, a, f"{m}/{a}", d, f"truth/{a}")
        for (m, a), (_, d) in estimates.items()
        if a in truth
    ]
    first: dict[str, float] = {}
    for c in comparisons:
        first.setdefault(c.axis, 0.5 * (c.window[0] + c.window[1]))
    tooth = comparisons[0].tooth_hz if comparisons else 0.0
    traces = PlotTraces(est, n, fs, first or None, tooth)
    data = {f"truth/{a}": np.asarray(v, dtype=float) for a, v in truth.items()}
    data.update({f"{m}/{a}": np.asarray(v, dtype=float) for (m, a), (v, _) in estimates.items()})
    traces.add(0, data)
    plot_traces(path, fs, traces, comparisons, units)


def plot_traces(
    path: str | Path,
    fs: float,
    traces: PlotTraces,
    comparisons: Sequence[HarmonicComparison],
    units: Mapping[str, str],
    references: Mapping[str, str] | None = None,
) -> None:
    """The estimate-vs-truth PNG from streamed traces (:class:`~millsense.report.
    estimate_stream.PlotTraces`): whole record as min/max envelopes (no peak dropped), zoom
    of 12 tooth periods from the raw samples, amplitudes at the tooth harmonics.

    The whole-record y-scale spans :data:`FULL_PERCENTILES` of the envelope points (each
    bin's minimum and maximum; decision 0961), and the legend counts the envelope points off
    that scale. ``references`` (axis → reference channel) labels a measured force by its
    channel name instead of "truth" (decision 1702).
    """
    axes = list(traces.axes)
    fig, grid = plt.subplots(
        max(len(axes), 1),
        3,
        figsize=(15, 3.0 * max(len(axes), 1) + 0.8),
        squeeze=False,
        gridspec_kw={"width_ratios": [2.2, 1.6, 1.2]},
    )
    for row, ax_name in enumerate(axes):
        tr = traces.axes[ax_name]
        comps = [c for c in comparisons if c.axis == ax_name]
        a_full, a_zoom, a_spec = grid[row]
        ref = (references or {}).get(ax_name, "truth/")
        ref_label = "truth" if ref.startswith("truth/") else ref  # a measured force by name
        t, y = tr.truth.xy(fs)
        a_full.plot(t, y, "k", lw=0.8, label=ref_label)
        tz = tr.truth_zoom
        t_zoom = np.arange(tz.start, tz.stop) / fs
        a_zoom.plot(t_zoom, tz.values, "k", lw=1.2, label=ref_label)
        shown = [y]
        inside = [tz.values]
        for (method, _), (env, zoom, delay) in tr.estimates.items():
            te, ye = env.xy(fs, delay)
            a_full.plot(te, ye, lw=0.6, alpha=0.8, label=method)
            a_zoom.plot(
                (np.arange(zoom.start, zoom.stop) - delay) / fs, zoom.values, lw=0.9, label=method
            )
            shown.append(ye)
            inside.append(zoom.values)
        unit = units.get(ax_name, "")
        what = (
            f"tool force {ax_name.removeprefix('tool_')}"
            if ax_name.startswith("tool_")
            else f"{ax_name} load"
        )
        a_full.set_ylabel(f"{what} [{unit}]")
        lo, hi = value_limits(shown, FULL_PERCENTILES)
        a_full.set_ylim(lo, hi)
        clipped = sum(int(np.count_nonzero((v < lo) | (v > hi))) for v in shown)
        if clipped:
            a_full.plot([], [], " ", label=f"{clipped} envelope points off scale")
        a_full.legend(loc="upper right", fontsize=7)
        if comps and tr.zoom_s is not None:
            c0 = comps[0]
            a_zoom.set_xlim(*tr.zoom_s)
            a_zoom.set_ylim(*value_limits(inside))
            a_full.axvspan(c0.window[0] / fs, c0.window[1] / fs, color="0.9", zorder=0)
            h = c0.harmonics
            width = 0.8 / (len(comps) + 1)
            a_spec.bar(h - 0.4 + width / 2, c0.true_amp, width, color="k", label=ref_label)
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
