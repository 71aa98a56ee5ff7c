"""Compiled parts of the chatter decision step (the per-window arithmetic after the FFTs).

One call per window replaces a dozen NumPy passes over the 2049 bins: amplitude spectra, the
tooth-passing line and the band median of the cutting gate (Aslan §5.4: ratio of the largest
comb-filtered peak to the tooth-passing line, Eq. 5.30), the novelty against the learned
background (decision 1504), the band's largest novel bin, the background update, and the
variance sums of the SDFT criterion (Yamada Eq. 6-12, Parseval). Same equations as the NumPy
forms they replaced; only the order of floating-point sums differs (≤ 1e-15 relative).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
BoolArray = NDArray[np.bool_]


@numba.njit(cache=True, nogil=True)
def _select(a: FloatArray, kth: int) -> float:  # pragma: no cover - compiled
    """The ``kth`` smallest value of ``a`` (left unchanged). Quickselect around the median of
    three, each pass a branch-free three-way partition into a scratch array: every value is
    written to the next slot of both ends and only the end its comparison with the pivot
    chooses advances, so the lower part ends at ``lo``, the upper starts after ``hi`` and the
    values equal to the pivot drop out. A data-dependent branch per value (Hoare's partition,
    decision 1535) mispredicted half the time on spectra: ≈ 20 µs for 1800 bins against ≈ 7
    (decision 1536). An order statistic is a value of the data, so any selection algorithm
    returns the same number as ``np.partition``."""
    n = a.shape[0]
    src = a.copy()
    dst = np.empty(n)
    while n > 1:
        x = src[0]
        y = src[n >> 1]
        z = src[n - 1]
        if x > y:
            x, y = y, x
        if y > z:
            y = z
        if x > y:
            y = x
        pivot = y
        lo = 0
        hi = n - 1
        for i in range(n):
            v = src[i]
            dst[lo] = v
            dst[hi] = v
            lo += v < pivot
            hi -= v > pivot
        if kth < lo:  # in the lower part dst[:lo]
            n = lo
            src, dst = dst[:n], src
        elif kth > hi:  # in the upper part dst[hi + 1:]
            kth -= hi + 1
            n -= hi + 1
            src, dst = dst[hi + 1 : hi + 1 + n], src
        else:
            return pivot
    return src[0]


#: Buckets of the first pass of :func:`_select_radix`.
_RADIX_BUCKETS = 2048


@numba.njit(cache=True, nogil=True)
def _select_radix(a: FloatArray, kth: int) -> float:  # pragma: no cover - compiled
    """:func:`_select` for values that are all ≥ +0 (an amplitude spectrum), by their bit
    patterns, which order such doubles as their values do: one pass for the smallest and
    largest pattern, one counting the values in 2048 equal ranges of patterns between them,
    one copying the range that holds the ``kth`` value, which :func:`_select` then orders
    alone (a few dozen values of the 1800 of a spectrum's band: ≈ 4 µs against ≈ 10 for
    :func:`_select` over the band). An order statistic is a value of the data, so it is the
    number :func:`_select` returns. A NaN, a negative value or −0 (whose patterns do not order
    as their values), fewer than 64 values or ``a`` not contiguous: :func:`_select`."""
    n = a.shape[0]
    if n < 64 or not a.flags.c_contiguous:
        return _select(a, kth)
    bits = a.view(np.uint64)
    lo = bits[0]
    hi = bits[0]
    odd = False
    for i in range(n):
        b = bits[i]
        odd |= not (a[i] >= 0.0) or (b >> np.uint64(63)) != np.uint64(0)
        lo = min(lo, b)
        hi = max(hi, b)
    if odd:
        return _select(a, kth)
    if lo == hi:
        return a[0]
    span = hi - lo
    shift = np.uint64(0)
    while (span >> shift) >= np.uint64(_RADIX_BUCKETS):
        shift += np.uint64(1)
    counts = np.zeros(int(span >> shift) + 1, dtype=np.int64)
    for i in range(n):
        counts[int((bits[i] - lo) >> shift)] += 1
    below = 0
    t = 0
    while below + counts[t] <= kth:
        below += counts[t]
        t += 1
    part = np.empty(counts[t])
    j = 0
    tb = np.uint64(t)
    for i in range(n):
        if (bits[i] - lo) >> shift == tb:
            part[j] = a[i]
            j += 1
    return _select(part, kth - below)


@numba.njit(cache=True, nogil=True)
def amplitude_line_median(
    c: ComplexArray, scale: float, k0: int, k1: int, b0: int, b1: int, out: FloatArray
) -> tuple[float, float]:  # pragma: no cover - compiled
    """``out = |c|·scale`` (one-sided amplitudes); returns the largest amplitude in bins
    ``k0:k1`` (the tooth-passing line; 0 if empty) and the median of bins ``b0:b1`` (0 if
    empty; as ``np.median``: the middle value, or the mean of the two middle values)."""
    for i in range(c.shape[0]):
        out[i] = np.sqrt(c[i].real * c[i].real + c[i].imag * c[i].imag) * scale
    tooth = 0.0
    for i in range(k0, k1):
        if out[i] > tooth:
            tooth = out[i]
    med = 0.0
    if b1 > b0:
        w = out[b0:b1]
        m = w.shape[0]
        h = m // 2
        med = _select_radix(w, h)
        if m % 2 == 0:  # the mean of the two middle values, as numpy's median
            # the lower middle value: the largest value below the upper one if exactly h
            # values are below it, else a tie with it
            below = 0
            lower = -np.inf
            for i in range(m):
                v = w[i]
                below += v < med
                lower = max(lower, v if v < med else -np.inf)
            if below < h:
                lower = med
            med = 0.5 * (med + lower)
    return tooth, med


@numba.njit(cache=True, nogil=True)
def amplitude(c: ComplexArray, scale: float, out: FloatArray) -> None:  # pragma: no cover
    """``out = |c|·scale``."""
    for i in range(c.shape[0]):
        out[i] = np.sqrt(c[i].real * c[i].real + c[i].imag * c[i].imag) * scale


@numba.njit(cache=True, nogil=True)
def band_power(amp: FloatArray, mask: BoolArray, b0: int, b1: int) -> float:  # pragma: no cover
    """``Σ amp²`` over the bins ``b0:b1`` not ``masked`` (one-sided amplitudes: twice the
    band's variance, Parseval; decision 1687)."""
    p = 0.0
    for i in range(b0, b1):
        if not mask[i]:
            p += amp[i] * amp[i]
    return p


@numba.njit(cache=True, nogil=True)
def near_harmonics(
    f: FloatArray, f_rev: float, half_width: float, out: BoolArray
) -> None:  # pragma: no cover - compiled
    """``out = |f − f_rev·rint(f / f_rev)| ≤ half_width``: the bins within ``half_width`` Hz
    of a spindle harmonic (the NumPy expression's steps per bin, the same booleans)."""
    for i in range(f.shape[0]):
        out[i] = abs(f[i] - f_rev * np.rint(f[i] / f_rev)) <= half_width


@numba.njit(cache=True, nogil=True)
def widened_maximum(
    values: FloatArray, gains: FloatArray, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """``out[i]`` = the largest of ``values[i]`` and ``gains[d − 1]·values[i ± d]`` for ``d`` =
    1 … len(gains) within the array (NaN if any of them is, as ``np.maximum``): each bin's
    reference from its neighbours' lines seen through a part's main lobe (decision 1546)."""
    n = values.shape[0]
    for i in range(n):
        r = values[i]
        for d in range(1, gains.shape[0] + 1):
            g = gains[d - 1]
            if i >= d:
                v = g * values[i - d]
                if v > r or v != v:
                    r = v
            if i + d < n:
                v = g * values[i + d]
                if v > r or v != v:
                    r = v
        out[i] = r


@numba.njit(cache=True, nogil=True)
def novelty(
    comb: FloatArray, background: FloatArray, factor: float, mask: BoolArray, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """``out = comb − factor·background``, −1 on the masked (spindle-harmonic) bins."""
    for i in range(comb.shape[0]):
        out[i] = -1.0 if mask[i] else comb[i] - factor * background[i]


@numba.njit(cache=True, nogil=True)
def band_argmax(
    novel: FloatArray, b0: int, b1: int, nan_first: bool = False
) -> int:  # pragma: no cover - compiled
    """``argmax(where(band, novel, 0))`` for the band ``b0:b1`` without the masked copy (the
    first of equal maxima); ``nan_first``: the first NaN in the band wins, as in NumPy's
    argmax (the threshold criterion's verdict, decision 1538), else NaNs are passed over."""
    k = 0
    best = novel[0] if b0 <= 0 < b1 else 0.0
    if nan_first and best != best:
        return 0
    for i in range(1, novel.shape[0]):
        v = novel[i] if b0 <= i < b1 else 0.0
        if nan_first and v != v:
            return i
        if v > best:
            best = v
            k = i
    return k


@numba.njit(cache=True, nogil=True)
def learn(
    background: FloatArray, comb: FloatArray, novel: FloatArray, a_plain: float, a_novel: float
) -> None:  # pragma: no cover - compiled
    """``background += a·(comb − background)`` with ``a = a_novel`` where ``novel > 0``."""
    for i in range(comb.shape[0]):
        a = a_novel if novel[i] > 0.0 else a_plain
        background[i] += a * (comb[i] - background[i])


@numba.njit(cache=True, nogil=True)
def variance_sums(
    novel: FloatArray, raw: FloatArray, comb: FloatArray, b0: int, b1: int
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Over the band: Σ max(novel, 0)², Σ (raw² − comb²), Σ raw² (one-sided amplitudes)."""
    chat = 0.0
    harm = 0.0
    tot = 0.0
    for i in range(b0, b1):
        v = novel[i]
        if v > 0.0:
            chat += v * v
        r2 = raw[i] * raw[i]
        harm += r2 - comb[i] * comb[i]
        tot += r2
    return chat, harm, tot


@numba.njit(cache=True, nogil=True)
def centred_window(
    ring: FloatArray,
    pos: int,
    taper: FloatArray,
    out: FloatArray,
    out_tapered: FloatArray,
    ring_y: FloatArray | None = None,
    out_y: FloatArray | None = None,
) -> tuple[float, float]:  # pragma: no cover - compiled
    """The last ``len(out)`` samples written to ``ring`` before ``pos`` (a power-of-two ring),
    oldest first, less their mean, in ``out`` and times ``taper`` in ``out_tapered``; returns
    the mean and the difference of the means of the newer and the older half. With ``ring_y``
    and ``out_y``, the same samples of ``ring_y`` (as written) in ``out_y``.

    Every sum runs in sample order. The older half's and the newer half's sums are two
    independent chains, advanced in the same pass (sample i and sample h + i), so the
    processor overlaps their additions: the same numbers in two thirds of the time of one
    chain after the other (the loop is bound by the latency of the additions; decision 1538).
    The copy of ``ring_y`` rides in the mean's pass, whose chain of additions leaves the
    processor idle between them (a fifth of the windows' time against a pass of its own).
    """
    n = out.shape[0]
    mask = ring.shape[0] - 1
    start = pos - n
    total = 0.0
    if ring_y is None or out_y is None:
        for i in range(n):
            v = ring[(start + i) & mask]
            out[i] = v
            total += v
    else:
        for i in range(n):
            j = (start + i) & mask
            v = ring[j]
            out[i] = v
            out_y[i] = ring_y[j]
            total += v
    level = total / n
    h = n // 2
    old = 0.0
    new = 0.0
    for i in range(h):
        v = out[i] - level
        out[i] = v
        out_tapered[i] = v * taper[i]
        old += v
        u = out[h + i] - level
        out[h + i] = u
        out_tapered[h + i] = u * taper[h + i]
        new += u
    for i in range(2 * h, n):  # the last sample of an odd window
        u = out[i] - level
        out[i] = u
        out_tapered[i] = u * taper[i]
        new += u
    return level, new / (n - h) - old / h


#: The cutting gate's state, one vector per monitor (decisions 1504, 1531): the median raw
#: amplitude (air floor) and the mean learned out of the cut, the spindle frequency of that
#: mean, and whether the floor and the mean are known yet.
AIR_FLOOR = 0
AIR_MEAN = 1
AIR_F_REV = 2
HAS_FLOOR = 3
HAS_MEAN = 4
AIR_SIZE = 5
#: The gate's settings, one vector: cutting gate, load gate, steady speed, steady mean,
#: steady noise (block constants of decisions 1504, 1531), air learning weight per window.
GATE_SIZE = 6


@numba.njit(cache=True, nogil=True)
def air_loaded(
    level: float, f_rev: float, air: FloatArray, load_gate: float, same_speed_tol: float,
    grow: float,
) -> bool:  # pragma: no cover - compiled  # fmt: skip
    """The load test of the cutting gate (decisions 1531, 1537): the mean ``level`` is
    ``load_gate`` floors learned out of the cut (× ``grow``: a part's higher noise, decision
    1539) away from the mean learned there; at another speed (beyond ``same_speed_tol``) the
    air torque may differ from the one learned by up to its own size (drag and friction grow
    with speed), so the air mean's size is added. False before a floor and a mean are
    learned."""
    if not (air[HAS_MEAN] > 0.0 and air[HAS_FLOOR] > 0.0):
        return False
    air_floor = air[AIR_FLOOR] * grow
    air_mean = air[AIR_MEAN]
    air_f = air[AIR_F_REV]
    same_speed = abs(f_rev - air_f) <= same_speed_tol * air_f
    span = load_gate * air_floor if same_speed else load_gate * air_floor + abs(air_mean)
    return abs(level - air_mean) > span


@numba.njit(cache=True, nogil=True)
def tooth_bins(
    f_t: float, f_rev: float, df: float, nf: int, min_speed_rpm: float
) -> tuple[int, int]:  # pragma: no cover - compiled
    """The bins ``k0:k1`` searched for the tooth-passing line at ``f_t`` (bins ``df`` apart,
    ``nf`` of them): within ±max(2 bins, 0.5 % of ``f_t``); none (0, 0) while the spindle
    frequency ``f_rev`` is below ``min_speed_rpm``."""
    k0 = 0
    k1 = 0
    if f_rev * 60.0 >= min_speed_rpm:
        half = max(2.0 * df, 0.005 * f_t)
        k0 = max(0, math.ceil((f_t - half) / df))
        k1 = max(k0, min(nf, math.floor((f_t + half) / df) + 1))
    return k0, k1


@numba.njit(cache=True, nogil=True)
def cutting_gate(
    c: ComplexArray,
    scale: float,
    f_t: float,
    df: float,
    min_speed_rpm: float,
    b0: int,
    b1: int,
    raw: FloatArray,
    level: float,
    half_step: float,
    f_rev: float,
    air: FloatArray,
    gate: FloatArray,
    air_before: FloatArray,
) -> tuple[bool, bool, float, float, int, int]:  # pragma: no cover - compiled
    """The raw window's amplitudes ``raw`` (:func:`amplitude_line_median`: tooth-passing line
    at ``f_t`` in the bins :func:`tooth_bins` gives, band median) and the cutting gate
    (decisions 1504, 1531): in the cut when the tooth line stands ``gate[0]``× out of the floor
    (the band median, or the smaller floor learned out of the cut) or the window's mean
    ``level`` is ``gate[1]`` floors away from the mean learned out of the cut at this speed
    (within ``gate[2]``); out of the cut the floor and mean are learned (weight ``gate[5]``;
    the mean afresh at a new speed). Returns (cutting, steady: the halves' means differ by at
    most ``gate[3]``× the tooth line or ``gate[4]``× the floor, tooth line, reference of the
    ratio: the line, in the cut no less than ``gate[0]``× floor, and the tooth line's bins
    ``k0``, ``k1``). ``air_before`` ← ``air`` as it was before the window (decisions 1543,
    1680)."""
    for i in range(air.shape[0]):
        air_before[i] = air[i]
    k0, k1 = tooth_bins(f_t, f_rev, df, c.shape[0], min_speed_rpm)
    tooth, med = amplitude_line_median(c, scale, k0, k1, b0, b1, raw)
    has_floor = air[HAS_FLOOR] > 0.0
    has_mean = air[HAS_MEAN] > 0.0
    air_floor = air[AIR_FLOOR]
    air_mean = air[AIR_MEAN]
    air_f = air[AIR_F_REV]
    floor = air_floor if has_floor and air_floor < med else med
    loaded = air_loaded(level, f_rev, air, gate[1], gate[2], 1.0)
    cutting = tooth > 0.0 and (tooth > gate[0] * floor or loaded)
    if not cutting and tooth > 0.0:
        a = gate[5]
        air[AIR_FLOOR] = air_floor + a * (med - air_floor) if has_floor else med
        air[HAS_FLOOR] = 1.0
        if not has_mean or abs(f_rev - air_f) > gate[2] * air_f:
            air[AIR_MEAN] = level  # the air level at a new speed (friction changes)
        else:
            air[AIR_MEAN] = air_mean + a * (level - air_mean)
        air[HAS_MEAN] = 1.0
        air[AIR_F_REV] = f_rev
    tooth_ref = tooth
    steady = True
    if cutting:
        least = gate[0] * floor
        if least > tooth:
            tooth_ref = least
        tol = gate[3] * tooth
        noise = gate[4] * floor
        if noise > tol:
            tol = noise
        steady = abs(half_step) <= tol
    return cutting, steady, tooth, tooth_ref, k0, k1


@numba.njit(cache=True, nogil=True)
def decision_windows(
    ring_x: FloatArray,
    ring_y: FloatArray,
    pos: int,
    taper: FloatArray,
    comb_taper: FloatArray,
    out: FloatArray,
    windows: FloatArray,
) -> tuple[float, float]:  # pragma: no cover - compiled
    """A decision's windows in one call (decision 1700): :func:`centred_window` of ``ring_x``
    into ``out`` and (times ``taper``) ``windows[0]``, returning its mean and half-step; with a
    second row, the comb-filtered window (the same samples of ``ring_y``, copied in the same
    pass) into ``windows[1]``, times ``comb_taper`` unless that is empty (a rectangular
    window)."""
    if windows.shape[0] == 1:
        return centred_window(ring_x, pos, taper, out, windows[0])
    row = windows[1]
    level, half_step = centred_window(ring_x, pos, taper, out, windows[0], ring_y, row)
    if comb_taper.shape[0] > 0:
        for i in range(row.shape[0]):
            row[i] *= comb_taper[i]
    return level, half_step


@numba.njit(cache=True, nogil=True)
def novel_peak(
    c: ComplexArray,
    scale: float,
    comb: FloatArray,
    background: FloatArray,
    first: bool,
    factor: float,
    mask: BoolArray,
    novel: FloatArray,
    b0: int,
    b1: int,
    a_plain: float,
    a_novel: float,
    power_mask: BoolArray,
) -> tuple[int, float]:  # pragma: no cover - compiled
    """The comb-filtered window's amplitudes ``comb = |c|·scale``; on the ``first`` window the
    background is ``comb`` (the monitor then settles: decision 1537; decision 1504 started a
    first window in the cut from 0); the
    novelty (:func:`novelty`), the band's largest novel bin (:func:`band_argmax`, returned)
    and then the background update (:func:`learn`; the verdict does not read the
    background). Returns that bin and, unless ``power_mask`` is empty, the band's power off
    its masked bins (:func:`band_power`, decision 1687; else 0)."""
    amplitude(c, scale, comb)
    if first:
        for i in range(comb.shape[0]):
            background[i] = comb[i]
    novelty(comb, background, factor, mask, novel)
    k = band_argmax(novel, b0, b1)
    learn(background, comb, novel, a_plain, a_novel)
    power = band_power(comb, power_mask, b0, b1) if power_mask.shape[0] > 0 else 0.0
    return k, power


@numba.njit(cache=True, nogil=True)
def step_start(x: FloatArray) -> int:  # pragma: no cover - compiled
    """The first sample after the largest step of the mean in ``x`` (mean removed): the
    argmax over k of |Σ_{i<k} x_i| (the cumulative sum of a zero-mean window is a triangle
    peaking at a single mean step, wherever it is; the least-squares single change point of
    the mean up to the triangle's weighting; decision 1539). Sums in sample order."""
    c = 0.0
    best = -1.0
    k = 1
    for i in range(x.shape[0] - 1):
        c += x[i]
        a = abs(c)
        if a > best:
            best = a
            k = i + 1
    return k


@numba.njit(cache=True, nogil=True)
def segment_windows(
    x: FloatArray, ring_y: FloatArray, pos: int, start: int, hann_comb: bool, out: FloatArray
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """The part of a window after its mean step (decision 1539), zero-padded to the window's
    length: ``out[0]`` the raw samples ``x[start:]`` (mean removed, ``x`` itself already less
    the window's mean) less their own mean times a Hann taper of the segment's length
    (``np.hanning``), ``out[1]`` the comb-filtered samples of the same span from ``ring_y``
    (last ``len(x)`` written before ``pos``), rectangular or (``hann_comb``) Hann-tapered;
    zeros after. Returns the segment's mean (relative to the window's), the difference of the
    means of its newer and older half, the sum of the Hann taper and of the comb row's taper
    (the amplitude scales are 2 / these sums)."""
    n = x.shape[0]
    m = n - start
    mask = ring_y.shape[0] - 1
    first = pos - n + start
    total = 0.0
    for i in range(m):
        total += x[start + i]
    mean = total / m
    h = m // 2
    old = 0.0
    new = 0.0
    for i in range(h):
        old += x[start + i] - mean
    for i in range(h, m):
        new += x[start + i] - mean
    w_sum = 0.0
    c_sum = 0.0
    den = m - 1.0 if m > 1 else 1.0
    for i in range(m):
        w = 0.5 - 0.5 * np.cos(2.0 * np.pi * i / den)
        w_sum += w
        out[0, i] = (x[start + i] - mean) * w
        c = w if hann_comb else 1.0
        c_sum += c
        out[1, i] = ring_y[(first + i) & mask] * c
    for i in range(m, n):
        out[0, i] = 0.0
        out[1, i] = 0.0
    return mean, new / (m - h) - old / h, w_sum, c_sum


@numba.njit(cache=True, nogil=True)
def power_step_start(x: FloatArray, ring_y: FloatArray, pos: int) -> int:  # pragma: no cover
    """The first sample after the largest step of the power of the window's harmonic part
    (decision 1542): with ``p = (x − y)²`` (``x`` the raw window less its mean, ``y`` the
    comb-filtered samples, the last ``len(x)`` written to ``ring_y`` before ``pos``; ``1 −
    G_cb`` passes the spindle harmonics, Aslan Eq. 5.26), the argmax over k of
    |Σ_{i<k} (p_i − mean p)| (:func:`step_start` on the power: the single change point of its
    mean, an entry or an exit without a mean step). Sums in sample order."""
    n = x.shape[0]
    mask = ring_y.shape[0] - 1
    start = pos - n
    p = np.empty(n)
    total = 0.0
    for i in range(n):
        d = x[i] - ring_y[(start + i) & mask]
        p[i] = d * d
        total += p[i]
    mean = total / n
    for i in range(n):
        p[i] -= mean
    return step_start(p)


@numba.njit(cache=True, nogil=True)
def line_amplitude(x: FloatArray, lo: int, hi: int, cycles: float) -> float:  # pragma: no cover
    """The amplitude of the line at ``cycles`` per sample in ``x[lo:hi]`` (less its own mean)
    under a Hann taper of the part's length (``np.hanning``): ``2·|Σ w_i x_i e^{−j2π·cycles·i}|
    / Σ w_i`` (decision 1542). The phasors are advanced by rotation (one complex product per
    sample; the rounding drifts by ~1e-13 over 4096 samples)."""
    m = hi - lo
    if m < 2:
        return 0.0
    total = 0.0
    for i in range(lo, hi):
        total += x[i]
    mean = total / m
    # the taper's cosine and the line's phasor, rotated sample by sample
    ct, st = np.cos(2.0 * np.pi / (m - 1)), np.sin(2.0 * np.pi / (m - 1))
    cl, sl = np.cos(2.0 * np.pi * cycles), np.sin(2.0 * np.pi * cycles)
    wc, ws = 1.0, 0.0
    pc, ps = 1.0, 0.0
    re = 0.0
    im = 0.0
    w_sum = 0.0
    for i in range(m):
        w = 0.5 - 0.5 * wc
        v = (x[lo + i] - mean) * w
        re += v * pc
        im -= v * ps
        w_sum += w
        wc, ws = wc * ct - ws * st, ws * ct + wc * st
        pc, ps = pc * cl - ps * sl, ps * cl + pc * sl
    return 2.0 * np.sqrt(re * re + im * im) / w_sum
