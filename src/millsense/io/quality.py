"""Data quality of a recording made outside millsense (decision 1701): what a real file has
and a simulation does not, each found with its numbers.

Every check is vectorised numpy over whole channels:

* :func:`rate_from_time` — the effective rate of a time column (mean step over the steps that
  are not gaps) against the stated one; gaps (steps > 1.5 nominal) and non-monotonic time;
* :func:`rate_from_angle_speed` — the effective rate without a time column, from an encoder
  angle and the speed the drive reports beside it (``<axis>/motor_angle``,
  ``<axis>/motor_speed``): over windows of ``m`` samples the angle advances by
  ``Δθ = Σω / f_s``, so the least-squares ``f_s = Σ S·Δθ / Σ Δθ²`` (``S`` = sum of the speed
  over the window) is independent of the stated rate;
* :func:`repeated_rows` — runs of rows where every continuously varying channel of one file
  repeats its previous sample exactly (up-sampling by hold, duplicated buffers), with start
  and length; runs no longer than the channels' quantisation repeats by chance are not
  reported (decision 1703);
* :func:`clipped_runs` — flat tops at a channel's own maximum or minimum longer than any hold
  the channel shows elsewhere (a converter or amplifier at its rail);
* :func:`nan_runs`, :func:`is_constant`;
* :func:`mains_hum` — 50 or 60 Hz and harmonics standing 20 dB above the spectrum around
  them, unless the line is a multiple of the spindle rotation;
* :func:`offset_drift` — a steady change of the mean across the quiet stretches (at rest / in
  air) of an external sensor (force, torque, acceleration, sound, voltage).

:func:`check_recording` runs them on a :class:`~millsense.core.recording.Recording`;
:class:`QualityReport` holds the findings (warnings, refusals) and serialises to JSON.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from millsense.core.recording import COMPUTED_CHANNELS, TRUTH_PREFIX, Recording

__all__ = [
    "CHANCE_RUN_PROBABILITY",
    "RATE_TOLERANCE",
    "Finding",
    "QualityReport",
    "chance_repeat_probability",
    "check_recording",
    "clipped_runs",
    "is_constant",
    "mains_hum",
    "nan_runs",
    "offset_drift",
    "rate_from_angle_speed",
    "rate_from_time",
    "repeated_rows",
    "runs_of",
]

#: A measured rate further than this from the stated one is reported (fraction).
RATE_TOLERANCE = 1e-3
#: A time step longer than this many nominal periods is a gap.
GAP_FACTOR = 1.5
#: A step shorter than this share of the median step is refused: two rows within less than half
#: a sample period are no regular sampling (a logger's write times, a merged file), and no
#: uniform grid holds both. Jitter within it is resampled linearly (reported).
MIN_STEP_SHARE = 0.5
#: A channel is "continuous" (checked for repeats and clipping) when at least this fraction
#: of its steps change the value.
CONTINUOUS_FRACTION = 0.95
#: A run of repeated rows is reported only when chance (the columns' quantisation repeating
#: a value) would give a run as long anywhere in the file with less than this probability
#: (decision 1703).
CHANCE_RUN_PROBABILITY = 0.01
#: Mains lines: a line this many times the median spectrum around it (20 dB).
HUM_RATIO = 10.0
#: ... and this many times the 99th percentile of that spectrum, away from the spindle's
#: lines: a line of a comb (a periodic motion's harmonics, every 1/15 Hz of a position
#: reversing every 15 s) has its like all around it and is no mains hum.
HUM_COMB_RATIO = 3.0
#: Units of external sensors whose offset may drift (charge amplifiers, IEPE, microphones).
DRIFT_UNITS = ("N", "N*m", "m/s^2", "Pa", "V")


@dataclass
class Finding:
    """One thing found: ``kind`` (rate, gap, time, repeated, clipped, nan, constant, hum,
    drift), the channel or file it is about, ``refuse`` when the data cannot be used, a
    one-line message with the numbers, and the numbers themselves (``data``)."""

    kind: str
    where: str
    message: str
    refuse: bool = False
    data: dict[str, Any] = field(default_factory=dict)


@dataclass
class QualityReport:
    """All findings of one import or check; ``rates`` maps a file or pair to
    (stated, measured) Hz."""

    findings: list[Finding] = field(default_factory=list)
    rates: dict[str, tuple[float | None, float]] = field(default_factory=dict)

    def add(self, f: Finding) -> None:
        """Append a finding."""
        self.findings.append(f)

    @property
    def refusals(self) -> list[Finding]:
        """Findings that make the data unusable."""
        return [f for f in self.findings if f.refuse]

    def of_kind(self, kind: str) -> list[Finding]:
        """Findings of one kind."""
        return [f for f in self.findings if f.kind == kind]

    def to_json(self) -> str:
        """The report as JSON (stored in an imported recording's ``quality_json``)."""
        return json.dumps(
            {
                "findings": [asdict(f) for f in self.findings],
                "rates": {k: list(v) for k, v in self.rates.items()},
            }
        )

    @classmethod
    def from_json(cls, text: str) -> QualityReport:
        """Inverse of :meth:`to_json`."""
        d = json.loads(text)
        rep = cls([Finding(**f) for f in d.get("findings", [])])
        rep.rates = {k: (v[0], v[1]) for k, v in d.get("rates", {}).items()}
        return rep


def finding_counts(text: str) -> str | None:
    """``"10 findings (gap 1, hum 1, ...)"``: the findings of a stored report
    (:meth:`QualityReport.to_json`) per kind, in one line; None if it is no such JSON."""
    try:
        findings = json.loads(text).get("findings", [])
        kinds = Counter(str(f.get("kind")) for f in findings)
    except (ValueError, AttributeError, TypeError):
        return None
    per_kind = ", ".join(f"{k} {n}" for k, n in sorted(kinds.items())) or "none"
    return f"{sum(kinds.values())} findings ({per_kind})"


def runs_of(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Starts and lengths of the runs of True in ``mask``."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2]
    return starts.astype(np.int64), (stops - starts).astype(np.int64)


# ------------------------------------------------------------------------------ time and rate
def _refuse_steps(report: QualityReport, where: str, steps: np.ndarray, what: str) -> None:
    """The refusal of a time column at its first offending step (``steps``, indices into the
    steps): one line naming ``where`` and the table row, the row and count in its data."""
    report.add(Finding("time", where, f"{where}: {what}", refuse=True,
                       data={"row": int(steps[0]) + 1, "count": int(steps.size)}))  # fmt: skip


def rate_from_time(
    t: NDArray[np.float64], stated_hz: float | None, where: str, report: QualityReport
) -> tuple[float, NDArray[np.int64], NDArray[np.int64]]:
    """Effective rate of a time column; gaps and non-monotonic time as findings.

    Parameters
    ----------
    t : times, s.
    stated_hz : the rate the file or map states (None: none stated).
    where : file name for the messages.

    Returns
    -------
    fs : measured rate, Hz: (number of regular steps) / (their total duration).
    gap_rows : rows after which a gap starts.
    gap_missing : samples missing in each gap (round(step·fs) − 1).

    Notes
    -----
    The nominal step is the median step; a step > 1.5 nominal is a gap, ≤ 0 is time going
    backwards or standing, < :data:`MIN_STEP_SHARE` nominal irregular time (refusals naming the
    row).
    """
    dt = np.diff(np.asarray(t, dtype=np.float64))
    if dt.size < 2:
        report.add(Finding("time", where, f"{where}: fewer than 3 samples", refuse=True))
        return float(stated_hz or 1.0), np.zeros(0, np.int64), np.zeros(0, np.int64)
    refused = (float(stated_hz or 1.0), np.zeros(0, np.int64), np.zeros(0, np.int64))
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = int(bad[0])
        _refuse_steps(report, where, bad,
                      f"time does not increase at row {k + 2} of the table ({t[k]:.9g} s then "
                      f"{t[k + 1]:.9g} s; {bad.size} such steps)")  # fmt: skip
        # refused: no rate to measure (a column standing still has no regular step at all)
        return refused
    nominal = float(np.median(dt))
    short = np.flatnonzero(dt < MIN_STEP_SHARE * nominal)
    if short.size:
        k = int(short[0])
        _refuse_steps(report, where, short,
                      f"irregular time column: a step of {dt[k] * 1e3:.6g} ms after "
                      f"{t[k]:.9g} s at row {k + 2} of the table, less than "
                      f"{MIN_STEP_SHARE:g} x the median step {nominal * 1e3:.6g} ms "
                      f"({short.size} such steps): give [[files]] time_column = \"\" and "
                      "sample_rate_hz if the rows are evenly sampled")  # fmt: skip
        return refused
    regular = (dt > 0) & (dt <= GAP_FACTOR * nominal)
    fs = float(np.count_nonzero(regular) / np.sum(dt[regular]))
    gap_rows = np.flatnonzero(dt > GAP_FACTOR * nominal).astype(np.int64)
    gap_missing = (np.rint(dt[gap_rows] * fs) - 1).astype(np.int64)
    for r, miss in zip(gap_rows, gap_missing, strict=True):
        report.add(
            Finding(
                "gap",
                where,
                f"{where}: gap of {dt[r] * 1e3:.4g} ms after t = {t[r]:.6g} s "
                f"({int(miss)} samples missing, filled by linear interpolation)",
                data={
                    "row": int(r),
                    "t_s": float(t[r]),
                    "duration_s": float(dt[r]),
                    "missing": int(miss),
                },
            )
        )
    total_missing = int(gap_missing.sum())
    if total_missing > 0.1 * (t.size + total_missing):
        report.add(
            Finding(
                "gap",
                where,
                f"{where}: {total_missing} samples missing in gaps, more than 10 % of the record",
                refuse=True,
            )
        )
    _rate_finding(where, stated_hz, fs, "time column", report)
    return fs, gap_rows, gap_missing


def _rate_finding(
    where: str, stated: float | None, measured: float, how: str, report: QualityReport
) -> None:
    report.rates[where] = (stated, measured)
    if stated is not None and abs(measured / stated - 1.0) > RATE_TOLERANCE:
        report.add(
            Finding(
                "rate",
                where,
                f"{where}: stated rate {stated:.6g} Hz, measured {measured:.6g} Hz from the "
                f"{how} ({100 * (measured / stated - 1):+.2f} %); the measured rate is used",
                data={"stated_hz": stated, "measured_hz": measured, "how": how},
            )
        )


def rate_from_angle_speed(
    angle: NDArray[np.float64],
    speed: NDArray[np.float64],
    exclude: NDArray[np.bool_] | None = None,
    window: int = 64,
) -> float | None:
    """Effective rate (Hz) from an angle and its speed (rad, rad/s), or None if it hardly moves.

    Parameters
    ----------
    angle, speed : one encoder's angle and the speed reported beside it.
    exclude : samples not to use (repeated rows, filled gaps, NaN).
    window : samples per window.

    Notes
    -----
    With the speed the backward difference of the angle (what a drive reports),
    :math:`\\theta_{k+m} - \\theta_k = \\frac{1}{f_s}\\sum_{j=k+1}^{k+m} \\omega_j` exactly;
    for a filtered speed the relation holds to the filter's lag over windows much longer
    than it. ``f_s = ΣSΔθ/ΣΔθ²`` over the windows with motion.
    """
    th = np.asarray(angle, dtype=np.float64)
    w = np.asarray(speed, dtype=np.float64)
    n = (th.size - 1) // window
    if n < 4:
        return None
    idx = np.arange(n + 1) * window
    d_th = th[idx[1:]] - th[idx[:-1]]
    cs = np.concatenate([[0.0], np.cumsum(w[1:])])
    s = cs[idx[1:]] - cs[idx[:-1]]
    ok = np.isfinite(d_th) & np.isfinite(s)
    if exclude is not None:
        ex = np.concatenate([[0], np.cumsum(np.asarray(exclude, dtype=np.int64))])
        ok &= (ex[idx[1:] + 1] - ex[idx[:-1]]) == 0
    moving = np.abs(d_th) > 1e-3 * max(float(np.max(np.abs(d_th[ok]), initial=0.0)), 1e-300)
    ok &= moving
    if np.count_nonzero(ok) < 4 or not np.any(d_th[ok]):
        return None
    return float(np.sum(s[ok] * d_th[ok]) / np.sum(d_th[ok] ** 2))


# ------------------------------------------------------------------------------ samples
def _continuous(x: NDArray[np.float64]) -> bool:
    d = np.diff(x)
    return bool(d.size > 0 and np.count_nonzero(d) >= CONTINUOUS_FRACTION * d.size)


def chance_repeat_probability(x: NDArray[np.float64]) -> float:
    """Probability that a step of a quantised signal is exactly zero by chance.

    Where the steps' distribution is smooth on the scale of the quantum ``q`` (the smallest
    non-zero |step|), a step rounds to 0 about as often as to +q or to −q, so the chance of a
    zero step is half the fraction of steps of one quantum (|Δ| in (q/2, 3q/2]). Repeats made
    by holding or duplicating rows add zero steps, not steps of one quantum, so they do not
    raise the estimate. A column at full floating-point precision has almost no steps of its
    smallest size: its estimate is ≈ 1/(2n), and every repeat counts.
    """
    d = np.abs(np.diff(np.asarray(x, dtype=np.float64)))
    d = d[np.isfinite(d)]
    nz = d[d > 0]
    if nz.size == 0:
        return 1.0
    q = float(nz.min())
    one = np.count_nonzero((d > 0.5 * q) & (d <= 1.5 * q))
    return min(1.0, one / (2.0 * d.size))


def repeated_rows(
    columns: Mapping[str, NDArray[np.float64]], min_length: int = 2
) -> tuple[NDArray[np.int64], NDArray[np.int64], list[str]]:
    """Runs of rows where every continuously varying column repeats its previous sample.

    Returns starts (first row of the run, i.e. the sample that is repeated), lengths (rows
    holding the same values, the original included) and the columns that were used.
    Nothing is found when no column is continuous.

    Quantised columns repeat a value by chance (a 16-bit microphone at 44.1 kHz: a few hundred
    pairs of equal samples in 20 s). With ``p`` the product over the columns of
    :func:`chance_repeat_probability` and ``n`` the steps, chance gives about ``n·p^(L−1)``
    runs of ``L`` rows or more; a run is reported only when that is below
    :data:`CHANCE_RUN_PROBABILITY` (decision 1703).
    """
    cont = [c for c, x in columns.items() if x.size > 2 and _continuous(np.asarray(x))]
    if not cont:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), []
    same = np.ones(next(iter(columns.values())).size - 1, dtype=bool)
    p = 1.0
    for c in cont:
        x = np.asarray(columns[c])
        same &= np.diff(x) == 0
        p *= chance_repeat_probability(x)
    starts, lengths = runs_of(same)
    keep = lengths + 1 >= min_length
    if p > 0.0:
        with np.errstate(under="ignore"):
            keep &= same.size * p ** lengths.astype(np.float64) < CHANCE_RUN_PROBABILITY
    return starts[keep], lengths[keep] + 1, cont


def clipped_runs(
    x: NDArray[np.float64], exclude: NDArray[np.bool_] | None = None
) -> list[tuple[int, int, float]]:
    """Flat tops at the channel's maximum or minimum: (start, length, rail value).

    A run of equal samples at the extreme counts when it is at least 2 samples long and
    longer than every run of equal samples elsewhere in the channel (a channel that holds
    values by itself, e.g. a current command updated at a slower loop rate, must exceed its
    own longest hold; runs starting in ``exclude``, the repeated rows, are not such holds).
    Only continuously varying channels are checked (decision 1701).
    """
    x = np.asarray(x, dtype=np.float64)
    fin = np.isfinite(x)
    if not fin.all():
        return []  # NaN is reported (and refused or filled) on its own
    if x.size < 3:
        return []
    lo, hi = float(np.min(x)), float(np.max(x))
    if hi == lo:
        return []
    eq = np.diff(x) == 0
    starts, lengths = runs_of(eq)
    lengths = lengths + 1
    values = x[starts]
    at_rail = (values == hi) | (values == lo)
    d = np.diff(x)
    rail = (x == hi) | (x == lo)
    other = ~(rail[:-1] & rail[1:] & (d == 0))  # steps not inside a flat top
    n_other = int(np.count_nonzero(other))
    if n_other < 0.5 * d.size or np.count_nonzero(d[other]) < CONTINUOUS_FRACTION * n_other:
        return []
    elsewhere = ~at_rail
    if exclude is not None:
        elsewhere &= ~np.asarray(exclude, dtype=bool)[starts]
    natural = int(lengths[elsewhere].max()) if np.any(elsewhere) else 1
    need = max(2, natural + 1)
    pick = at_rail & (lengths >= need)
    return [
        (int(s), int(n), float(v))
        for s, n, v in zip(starts[pick], lengths[pick], values[pick], strict=True)
    ]


def nan_runs(x: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Starts and lengths of the runs of NaN/inf."""
    return runs_of(~np.isfinite(np.asarray(x, dtype=np.float64)))


def is_constant(x: NDArray[np.float64]) -> bool:
    """True if every finite sample has the same value."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    return x.size > 0 and float(np.max(x)) == float(np.min(x))


def mains_hum(
    x: NDArray[np.float64], fs: float, rotation_hz: float | None = None, n_harm: int = 5
) -> tuple[float, list[tuple[float, float, float]]] | None:
    """Mains hum: (mains Hz, [(line Hz, amplitude, ratio to the spectrum around it)...]) or None.

    Parameters
    ----------
    x : one channel; fs : its rate, Hz.
    rotation_hz : spindle rotation frequency; lines within 0.5 Hz of one of its multiples are
        the process, not the mains.

    Notes
    -----
    Hann-windowed amplitude spectrum of the whole channel (linear trend removed); a line is
    the peak within ±0.5 Hz of k·50 or k·60 Hz, compared with the median of the spectrum
    from −10 to +10 Hz around it (±1.5 Hz excluded). The fundamental must stand
    :data:`HUM_RATIO` above; harmonics are listed when they do too. A line must also reach
    half the channel's quantisation step (its smallest non-zero change between samples): below
    it the line is the rounding pattern of the file's resolution (a speed written to
    0.01 rev/min), and a constant channel has no hum; and it must stand :data:`HUM_COMB_RATIO`
    above the 99th percentile around it, away from the spindle's lines (a comb's line is no
    hum).
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    if n < fs or not np.all(np.isfinite(x)) or fs < 2 * 65:
        return None
    change = np.abs(np.diff(x))
    change = change[change > 0]
    if not change.size:
        return None  # constant
    least = 0.5 * float(change.min())
    k = np.arange(n)
    y = x - np.polyval(np.polyfit(k, x, 1), k)
    win = np.hanning(n)
    spec = np.abs(np.fft.rfft(y * win)) * 2.0 / win.sum()
    freqs = np.fft.rfftfreq(n, 1.0 / fs)

    def line(f: float) -> tuple[float, float] | None:
        if f + 10 >= fs / 2:
            return None
        near = np.abs(freqs - f) <= 0.5
        around = (np.abs(freqs - f) <= 10) & (np.abs(freqs - f) > 1.5)
        if not near.any() or not around.any():
            return None
        floor = float(np.median(spec[around]))
        peak = float(spec[near].max())
        if peak < least:
            return None
        if rotation_hz and rotation_hz > 0:  # the spindle's own lines are no comb
            r = freqs / rotation_hz
            around &= (np.abs(r - np.rint(r)) * rotation_hz > 1.0) | (np.rint(r) < 1)
        if around.any() and peak < HUM_COMB_RATIO * float(np.percentile(spec[around], 99)):
            return None
        return peak, peak / max(floor, 1e-300)

    def process_line(f: float) -> bool:
        if not rotation_hz or rotation_hz <= 0:
            return False
        r = f / rotation_hz
        return abs(r - round(r)) * rotation_hz < 0.5 and round(r) >= 1

    best: tuple[float, list[tuple[float, float, float]]] | None = None
    for mains in (50.0, 60.0):
        if process_line(mains):
            continue
        fund = line(mains)
        if fund is None or fund[1] < HUM_RATIO:
            continue
        lines = [(mains, fund[0], fund[1])]
        for h in range(2, n_harm + 1):
            got = line(h * mains)
            if got is not None and got[1] >= HUM_RATIO and not process_line(h * mains):
                lines.append((h * mains, got[0], got[1]))
        if best is None or fund[1] > best[1][0][2]:
            best = (mains, lines)
    return best


def offset_drift(
    x: NDArray[np.float64], fs: float, window_s: float = 0.05
) -> tuple[float, float, float] | None:
    """A steady offset change across the quiet stretches: (rate per s, change over the quiet
    span, quiet span s) or None.

    Notes
    -----
    Windows of ``window_s``; quiet windows have a standard deviation at most 3 times the
    10th percentile of all windows' (at rest, in air). A line is fitted to the quiet windows'
    means against time; it is a drift when the quiet windows span ≥ 0.2 s, the line explains
    ≥ 90 % of the means' variance and its change over the span exceeds 5 times the quiet
    windows' median standard deviation.
    """
    x = np.asarray(x, dtype=np.float64)
    m = max(round(window_s * fs), 4)
    nw = x.size // m
    if nw < 6 or not np.all(np.isfinite(x)):
        return None
    w = x[: nw * m].reshape(nw, m)
    mean, std = w.mean(axis=1), w.std(axis=1)
    quiet = std <= 3.0 * max(float(np.percentile(std, 10)), 1e-300)
    t = (np.arange(nw) + 0.5) * m / fs
    if np.count_nonzero(quiet) < 4:
        return None
    tq, mq = t[quiet], mean[quiet]
    span = float(tq[-1] - tq[0])
    if span < 0.2:
        return None
    slope, icpt = np.polyfit(tq, mq, 1)
    resid = mq - (slope * tq + icpt)
    var = float(np.var(mq))
    r2 = 1.0 - float(np.var(resid)) / var if var > 0 else 0.0
    change = float(slope) * span
    if r2 >= 0.9 and abs(change) > 5.0 * float(np.median(std[quiet])):
        return float(slope), change, span
    return None


# ------------------------------------------------------------------------------ the whole check
def _unit(unit: str) -> str:
    return "" if unit == "1" else " " + unit


def _rotation_hz(rec: Recording) -> float | None:
    if "spindle/speed" in rec:
        w = np.asarray(rec.channel("spindle/speed"), dtype=np.float64)
        w = w[np.isfinite(w)]
        if w.size:
            return float(np.median(np.abs(w))) / (2 * math.pi)
    rpm = rec.metadata.get("spindle_rpm")
    return float(rpm) / 60.0 if isinstance(rpm, int | float) else None


def check_recording(
    rec: Recording,
    report: QualityReport | None = None,
    channels: Sequence[str] | None = None,
    stated_hz: float | None = None,
) -> QualityReport:
    """Run every check on the measured channels of ``rec`` (truth channels and the channels
    the metadata's ``computed_channels`` lists are skipped).

    ``stated_hz``: the rate the source stated (default: the recording's rate); the rate is
    measured from every ``<axis>/motor_angle`` + ``<axis>/motor_speed`` pair that moves.
    """
    rep = report if report is not None else QualityReport()
    src = rec.source
    # what millsense computed from the data (a session's block outputs, where NaN means
    # "none": no chatter frequency, no threshold yet) is not the data (decision 1745)
    listed = rec.metadata.get(COMPUTED_CHANNELS)
    computed = {str(c) for c in listed} if isinstance(listed, list) else set()
    names = [c for c in (channels or rec.channel_names)
             if not c.startswith(TRUTH_PREFIX) and c not in computed]  # fmt: skip
    fs = rec.sample_rate_hz
    cols = {c: np.asarray(rec.channel(c), dtype=np.float64) for c in names}
    for c, x in cols.items():
        st, ln = nan_runs(x)
        if st.size:
            rep.add(
                Finding(
                    "nan",
                    c,
                    f"{src}: channel '{c}': {int(ln.sum())} NaN/inf samples "
                    f"in {st.size} runs, first at sample {int(st[0])} "
                    f"(t = {rec.t0_s + st[0] / fs:.6g} s)",
                    data={"starts": st.tolist(), "lengths": ln.tolist()},
                )
            )
        if is_constant(x):
            v = float(x[np.isfinite(x)][0])
            rep.add(
                Finding(
                    "constant",
                    c,
                    f"{src}: channel '{c}' is constant "
                    f"({v:.6g}{_unit(rec.info(c).unit)}): it carries no signal",
                    data={"value": v},
                )
            )
    st, ln, _ = repeated_rows(cols)
    for s, n in zip(st, ln, strict=True):
        rep.add(
            Finding(
                "repeated",
                src,
                f"{src}: samples {int(s)}–{int(s + n - 1)} "
                f"(t = {rec.t0_s + s / fs:.6g} s, {int(n)} samples) repeat one row "
                f"in every continuously varying channel (up-sampled or duplicated)",
                data={"start": int(s), "length": int(n), "t_s": rec.t0_s + s / fs},
            )
        )
    exclude = np.zeros(rec.n_samples, dtype=bool)
    for s, n in zip(st, ln, strict=True):
        exclude[s : s + n] = True
    for c, x in cols.items():
        runs = clipped_runs(x, exclude)
        if runs:
            total = sum(n for _, n, _ in runs)
            rails = sorted({v for _, _, v in runs})
            rep.add(
                Finding(
                    "clipped",
                    c,
                    f"{src}: channel '{c}' clipped at "
                    f"{', '.join(f'{v:.6g}' for v in rails)} {rec.info(c).unit}: "
                    f"{len(runs)} flat tops, {total} samples, first at sample "
                    f"{runs[0][0]} ({runs[0][1]} samples)",
                    data={"runs": [[s, n, v] for s, n, v in runs]},
                )
            )
    stated = stated_hz if stated_hz is not None else fs
    for c in names:
        if not c.endswith("/motor_angle"):
            continue
        speed = c.removesuffix("motor_angle") + "motor_speed"
        if speed not in cols:
            continue
        est = rate_from_angle_speed(cols[c], cols[speed], exclude)
        if est is not None:
            _rate_finding(
                f"{src} ({c}, {speed})", stated, est, f"angle/speed pair {c}, {speed}", rep
            )
    rot = _rotation_hz(rec)
    for c, x in cols.items():
        hum = mains_hum(x, fs, rot)
        if hum is not None:
            mains, lines = hum
            text = ", ".join(
                f"{f:g} Hz {a:.3g} {rec.info(c).unit} ({20 * math.log10(r):.0f} dB)"
                for f, a, r in lines
            )
            rep.add(
                Finding(
                    "hum",
                    c,
                    f"{src}: channel '{c}': {mains:g} Hz mains hum: {text}",
                    data={"mains_hz": mains, "lines": [list(v) for v in lines]},
                )
            )
        if rec.info(c).unit in DRIFT_UNITS:
            dr = offset_drift(x, fs)
            if dr is not None:
                slope, change, span = dr
                u = rec.info(c).unit
                rep.add(
                    Finding(
                        "drift",
                        c,
                        f"{src}: channel '{c}': offset drifts by "
                        f"{slope:+.4g} {u}/s ({change:+.4g} {u} over the {span:.3g} s "
                        "at rest)",
                        data={"per_s": slope, "change": change, "span_s": span},
                    )
                )
    return rep
