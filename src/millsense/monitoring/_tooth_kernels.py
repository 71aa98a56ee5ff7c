"""Compiled per-sample and per-tooth-period kernels of the breakage monitors.

Two jobs, both resumable across chunks through a small float64 state vector so that a stream
cut into chunks of any size gives the same result as the whole stream:

* :func:`segment_periods` — integrate the spindle speed into a phase counted in tooth periods
  (phase += |Ω|·N/(2π f_s) per sample) and average the signal(s) over each complete tooth
  period (Aslan Eq. 6.1; Munasinghe Eqs. 3.43–3.44). A period ends at the sample whose phase
  crosses the next integer; it is reported at that sample (one sample after its last one).
* :func:`detect_periods` — first and lag-N differences of the period averages, adaptive AR(1)
  residuals with recursive least squares (Aslan Eqs. 6.2–6.4; Munasinghe Eqs. 3.46–3.49),
  thresholds of the three detectors, the noise floor of the torque's band (decision 1550), the
  confirmation count, a broken flute's signature over the last revolution (decision 1681) and
  its pattern against the flute's own past revolutions (decision 1684).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.noise import SIGMA_PER_MEDIAN_ABS_DIFF

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
#: Violation and alarm flags: bool rows of a lone detector, int64 rows (2-3) of a group's packed
#: integer array; the kernels compile for both.
FlagArray = NDArray[np.bool_] | IntArray

# segment state layout
SEG_PHASE = 0  # fractional phase in tooth periods, [0, 1)
SEG_INDEX = 1  # index of the current (incomplete) tooth period since the stream start
SEG_COUNT = 2  # samples accumulated in the current period
SEG_SUM0 = 3  # sums of channel 0, channel 1, expected torque in the current period
SEG_SUM1 = 4
SEG_SUME = 5
SEG_SUMG = 6  # sum of the enable (gate) channel in the current period
SEG_SUMF = 7  # sum of the plan's transient floor in the current period (decision 1674)
SEG_SIZE = 8


@numba.njit(cache=True)
def segment_periods(
    a: FloatArray,
    b: FloatArray,
    expected: FloatArray,
    gate: FloatArray,
    floor: FloatArray,
    speed: FloatArray,
    fs: float,
    n_flutes: int,
    state: FloatArray,
    out_mean0: FloatArray,
    out_mean1: FloatArray,
    out_mean_e: FloatArray,
    out_mean_g: FloatArray,
    out_mean_f: FloatArray,
    out_count: FloatArray,
    out_end: IntArray,
    out_index: IntArray,
) -> int:
    """Average ``a`` (and ``b``, ``expected``, the 1/0 ``gate``, the plan's transient
    ``floor`` when non-empty; the gate's mean is 1 without one, the floor's 0) over complete
    tooth periods; ``out_count``: each period's samples.

    ``out_*`` are sized ≥ the number of periods that can end in the chunk; ``out_end`` is the
    chunk sample at which each period is reported (strictly increasing), ``out_index`` its
    index since the stream start. Returns the number of periods completed in this chunk.
    """
    n = a.shape[0]
    has_b = b.shape[0] == n
    has_e = expected.shape[0] == n
    has_g = gate.shape[0] == n
    has_f = floor.shape[0] == n
    scale = n_flutes / (2.0 * math.pi * fs)
    phase = state[SEG_PHASE]
    idx = state[SEG_INDEX]
    cnt = state[SEG_COUNT]
    s0 = state[SEG_SUM0]
    s1 = state[SEG_SUM1]
    se = state[SEG_SUME]
    sg = state[SEG_SUMG]
    sf = state[SEG_SUMF]
    m = 0
    for k in range(n):
        phase += abs(speed[k]) * scale
        if phase >= 1.0 and cnt > 0:
            # period `idx` is complete with the samples before this one
            out_mean0[m] = s0 / cnt
            out_mean1[m] = s1 / cnt if has_b else 0.0
            out_mean_e[m] = se / cnt if has_e else 0.0
            out_mean_g[m] = sg / cnt if has_g else 1.0
            out_mean_f[m] = sf / cnt if has_f else 0.0
            out_count[m] = cnt
            out_end[m] = k
            out_index[m] = int(idx)
            m += 1
            idx += 1.0
            cnt = 0.0
            s0 = 0.0
            s1 = 0.0
            se = 0.0
            sg = 0.0
            sf = 0.0
        if phase >= 1.0:
            phase -= math.floor(phase)
        cnt += 1.0
        s0 += a[k]
        if has_b:
            s1 += b[k]
        if has_e:
            se += expected[k]
        if has_g:
            sg += 1.0 if gate[k] > 0.5 else 0.0
        if has_f:
            sf += floor[k]
    state[SEG_PHASE] = phase
    state[SEG_INDEX] = idx
    state[SEG_COUNT] = cnt
    state[SEG_SUM0] = s0
    state[SEG_SUM1] = s1
    state[SEG_SUME] = se
    state[SEG_SUMG] = sg
    state[SEG_SUMF] = sf
    return m


@numba.njit(cache=True)
def segment_group(
    x: FloatArray,
    speed: FloatArray,
    fs: float,
    n_flutes: int,
    fstate: FloatArray,
    istate: IntArray,
    means: FloatArray,
    ends: IntArray,
) -> int:
    """:func:`segment_periods` for several detectors on one speed channel in one call:
    detector ``j`` averages the rows ``istate[j, I_ROWS:I_ROWS + 5]`` = (a, b, expected, gate,
    floor) of ``x`` (−1: none) with its segment state ``fstate[j, F_SEG:F_HELD]`` into
    ``means[j, 0:3]``, ``means[j, PP_GATE]``, ``means[j, PP_FLOOR]`` and ``means[j, PP_COUNT]``,
    ``ends[j, 0:2]``;
    ``istate[j, I_COUNT]`` ← its periods completed. Returns the largest count (the group's
    packed layout: :data:`F_SEG`, :data:`I_ROWS`)."""
    empty = x[0, :0]
    top = 0
    for j in range(istate.shape[0]):
        rows = istate[j, I_ROWS : I_ROWS + 5]
        a = x[rows[0]]
        b = x[rows[1]] if rows[1] >= 0 else empty
        e = x[rows[2]] if rows[2] >= 0 else empty
        g = x[rows[3]] if rows[3] >= 0 else empty
        f = x[rows[4]] if rows[4] >= 0 else empty
        k = segment_periods(a, b, e, g, f, speed, fs, n_flutes, fstate[j, F_SEG:F_HELD],
                            means[j, 0], means[j, 1], means[j, 2], means[j, PP_GATE],
                            means[j, PP_FLOOR], means[j, PP_COUNT], ends[j, 0],
                            ends[j, 1])  # fmt: skip
        istate[j, I_COUNT] = k
        top = max(top, k)
    return top


# detector state layout
DET_PHI1 = 0
DET_P1 = 1
DET_PHI2 = 2
DET_P2 = 3
DET_D1_PREV = 4  # Δx(m−1)
DET_DN_PREV = 5  # Δ_N x(m−1)
DET_SEEN = 6  # periods seen
DET_RUN = 7  # consecutive violating periods
DET_LEARN = 8  # periods learnt so far (−1: learning not started)
DET_MAX1 = 9
DET_MAX2 = 10
DET_THR1 = 11  # learnt thresholds (0 until learnt)
DET_THR2 = 12
DET_MEAN = 13  # sum of x over the learning periods
DET_REF = 14  # learnt constant reference torque (mean over the learning periods)
DET_GAP = 15  # 1: the previous period was not judged (start, or a transient of the plan)
DET_NOISE_N = 16  # |lag-N differences| held in the noise window (≤ NOISE_WINDOW)
DET_NOISE_POS = 17  # next slot of the noise window
DET_MISS = 18  # periods in a row without a violation inside the running violation
DET_ALARMED = 19  # 1: the running violation has raised its alarm
DET_LOW = 20  # judged periods in a row whose revolution mean is under 1 − 1/N − tol
DET_PRUN = 21  # flute pattern (decision 1684): two-sided judged periods in a row
DET_PN = 22  # |contrast| values held in the pattern's scale windows (≤ NOISE_WINDOW)
DET_PPOS = 23  # next slot of the pattern's scale windows
DET_PALARMED = 24  # 1: an alarm was raised since the last gap or re-arm (pattern on)
DET_NOISE_SLOW = 25  # the band's slow noise floor: σ̂ averaged (NOISE_SLOW, decision 1718)
DET_NOISE_NAN = 26  # NaN values held in the noise window (not in its sorted copy)
DET_PAIRED = 27  # plan-free constant reference: 1 once its running violation held a flute pair
DET_CHANGED = 28  # virtual: 1 once the running violation held a change (decision 1729)
DET_JUDGED = 29  # virtual: judged periods in a row before this one (decisions 1729, 1672)
DET_BASE = 30  # ring buffers: the last N period values, the noise window, then the last N
# references (NaN: not judged) and one-sided flags of the flute signature (decision 1681), then
# the flute pattern's (decision 1684): N references, N innovations, PATTERN_REVS × N drop and
# PATTERN_REVS × N drop-then-rise scores, and two scale windows of NOISE_WINDOW; then the
# noise window's values but NaN in ascending order (its median without a selection per period);
# last, the plan-free flute check's (decisions 1707, 1724) rings of the last N periods: Δ_N x,
# 1 where the period is a violation waiting for its pair (else 0), and its residuals ε1, ε2

#: Decision 1550: the noise of the tooth-period average is judged from the median |x(m) −
#: x(m−N)| of the last NOISE_WINDOW periods (same flute one revolution apart: runout and a
#: steady engagement cancel), once NOISE_MIN of them are held.
NOISE_WINDOW = 128
NOISE_MIN = 16
#: σ = median|d| / (0.6745 √2) (:mod:`millsense.core.noise`).
NOISE_SCALE = SIGMA_PER_MEDIAN_ABS_DIFF
#: Decision 1718: the band's σ is the larger of the window's σ̂ and its exponential mean over
#: NOISE_SLOW periods, which a statistical low of the window's median cannot pull down.
NOISE_SLOW = 256
#: σ = median|z| / 0.6745 of a zero-mean normal variable.
MAD_SCALE = 1.0 / 0.6745
#: Decision 1684, the flute pattern: each flute's residual to the plan is referenced to its own
#: mean over the previous revolutions (running mean over the first 1/PATTERN_BETA, then an
#: exponential one with weight PATTERN_BETA: 8 revolutions), judged once PATTERN_WARM
#: revolutions of two-sided judged periods are held, and its evidence accumulated over up to
#: PATTERN_REVS revolutions of the same flute.
PATTERN_BETA = 0.125
PATTERN_WARM = 8
PATTERN_REVS = 4
#: Decision 1685: revolutions before a pattern's first drop whose spread it is judged against.
PATTERN_BEFORE = 2
#: Decision 1729: a change of the cut over one revolution, |Δ_N x|, counts for the virtual
#: threshold's run from this many standard deviations of that difference's noise (√2 σ̂).
CHANGE_K = 3.0
#: Decision 1728: a plan-free flute pair's larger change over one revolution must stand this
#: many times the RMS of those changes over the PATTERN_BEFORE revolutions (at least
#: GROWTH_PERIODS periods) before it (3σ).
PAIR_OUTLIER = 3.0
#: Decision 1727: the spread of the newer of those revolutions over the older's at which the
#: contrast counts as growing (chatter's onset), and the spread then extrapolated to the drop.
PATTERN_GROWTH = 1.5
#: ... each spread taken over one revolution or this many periods, whichever is longer: the
#: RMS of a 2-flute revolution's two contrasts grew 1.5× by chance (decisions 1727, 1728).
GROWTH_PERIODS = 8
#: Steps of the signal's resolution within which no deviation, change or drop is a breakage's
#: (decision 1732): a quantisation-only period's innovation reaches two steps (a count flipped
#: at each end of the period); the third leaves one for the noise on top.
RESOLUTION_K = 3.0

#: Rows of ``pp`` (per-period values: 0 mean0, 1 mean1, 2 expected, 3 x, 4 ε1, 5 limit1, 6 ε2,
#: 7 limit2, 8 band, 9 the gate's mean, 10 the plan's transient floor's mean, 11 the revolution
#: mean's ratio to the plan's, 12 the same flute's deviation one revolution earlier, 13 the
#: flute pattern's evidence (decision 1684), 14 1.0 where the pattern confirmed the alarm, 15-16
#: the residuals of the violation before a plan-free flute check's alarm (decision 1707), 17
#: the period's samples; NaN where not known) and of a detector's outputs (rows 3 … 8).
PP_ROWS = 18
PP_GATE = 9
PP_FLOOR = 10
PP_REV = 11
PP_LAG = 12
PP_PAT = 13
PP_BY = 14
PP_CE1 = 15  # the residuals of the violation before an alarm of the plan-free flute check at
PP_CE2 = 16  # the next period, which completed the pair (decision 1707); NaN elsewhere
PP_COUNT = 17
OUT_ROWS = 6

MODE_VIRTUAL = 0  # seed 000: |ε1| > σ_TB τ_sim and |τ − τ_sim| > σ_TB τ_sim, confirm
MODE_CONSTANT = 1  # the same with a constant τ_ref (given, or the mean of the first revolutions)
MODE_DUAL = 2  # seed 002: |ε1| > thr1 and |ε2| > thr2 in the same period

#: Lengths of a detector's ``params`` and ``iparams`` (:func:`detect_periods`).
N_PARAMS = 12
N_IPARAMS = 9
#: A group's packed state (one compiled call per chunk with few arguments: each array argument
#: costs its unboxing at every call). Row j of ``fstate`` (float) holds detector j's segment
#: state, held outputs, params and detector state from these offsets on; row j of ``istate``
#: (int) its rows of ``x`` (a, b, expected, gate, floor; −1: none), iparams, 1 if its signal
#: is two channels, its periods ending in the chunk, the first period of its running violation
#: (−1: none) and its alarms in the chunk.
F_SEG = 0
F_HELD = F_SEG + SEG_SIZE
F_PARAMS = F_HELD + OUT_ROWS
F_DET = F_PARAMS + N_PARAMS
I_ROWS = 0
I_IPARAMS = I_ROWS + 5
I_TWO = I_IPARAMS + N_IPARAMS
I_COUNT = I_TWO + 1
I_FIRST = I_COUNT + 1
I_ALARMS = I_FIRST + 1
I_SIZE = I_ALARMS + 1
#: Rows of a group's ``pi`` (int, per period): 0 the sample it ends at, 1 its index, 2 its
#: violation flag, 3 its alarm flag (the last two a detector's ``pb``).
PI_ROWS = 4


@numba.njit(cache=True)
def pattern_base(n_flutes: int) -> int:
    """Index of the flute pattern's rings in the detector state (decision 1684)."""
    return DET_BASE + 3 * n_flutes + NOISE_WINDOW


@numba.njit(cache=True)
def sorted_noise_base(n_flutes: int) -> int:
    """Index of the noise window's sorted copy in the detector state."""
    return pattern_base(n_flutes) + (2 + 2 * PATTERN_REVS) * n_flutes + 2 * NOISE_WINDOW


@numba.njit(cache=True)
def lag_ring_base(n_flutes: int) -> int:
    """Index of the flute check's rings in the detector state (decisions 1707, 1724): Δ_N x,
    the waiting violation's flag, ε1 and ε2 of the last N periods, N values each."""
    return sorted_noise_base(n_flutes) + NOISE_WINDOW


@numba.njit(cache=True)
def pair_reach(n_flutes: int) -> int:
    """Periods that may lie between a broken flute's drop and the next flute's rise, ⌈N/2⌉
    (decision 1724): a flute's torque in a slot spans half a revolution, N/2 tooth periods,
    so the drop (the broken flute's first period) and the rise (the period after the next
    flute's last, which cuts the broken flute's chip) lie up to that far apart; 1 for N = 2
    (decision 1707's consecutive periods)."""
    return max(1, (n_flutes + 1) // 2)


def detector_state(n_flutes: int, phi0: float, p0: float) -> FloatArray:
    """Initial detector state (Munasinghe §2.5: φ₀ = 0.01, P₀ = 10, histories 0)."""
    st = np.zeros(lag_ring_base(n_flutes) + 4 * n_flutes)
    st[DET_BASE + n_flutes + NOISE_WINDOW : DET_BASE + 2 * n_flutes + NOISE_WINDOW] = math.nan
    st[DET_PHI1] = phi0
    st[DET_PHI2] = phi0
    st[DET_P1] = p0
    st[DET_P2] = p0
    st[DET_LEARN] = -1.0
    st[DET_GAP] = 1.0
    return st


@numba.njit(cache=True)
def _rls_ar1(
    e_x: float, x_prev: float, phi: float, p: float, lam: float, p_max: float
) -> tuple[float, float, float]:
    """One step of RLS for x(m) = φ x(m−1) + ε: a-priori residual, new φ and P."""
    eps = e_x - phi * x_prev
    gain = p * x_prev / (lam + x_prev * x_prev * p)
    phi_new = phi + gain * eps
    p_new = (p - gain * x_prev * p) / lam
    if p_new > p_max:
        p_new = p_max
    return eps, phi_new, p_new


@numba.njit(cache=True)
def _flute_signature(
    state: FloatArray, nf: int, seen: int, x_lag: float, ref: float, one_sided: bool
) -> tuple[float, float, bool, float, float]:
    """The revolution and the flute of a period (decision 1681): store its reference ``ref``
    (NaN: not judged) and one-sided flag in the signature's rings, and return the ratio of the
    last N periods' torque to their references (one revolution: NaN unless all N judged), the
    deviation x − ref of the same flute one revolution earlier (``x_lag`` its torque; NaN
    unless judged), whether a period of the revolution is one-sided (decision 1674) and the
    largest and smallest deviations x − ref of the revolution's periods (NaN unless all N
    judged; decision 1742)."""
    r_ex = DET_BASE + nf + NOISE_WINDOW
    r_one = r_ex + nf
    slot = seen % nf
    lag = math.nan
    if seen >= nf and state[r_ex + slot] == state[r_ex + slot]:
        lag = x_lag - state[r_ex + slot]
    state[r_ex + slot] = ref
    state[r_one + slot] = 1.0 if one_sided else 0.0
    if seen + 1 < nf:
        return math.nan, lag, False, math.nan, math.nan
    sx = 0.0
    se = 0.0
    one = False
    top = -math.inf
    bottom = math.inf
    for i in range(nf):
        e = state[r_ex + i]
        if e != e:
            return math.nan, lag, False, math.nan, math.nan
        sx += state[DET_BASE + i]
        se += e
        top = max(top, state[DET_BASE + i] - e)
        bottom = min(bottom, state[DET_BASE + i] - e)
        one = one or state[r_one + i] > 0.0
    return sx / se, lag, one, top, bottom


@numba.njit(cache=True)
def _noise_push(state: FloatArray, nf: int, value: float) -> None:
    """Add ``value`` (|Δ_N x|) to the noise window (decision 1550), the oldest one out once it
    holds NOISE_WINDOW, and keep the sorted copy of its values but NaN (:func:`_noise_median`)."""
    noise0 = DET_BASE + nf
    srt = sorted_noise_base(nf)
    n_noise = int(state[DET_NOISE_N])
    pos = int(state[DET_NOISE_POS])
    n_sorted = n_noise - int(state[DET_NOISE_NAN])
    if n_noise == NOISE_WINDOW:  # the oldest value leaves
        old = state[noise0 + pos]
        if old != old:
            state[DET_NOISE_NAN] -= 1.0
        else:
            i = _sorted_find(state, srt, n_sorted, old)
            for r in range(srt + i, srt + n_sorted - 1):
                state[r] = state[r + 1]
            n_sorted -= 1
    state[noise0 + pos] = value
    if value != value:
        state[DET_NOISE_NAN] += 1.0
    else:
        i = _sorted_find(state, srt, n_sorted, value)
        for r in range(srt + n_sorted, srt + i, -1):
            state[r] = state[r - 1]
        state[srt + i] = value
    state[DET_NOISE_POS] = (pos + 1) % NOISE_WINDOW
    state[DET_NOISE_N] = min(n_noise + 1.0, NOISE_WINDOW)


@numba.njit(cache=True)
def _sorted_find(state: FloatArray, start: int, n: int, value: float) -> int:
    """The first i in [0, n] with state[start + i] ≥ ``value`` (ascending values)."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if state[start + mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _noise_median(state: FloatArray, nf: int) -> float:
    """The median of the noise window, np.median's value: the middle of its sorted copy (the
    mean of the middle two for an even count); np.median itself where it holds a NaN."""
    n_noise = int(state[DET_NOISE_N])
    if state[DET_NOISE_NAN] > 0.0:
        noise0 = DET_BASE + nf
        return np.median(state[noise0 : noise0 + n_noise])
    srt = sorted_noise_base(nf)
    half = n_noise >> 1
    if n_noise & 1:
        return state[srt + half]
    return (state[srt + half - 1] + state[srt + half]) / 2


@numba.njit(cache=True)
def _noise_sigma(state: FloatArray, nf: int) -> float:
    """The standard deviation of one tooth-period average (decision 1550: the median |x(m) −
    x(m−N)| of the noise window) held up by its exponential mean over NOISE_SLOW calls
    (decision 1718); call once per judged period."""
    sigma = NOISE_SCALE * _noise_median(state, nf)
    slow = state[DET_NOISE_SLOW]
    slow = sigma if slow == 0.0 else slow + (sigma - slow) / NOISE_SLOW
    state[DET_NOISE_SLOW] = slow
    return max(sigma, slow)


@numba.njit(cache=True)
def _pattern_reset(state: FloatArray, nf: int) -> None:
    """Forget the flute pattern's references and evidence (a period not judged two-sided)."""
    base = DET_BASE + 3 * nf + NOISE_WINDOW
    state[DET_PRUN] = 0.0
    state[DET_PN] = 0.0
    state[DET_PPOS] = 0.0
    state[DET_PALARMED] = 0.0
    for i in range(base + 2 * nf, base + (2 + 2 * PATTERN_REVS) * nf):
        state[i] = math.nan


@numba.njit(cache=True)
def _ring_rms(state: FloatArray, ring: int, pos: int, n: int, first: int, count: int) -> float:
    """The RMS of ``count`` values of a NOISE_WINDOW ring at ``ring`` (next slot ``pos``,
    ``n`` values held) from the ``first``-th before ``pos`` back (1: the newest); NaN where not
    all are held (or one is NaN)."""
    if first + count - 1 > n:
        return math.nan
    ss = 0.0
    for j in range(first, first + count):
        v = state[ring + (pos - j) % NOISE_WINDOW]
        ss += v * v
    return math.sqrt(ss / count)


@numba.njit(cache=True)
def _scale_before(state: FloatArray, window: int, n: int, first: int, count: int) -> float:
    """The RMS of a contrast over ``count`` periods from ``first`` periods before the current
    one back (its scale window's ring at ``window``, decision 1685); NaN where not all held."""
    return _ring_rms(state, window, int(state[DET_PPOS]), n, first, count)


@numba.njit(cache=True)
def _growing_spread(
    state: FloatArray, window: int, n: int, first: int, nf: int, scale: float
) -> float:
    """The spread a pattern's drop is judged against (decisions 1685, 1727): the contrast's
    RMS over the PATTERN_BEFORE revolutions from ``first`` periods back (:func:`_scale_before`)
    or, where of two windows of w = max(N, GROWTH_PERIODS) periods from there back the newer
    spreads PATTERN_GROWTH times the older and the contrast's ``scale`` or more (an oscillation
    growing: chatter's onset, regenerative and exponential, not a break, which comes as a step
    into a steady cut), the newer's RMS grown at that rate over the ``first`` periods from it
    to the current one, newer · (newer/older)^(first/w)."""
    before = _scale_before(state, window, n, first, PATTERN_BEFORE * nf)
    w = max(nf, GROWTH_PERIODS)
    newer = _scale_before(state, window, n, first, w)
    older = _scale_before(state, window, n, first + w, w)
    if newer > PATTERN_GROWTH * max(older, scale) and older > 0.0:
        return max(before, newer * (newer / older) ** (first / w))
    return before


@numba.njit(cache=True)
def _flute_pattern(state: FloatArray, nf: int, slot: int, r: float, size: float) -> float:
    """A broken flute's pattern on a two-sided judged period (decision 1684; seed 002 §2.5:
    the broken flute k loses its chip, the next flute k + 1 cuts it as well): the evidence, in
    standard deviations, that this period's flute dropped (or the previous one dropped and this
    one rose), accumulated over up to PATTERN_REVS revolutions of the same flute; NaN until the
    references and scales are learnt.

    ``r`` = x − τ_sim, the period's residual to the plan. Its innovation u = r − r̄_k against
    the same flute's mean residual over the previous revolutions (the plan's error and the
    runout of flute k cancel) gives two contrasts in which whatever moves every flute together
    (a feed override, the plan's error along the path, a depth step) cancels:
    c = u − mean(u of the other N − 1 flutes' last periods) (a drop of this flute alone) and
    d = u − u(previous period) (the previous flute dropped, this one rose). Each is scaled by
    its own robust standard deviation (median |·| / 0.6745 over the last NOISE_WINDOW periods),
    z = min(−c, −u)/σ_c and q = min(d, −2 u_prev)/σ_d (the dropped flute must have dropped
    against its own past as well: a rise of the others, or a transient of the plan every
    flute passes, is no drop of this one), and the evidence is the largest of (Σ_{l<L} z_l)/√L and
    (Σ_{l<L} q_l)/√L over the last L = 1 … PATTERN_REVS revolutions of this flute with every
    term positive (the same flute each revolution: a broken flute stays broken), the drop alone
    (z) from its second revolution on: the next flute must have kept its torque (q) before a
    single revolution confirms, or a loss of every flute (an unplanned air gap, the tool lost)
    would start as one flute's drop. Every term needs the dropped flute's innovation at least
    ``size`` below its past (half the seed's σ_TB band, decision 1684): a change of every flute
    a fraction of a revolution off the plan's (a depth step the plan places early) leaves a
    drop and a rise of a few per cent that a quiet cut's small σ would otherwise confirm.
    A break comes into a steady cut: where the same contrast's RMS over the PATTERN_BEFORE
    revolutions ending one revolution before the first counted drop exceeds its scale (chatter
    growing faster than the scale's window follows), the evidence is judged at that RMS
    instead (:func:`_scale_before`, decision 1685)."""
    base = DET_BASE + 3 * nf + NOISE_WINDOW
    ref = base
    uu = base + nf
    zr = base + 2 * nf
    qr = zr + PATTERN_REVS * nf
    cw = qr + PATTERN_REVS * nf
    dw = cw + NOISE_WINDOW
    run = int(state[DET_PRUN])
    if run < nf:
        state[ref + slot] = r
    u = r - state[ref + slot]
    evidence = math.nan
    if run >= nf:
        others = 0.0
        for i in range(1, nf):
            others += state[uu + (slot - i) % nf]
        c = u - others / (nf - 1) if nf > 1 else u
        up = state[uu + (slot - 1) % nf]
        d = u - up
        n = int(state[DET_PN])
        if run >= PATTERN_WARM * nf and n >= NOISE_MIN:
            # the scales only where a term can count (a drop of a breakage's size; about one
            # judged period in 17 of the intact cuts): a median of 128 values costs as much as
            # the rest of the period's work
            big = -u >= size
            big_prev = -up >= size
            sc = MAD_SCALE * np.median(state[cw : cw + n]) if big else 0.0
            sd = MAD_SCALE * np.median(state[dw : dw + n]) if big_prev else 0.0
            for i in range(PATTERN_REVS - 1, 0, -1):  # this flute's last revolutions
                state[zr + i * nf + slot] = state[zr + (i - 1) * nf + slot]
                state[qr + i * nf + slot] = state[qr + (i - 1) * nf + slot]
            # the dropped flute must have dropped against its own past too, by a breakage's
            # size: a rise of the other flutes is no drop of this one
            z = min(-c, -u) / sc if big and sc > 0.0 else math.nan
            q = min(d, -2.0 * up) / sd if big_prev and sd > 0.0 else math.nan
            state[zr + slot] = z
            state[qr + slot] = q
            evidence = -math.inf
            for ring in (qr, zr):
                acc = 0.0
                scale = sd if ring == qr else sc
                for i in range(PATTERN_REVS):
                    term = state[ring + i * nf + slot]
                    if not term > 0.0:  # NaN (no drop of a breakage's size) or not this way
                        break
                    acc += term
                    if ring == qr or i > 0:  # a drop alone is judged once it repeats
                        # a break comes into a steady cut: where the cut varied more in the
                        # PATTERN_BEFORE revolutions before the drop began than the scale
                        # holds (chatter growing, decision 1685), judged at that spread
                        e = acc / math.sqrt(i + 1.0)
                        first = (i + 1) * nf + (1 if ring == qr else 0)
                        window = dw if ring == qr else cw
                        before = _growing_spread(state, window, n, first, nf, scale)
                        if before > scale > 0.0:
                            e *= scale / before
                        evidence = max(evidence, e)
        pos = int(state[DET_PPOS])
        state[cw + pos] = abs(c)
        state[dw + pos] = abs(d)
        state[DET_PPOS] = (pos + 1) % NOISE_WINDOW
        state[DET_PN] = min(n + 1.0, NOISE_WINDOW)
    k = run // nf + 1.0  # revolutions of this flute's reference, this one included
    state[ref + slot] += max(PATTERN_BETA, 1.0 / k) * (r - state[ref + slot])
    state[uu + slot] = u
    state[DET_PRUN] = run + 1.0
    return evidence


@numba.njit(cache=True)
def _flute_pair(a: float, b: float, share: float, size: float) -> bool:
    """Two consecutive tooth periods' changes over one revolution ago, Δ_N x ``a`` then ``b``:
    a broken flute's drop and the next flute's rise, in either order (the break may fall before
    or after the periods' boundary), of a breakage's size (the larger at least ``size``) and
    alike, the smaller at least ``share`` of the larger (the next flute cuts the broken flute's
    chip: its rise is the drop less the broken flute's edge force; decision 1707). An entry, a
    step, an exit or a cavity moves neighbouring flutes the same way."""
    big = max(abs(a), abs(b))
    return a * b < 0.0 and big >= size and min(abs(a), abs(b)) >= share * big


@numba.njit(cache=True, inline="always")
def _pair_slot(
    state: FloatArray, ring: int, seen: int, nf: int, reach: int, dn: float, share: float,
    size: float, waiting: bool,
) -> int:
    """The ring slot (:func:`lag_ring_base`) of the nearest of the ``reach`` periods before
    period ``seen`` whose Δ_N x forms a flute pair with ``dn`` (:func:`_flute_pair`), only
    among violations waiting for their pair where ``waiting``; −1: none (decision 1724)."""
    for j in range(1, reach + 1):
        if seen - j < nf:  # Δ_N x not known there
            return -1
        r = ring + (seen - j) % nf
        if (not waiting or state[r + nf] != 0.0) and _flute_pair(state[r], dn, share, size):
            return r
    return -1


@numba.njit(cache=True)
def _lag_n_spread(state: FloatArray, nf: int, back: int) -> float:
    """The RMS of the cut's changes over one revolution, |Δ_N x|, over the PATTERN_BEFORE
    revolutions (at least GROWTH_PERIODS periods) before the last ``back`` periods (the noise
    window's ring, decision 1550); NaN until the window holds them or where one is NaN
    (decision 1728)."""
    count = max(PATTERN_BEFORE * nf, GROWTH_PERIODS)
    return _ring_rms(state, DET_BASE + nf, int(state[DET_NOISE_POS]), int(state[DET_NOISE_N]),
                     back + 1, count)  # fmt: skip


@numba.njit(cache=True)
def _stands_out(state: FloatArray, nf: int, reach: int, dn: float, mate: int) -> bool:
    """Whether a flute pair (this period's Δ_N x ``dn`` and that in ring slot ``mate``) stands
    out of the cut's changes before it (decision 1728): its larger change at least PAIR_OUTLIER
    times their RMS over the PATTERN_BEFORE revolutions (at least GROWTH_PERIODS periods)
    before the pair's reach (:func:`_lag_n_spread`); True where that spread is not known. A
    break comes as a step into a steady cut; chatter's onset has changed the cut for
    revolutions before."""
    spread = _lag_n_spread(state, nf, reach + 1)
    big = max(abs(dn), abs(state[mate]))
    return not (spread == spread) or big >= PAIR_OUTLIER * spread


@numba.njit(cache=True)
def detect_periods(
    pp: FloatArray,
    pb: FlagArray,
    k: int,
    params: FloatArray,
    iparams: IntArray,
    state: FloatArray,
) -> None:
    """Residuals, thresholds and decisions for consecutive tooth-period values ``x``.

    Residuals (a-priori, i.e. with φ̂ of the previous period, then φ̂ is updated):
    ε1(m) = Δx(m) − φ̂1 Δx(m−1), Δx(m) = x(m) − x(m−1) (Aslan 6.2–6.3, Munasinghe 3.46–3.47);
    ε2(m) = Δ_N x(m) − φ̂2 Δ_N x(m−1), Δ_N x(m) = x(m) − x(m−N) (Aslan 6.4, Munasinghe
    3.48–3.49). ``alarm[m]`` is True at the period where a run of violations reaches
    ``confirm`` violating periods (one alarm per run); a run bridges up to N − 1 periods in a
    row without a violation in the virtual mode (decision 1552), N − 2 in the constant mode
    (decision 1550). For the virtual and
    constant modes a run starts when the residual and the torque both violate σ_TB·τ_ref and
    continues while the torque does (``check_deviation``), else while the residual does.
    ``expected`` is overwritten with the reference used (τ_sim, or the constant τ_ref).
    In the virtual mode a period with a positive mean ``floor`` (row 10; samples in the plan's
    transients, where the plan gives the lowest torque over its timing window) is judged
    one-sided against expected + floor, the lower bound of its samples: only a drop below it
    by the band violates (decision 1674).

    The torque's band (decision 1550) is max(σ_TB·τ_ref, k_noise·σ̂) (row 8): σ̂, the standard
    deviation of a tooth-period average, is estimated from the median |Δ_N x| of the last
    NOISE_WINDOW periods (air, cut and transients alike; the median ignores the revolution a
    breakage or a step makes); k_noise = 0 gives the seed's band alone. The residual's limit
    stays σ_TB·τ_ref (the seed's trigger). With k_noise > 0 no period is judged before the
    window holds NOISE_MIN periods (decision 1553). σ̂ is held up by its exponential mean over
    NOISE_SLOW judged periods (decision 1718). The dual mode's thresholds are at least
    k_noise·√2·σ̂, with the same wait for the window, and are learnt afresh after the gate
    closes (decision 1719).

    With the flute signature (virtual mode, decision 1681) a run's alarm comes at its first
    violating period from the ``confirm``-th on where the last revolution looks like a broken
    flute (:func:`_flute_signature`): its torque within [1 − edge_share/N − tol, 1 + tol] of
    the references (no upper bound where a period of it is one-sided) and the same flute one
    revolution earlier deviating the same way, and not every flute of the revolution below the
    plan by half the band, with two flutes the other flute risen by 1 − edge_share − tol of the
    drop (decision 1742); or once the revolution's torque has stayed under
    1 − 1/N − tol (more than one flute's share missing) for ``lost_periods`` judged periods in a
    row (the whole cut lost). Rows 11 and 12 of ``pp`` get the revolution's ratio and the same
    flute's earlier deviation (virtual mode).

    With the flute pattern (virtual mode, ``iparams[7]``, decision 1684) a two-sided judged
    period also gets the pattern's evidence (:func:`_flute_pattern`, row 13); at
    ``params[10]`` (σ) or more, with the revolution keeping a broken flute's share (the
    signature's bound above), it alarms where the seed's rule does not (row 14: 1.0), once
    until a period not judged two-sided or a re-arm.

    With a resolution ``params[11]`` > 0 (the signal's step summed over a period, in its unit ×
    samples: a period's mean moves in steps of it over the period's samples, decision 1732) no
    deviation, change, drop or threshold is smaller than RESOLUTION_K such steps: the band,
    the dual's thresholds, the change a virtual run needs and the flute pattern's drop.

    With the plan-free flute check (dual and constant modes, ``iparams[8]``, decisions 1707 and
    1724) an alarm needs a broken flute's drop and the next flute's rise in Δ_N x
    (:func:`_flute_pair`, share 1 − edge_share − tol) at most :func:`pair_reach` periods apart
    (consecutive for N = 2), the larger at least the learnt lag-N threshold (dual) or the band
    (constant, whose running violation alarms from its confirming period on once such a pair
    lay in it). The dual alarms at a violating period that completes such a pair with one of
    the periods before it, or at one of the periods after a violation, up to that reach, that
    completes it (rows 15-16: the violation's residuals).

    Packed arguments (few arguments keep the compiled call cheap at 100 calls per second):
    ``pp`` rows 2 expected, 3 x, 4 ε1, 5 limit1, 6 ε2, 7 limit2, 8 band, 9 gate, 10 floor,
    17 samples (columns :k); ``pb``
    rows 0 violation, 1 alarm; ``params`` = (λ, P_max, σ_TB, min expected, reference, α,
    learn_from, k_noise, edge_share, tol, pattern threshold, resolution); ``iparams`` = (N, mode,
    check_deviation, learn_periods, confirm, flute signature, lost_periods, flute pattern,
    plan-free flute check).
    """
    lam, p_max, sigma_tb, min_expected = params[0], params[1], params[2], params[3]
    reference, alpha, learn_from, k_noise = params[4], params[5], params[6], params[7]
    edge_share, rev_tol = params[8], params[9]
    nf, mode, check_deviation = iparams[0], iparams[1], iparams[2] != 0
    learn_periods, confirm = iparams[3], iparams[4]
    signature = iparams[5] != 0 and mode == MODE_VIRTUAL
    lost_periods = iparams[6]
    pattern = iparams[7] != 0 and mode == MODE_VIRTUAL
    pair_check = iparams[8] != 0 and mode == MODE_DUAL
    run_pair_check = iparams[8] != 0 and mode == MODE_CONSTANT
    reach = pair_reach(nf)
    ring = lag_ring_base(nf)
    # a broken flute's chip is cut by the next flute: it rises by at least the share of the
    # drop that is not the broken flute's edge force, less the tolerance (decision 1707)
    rise_share = 1.0 - edge_share - rev_tol
    pattern_z = params[10]
    resolution = params[11]
    # a broken flute's revolution keeps at least this share of the plan's; under the other
    # flutes' shares more than one flute's torque is missing (decision 1681)
    rev_low = 1.0 - edge_share / nf - rev_tol
    rev_lost = 1.0 - 1.0 / nf - rev_tol
    x = pp[3]
    expected = pp[2]
    eps1 = pp[4]
    lim1 = pp[5]
    eps2 = pp[6]
    lim2 = pp[7]
    band_out = pp[8]
    viol = pb[0]
    alarm = pb[1]
    gate = pp[PP_GATE]
    floor = pp[PP_FLOOR]
    rev_out = pp[PP_REV]
    lag_out = pp[PP_LAG]
    pat_out = pp[PP_PAT]
    by_out = pp[PP_BY]
    ce1_out = pp[PP_CE1]
    ce2_out = pp[PP_CE2]
    count = pp[PP_COUNT]
    for m in range(k):
        rev_out[m] = math.nan
        lag_out[m] = math.nan
        pat_out[m] = math.nan
        by_out[m] = 0.0
        ce1_out[m] = math.nan
        ce2_out[m] = math.nan
        if gate[m] < 1.0:
            # a period with a sample where the gate is off (the spindle not at speed: the
            # torque holds the acceleration torque) is not judged and restarts the differences
            # (decision 1550); the noise window is kept, and so are the constant reference and
            # the dual thresholds once learnt, but for a new cut of the dual (decision 1719)
            eps1[m] = 0.0
            eps2[m] = 0.0
            lim1[m] = math.nan
            lim2[m] = math.nan
            band_out[m] = math.nan
            expected[m] = 0.0
            viol[m] = False
            alarm[m] = False
            state[DET_SEEN] = 0.0
            state[DET_RUN] = 0.0
            state[DET_MISS] = 0.0
            state[DET_GAP] = 1.0
            state[DET_JUDGED] = 0.0
            state[DET_ALARMED] = 0.0
            state[DET_LOW] = 0.0
            _pattern_reset(state, nf)
            if mode == MODE_DUAL:
                # seed 002 learns its thresholds on the first revolutions of the cut: the gate
                # reopening is another cut (an entry after air, a new speed), learnt afresh
                # (decision 1719)
                state[DET_LEARN] = -1.0
                state[DET_MAX1] = 0.0
                state[DET_MAX2] = 0.0
                state[DET_THR1] = 0.0
                state[DET_THR2] = 0.0
            continue
        seen = int(state[DET_SEEN])
        xm = x[m]
        # nothing within RESOLUTION_K steps of the signal's resolution is a breakage's
        # (decision 1732): the DOB's mean moves by a step where an encoder count flips at an
        # end of the period, and a flip holds for revolutions while the speed holds
        floor_q = RESOLUTION_K * resolution / count[m] if resolution > 0.0 else 0.0
        x1 = state[DET_BASE + (seen - 1) % nf] if seen >= 1 else 0.0
        xn = state[DET_BASE + (seen - nf) % nf] if seen >= nf else 0.0
        d1 = xm - x1 if seen >= 1 else 0.0
        dn = xm - xn if seen >= nf else 0.0
        e1, phi1, p1 = _rls_ar1(d1, state[DET_D1_PREV], state[DET_PHI1], state[DET_P1], lam, p_max)
        e2, phi2, p2 = _rls_ar1(dn, state[DET_DN_PREV], state[DET_PHI2], state[DET_P2], lam, p_max)
        if seen >= 2:
            state[DET_PHI1] = phi1
            state[DET_P1] = p1
        else:
            e1 = 0.0
        if seen >= nf + 1:
            state[DET_PHI2] = phi2
            state[DET_P2] = p2
        else:
            e2 = 0.0
        state[DET_D1_PREV] = d1
        state[DET_DN_PREV] = dn
        state[DET_BASE + seen % nf] = xm
        state[DET_SEEN] = seen + 1
        if seen >= nf:  # the noise window of |Δ_N x| (decision 1550)
            _noise_push(state, nf, abs(dn))
        eps1[m] = e1
        eps2[m] = e2
        v = False
        flute = True  # the flute signature holds (or is not asked for)
        keeps = False  # the revolution keeps a broken flute's share of the plan's torque
        evidence = math.nan  # the flute pattern's (decision 1684)
        run = state[DET_RUN]
        learn = state[DET_LEARN]
        if learn < 0 and seen >= nf + 1 and abs(xm) >= learn_from:
            learn = 0.0
        if learn >= 0 and learn < learn_periods:
            # learning: mean of x (constant reference) and max |ε| (dual thresholds)
            state[DET_MEAN] += xm
            state[DET_MAX1] = max(state[DET_MAX1], abs(e1))
            state[DET_MAX2] = max(state[DET_MAX2], abs(e2))
            learn += 1.0
            if learn >= learn_periods:
                state[DET_REF] = state[DET_MEAN] / learn_periods
                state[DET_THR1] = alpha * state[DET_MAX1]
                state[DET_THR2] = alpha * state[DET_MAX2]
        state[DET_LEARN] = learn
        ready = learn >= learn_periods
        band_out[m] = math.nan
        below = False  # judged one-sided, against the plan's transient floor (decision 1674)
        # a breakage's size in the plan-free flute check: the dual's learnt lag-N threshold
        # (decision 1707), the constant's band where it judges (decision 1724)
        pair_size = state[DET_THR2] if mode == MODE_DUAL else math.inf
        # the same flute's period one revolution before was not judged: this period's change
        # over one revolution may lie in the periods not judged (decision 1672)
        unjudged_before = state[DET_JUDGED] < nf
        judge = False  # (virtual, constant) the period is judged against its band
        sigma_now = 0.0  # σ̂ of a tooth average where the band uses it (virtual, constant)
        limit = 0.0  # (virtual, constant) the seed's band σ_TB·τ_ref
        if mode == MODE_DUAL:
            thr1 = state[DET_THR1]
            thr2 = state[DET_THR2]
            if k_noise > 0.0:
                # the residuals of a difference of two tooth-period averages are not judged
                # inside k σ of that difference's noise, nor before it is known (decision 1719)
                if state[DET_NOISE_N] < NOISE_MIN:
                    ready = False
                elif ready:
                    floor_d = k_noise * math.sqrt(2.0) * _noise_sigma(state, nf)
                    thr1 = max(thr1, floor_d)
                    thr2 = max(thr2, floor_d)
            if ready:
                thr1 = max(thr1, floor_q)
                thr2 = max(thr2, floor_q)
                pair_size = max(pair_size, floor_q)
            lim1[m] = thr1 if ready else math.nan
            lim2[m] = thr2 if ready else math.nan
            v = ready and abs(e1) > thr1 and abs(e2) > thr2
        else:
            if mode == MODE_VIRTUAL:
                ex = expected[m]
                if floor[m] > 0.0:
                    # a period in the plan's transient: its samples' lower bound (the floor
                    # there, the expected torque where steady) judges a drop only
                    ex += floor[m]
                    below = True
                judge = ex >= min_expected and seen >= 2
            else:
                ex = reference if reference > 0 else state[DET_REF]
                judge = (reference > 0 or ready) and ex >= min_expected and seen >= 2
            if k_noise > 0.0 and state[DET_NOISE_N] < NOISE_MIN:
                # no band before the noise is known (decision 1553): a trace that starts in
                # the cut would be judged on the seed's 40 % alone, which noise can confirm
                judge = False
            limit = sigma_tb * ex
            lim1[m] = limit if judge else math.nan
            lim2[m] = limit if judge else math.nan
            if judge:
                band = limit
                if k_noise > 0.0 and state[DET_NOISE_N] >= NOISE_MIN:
                    sigma_now = _noise_sigma(state, nf)
                    band = max(limit, k_noise * sigma_now)
                band = max(band, floor_q)
                band_out[m] = band
                pair_size = band
                v_res = abs(e1) > limit
                v_tq = (ex - xm if below else abs(xm - ex)) > band
                if check_deviation:
                    # trigger on the residual, confirm on the torque itself (Aslan §6.3); after
                    # periods not judged the change may lie in the gap, where the residual saw
                    # it unjudged: the torque alone starts a run (decision 1625)
                    gap = state[DET_GAP] != 0.0 and mode == MODE_VIRTUAL
                    v = (v_res and v_tq) if run == 0 and not gap else v_tq
                else:
                    v = v_res
                # a one-sided period leaves a rise unjudged, which the residual's AR(1) may
                # learn (a broken flute's alternation): it counts as a gap (decision 1674)
                state[DET_GAP] = 1.0 if below else 0.0
            elif seen >= 2:
                state[DET_GAP] = 1.0
            if mode == MODE_VIRTUAL:
                ratio, lag, one, top, bottom = _flute_signature(
                    state, nf, seen, xn, ex if judge else math.nan, below
                )
                rev_out[m] = ratio
                lag_out[m] = lag
                keeps = ratio >= rev_low and (one or ratio <= 1.0 + rev_tol)
                if pattern:
                    if judge and not below:
                        evidence = _flute_pattern(state, nf, seen % nf, xm - ex,
                                                   max(0.5 * limit, floor_q))  # fmt: skip
                    else:  # a transient or a period not judged: the pattern starts afresh
                        _pattern_reset(state, nf)
                if signature:
                    # a broken flute (decision 1681): the next flute cuts its chip, so the
                    # revolution keeps its torque but for the broken flute's edge share, and
                    # the deviation comes back at the same flute one revolution on; chatter's
                    # drops and surges take every flute together (the revolution mean moves)
                    # and are not locked to a flute. The whole cut lost is a revolution mean
                    # under the other flutes' shares (more than one flute's torque missing)
                    # for lost_periods judged periods in a row: chatter's lows are followed by
                    # the surges that cut what they left.
                    low = judge and ratio == ratio and ratio < rev_lost
                    state[DET_LOW] = state[DET_LOW] + 1.0 if low else 0.0
                    locked = lag * (xm - ex) > 0.0  # False where NaN
                    lost = lost_periods > 0 and state[DET_LOW] >= lost_periods
                    # one flute's (decision 1742): the revolution is not below the plan at
                    # every flute by half the band or more (the plan's error moves every flute
                    # together); with two flutes, whose revolution bound (1 − edge_share/2 −
                    # tol, 65 %) a plan's error or a flute losing its chip to runout passes,
                    # the other flute has risen by the share of the drop it cuts (decision
                    # 1707's, 1 − edge_share − tol): it cuts the broken flute's chip
                    single = judge and top >= -0.5 * band_out[m]  # False where NaN
                    if nf == 2:
                        single = single and top >= rise_share * max(-bottom, 0.0)
                    flute = (keeps and locked and single) or lost
        pat_out[m] = evidence
        expected[m] = ex if mode != MODE_DUAL else 0.0
        # a broken flute of N shows once a revolution at least (its own period; the next
        # flute's double chip need not leave the band where the flute's pulse is shorter than
        # its period): the virtual detector's run bridges up to N − 1 periods without a
        # violation (decision 1552), the constant one, the thesis' comparison, N − 2 (decision
        # 1550; none for N ≤ 2); the run counts the violating periods
        bridge = nf - 1 if mode == MODE_VIRTUAL else nf - 2
        if v:
            run += 1.0
            state[DET_MISS] = 0.0
        elif run > 0 and mode != MODE_DUAL and state[DET_MISS] < bridge:
            state[DET_MISS] += 1.0
        else:
            run = 0.0
            state[DET_MISS] = 0.0
        viol[m] = run > 0  # inside the running violation
        state[DET_RUN] = run
        if run == 0:
            state[DET_ALARMED] = 0.0
        # one alarm per run, at its confirm-th violation or, with the flute signature, at
        # the first violation from there on where the signature holds (decision 1681)
        fire = v and run >= confirm and state[DET_ALARMED] == 0.0 and flute
        if mode == MODE_VIRTUAL:
            # a break changes the cut: the run must hold a violating period whose change over
            # one revolution is a breakage's size beyond that change's noise (half the seed's
            # band and CHANGE_K σ of the difference), or begin within a revolution of a period
            # not judged (the change may lie in the periods not judged, decision 1625: a flute
            # broken while the plan's torque ramps up under the judged level shows its deficit
            # at once, against the same flute's unjudged period; decision 1672); a flute that has
            # deviated from the plan for revolutions (runout, the plan's error at that flute,
            # in a light cut whose band the noise no longer widens) is not broken (decision 1729)
            if run == 0:
                state[DET_CHANGED] = 0.0
            elif v and (
                (run == 1.0 and unjudged_before)
                or abs(dn) >= max(0.5 * limit, CHANGE_K * math.sqrt(2.0) * sigma_now, floor_q)
            ):
                state[DET_CHANGED] = 1.0
            if state[DET_CHANGED] == 0.0:
                fire = False
            state[DET_JUDGED] = state[DET_JUDGED] + 1.0 if judge else 0.0
        if pair_check:
            # without a plan (decisions 1707, 1724): a broken flute drops and the next flute,
            # cutting its chip too, rises (:func:`_flute_pair` of their changes over one
            # revolution), up to `reach` periods later or earlier. A violation alarms where it
            # and one of the `reach` periods before it are such a pair; otherwise it waits for
            # the next `reach` periods, the first of which to complete the pair alarms,
            # violating or not (after a flute's change the next residual ε2 = Δ_N x −
            # φ̂2·Δ_N x(m−1) can be small: the AR(1) of the lag-N differences has φ̂2 < 0)
            waits, by = False, -1  # by: the waiting violation whose pair this period completes
            mate = -1  # the ring slot of the period it pairs with
            if fire:
                mate = _pair_slot(state, ring, seen, nf, reach, dn, rise_share, pair_size, False)
                waits = mate < 0
            elif state[DET_ALARMED] == 0.0:
                by = _pair_slot(state, ring, seen, nf, reach, dn, rise_share, pair_size, True)
            if waits:
                fire = False
            elif by >= 0:
                fire = True
                mate = by
                ce1_out[m] = state[by + 2 * nf]
                ce2_out[m] = state[by + 3 * nf]
            if fire and not _stands_out(state, nf, reach, dn, mate):
                # the pair does not stand out of the changes before it: chatter's onset, no
                # broken flute (decision 1728); the violations keep waiting
                fire = False
                ce1_out[m] = math.nan
                ce2_out[m] = math.nan
            if fire:  # the waiting violations are answered
                for j in range(nf):
                    state[ring + nf + j] = 0.0
            r = ring + seen % nf
            state[r] = dn
            state[r + nf] = 1.0 if waits else 0.0
            state[r + 2 * nf] = e1
            state[r + 3 * nf] = e2
        elif run_pair_check:
            # the constant reference without a plan (decision 1724): its running violation
            # alarms once it holds a broken flute's drop and the next flute's rise over one
            # revolution ago, up to `reach` periods apart (the pair comes in the break's first
            # revolution, before the run's confirming period); a retract, an exit or a jump
            # of the whole cut moves every flute the same way
            if run == 0:
                state[DET_PAIRED] = 0.0
            else:
                r = _pair_slot(state, ring, seen, nf, reach, dn, rise_share, pair_size, False)
                if r >= 0 and _stands_out(state, nf, reach, dn, r):  # decision 1728
                    state[DET_PAIRED] = 1.0
            if state[DET_PAIRED] == 0.0:
                fire = False
            state[ring + seen % nf] = dn
        if pattern:
            # the flute pattern's path (decision 1684): its evidence at the threshold set from
            # the false-alarm rate, the revolution keeping a broken flute's share; one alarm
            # of either path until a period not judged two-sided or a re-arm
            # (1: the seed's path alarmed, which keeps its own rule; 2: the pattern did, after
            # which neither alarms again)
            if state[DET_PALARMED] == 2.0:
                fire = False
            elif fire:
                state[DET_PALARMED] = 1.0
            elif (
                state[DET_PALARMED] == 0.0
                and state[DET_ALARMED] == 0.0
                and keeps
                and evidence >= pattern_z
            ):
                fire = True
                by_out[m] = 1.0
                state[DET_PALARMED] = 2.0
        if fire:
            state[DET_ALARMED] = 1.0
        alarm[m] = fire


@numba.njit(cache=True)
def accumulate_revolutions(
    speed: FloatArray, fs: float, state: FloatArray, out_angle: FloatArray, out_rev: IntArray
) -> None:
    """Spindle angle within the revolution (rad) and revolution index of every sample.

    ``state = [fraction of a revolution, revolution index]``; the angle advances by |Ω|/f_s
    per sample (sample k carries the angle reached at k), sequentially, so any chunking gives
    the same result bit for bit.
    """
    frac = state[0]
    rev = state[1]
    scale = 1.0 / (2.0 * math.pi * fs)
    for k in range(speed.shape[0]):
        if k > 0 or rev >= 0:
            frac += abs(speed[k]) * scale
        if rev < 0:
            rev = 0.0
        while frac >= 1.0:
            frac -= 1.0
            rev += 1.0
        out_angle[k] = 2.0 * math.pi * frac
        out_rev[k] = int(rev)
    state[0] = frac
    state[1] = rev


@numba.njit(cache=True)
def fill_outputs(
    held_prev: FloatArray, per_period: FloatArray, k: int, end: IntArray, out: FloatArray
) -> None:
    """out[:, s] = the values of the last period reported at or before sample s (columns of
    ``per_period[:, :k]``, period i reported at sample ``end[i]``), or ``held_prev`` before the
    first one; then ``held_prev`` ← the last column. Row by row, one constant run per period
    (contiguous stores, where a column at a time strides across the rows)."""
    n = out.shape[1]
    for j in range(out.shape[0]):
        row = out[j]
        v = held_prev[j]
        s = 0
        for i in range(k):
            e = end[i]
            row[s:e] = v
            v = per_period[j, i]
            s = e
        row[s:n] = v
        held_prev[j] = v


@numba.njit(cache=True)
def _judge(
    pp: FloatArray,
    pb: FlagArray,
    k: int,
    has_b: bool,
    params: FloatArray,
    iparams: IntArray,
    state: FloatArray,
    first: int,
    index: IntArray,
) -> tuple[int, int]:
    """The period values x (the resultant hypot(mean0, mean1) of two channels, else mean0)
    and :func:`detect_periods` of ``k`` periods; returns the first period of the running
    violation after them (−1: none; ``first`` before them) and the number of alarms."""
    for i in range(k):
        pp[3, i] = math.hypot(pp[0, i], pp[1, i]) if has_b else pp[0, i]
    detect_periods(pp, pb, k, params, iparams, state)
    alarms = 0
    for i in range(k):
        if pb[0, i]:
            if first < 0:
                first = index[i]
        else:
            first = -1
        if pb[1, i]:
            alarms += 1
    return first, alarms


@numba.njit(cache=True)
def periods_step(
    pp: FloatArray,
    pb: FlagArray,
    k: int,
    has_b: bool,
    params: FloatArray,
    iparams: IntArray,
    state: FloatArray,
    held_prev: FloatArray,
    out: FloatArray,
    first: int,
    end: IntArray,
    index: IntArray,
) -> tuple[int, int]:
    """The per-period step of a chunk in one call: :func:`_judge` (the period values,
    :func:`detect_periods`), :func:`fill_outputs`; returns the first period of the running
    violation after the chunk (−1: none; ``first`` before it) and the number of alarms."""
    first, alarms = _judge(pp, pb, k, has_b, params, iparams, state, first, index)
    fill_outputs(held_prev, pp[3:], k, end, out)
    return first, alarms


@numba.njit(cache=True)
def periods_group(
    pp: FloatArray,
    pi: IntArray,
    fstate: FloatArray,
    istate: IntArray,
    out: FloatArray,
    shown: int,
) -> tuple[int, bool]:
    """:func:`periods_step` of several detectors in one call (detector ``j``: ``pp[j]``, period
    ends, indices and flags ``pi[j]`` (:data:`PI_ROWS`), its packed state ``fstate[j]``,
    ``istate[j]`` with ``istate[j, I_COUNT]`` periods; ``istate[j, I_ALARMS]`` ← its alarms).
    Only the first ``shown`` detectors have outputs, ``out[R j:R j + R]`` (R = OUT_ROWS), and
    only when a period of one of them ends in the chunk (a detector without one holds its
    values); else ``out`` is not written and their held values stand. Returns the alarms of
    all and whether ``out`` was written."""
    changed = False
    for j in range(shown):
        if istate[j, I_COUNT] > 0:
            changed = True
    total = 0
    for j in range(istate.shape[0]):
        k = istate[j, I_COUNT]
        held_prev = fstate[j, F_HELD:F_PARAMS]
        fill = changed and j < shown
        if k == 0:
            if fill:
                fill_outputs(held_prev, pp[j, 3:], 0, pi[j, 0],
                             out[OUT_ROWS * j : OUT_ROWS * j + OUT_ROWS])  # fmt: skip
            istate[j, I_ALARMS] = 0
            continue
        params = fstate[j, F_PARAMS:F_DET]
        state = fstate[j, F_DET:]
        iparams = istate[j, I_IPARAMS:I_TWO]
        two = istate[j, I_TWO] != 0
        first = istate[j, I_FIRST]
        pb = pi[j, 2:PI_ROWS]
        if fill:
            rows = out[OUT_ROWS * j : OUT_ROWS * j + OUT_ROWS]
            first, a = periods_step(pp[j], pb, k, two, params, iparams, state, held_prev, rows,
                                    first, pi[j, 0], pi[j, 1])  # fmt: skip
        else:  # no outputs: the values of its last period held
            first, a = _judge(pp[j], pb, k, two, params, iparams, state, first, pi[j, 1])
            for r in range(OUT_ROWS):
                held_prev[r] = pp[j, 3 + r, k - 1]
        istate[j, I_FIRST] = first
        istate[j, I_ALARMS] = a
        total += a
    return total, changed


@numba.njit(cache=True)
def group_step(
    x: FloatArray,
    speed: FloatArray,
    fs: float,
    n_flutes: int,
    fstate: FloatArray,
    istate: IntArray,
    pp: FloatArray,
    pi: IntArray,
    out: FloatArray,
    shown: int,
) -> tuple[int, int, bool]:
    """A group's chunk in one call: :func:`segment_group`, then, when a period ends,
    :func:`periods_group` (for detectors whose expected torque is a channel, not a plan matched
    between the two). Returns the largest count of periods, the alarms and whether ``out`` was
    written."""
    top: int = segment_group(x, speed, fs, n_flutes, fstate, istate, pp, pi)
    if top == 0:
        return 0, 0, False
    total, changed = periods_group(pp, pi, fstate, istate, out, shown)
    return top, total, changed
