"""Estimate vs truth and its plot from chunks: the same figures, memory independent of length.

:func:`~millsense.report.estimate_metrics.compare` fits the tooth harmonics to whole arrays;
on an hour at 10 kHz those are 36 million samples per channel. Here the same quantities are
accumulated while the estimates stream (decision 0961 "Streaming with constant memory"):

* the cut window (longest run of ``truth/process/engagement ≥ 0``, trimmed by 20 % at each
  end) and the mean spindle speed over it are found before the run by
  :func:`scan_cut_window` and :func:`window_mean`, reading the two channels in blocks;
* the least-squares fit of ``c₀ + Σ_k (a_k cos kω_t t + b_k sin kω_t t)`` (module
  :mod:`~millsense.report.estimate_metrics`) is solved from its normal equations
  ``(XᵀX) c = Xᵀy``, whose 13 × 13 matrix and right-hand side are sums over the samples
  (:class:`HarmonicAccumulator`): the columns are the same numbers as the whole-record fit
  (``t = (k − i₀)/f_s`` from the integer sample index), so the result equals ``lstsq`` to
  rounding (the columns are near-orthogonal over many tooth periods: cond(XᵀX) ≈ 2);
* the plot's whole-record panel draws a min/max envelope (:class:`Envelope`): every bin of
  ``⌈n / bins⌉`` samples is drawn from its minimum to its maximum, so no peak is dropped;
  the zoom keeps the raw samples of its 12 tooth periods (:class:`ZoomCapture`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError
from millsense.report.estimate_metrics import HarmonicComparison

#: Samples read at once by the scans before the run.
SCAN_BLOCK = 65536
#: Bins of the whole-record envelope of each trace.
ENVELOPE_BINS = 4000
#: Tooth periods in the zoom panel (the plot's "zoom (12 tooth periods)").
ZOOM_PERIODS = 12.0

Reader = Callable[[int, int], NDArray[np.float64]]


def scan_cut_window(
    read: Reader | None, n: int, trim: float = 0.2, block: int = SCAN_BLOCK
) -> tuple[int, int]:
    """:func:`~millsense.report.estimate_metrics.cut_window` from blocks of the engagement.

    ``read(a, b)`` returns samples ``[a, b)`` of ``truth/process/engagement`` (None: whole
    record). The longest run of ``≥ 0`` (the first of equal length) is tracked across blocks.

    Raises
    ------
    InputDataError
        When the recording never cuts (the same line as ``cut_window``).
    """
    if read is None:
        i0, i1 = 0, n
    else:
        best = (0, 0)
        run_start: int | None = None
        for a in range(0, n, block):
            b = min(n, a + block)
            ok = np.asarray(read(a, b)) >= 0
            prev = run_start is not None
            edges = np.flatnonzero(np.diff(np.concatenate([[prev], ok]).astype(np.int8)))
            for e in edges:
                k = a + int(e)
                if run_start is None:
                    run_start = k
                else:
                    if k - run_start > best[1] - best[0]:
                        best = (run_start, k)
                    run_start = None
        if run_start is not None and n - run_start > best[1] - best[0]:
            best = (run_start, n)
        if best[1] <= best[0]:
            raise InputDataError("estimate vs truth: the recording never cuts")
        i0, i1 = best
    d = int(trim * (i1 - i0))
    return i0 + d, i1 - d


def scan_force_window(
    read: Reader,
    n: int,
    period: int,
    trim: float = 0.2,
    fraction: float = 0.2,
    block: int = SCAN_BLOCK,
) -> tuple[int, int]:
    """The cut window from a measured force (a dynamometer) when no engagement is recorded.

    The force is cut into blocks of ``period`` samples (one spindle revolution); a block is
    in the cut when its standard deviation (the tooth-periodic force, whatever the offset)
    exceeds ``fraction`` of the largest block's. The longest run of such blocks is refined to
    the sample where the force leaves (and comes back to) the level of the air block beside
    it by more than 6 of its standard deviations and ``fraction`` of the largest block's
    standard deviation; then trimmed by ``trim`` at each end like :func:`scan_cut_window`
    (decision 1702).

    Raises
    ------
    InputDataError
        When the force never varies (no cut).
    """
    period = max(int(period), 2)
    step = max(period * max(block // period, 1), period)
    stds: list[NDArray[np.float64]] = []
    for a in range(0, n - period + 1, step):
        b = min(n, a + step)
        m = (b - a) // period
        if m == 0:
            break
        x = np.asarray(read(a, a + m * period), dtype=float).reshape(m, period)
        stds.append(x.std(axis=1))
    s = np.concatenate(stds) if stds else np.zeros(0)
    if not s.size or float(s.max()) <= 0:
        raise InputDataError("estimate vs reference: the measured force never varies (no cut)")
    cut = np.concatenate([[False], s > fraction * float(s.max()), [False]])
    edges = np.flatnonzero(np.diff(cut.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    b0, b1 = int(starts[k]), int(stops[k])
    thr = fraction * float(s.max())
    i0, i1 = b0 * period, (n if b1 == s.size else b1 * period)  # to the end: the last samples
    if b0 >= 1:  # the first sample leaving the air level of the block before
        a = (b0 - 1) * period
        x = np.asarray(read(a, min(n, a + 2 * period)), dtype=float)
        air = x[:period]
        dev = np.abs(x - float(np.median(air))) > max(6.0 * float(air.std()), thr)
        if dev.any():
            i0 = a + int(np.argmax(dev))
    if b1 < s.size:  # the last sample off the air level of the block after
        a = (b1 - 1) * period
        x = np.asarray(read(a, min(n, a + 2 * period)), dtype=float)
        air = x[period:]
        dev = np.abs(x - float(np.median(air))) > max(6.0 * float(air.std()), thr)
        if dev.any():
            i1 = a + int(np.flatnonzero(dev)[-1]) + 1
    d = int(trim * (i1 - i0))
    return i0 + d, i1 - d


def window_mean(read: Reader, i0: int, i1: int, block: int = SCAN_BLOCK) -> float:
    """Mean of samples ``[i0, i1)`` read in blocks."""
    total = 0.0
    for a in range(i0, i1, block):
        total += float(np.sum(np.asarray(read(a, min(i1, a + block)), dtype=float)))
    return total / max(i1 - i0, 1)


class HarmonicAccumulator:
    """Least-squares mean and tooth-harmonic amplitudes of a signal given in chunks.

    Parameters
    ----------
    fs : sample rate, Hz.
    f0_hz : tooth frequency, Hz.
    n_harm : harmonics 1…n.
    start, stop : the samples ``[start, stop)`` of the signal's own index that are fitted;
        the fit's time is ``t = (k − start)/fs``.

    Notes
    -----
    Same model and columns as :func:`~millsense.report.estimate_metrics.harmonic_fit`; the
    sums ``XᵀX`` and ``Xᵀy`` are order-independent up to rounding, so the result does not
    depend on the chunking.
    """

    def __init__(self, fs: float, f0_hz: float, n_harm: int, start: int, stop: int) -> None:
        self.fs = fs
        self.f0_hz = f0_hz
        self.n_harm = n_harm
        self.start = start
        self.stop = stop
        m = 2 * n_harm + 1
        self.gram = np.zeros((m, m))
        self.rhs = np.zeros(m)
        self.count = 0

    def columns(self, k0: int, k1: int) -> NDArray[np.float64]:
        """Regressors of samples ``[k0, k1)`` (inside the window), shape (k1 − k0, 2n + 1)."""
        t = (np.arange(k0, k1) - self.start) / self.fs
        cols = np.empty((len(t), 2 * self.n_harm + 1))
        cols[:, 0] = 1.0
        for k in range(1, self.n_harm + 1):
            w = 2 * np.pi * k * self.f0_hz * t
            cols[:, 2 * k - 1] = np.cos(w)
            cols[:, 2 * k] = np.sin(w)
        return cols

    def span(self, chunk_start: int, n: int) -> tuple[int, int]:
        """Samples of a chunk ``[chunk_start, chunk_start + n)`` inside the window."""
        return max(self.start, chunk_start), min(self.stop, chunk_start + n)

    def add(
        self, chunk_start: int, values: NDArray[np.float64], cols: NDArray[np.float64] | None = None
    ) -> None:
        """Add a chunk whose first sample is ``chunk_start``; ``cols`` may be shared by
        signals with the same window (as from :meth:`columns` of :meth:`span`)."""
        k0, k1 = self.span(chunk_start, len(values))
        if k1 <= k0:
            return
        x = self.columns(k0, k1) if cols is None else cols
        y = np.asarray(values[k0 - chunk_start : k1 - chunk_start], dtype=float)
        self.gram += x.T @ x
        self.rhs += x.T @ y
        self.count += k1 - k0

    def result(self) -> tuple[float, NDArray[np.complex128]]:
        """(mean, complex amplitudes ``a_k − j b_k``) as ``harmonic_fit`` returns them."""
        coef = np.linalg.lstsq(self.gram, self.rhs, rcond=None)[0]
        return float(coef[0]), np.asarray(coef[1::2] - 1j * coef[2::2], dtype=np.complex128)


@dataclass(frozen=True)
class StreamedEstimate:
    """One estimate compared with its truth: (method, axis, estimate channel, delay)."""

    method: str
    axis: str
    channel: str
    delay: int
    truth: str


class StreamedComparison:
    """:func:`~millsense.report.estimate_metrics.compare` for every estimate, from chunks.

    Parameters
    ----------
    estimates : the estimates compared (their truth channel named).
    fs : sample rate, Hz.
    n : samples in the recording.
    window : the cut window ``(i0, i1)`` (:func:`scan_cut_window`).
    omega_mean : ``(i0, i1) →`` mean spindle speed over those samples, rad/s
        (:func:`window_mean`); asked once per distinct window.
    flutes : teeth.
    n_harm : harmonics compared.

    Raises
    ------
    InputDataError
        Window too short, spindle not turning (the lines of ``compare``).
    """

    def __init__(
        self,
        estimates: Sequence[StreamedEstimate],
        fs: float,
        n: int,
        window: tuple[int, int],
        omega_mean: Callable[[int, int], float],
        flutes: int,
        n_harm: int = 6,
    ) -> None:
        self.estimates = list(estimates)
        self.fs = fs
        self.n_harm = n_harm
        i0, i1w = window
        #: delay → the window compared (``i1`` clipped to ``n − delay``, as ``compare``)
        self.windows: dict[int, tuple[int, int]] = {}
        #: delay → tooth frequency from the mean spindle speed over that window, Hz
        self.tooth_hz: dict[int, float] = {}
        for e in self.estimates:
            if e.delay in self.windows:
                continue
            i1 = min(i1w, n - e.delay)
            if i1 - i0 < 10:
                raise InputDataError("estimate vs truth: steady cut too short to compare")
            f_tooth = flutes * abs(omega_mean(i0, i1)) / (2 * np.pi)
            if not f_tooth > 0:
                raise InputDataError("estimate vs truth: spindle not turning in the cut window")
            self.windows[e.delay] = (i0, i1)
            self.tooth_hz[e.delay] = f_tooth
        self._est: dict[StreamedEstimate, HarmonicAccumulator] = {}
        self._tru: dict[StreamedEstimate, HarmonicAccumulator] = {}
        for e in self.estimates:
            i0, i1 = self.windows[e.delay]
            f0 = self.tooth_hz[e.delay]
            self._est[e] = HarmonicAccumulator(fs, f0, n_harm, i0 + e.delay, i1 + e.delay)
            self._tru[e] = HarmonicAccumulator(fs, f0, n_harm, i0, i1)

    def add(self, start: int, data: dict[str, NDArray[np.float64]]) -> None:
        """A chunk starting at sample ``start`` holding the estimates and truth channels."""
        cols: dict[tuple[int, int, float, int], NDArray[np.float64]] = {}
        n = len(next(iter(data.values()))) if data else 0
        for e in self.estimates:
            for acc, name in ((self._est[e], e.channel), (self._tru[e], e.truth)):
                k0, k1 = acc.span(start, n)
                if k1 <= k0:
                    continue
                key = (acc.start, acc.stop, acc.f0_hz, k0)
                if key not in cols:
                    cols[key] = acc.columns(k0, k1)
                acc.add(start, data[name], cols[key])

    def results(self) -> list[HarmonicComparison]:
        out = []
        for e in self.estimates:
            me, ce = self._est[e].result()
            mt, ct = self._tru[e].result()
            ae, at = np.abs(ce), np.abs(ct)
            err = np.abs(ae - at) / np.maximum(at, 1e-300)
            out.append(
                HarmonicComparison(
                    e.method,
                    e.axis,
                    self.tooth_hz[e.delay],
                    np.arange(1, self.n_harm + 1),
                    ae,
                    at,
                    err,
                    me,
                    mt,
                    self.windows[e.delay],
                )
            )
        return out


class Envelope:
    """Min/max of a trace per bin of ``width`` samples (its own index), from chunks.

    The drawn envelope goes from each bin's minimum to its maximum: a decimated copy that
    never drops a peak. NaN samples are ignored (a bin of only NaN stays NaN).
    """

    def __init__(self, n: int, bins: int = ENVELOPE_BINS) -> None:
        self.n = n
        self.width = max(1, math.ceil(n / max(bins, 1)))
        nb = max(1, math.ceil(n / self.width))
        self.lo = np.full(nb, np.nan)
        self.hi = np.full(nb, np.nan)

    def add(self, start: int, values: NDArray[np.float64]) -> None:
        v = np.asarray(values, dtype=float)
        if not len(v):
            return
        k = start + np.arange(len(v))
        b0, b1 = k[0] // self.width, k[-1] // self.width
        edges = np.arange(b0, b1 + 1) * self.width - start
        edges[0] = 0
        lo = np.fmin.reduceat(v, edges)
        hi = np.fmax.reduceat(v, edges)
        self.lo[b0 : b1 + 1] = np.fmin(self.lo[b0 : b1 + 1], lo)
        self.hi[b0 : b1 + 1] = np.fmax(self.hi[b0 : b1 + 1], hi)

    def xy(self, fs: float, delay: int = 0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Times (s, shifted back by ``delay`` samples) and values of the zig-zag through every
        bin's minimum and maximum (two points per bin, at the bin's first sample)."""
        t = (np.arange(len(self.lo)) * self.width - delay) / fs
        return np.repeat(t, 2), np.column_stack([self.lo, self.hi]).ravel()


class ZoomCapture:
    """The raw samples ``[start, stop)`` of a trace (its own index), from chunks."""

    def __init__(self, start: int, stop: int) -> None:
        self.start = max(0, start)
        self.stop = max(self.start, stop)
        self.values = np.full(self.stop - self.start, np.nan)

    def add(self, start: int, values: NDArray[np.float64]) -> None:
        a, b = max(self.start, start), min(self.stop, start + len(values))
        if b > a:
            self.values[a - self.start : b - self.start] = values[a - start : b - start]


@dataclass
class AxisTraces:
    """What the plot of one axis needs: envelopes, zoom samples and the zoom's span."""

    truth: Envelope
    truth_zoom: ZoomCapture
    estimates: dict[tuple[str, str], tuple[Envelope, ZoomCapture, int]] = field(
        default_factory=dict
    )
    zoom_s: tuple[float, float] | None = None


class PlotTraces:
    """Envelopes and zoom samples of every plotted trace, filled from chunks.

    Parameters
    ----------
    estimates : the estimates plotted (their truth channels are plotted once per axis).
    n : samples in the recording.
    fs : sample rate, Hz.
    zoom_centre : sample at the middle of the zoom of each axis (the middle of the first
        estimate's cut window), or None for no zoom.
    tooth_hz : tooth frequency (the zoom spans :data:`ZOOM_PERIODS` periods).
    """

    def __init__(
        self,
        estimates: Sequence[StreamedEstimate],
        n: int,
        fs: float,
        zoom_centre: dict[str, float] | None,
        tooth_hz: float,
        bins: int = ENVELOPE_BINS,
    ) -> None:
        self.fs = fs
        self.axes: dict[str, AxisTraces] = {}
        self._truth_names: dict[str, str] = {}
        self._est_names: dict[tuple[str, str], str] = {}
        for e in estimates:
            half = 0.5 * ZOOM_PERIODS / tooth_hz if tooth_hz > 0 else 0.0
            mid = None if zoom_centre is None else zoom_centre.get(e.axis)
            if e.axis not in self.axes:
                if mid is None:
                    z0 = z1 = 0
                    span = None
                else:
                    span = (mid / fs - half, mid / fs + half)
                    z0, z1 = math.floor(span[0] * fs), math.ceil(span[1] * fs) + 1
                self.axes[e.axis] = AxisTraces(Envelope(n, bins), ZoomCapture(z0, z1))
                self.axes[e.axis].zoom_s = span
                self._truth_names[e.axis] = e.truth
            tz = self.axes[e.axis].truth_zoom
            zoom = ZoomCapture(tz.start + e.delay, tz.stop + e.delay)
            self.axes[e.axis].estimates[(e.method, e.axis)] = (Envelope(n, bins), zoom, e.delay)
            self._est_names[(e.method, e.axis)] = e.channel

    def add(self, start: int, data: dict[str, NDArray[np.float64]]) -> None:
        for axis, tr in self.axes.items():
            v = data[self._truth_names[axis]]
            tr.truth.add(start, v)
            tr.truth_zoom.add(start, v)
            for key, (env, zoom, _) in tr.estimates.items():
                x = data[self._est_names[key]]
                env.add(start, x)
                zoom.add(start, x)
