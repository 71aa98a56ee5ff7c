"""The chatter criteria, one per seed, on the spectra of one analysis window.

Each method turns the window's spectra (the raw signal's and the comb-filtered one's, see
:mod:`.comb`) into an *energy ratio* compared with its threshold and a chatter frequency:

- ``chatter-comb`` (seed 000, Aslan §5.4, Eq. 5.26–5.30): 4096-point spectrum (Eq. 5.30); the
  ratio is the largest comb-filtered (non-harmonic) peak over the raw signal's tooth-passing
  line, chatter above **1.5**; the peak's frequency (parabolic interpolation) is ω_c. The
  peak is read as the line's amplitude, its bin corrected for where the line falls between
  the bins of the rectangular spectrum (:func:`line_amplitude`, decision 1551).
- ``chatter-sdft`` (seed 001, Yamada §2.10, Eq. 6-12): sliding DFT over a rectangular
  window and the moving variance. The variance of a window is its total PSD without DC
  (Parseval, Koike's moving variance); the ratio is the variance of the comb residual in the
  band (the non-harmonic, chatter variance) over the variance of the spindle harmonics
  (raw-signal variance minus residual variance), chatter above **0.5** (the thesis gives no
  threshold: decision 1503, 0.5); the band's largest SDFT bin is f_c. The SDFT recursion
  ``S_k[n] = e^{j2πk/N}(S_k[n−1] + y[n] − y[n−N])`` gives at sample n exactly the DFT of the
  last N samples; it is read only at the decision instants, where it is computed by one FFT
  (identical values, decision 1503).
- ``chatter-threshold`` (seed 002, Munasinghe §2.6): the maximum of a 256-point windowed
  spectrum of the raw signal against a fixed threshold (given, or 2 × the largest maximum
  over the first second of the run, "set from stable cuts"; decision 1507). A baseline: it
  knows nothing of harmonics, tones or depth changes.

Robustness shared by the first two (decision 1504, in :mod:`.block`): a per-bin *background*
of the comb-filtered spectrum is learned (out of the cut in 0.5 s, in the cut in 2 s, new
components in 30 s); a component counts as chatter only where the spectrum exceeds 5 × its
background, so steady tones and stable resonances present before the cut or constant over
time are not called chatter; decisions are taken only while the tooth-passing line stands 3 ×
above the spectrum's median or the window's mean stands off the air mean (the tool is cutting),
the window's mean is steady (no entry or exit step) and the speed is steady; bins on the spindle
harmonics are not searched. After a speed change the background re-learns every bin for 0.5 s
before a verdict (lines whose frequency the speed sets, decision 1537). A window in the cut
whose mean steps is judged by ``chatter-comb`` on its part after the step (zero-padded, the
lines at a full window's amplitude, the background taken √(n/L) higher as the noise) when that
part resolves a line at the edge of the harmonics' excluded band (decision 1539). A window of
``chatter-comb`` that straddles an entry or an exit without a mean step is judged on its part
in the cut, not against the Hann-weighted tooth line of a window mostly in air, beside which
the comb's ring-down of the harmonics switched on or off read as chatter; ``chatter-sdft``
gives such a window no verdict (decision 1542).

A ``chatter-comb`` ratio above its threshold starts chatter only when the line also stands out
of its own window (decision 1658, :func:`line_level`): above the top 1 % of the searched bins
by the factor that Rayleigh noise with that tail reaches over the window's independent bins
with a chance of 1e-3. The seed's ratio compares the line with the tooth-passing line only, so
a compensated torque whose observer noise holds a dozen lines as strong as the tooth line (a
light full slot of a 3-flute tool) alarms on whichever of them is new to its background. While
chatter is flagged the test is not made (the 2 × novelty hold ends it, decision 1504). The
``energy_ratio`` output is the seed's ratio either way. The test compares the line's bin with
the window's bins, each read on the grid; the ratio takes the line's amplitude, and while
chatter is flagged the run lasts while the ratio stays above :data:`RUN_LEVEL` × the threshold
(decision 1551).

At an onset the ``chatter-comb`` line must also be power added to the window's band, not power
moved within it (decision 1687, :func:`adds_power`): the band's ``Σ comb²`` off the harmonics
must exceed the sum learned at the background's plain rate by half the line's ``A²``. A
compensated torque's encoder-quantisation lines (the drive's velocity PI on a quantised speed)
appear at a cut entry by the cut's dither moving their power from one line to another; a line
found to be moved power is learned at once (its lobe and the band's sum). With the drive
encoder's resolution known (decision 1697) the test is not made where the count rate moved by
more than the spindle frequency between the window's last two hops (no quantisation line
stands there, and the swept quantisation's power leaves the band), and elsewhere the midpoint
must be passed, either way, by the band's learned spread times the normal quantile of
:data:`LINE_FALSE_ALARM`; a line between is neither chatter nor learned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from millsense.monitoring.chatter import _kernels as _kn

FloatArray = NDArray[np.float64]

#: Seed 000 decision threshold (Aslan §5.4, digest P10).
SEED000_RATIO = 1.5
#: A chatter line must stand out of its own window's spectrum (decision 1658): the searched
#: bins' quantile that stands for the noise's own lines ...
LINE_QUANTILE = 0.99
#: ... and the chance per window that Rayleigh noise with that upper tail puts its largest bin
#: above the level asked of a chatter line.
LINE_FALSE_ALARM = 1e-3
#: A window whose ratio passes this fraction of the threshold starts (or continues) a rising
#: run (its first window is the alarm's ``onset_s``); such a window of chatter-comb that
#: straddles an entry or an exit is read against the tooth line of its part in the cut
#: (decision 1542). While chatter is flagged a chatter-comb line stays chatter above it
#: (decision 1551).
RUN_LEVEL = 0.5


@dataclass(slots=True)
class Spectra:
    """Spectra of one analysis window (one-sided amplitude, channel units). Made once per
    window and criterion and only read (a plain slotted dataclass: a frozen one's construction,
    a ``object.__setattr__`` per field, cost ≈ 3 µs of each window's decision).

    Attributes
    ----------
    f_hz : bin frequencies.
    raw, comb : amplitude spectra of the raw (mean removed) and comb-filtered window.
    band : bins searched for chatter.
    tooth : amplitude of the raw tooth-passing line, in the cut at least 3 × the noise floor
        (the cutting gate's level, decision 1531).
    f_tooth_hz, f_rev_hz : tooth-passing and spindle frequencies over the last hop.
    cutting : the tooth-passing line stands out (the tool is in the material).
    novel : comb amplitude above 5 × its learned background (≤ 0: nothing new).
    raw_rect : the raw window's rectangular spectrum (same taper as ``comb``; for Parseval).
    band_slice : ``band`` as the bins ``b0:b1`` (it is contiguous), or None to derive it.
    peak_bin : the band's largest bin of ``novel`` if known (−1: found by the criterion).
    masked : the bins not searched (spindle harmonics, known lines), or None (not known: the
        onset's line test of decision 1658 is not made).
    part : the fraction of the window the transformed samples fill (a part after a step,
        zero-padded: m / n; decision 1539).
    held : chatter is flagged (the onset's line test of decision 1658 is not made).
    band_excess : the band's ``Σ comb²`` off the spindle harmonics (a part's on a full
        window's scale) less the sum learned at the background's plain rate, or None (no
        learned sum: the power test of decision 1687 is not made).
    band_noise : the spread of ``band_excess`` learned at the same rate (its root mean square;
        a part's √(n/m) higher), N²·m² (decision 1697).
    sweeps : the encoder's count rate moved by more than the spindle frequency between the
        window's last two hops: no encoder-quantisation line stands in the window and the power
        test is not made (decision 1697).
    """

    f_hz: FloatArray
    raw: FloatArray
    comb: FloatArray
    band: NDArray[np.bool_]
    tooth: float
    f_tooth_hz: float
    f_rev_hz: float
    cutting: bool
    novel: FloatArray
    raw_rect: FloatArray | None = None
    band_slice: tuple[int, int] | None = None
    peak_bin: int = -1
    masked: NDArray[np.bool_] | None = None
    part: float = 1.0
    held: bool = False
    band_excess: float | None = None
    band_noise: float = 0.0
    sweeps: bool = False


@dataclass(slots=True)
class Verdict:
    """Outcome of one window: energy ratio (vs ``threshold``) and chatter frequency, Hz (made
    once per window and only read: slotted, not frozen, as :class:`Spectra`). ``stands_out``:
    the line stands out of its window's own spectrum (decision 1658; a ratio above the
    threshold without it is no chatter). ``hold``: while chatter is flagged, the level the
    ratio must stay above instead of the threshold (None: the threshold; decision 1551).
    ``moved``: the line stood out but is power moved within the band, not added to it (no
    chatter; the monitor learns the window's band as its background, decision 1687)."""

    ratio: float
    frequency_hz: float
    threshold: float
    stands_out: bool = True
    hold: float | None = None
    moved: bool = False

    @property
    def chatter(self) -> bool:
        level = self.threshold if self.hold is None else self.hold
        return bool(self.stands_out and self.ratio > level)


def line_level(
    amp: FloatArray,
    masked: NDArray[np.bool_],
    b0: int,
    b1: int,
    part: float = 1.0,
    peak: int = -1,
    quantile: float = LINE_QUANTILE,
    false_alarm: float = LINE_FALSE_ALARM,
) -> float:
    """The level a chatter line must exceed to stand out of its window's own spectrum
    (decision 1658): the ``quantile`` of the searched bins (``b0:b1`` less ``masked`` and less
    the main lobe of the line at bin ``peak``, if given) times
    ``√(ln(N_eff / p) / ln(1 / (1 − q)))``.

    For Gaussian noise the amplitude of a bin is Rayleigh distributed, ``P(A > a) =
    exp(−a² / 2σ²)``: its ``q`` quantile is ``σ√(−2 ln(1 − q))`` and the largest of ``N_eff``
    independent bins exceeds ``σ√(2 ln(N_eff / p))`` with probability ``p`` (``N_eff P(A > a)
    = p``, the union bound). The quantile is taken high (the top 1 %): an observer's noise is
    rich in lines (encoder quantisation tones whose frequencies the speed sets to 1e-5), which
    the median, the floor between them, does not measure. A part of ``part`` of the window,
    zero-padded, has ``N · part`` independent bins: each line spreads over ``1 / part`` of
    them, so the top 1 % of the bins is the top 1 % of its lines. The line judged is not part
    of the noise: its main lobe, ``⌈1 / part⌉`` bins to each side (the first zero of a
    rectangular part's transform), is left out, else in a part of a few revolutions the
    line's own spread fills the top 1 %. Returns +inf when no bin is left."""
    keep = ~masked[b0:b1]
    if peak >= 0:
        lobe = math.ceil(1.0 / part)
        keep[max(0, peak - lobe - b0) : max(0, peak + lobe + 1 - b0)] = False
    sel = amp[b0:b1][keep]
    n = sel.shape[0]
    if n == 0:
        return math.inf
    top = int((1.0 - quantile) * n)  # bins above the quantile
    q_amp = float(np.partition(sel, n - 1 - top)[n - 1 - top])
    n_eff = max(n * part, 1.0)
    return q_amp * math.sqrt(math.log(n_eff / false_alarm) / math.log(1.0 / (1.0 - quantile)))


#: One-sided standard normal quantile of :data:`LINE_FALSE_ALARM`: the band's power must pass
#: the midpoint of decision 1687 by this many of its learned spreads (decision 1697).
POWER_MARGIN = NormalDist().inv_cdf(1.0 - LINE_FALSE_ALARM)


def adds_power(excess: float | None, amplitude: float, noise: float = 0.0) -> bool:
    """Whether a new chatter-comb line of ``amplitude`` is power added to its window's band
    (decisions 1687, 1697): ``excess ≥ ½·amplitude² + z·noise``, ``excess`` the band's
    ``Σ comb²`` off the spindle harmonics less the same sum learned with the background
    (one-sided amplitudes: a line of amplitude ``A`` holds ``A²`` of the sum over its lobe on
    the rectangular window, Parseval), ``noise`` the spread of that difference learned at the
    same rate and ``z`` = :data:`POWER_MARGIN`; None (the run's start: no learned sum to
    compare with) passes.

    The margin (decision 1697): the band's sum is a sum over some 1800 bins of a noise whose
    lines (an observer's) move between windows, and its difference from the learned sum
    spreads by 0.1-0.3 N²·m² window to window in a compensated torque's cut; a line of
    0.5 N·m holds 0.25 of it. At the midpoint alone the two hypotheses are told apart at the
    chance of that spread, once a window; the line must pass it at the chance the line's own
    level test takes (:data:`LINE_FALSE_ALARM`). A line between the two levels is neither
    chatter nor learned (:func:`moves_power`): the next window tests it again.

    Chatter is a vibration the regeneration adds to the cut (Aslan Eq. 5.25: energy at
    ω_c ± lΩ on top of the stable cut's lΩ): the band gains at least the line's power, ``A²``,
    whatever else holds still. A line that appears by moving power already in the band gains
    the band nothing (``≈ 0``): the compensated torque's encoder-quantisation tones, the
    limit cycle of the drive's velocity PI on a quantised speed (frequencies
    ``|frac(f_rev·N_enc·T_v)/T_v + m·f_rev|`` folded at the loop's rate, bounded in power by
    the quantisation step), which the cut's speed ripple dithers from one family of lines to
    another at an entry. The level is the midpoint of the two hypotheses (``0`` and ``A²``):
    neither the record nor a rate was fitted to it."""
    return excess is None or excess >= 0.5 * amplitude * amplitude + POWER_MARGIN * noise


def moves_power(excess: float | None, amplitude: float, noise: float = 0.0) -> bool:
    """Whether a new chatter-comb line of ``amplitude`` is power moved within its band, found
    so beyond the band's spread (decision 1697): ``excess < ½·amplitude² − z·noise`` (see
    :func:`adds_power`); such a line is learned (decision 1687)."""
    return excess is not None and excess < 0.5 * amplitude * amplitude - POWER_MARGIN * noise


def line_amplitude(
    amp: FloatArray, k: int, part: float = 1.0, masked: NDArray[np.bool_] | None = None
) -> float:
    """Amplitude of the line whose largest bin in the rectangular (comb) spectrum ``amp`` is
    ``k``, corrected for the bin grid (decision 1551).

    A line ``δ`` bins off bin ``k`` reads ``A·|sinc(part·δ)|`` there and ``A·|sinc(part·(1 −
    δ))|`` in the neighbour on its side (the transform of a rectangular window of ``part`` of
    the ``N`` samples, zero-padded to ``N``): up to 36 % low (−3.9 dB) half a bin off on a full
    window, wherever the line falls on the grid, which the rate and the window length set (2.44
    Hz bins at 10 kHz, 10.8 Hz at 44.1 kHz). The offset follows from the ratio ``r`` of the
    larger neighbour to the peak: ``δ = r / (1 + r)`` on a full window (Jain's interpolation of
    the rectangular DFT), by bisection of ``sinc(part·(1 − δ)) = r·sinc(part·δ)`` on
    ``[0, ½]`` on a part; the amplitude is ``amp[k] / sinc(part·δ)`` (at most π/2 ×
    ``amp[k]``). The bin is returned as read when it is no local maximum (no resolved line of
    its own), at the spectrum's ends, or when the larger neighbour is ``masked`` (a spindle
    harmonic's bin: its reading is not the line's)."""
    a = float(amp[k])
    if not (0 < k < amp.shape[0] - 1 and a > 0.0):
        return a
    lo, hi = float(amp[k - 1]), float(amp[k + 1])
    j, nb = (k + 1, hi) if hi >= lo else (k - 1, lo)
    if nb > a or (masked is not None and masked[j]):
        return a
    r = nb / a
    if part >= 1.0:
        delta = r / (1.0 + r)
    else:
        lo_d, hi_d = 0.0, 0.5
        if _sinc(part) >= r:
            hi_d = 0.0  # no farther off than the part's own resolution shows
        for _ in range(40):  # |sinc(part·(1 − δ))| − r·|sinc(part·δ)| rises on [0, ½]
            mid = 0.5 * (lo_d + hi_d)
            if _sinc(part * (1.0 - mid)) < r * _sinc(part * mid):
                lo_d = mid
            else:
                hi_d = mid
        delta = 0.5 * (lo_d + hi_d)
    return a / _sinc(part * delta)


def _sinc(x: float) -> float:
    """|sin(πx)/(πx)| (1 at 0)."""
    if x == 0.0:
        return 1.0
    return abs(math.sin(math.pi * x) / (math.pi * x))


def peak_frequency(f_hz: FloatArray, amp: FloatArray, k: int) -> float:
    """Frequency of the peak at bin ``k`` by parabolic interpolation of log amplitudes (the
    logarithms by NumPy, the arithmetic on Python floats: the same IEEE operations as on NumPy
    scalars, at a fifth of the cost; decision 1538), within half a bin of bin ``k``.

    At a local maximum the parabola's vertex lies within half a bin. A bin that is a band's
    largest but not a local maximum (the band's edge, a larger neighbour outside it) put it
    anywhere: the threshold criterion's 256-point window read the demo part's low-frequency
    content at its 50 Hz band edge as "chatter at −5.0 Hz", with a spindle speed of −151 rev/min
    suggested. Where a neighbour is larger, the line is nearer it: the parabola is taken through
    that neighbour and its own neighbours (one step), and its offset is held to ±½ bin
    (decision 1693)."""
    if not 0 < k < len(amp) - 1:
        return float(f_hz[k])
    lo, mid, hi = amp[k - 1 : k + 2].tolist()
    if mid < max(lo, hi):  # no local maximum: the line lies toward the larger neighbour
        j = k - 1 if lo > hi else k + 1
        if 0 < j < len(amp) - 1:
            k = j
    trio = amp[k - 1 : k + 2]
    lo, mid, hi = trio.tolist()  # compared as Python floats, not NumPy scalars
    if lo > 0 and mid > 0 and hi > 0:
        a, b, c = np.log(trio).tolist()
        den = a - 2 * b + c
        if den < 0:
            fk, f0, f1 = float(f_hz[k]), float(f_hz[0]), float(f_hz[1])
            off = 0.5 * (a - c) / den
            off = 0.5 if off > 0.5 else -0.5 if off < -0.5 else off
            return fk + off * (f1 - f0)
    return float(f_hz[k])


@dataclass(frozen=True)
class ChatterMethod:
    """One criterion: its analysis window and decision rule.

    Attributes
    ----------
    name : registry name (``chatter-comb``...).
    window : samples per analysis window (at the stream rate).
    taper : ``hann`` or ``rect`` (the SDFT is rectangular).
    threshold : ratio above which the window is chatter (None for the threshold method:
        calibrated on the run).
    learns_background : use the learned background and the cutting gate.
    seed : the seed the criterion comes from (for messages).
    judges_segments : a window in the cut whose mean steps (entry, exit, depth step) is
        judged on its part after the step when that resolves the lines (decision 1539):
        ``chatter-comb`` only, whose ratio is a line over the tooth line of the same samples;
        the SDFT's ratio sums the variance of every new bin over its fixed N-sample window
        (Yamada Eq. 6-12), into which an entry's transients (the comb's ring-down of the
        harmonics, the structure's free vibration) enter at double weight on a half-window
        segment (a 0.64 > 0.5 false alarm on a stable stream).
    """

    name: str
    window: int
    taper: str
    threshold: float | None
    learns_background: bool
    seed: str
    judges_segments: bool = False

    def decide(self, s: Spectra, calibrated: float | None) -> Verdict:
        """The verdict on one window (``calibrated``: threshold of the threshold method)."""
        if self.name == "chatter-threshold":
            thr = self.threshold if self.threshold is not None else calibrated
            if s.band_slice is not None:  # argmax(where(band, raw, 0)) without the copy
                b0, b1 = s.band_slice
                k = _kn.band_argmax(s.raw, b0, b1, True)
                peak = float(s.raw[k]) if b0 <= k < b1 else 0.0
            else:
                amp = np.where(s.band, s.raw, 0.0)
                k = int(np.argmax(amp))
                peak = float(amp[k])
            if thr is None or not thr > 0:
                return Verdict(0.0, peak_frequency(s.f_hz, s.raw, k), 1.0)
            return Verdict(peak / thr, peak_frequency(s.f_hz, s.raw, k), 1.0)
        thr = float(self.threshold if self.threshold is not None else SEED000_RATIO)
        if s.band_slice is not None:
            b0, b1 = s.band_slice
        else:
            nz = np.flatnonzero(s.band)
            b0, b1 = (int(nz[0]), int(nz[-1]) + 1) if len(nz) else (0, 0)
        k = s.peak_bin if s.peak_bin >= 0 else _kn.band_argmax(s.novel, b0, b1)
        if not s.cutting or not b0 <= k < b1 or s.novel[k] <= 0.0 or s.tooth <= 0.0:
            return Verdict(0.0, float("nan"), thr)
        f_c = peak_frequency(s.f_hz, s.comb, k)
        if self.name == "chatter-comb":
            # the line's amplitude, not its bin's reading (decision 1551)
            ratio = line_amplitude(s.comb, k, s.part, s.masked) / s.tooth
            stands_out, moved = True, False
            if ratio > thr and not s.held and s.masked is not None:
                # an onset: the line's bin must stand out of its own window's bins (decision
                # 1658; bin against bins, each read on the grid)
                line = float(s.comb[k])
                stands_out = line > line_level(s.comb, s.masked, b0, b1, s.part, k)
                # ... and the line must be power added to the band, not moved within it
                # (decision 1687), beyond the band's own spread, unless the count rate swept
                # the encoder's quantisation lines away (decision 1697)
                if stands_out and not s.sweeps:
                    a = ratio * s.tooth
                    added = adds_power(s.band_excess, a, s.band_noise)
                    moved = not added and moves_power(s.band_excess, a, s.band_noise)
                    stands_out = added
            # while flagged, a run ends when the ratio falls below the rising run's level, not
            # the threshold: a line read at its amplitude that hovers at 1.5 is one run
            # (decision 1551)
            hold = RUN_LEVEL * thr if s.held else None
            return Verdict(ratio, f_c, thr, stands_out, hold, moved)
        # SDFT + moving variance: chatter variance over harmonic variance (Parseval, one-sided
        # amplitudes a → variance a²/2)
        raw = s.raw_rect if s.raw_rect is not None else s.raw
        chat2, harm2, tot2 = _kn.variance_sums(s.novel, raw, s.comb, b0, b1)
        harm = max(harm2 / 2.0, 0.0)
        floor = 1e-30 + 1e-12 * tot2
        return Verdict(chat2 / 2.0 / max(harm, floor), f_c, thr)


#: The chatter criteria by name (window lengths in samples, chosen for a 10 kHz stream).
METHODS: dict[str, ChatterMethod] = {
    "chatter-comb": ChatterMethod(
        "chatter-comb", 4096, "rect", SEED000_RATIO, True, "seed 000", judges_segments=True
    ),
    "chatter-sdft": ChatterMethod("chatter-sdft", 2048, "rect", 0.5, True, "seed 001"),
    "chatter-threshold": ChatterMethod("chatter-threshold", 256, "hann", None, False, "seed 002"),
}
