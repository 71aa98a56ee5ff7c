"""Frequency response function (FRF) estimation from excitation/response records.

Estimators (all return an :class:`FrfEstimate`):

* :func:`welch_frf` — H1 and H2 with the ordinary coherence from averaged, windowed cross and
  auto spectra (Welch); for chirp and random excitation.
* :func:`multisine_frf` — periodic excitation: the record is cut into whole periods, the
  spectra are taken per period with a rectangular window (no leakage for a periodic signal in
  steady state) and H1/H2/coherence are formed over the periods.
* :func:`stepped_sine_frf` — per-frequency lock-in: a least-squares sine fit (cos, sin, offset)
  of input and output over each dwell after a settling time; exact for a noiseless linear
  system in steady state.
* :func:`impact_frf` — impact (tap) tests: hits are found on the force channel, double hits
  and overloads (clipping) are rejected with one-line reasons, a force window and an
  exponential window are applied and H1/H2/coherence are formed over the accepted hits.

Generators :func:`chirp_signal`, :func:`multisine_signal` and :func:`stepped_sine_signal`
produce the matching excitations (seed 001 C11 uses a swept sine; seed 000 C5 and Ch. 4 tap
tests).

Record checks (:func:`check_records`) raise :class:`~millsense.core.errors.InputDataError` with
one line naming the channel: mismatched lengths, non-finite samples, a record too short for the
requested resolution, no excitation, and clipping (runs of samples held at the extreme value or
samples at a given full-scale level).

Notes
-----
With input u, output y and averaged spectra G_uu, G_yy, G_uy (G_uy = E[U* Y])::

    H1 = G_uy / G_uu,   H2 = G_yy / G_yu,   γ² = |G_uy|² / (G_uu G_yy) = H1 / H2.

Noise on the output only leaves H1 unbiased and biases |H2| upwards by 1 + G_nn/G_yy; noise on
the input only leaves H2 unbiased and biases |H1| downwards by G_uu/(G_uu + G_mm) (Bendat &
Piersol, Random Data, §9.1). The normalised random error of |H1| with n_d independent averages
is ε ≈ √(1 − γ²) / (|γ| √(2 n_d)) (Bendat & Piersol Eq. 9.90).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import InputDataError
from millsense.core.recording import Recording

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

__all__ = [
    "FrfEstimate",
    "ImpactHit",
    "check_records",
    "chirp_signal",
    "frf_from_recording",
    "h1_random_error",
    "impact_frf",
    "multisine_frf",
    "multisine_signal",
    "stepped_sine_frf",
    "stepped_sine_signal",
    "welch_frf",
]


@dataclass(frozen=True)
class FrfEstimate:
    """An estimated FRF with its coherence.

    Attributes
    ----------
    freq_hz : frequencies [Hz], ascending.
    h1 : H1 estimate [output unit / input unit].
    h2 : H2 estimate (equal to h1 where only one average exists, e.g. stepped sine).
    coherence : ordinary coherence γ² [-] (1 where undefined, e.g. stepped sine).
    n_averages : number of independent averages (segments, periods, hits or cycles fitted).
    method : "welch", "multisine", "stepped_sine" or "impact".
    pole_shift_rad_s : extra decay rate 1/τ [1/s] added to every pole by an exponential window
        (impact tests); a modal fit subtracts it from the fitted decay rates.
    notes : one-line remarks (e.g. reasons for rejected hits).
    """

    freq_hz: FloatArray
    h1: ComplexArray
    h2: ComplexArray
    coherence: FloatArray
    n_averages: int
    method: str
    pole_shift_rad_s: float = 0.0
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def h(self) -> ComplexArray:
        """The H1 estimate (the default for output noise)."""
        return self.h1

    def band(self, f_lo_hz: float, f_hi_hz: float) -> FrfEstimate:
        """The estimate restricted to ``f_lo_hz <= f <= f_hi_hz`` [Hz]."""
        sel = (self.freq_hz >= f_lo_hz) & (self.freq_hz <= f_hi_hz)
        if not sel.any():
            raise InputDataError(
                f"no FRF line in the band {f_lo_hz:g}-{f_hi_hz:g} Hz "
                f"(estimate covers {self.freq_hz[0]:g}-{self.freq_hz[-1]:g} Hz)"
            )
        return replace(
            self,
            freq_hz=self.freq_hz[sel],
            h1=self.h1[sel],
            h2=self.h2[sel],
            coherence=self.coherence[sel],
        )


def h1_random_error(coherence: ArrayLike, n_averages: int) -> FloatArray:
    """Normalised random error of |H1| (Bendat & Piersol Eq. 9.90).

    ``ε = √(1 − γ²) / (|γ| √(2 n_d))`` [-] for coherence γ² and n_d averages.
    """
    g2 = np.clip(np.asarray(coherence, dtype=float), 1e-12, 1.0)
    return np.asarray(np.sqrt(1.0 - g2) / (np.sqrt(g2) * math.sqrt(2.0 * n_averages)))


# ---------------------------------------------------------------------------------------------
# Record checks
# ---------------------------------------------------------------------------------------------


def _clipped(x: FloatArray, clip_level: float | None, run: int) -> str | None:
    """Reason if ``x`` looks clipped, else None."""
    peak = float(np.max(np.abs(x)))
    if peak == 0.0:
        return None
    if clip_level is not None and peak >= clip_level:
        n = int(np.count_nonzero(np.abs(x) >= clip_level))
        return f"{n} samples at or beyond the full-scale level {clip_level:g}"
    # A clipped converter holds its extreme code: a natural signal neither stays at its extreme
    # for `run` consecutive samples nor sits exactly at it in 1 % of its samples.
    at_max = np.abs(x) >= peak * (1.0 - 1e-12)
    n_at = int(at_max.sum())
    if n_at >= max(run, 0.01 * len(x)):
        return f"{n_at} samples ({n_at / len(x):.1%}) at its extreme value {peak:g}"
    if n_at >= run:
        pad = np.concatenate(([0], at_max.astype(np.int8), [0]))
        d = np.diff(pad)
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        longest = int((ends - starts).max())
        if longest >= run:
            return f"held at its extreme value {peak:g} for {longest} consecutive samples"
    return None


def check_records(
    u: ArrayLike,
    y: ArrayLike,
    sample_rate_hz: float,
    *,
    resolution_hz: float | None = None,
    names: tuple[str, str] = ("input", "output"),
    clip_levels: tuple[float | None, float | None] = (None, None),
    clip_run: int = 4,
) -> tuple[FloatArray, FloatArray]:
    """Validate an input/output record pair and return them as float arrays.

    Parameters
    ----------
    u, y : input and output samples (same length).
    sample_rate_hz : sampling rate [Hz].
    resolution_hz : requested frequency resolution [Hz]; the record must hold at least
        ``sample_rate_hz / resolution_hz`` samples.
    names : channel names used in the messages (input, output).
    clip_levels : full-scale levels of input and output [their units]; None to detect clipping
        only from samples held at the extreme value.
    clip_run : number of consecutive samples at the extreme value that count as clipping;
        1 % of the samples exactly at the extreme value also counts (a pure tone at fs/4 or
        another exact sub-multiple of the sampling rate trips this rule: give such records
        a slight frequency offset).

    Raises
    ------
    InputDataError
        One line naming the channel: lengths differ, non-finite samples, record too short,
        no excitation (input standard deviation zero or below 1e-9 of its mean level), clipped.
    """
    if not (sample_rate_hz > 0 and math.isfinite(sample_rate_hz)):
        raise InputDataError(f"sample rate must be positive, got {sample_rate_hz} Hz")
    ua = np.asarray(u, dtype=float)
    ya = np.asarray(y, dtype=float)
    for arr, nm in ((ua, names[0]), (ya, names[1])):
        if arr.ndim != 1:
            raise InputDataError(f"channel {nm!r} must be 1-D, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputDataError(f"channel {nm!r} has non-finite samples")
    if len(ua) != len(ya):
        raise InputDataError(
            f"channels {names[0]!r} ({len(ua)} samples) and {names[1]!r} ({len(ya)} samples) "
            "have different lengths"
        )
    if resolution_hz is not None:
        need = math.ceil(sample_rate_hz / resolution_hz - 1e-9)
        if len(ua) < need:
            raise InputDataError(
                f"channel {names[0]!r} has {len(ua)} samples, too short for a "
                f"{resolution_hz:g} Hz resolution at {sample_rate_hz:g} Hz (needs {need})"
            )
    level = float(np.max(np.abs(ua))) if len(ua) else 0.0
    if len(ua) < 2 or float(np.std(ua)) <= 1e-9 * max(level, 1e-300):
        raise InputDataError(f"channel {names[0]!r} carries no excitation (zero variance)")
    for arr, nm, lvl in ((ua, names[0], clip_levels[0]), (ya, names[1], clip_levels[1])):
        why = _clipped(arr, lvl, clip_run)
        if why is not None:
            raise InputDataError(f"channel {nm!r} is clipped: {why}")
    return ua, ya


# ---------------------------------------------------------------------------------------------
# Excitation signals
# ---------------------------------------------------------------------------------------------


def chirp_signal(
    sample_rate_hz: float,
    duration_s: float,
    f0_hz: float,
    f1_hz: float,
    amplitude: float = 1.0,
    method: str = "logarithmic",
) -> FloatArray:
    """Swept sine from ``f0_hz`` to ``f1_hz`` [Hz] over ``duration_s`` [s] (seed 001 C11)."""
    t = np.arange(round(duration_s * sample_rate_hz)) / sample_rate_hz
    return np.asarray(
        amplitude * scipy.signal.chirp(t, f0_hz, duration_s, f1_hz, method=method), dtype=float
    )


def multisine_signal(
    sample_rate_hz: float,
    period_samples: int,
    f_lo_hz: float,
    f_hi_hz: float,
    n_periods: int,
    rms: float = 1.0,
) -> tuple[FloatArray, FloatArray]:
    """Periodic multisine with Schroeder phases (low crest factor).

    Every DFT line of the period between ``f_lo_hz`` and ``f_hi_hz`` [Hz] is excited with equal
    amplitude. Returns the signal (``n_periods`` periods, RMS ``rms``) and the excited line
    frequencies [Hz].

    Notes
    -----
    Schroeder phases φ_k = −π k (k − 1) / K for the K excited lines (Schroeder 1970).
    """
    df = sample_rate_hz / period_samples
    k = np.arange(math.ceil(f_lo_hz / df), math.floor(f_hi_hz / df) + 1)
    k = k[(k > 0) & (k < period_samples // 2)]
    if len(k) == 0:
        raise InputDataError(f"no DFT line in {f_lo_hz:g}-{f_hi_hz:g} Hz for this period")
    idx = np.arange(len(k))
    spec = np.zeros(period_samples // 2 + 1, dtype=complex)
    spec[k] = np.exp(-1j * np.pi * idx * (idx - 1) / len(k))
    x = np.fft.irfft(spec, n=period_samples)
    x *= rms / float(np.sqrt(np.mean(x**2)))
    return np.tile(x, n_periods), np.asarray(k * df, dtype=float)


def stepped_sine_signal(
    sample_rate_hz: float,
    freqs_hz: Sequence[float],
    settle_s: float,
    dwell_s: float,
    amplitude: float = 1.0,
) -> FloatArray:
    """Stepped sine: for each frequency, ``settle_s + dwell_s`` [s] of a sine of that frequency.

    Each step starts at zero phase; :func:`stepped_sine_frf` with the same schedule analyses it.
    """
    n_step = round((settle_s + dwell_s) * sample_rate_hz)
    t = np.arange(n_step) / sample_rate_hz
    return np.concatenate([amplitude * np.sin(2 * np.pi * f * t) for f in freqs_hz])


# ---------------------------------------------------------------------------------------------
# Estimators
# ---------------------------------------------------------------------------------------------


def _from_spectra(
    guu: FloatArray, gyy: FloatArray, guy: ComplexArray
) -> tuple[ComplexArray, ComplexArray, FloatArray]:
    tiny = 1e-300
    h1 = np.asarray(guy / np.maximum(guu, tiny), dtype=np.complex128)
    h2 = np.asarray(gyy / np.where(np.abs(guy) > tiny, np.conj(guy), tiny), dtype=np.complex128)
    coh = np.abs(guy) ** 2 / np.maximum(guu * gyy, tiny)
    return h1, h2, np.clip(coh, 0.0, 1.0)


def welch_frf(
    u: ArrayLike,
    y: ArrayLike,
    sample_rate_hz: float,
    *,
    resolution_hz: float,
    window: str = "hann",
    overlap: float = 0.5,
    names: tuple[str, str] = ("input", "output"),
    clip_levels: tuple[float | None, float | None] = (None, None),
) -> FrfEstimate:
    """H1, H2 and coherence from Welch-averaged spectra (chirp or random excitation).

    Parameters
    ----------
    u, y : input and output records (same length, same units as the FRF wanted).
    sample_rate_hz : sampling rate [Hz].
    resolution_hz : line spacing [Hz]; the segment length is ``round(fs / resolution_hz)``.
    window : scipy window name for each segment.
    overlap : fraction of segment overlap, in [0, 1).
    names : channel names for error messages.
    clip_levels : full-scale levels (see :func:`check_records`).

    Notes
    -----
    Spectra by ``scipy.signal.csd``/``welch`` (one-sided, linear detrend off, mean removed per
    segment); the number of averages counted is the number of segments.
    """
    ua, ya = check_records(
        u, y, sample_rate_hz, resolution_hz=resolution_hz, names=names, clip_levels=clip_levels
    )
    nseg = round(sample_rate_hz / resolution_hz)
    nover = round(overlap * nseg)
    kw = dict(fs=sample_rate_hz, window=window, nperseg=nseg, noverlap=nover, detrend="constant")
    f, guu = scipy.signal.welch(ua, **kw)
    _, gyy = scipy.signal.welch(ya, **kw)
    _, guy = scipy.signal.csd(ua, ya, **kw)
    h1, h2, coh = _from_spectra(guu, gyy, guy)
    n_avg = 1 + (len(ua) - nseg) // (nseg - nover)
    f = np.asarray(f, dtype=float)
    return FrfEstimate(f[1:], h1[1:], h2[1:], coh[1:], n_avg, "welch")


def multisine_frf(
    u: ArrayLike,
    y: ArrayLike,
    sample_rate_hz: float,
    period_samples: int,
    *,
    skip_periods: int = 1,
    lines_hz: ArrayLike | None = None,
    names: tuple[str, str] = ("input", "output"),
    clip_levels: tuple[float | None, float | None] = (None, None),
) -> FrfEstimate:
    """H1, H2 and coherence from a periodic excitation, averaged over whole periods.

    Parameters
    ----------
    u, y : records containing whole periods of a periodic excitation and its response.
    sample_rate_hz : sampling rate [Hz].
    period_samples : samples per period.
    skip_periods : leading periods discarded (transient).
    lines_hz : excited lines [Hz] to return (default: lines where the input spectrum exceeds
        1e-6 of its maximum).
    names, clip_levels : see :func:`check_records`.

    Notes
    -----
    Per period p, U_p and Y_p are the DFT of the period (rectangular window, exact for a
    periodic steady state); G_uu = mean |U_p|², G_yy = mean |Y_p|², G_uy = mean U_p* Y_p.
    """
    ua, ya = check_records(
        u,
        y,
        sample_rate_hz,
        resolution_hz=sample_rate_hz / period_samples,
        names=names,
        clip_levels=clip_levels,
    )
    n_per = len(ua) // period_samples - skip_periods
    if n_per < 1:
        raise InputDataError(
            f"channel {names[0]!r} holds {len(ua) // period_samples} periods of "
            f"{period_samples} samples; need more than the {skip_periods} skipped"
        )
    a, b = skip_periods * period_samples, (skip_periods + n_per) * period_samples
    U = np.fft.rfft(ua[a:b].reshape(n_per, period_samples), axis=1)
    Y = np.fft.rfft(ya[a:b].reshape(n_per, period_samples), axis=1)
    f = np.asarray(np.fft.rfftfreq(period_samples, 1.0 / sample_rate_hz), dtype=float)
    guu = np.mean(np.abs(U) ** 2, axis=0)
    gyy = np.mean(np.abs(Y) ** 2, axis=0)
    guy = np.mean(np.conj(U) * Y, axis=0)
    if lines_hz is None:
        sel = np.flatnonzero((guu > 1e-6 * guu.max()) & (f > 0))
    else:
        sel = np.rint(np.asarray(lines_hz, dtype=float) * period_samples / sample_rate_hz)
        sel = sel.astype(int)
    h1, h2, coh = _from_spectra(guu[sel], gyy[sel], guy[sel])
    return FrfEstimate(f[sel], h1, h2, coh, n_per, "multisine")


def _sine_fit(x: FloatArray, t: FloatArray, f_hz: float) -> complex:
    """Complex amplitude X of ``x ≈ Re(X e^{iωt}) + c`` by linear least squares."""
    w = 2 * np.pi * f_hz
    a = np.column_stack([np.cos(w * t), -np.sin(w * t), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(a, x, rcond=None)
    return complex(coef[0], coef[1])


def stepped_sine_frf(
    u: ArrayLike,
    y: ArrayLike,
    sample_rate_hz: float,
    freqs_hz: Sequence[float],
    settle_s: float,
    dwell_s: float,
    *,
    names: tuple[str, str] = ("input", "output"),
    clip_levels: tuple[float | None, float | None] = (None, None),
) -> FrfEstimate:
    """FRF at each step of a stepped sine by a per-frequency lock-in (least-squares sine fit).

    Parameters
    ----------
    u, y : records of the schedule of :func:`stepped_sine_signal` (same ``freqs_hz``,
        ``settle_s``, ``dwell_s``).
    sample_rate_hz : sampling rate [Hz].
    freqs_hz : step frequencies [Hz].
    settle_s : time discarded at the start of each step [s] (transient).
    dwell_s : analysed time of each step [s].

    Notes
    -----
    For each step the complex amplitudes U, Y of ``Re(X e^{iωt}) + c`` are fitted by least
    squares over the dwell, and ``H = Y / U``. For a noiseless linear system in steady state the
    fit is exact (the model contains the signal), so H is exact at the step frequencies. The
    coherence returned is the fraction of output variance explained by the fitted sine.
    """
    ua, ya = check_records(u, y, sample_rate_hz, names=names, clip_levels=clip_levels)
    n_settle = round(settle_s * sample_rate_hz)
    n_step = round((settle_s + dwell_s) * sample_rate_hz)
    if len(ua) < n_step * len(freqs_hz):
        raise InputDataError(
            f"channel {names[0]!r} has {len(ua)} samples, fewer than the "
            f"{n_step * len(freqs_hz)} of {len(freqs_hz)} steps of {n_step}"
        )
    t = np.arange(n_settle, n_step) / sample_rate_hz
    h = np.empty(len(freqs_hz), dtype=complex)
    coh = np.empty(len(freqs_hz))
    for i, fr in enumerate(freqs_hz):  # one fit per frequency step (not per sample)
        seg = slice(i * n_step + n_settle, (i + 1) * n_step)
        cu = _sine_fit(ua[seg], t, fr)
        cy = _sine_fit(ya[seg], t, fr)
        if abs(cu) == 0.0:
            raise InputDataError(f"channel {names[0]!r} carries no excitation at {fr:g} Hz")
        h[i] = cy / cu
        yv = float(np.var(ya[seg]))
        coh[i] = min(1.0, 0.5 * abs(cy) ** 2 / yv) if yv > 0 else 1.0
    return FrfEstimate(np.asarray(freqs_hz, float), h, h.copy(), coh, 1, "stepped_sine")


# ---------------------------------------------------------------------------------------------
# Impact tests
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ImpactHit:
    """One detected hit: start sample, peak force [N] and the reason it was rejected (or "")."""

    start: int
    peak: float
    rejected: str = ""


def _find_hits(force: FloatArray, threshold: float, min_gap: int) -> NDArray[np.int64]:
    """Sample indices where |force| first rises above ``threshold`` after ``min_gap`` quiet."""
    above = np.abs(force) >= threshold
    idx = np.flatnonzero(above)
    if len(idx) == 0:
        return idx
    keep = np.concatenate(([True], np.diff(idx) > min_gap))
    return idx[keep]


def impact_frf(
    force: ArrayLike,
    response: ArrayLike,
    sample_rate_hz: float,
    *,
    record_s: float,
    trigger_fraction: float = 0.1,
    pre_trigger_s: float = 0.002,
    pulse_s: float = 0.003,
    exp_tau_s: float | None = None,
    double_hit_fraction: float = 0.1,
    force_clip_level: float | None = None,
    response_clip_level: float | None = None,
    names: tuple[str, str] = ("force", "response"),
) -> FrfEstimate:
    """H1, H2 and coherence averaged over the accepted hits of an impact test.

    Parameters
    ----------
    force, response : hammer force [N] and response records.
    sample_rate_hz : sampling rate [Hz].
    record_s : analysed length per hit [s] (sets the resolution 1/record_s).
    trigger_fraction : a hit starts where |force| exceeds this fraction of the largest peak.
    pre_trigger_s : samples kept before the trigger [s].
    pulse_s : force window length after the trigger [s]; the force outside the pulse (noise,
        rebound) is set to zero by a half-cosine-tapered window.
    exp_tau_s : time constant τ [s] of the exponential window applied to force and response;
        None chooses τ so that the window falls to 1 % at the end of the record. The window
        adds 1/τ to the decay rate of every pole; the estimate carries it in
        ``pole_shift_rad_s`` for the modal fit to remove.
    double_hit_fraction : a second force peak after the pulse above this fraction of the main
        peak rejects the hit ("double hit").
    force_clip_level, response_clip_level : full-scale levels; a hit reaching them, or held at
        its extreme value, is rejected ("overload").
    names : channel names for messages.

    Returns
    -------
    FrfEstimate with ``notes`` holding one line per rejected hit.

    Raises
    ------
    InputDataError
        If the records are unusable or no hit is accepted (the message gives the reasons).

    Notes
    -----
    Exponential window w(t) = exp(−t/τ) from the trigger: h(t)·w(t) ↔ H(s + 1/τ), so each pole
    p becomes p − 1/τ with unchanged residue; ζ_true ω = ζ_fit ω − 1/τ.
    """
    fa = np.asarray(force, dtype=float)
    ra = np.asarray(response, dtype=float)
    if len(fa) != len(ra):
        raise InputDataError(
            f"channels {names[0]!r} ({len(fa)} samples) and {names[1]!r} ({len(ra)} samples) "
            "have different lengths"
        )
    for arr, nm in ((fa, names[0]), (ra, names[1])):
        if not np.all(np.isfinite(arr)):
            raise InputDataError(f"channel {nm!r} has non-finite samples")
    fs = sample_rate_hz
    n_rec = round(record_s * fs)
    n_pre = round(pre_trigger_s * fs)
    n_pulse = max(2, round(pulse_s * fs))
    if len(fa) < n_rec:
        raise InputDataError(
            f"channel {names[0]!r} has {len(fa)} samples, too short for a {record_s:g} s "
            f"record ({1 / record_s:g} Hz resolution) at {fs:g} Hz"
        )
    peak_all = float(np.max(np.abs(fa)))
    if peak_all == 0.0 or float(np.std(fa)) <= 1e-9 * peak_all:
        raise InputDataError(f"channel {names[0]!r} carries no excitation (no hit found)")
    starts = _find_hits(fa, trigger_fraction * peak_all, n_rec)
    tau = exp_tau_s if exp_tau_s is not None else record_s / math.log(100.0)
    t = np.arange(n_rec) / fs
    w_exp = np.exp(-np.clip(t - n_pre / fs, 0.0, None) / tau)
    w_force = np.zeros(n_rec)
    taper = max(1, n_pulse // 4)
    w_force[: n_pre + n_pulse] = 1.0
    w_force[n_pre + n_pulse : n_pre + n_pulse + taper] = (
        0.5
        * (1 + np.cos(np.pi * np.arange(taper) / taper))[
            : max(0, min(taper, n_rec - n_pre - n_pulse))
        ]
    )
    hits: list[ImpactHit] = []
    F_list, R_list = [], []
    for k, s0 in enumerate(starts):  # loop over hits, not samples
        a = int(s0) - n_pre
        b = a + n_rec
        if a < 0 or b > len(fa):
            hits.append(ImpactHit(int(s0), 0.0, f"hit {k + 1} at sample {s0}: record truncated"))
            continue
        fseg, rseg = fa[a:b], ra[a:b]
        pk = float(np.max(np.abs(fseg[: n_pre + n_pulse])))
        after = np.abs(fseg[n_pre + n_pulse :])
        why = ""
        if after.size and after.max() > double_hit_fraction * pk:
            j = int(np.argmax(after)) + n_pulse
            why = (
                f"hit {k + 1} at {s0 / fs:.4f} s: double hit ({after.max():.3g} {names[0]} "
                f"peak {j / fs * 1e3:.1f} ms after the trigger, {after.max() / pk:.0%} of "
                f"the first)"
            )
        else:
            for arr, nm, lvl in ((fseg, names[0], force_clip_level),
                                 (rseg, names[1], response_clip_level)):  # fmt: skip
                c = _clipped(arr, lvl, 3)
                if c is not None:
                    why = f"hit {k + 1} at {s0 / fs:.4f} s: overload of {nm!r} ({c})"
                    break
        hits.append(ImpactHit(int(s0), pk, why))
        if not why:
            F_list.append(np.fft.rfft((fseg - np.mean(fseg[:n_pre] if n_pre else 0.0))
                                      * w_force * w_exp))  # fmt: skip
            R_list.append(np.fft.rfft((rseg - np.mean(rseg[:n_pre] if n_pre else 0.0)) * w_exp))
    reasons = tuple(h.rejected for h in hits if h.rejected)
    if not F_list:
        detail = "; ".join(reasons) if reasons else "no hit found"
        raise InputDataError(f"channel {names[0]!r}: no usable hit ({detail})")
    F = np.array(F_list)
    R = np.array(R_list)
    guu = np.mean(np.abs(F) ** 2, axis=0)
    gyy = np.mean(np.abs(R) ** 2, axis=0)
    guy = np.mean(np.conj(F) * R, axis=0)
    h1, h2, coh = _from_spectra(guu, gyy, guy)
    f = np.asarray(np.fft.rfftfreq(n_rec, 1.0 / fs), dtype=float)
    return FrfEstimate(f[1:], h1[1:], h2[1:], coh[1:], len(F_list), "impact", 1.0 / tau, reasons)


# ---------------------------------------------------------------------------------------------
# Recordings
# ---------------------------------------------------------------------------------------------


def frf_from_recording(
    rec: Recording,
    input_channel: str,
    output_channel: str,
    *,
    method: str = "welch",
    **kwargs: object,
) -> FrfEstimate:
    """FRF between two channels of a recording; errors name the channels.

    Parameters
    ----------
    rec : the recording (its sample rate is used).
    input_channel, output_channel : channel names.
    method : "welch", "multisine", "stepped_sine" or "impact".
    kwargs : passed to the estimator (e.g. ``resolution_hz`` for Welch).
    """
    for nm in (input_channel, output_channel):
        if nm not in rec:
            raise InputDataError(
                f"channel {nm!r} is not in the recording (has: {', '.join(rec.channel_names)})"
            )
    u = rec.channel(input_channel)
    y = rec.channel(output_channel)
    fs = rec.sample_rate_hz
    names = (input_channel, output_channel)
    funcs = {
        "welch": welch_frf,
        "multisine": multisine_frf,
        "stepped_sine": stepped_sine_frf,
        "impact": impact_frf,
    }
    if method not in funcs:
        raise InputDataError(f"unknown FRF method {method!r} (use one of {', '.join(funcs)})")
    return funcs[method](u, y, fs, names=names, **kwargs)  # type: ignore[operator]
