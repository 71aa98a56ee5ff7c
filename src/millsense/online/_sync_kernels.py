"""Compiled per-chunk steps of the on-line session's gates and plan sync (decision 1653).

At 10 ms chunks :class:`~millsense.online.gates.SpindleAtSpeed`,
:class:`~millsense.online.gates.AirReference` and :class:`~millsense.online.plan_sync.PlanSync`
spent their time in the call overhead of chains of numpy operations on 100 samples
(comparisons, ``maximum.accumulate`` of run lengths, ``where``, gathers from the per-row
tables). Each chain here is one loop that performs the same floating-point operations on the
same values (comparisons, gathers, integer counts, and the same products and sums in the
same order), so the outputs are unchanged bit for bit.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.streaming.recursions import exponential_average_kernel


@numba.njit(cache=True)
def at_speed_kernel(
    speed: NDArray[np.float64],
    command: NDArray[np.float64],
    fault: NDArray[np.float64],
    state: NDArray[np.float64],
    tolerance: float,
    still: float,
    n_settle: int,
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``spindle/at_speed`` of one chunk (:class:`~millsense.online.gates.SpindleAtSpeed`).

    ``state`` = [previous command (NaN before the stream), samples in a row that were ok]:
    a sample is ok where the command is not 0, the speed within ``tolerance`` of it, the
    command within ``still`` of the previous one (relative) and ``fault`` 0 (the source's
    guard: a held or filled sample is not the machine's, decision 1559); the output is 1 where
    the run of ok samples is longer than ``n_settle``.
    """
    prev = state[0]
    run = int(state[1])
    for k in range(command.shape[0]):
        c = command[k]
        ac = abs(c)
        ok = (
            ac > 0
            and abs(speed[k] - c) <= tolerance * ac
            and abs(c - prev) <= still * ac
            and fault[k] == 0.0
        )
        run = run + 1 if ok else 0
        out[k] = 1.0 if run > n_settle else 0.0
        prev = c
    state[0] = prev
    state[1] = run


@numba.njit(cache=True)
def air_reference_kernel(
    torque: NDArray[np.float64],
    in_cut: NDArray[np.float64],
    at_speed: NDArray[np.float64],
    state: NDArray[np.float64],
    alpha: float,
    n_settle: int,
    n_start: int,
    cutting: NDArray[np.float64],
    reference: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The air-cut reference and the torque less it, one chunk (:class:`~millsense.online.
    gates.AirReference`).

    ``state`` = [reference, samples used since the spindle was last off speed (counted up to
    ``n_start``), samples in air in a row]. A sample is used where the plan has said air for
    more than ``n_settle`` samples, the spindle is at speed and the torque is finite. The
    first ``n_start`` used samples after the stream's start or a sample off speed set the
    reference to their running mean (the k-th with weight 1/k, decision 1555); after them it
    follows the used samples with ``α·x + (1 − α)·y``; it is held in between.
    """
    n = torque.shape[0]
    run = int(state[2])
    seen = int(state[1])
    x = np.empty(n)
    fresh = np.empty(n, dtype=np.bool_)  # a used sample with the spindle off speed before it
    use = np.empty(n, dtype=np.bool_)
    m = 0
    off = False
    for k in range(n):
        run = run + 1 if in_cut[k] < 0.5 else 0
        if not at_speed[k] > 0.5:
            off = True
        use[k] = run > n_settle and at_speed[k] > 0.5 and math.isfinite(torque[k])
        if use[k]:
            x[m] = torque[k]
            fresh[m] = off
            off = False
            m += 1
    state[2] = run
    y = np.empty(m)
    prev = state[0]
    j = 0
    while j < m:
        if fresh[j]:
            seen = 0
        if seen < n_start:
            # the running mean of the first n_start used samples (decision 1555)
            seen += 1
            prev = x[j] if seen == 1 else prev + (x[j] - prev) / seen
            y[j] = prev
            j += 1
            continue
        # then the project's one first-order average, up to the next restart
        e = j + 1
        while e < m and not fresh[e]:
            e += 1
        y[j:e] = exponential_average_kernel(x[j:e], alpha, prev)
        prev = y[e - 1]
        j = e
    state[1] = 0 if off else seen
    prev = state[0]
    j = 0
    for k in range(n):
        if use[k]:
            prev = y[j]
            j += 1
        reference[k] = prev
        cutting[k] = torque[k] - prev
    state[0] = prev


@numba.njit(cache=True)
def plan_rows_kernel(
    at: NDArray[np.int64],
    matched: NDArray[np.int64],
    row: int,
    u: NDArray[np.float64],
    feed: NDArray[np.float64],
    feed_table: NDArray[np.float64],
    in_cut_table: NDArray[np.bool_],
    edge_table: NDArray[np.float64],
    shear_table: NDArray[np.float64],
    nc_table: NDArray[np.int64],
    steady_table: NDArray[np.bool_],
    depth_table: NDArray[np.float64],
    floor_edge_table: NDArray[np.float64],
    floor_shear_table: NDArray[np.float64],
    rows: NDArray[np.int64],
    values: NDArray[np.float64],
    in_cut: NDArray[np.bool_],
    steady: NDArray[np.bool_],
) -> None:  # pragma: no cover - compiled
    """The plan row of every sample and what the per-row tables say there
    (:class:`~millsense.online.plan_sync.PlanSync`).

    ``matched[i]`` is the row matched at sample ``at[i]`` (−1: none); a sample takes the last
    match at or before it, else ``row`` (the previous chunk's). Row −1 reads the tables' last
    entry ("no row yet"). ``values`` (≥ 10, n): rows 0–5 = [row, NC line, in cut, edge torque,
    shear torque × ``u``, axial depth], rows 8–9 = the transient floor's edge and shear × ``u``
    parts (decision 1674). Where the CNC's path ``feed`` is given (non-empty) and the row's
    programmed feed ``feed_table`` is positive, ``u[k]`` is overwritten with their ratio: the
    feed the chip follows, the override and the path's own accelerations and decelerations
    (decision 1733).
    """
    n = rows.shape[0]
    hold = np.full(n, -1, dtype=np.int64)
    for i in range(at.shape[0]):
        hold[at[i]] = matched[i]
    last = edge_table.shape[0] - 1
    cur = row
    path = feed.shape[0] == n
    for k in range(n):
        if hold[k] >= 0:
            cur = hold[k]
        rows[k] = cur
        r = cur if cur >= 0 else last
        if path and feed_table[r] > 0.0:
            u[k] = abs(feed[k]) / feed_table[r]
        in_cut[k] = in_cut_table[r]
        steady[k] = steady_table[r]
        values[0, k] = cur
        values[1, k] = nc_table[r]
        values[2, k] = 1.0 if in_cut_table[r] else 0.0
        values[3, k] = edge_table[r]
        values[4, k] = shear_table[r] * u[k]
        values[5, k] = depth_table[r]
        values[8, k] = floor_edge_table[r]
        values[9, k] = floor_shear_table[r] * u[k]


#: :func:`override_transient_kernel`'s state: [the override the axes follow, 1.0 once set].
OVERRIDE_STATE = 2


@numba.njit(cache=True)
def override_transient_kernel(
    u: NDArray[np.float64],
    alpha: float,
    tol: float,
    state: NDArray[np.float64],
    steady: NDArray[np.bool_],
    values: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """A feed-override change as a plan transient (decision 1714). ``u_f`` follows the override
    ``u`` through a first-order lag (``u_f += alpha·(u − u_f)`` per sample, the feed drives'
    response); where they differ by more than ``tol`` of the larger, the sample is not
    ``steady`` and its transient floor (``values`` rows 8–9, :func:`plan_rows_kernel`'s) is the
    row's torque at the lower of the two: the edge part, and the shear part (``values`` row 4,
    ∝ ``u``) at ``min(u, u_f)``; a row already in the plan's transient keeps its own floor's
    parts, its shear part scaled the same way. An override of 0 (a feed hold, the feed stopping)
    is no transient: the plan then expects the edge torque alone, which the torque falls to, so
    a drop cannot be read there, and the periods that end in it are judged as before."""
    uf = state[0]
    init = state[1] != 0.0
    for k in range(u.shape[0]):
        uk = u[k]
        if not init:
            uf = uk
            init = True
        else:
            uf += alpha * (uk - uf)
        if uk > 0.0 and abs(uk - uf) > tol * max(abs(uk), abs(uf)):
            low = min(uk, uf) / uk
            if steady[k]:
                values[8, k] = values[3, k]
                values[9, k] = values[4, k] * low
                steady[k] = False
            else:
                values[9, k] *= low
    state[0] = uf
    state[1] = 1.0 if init else 0.0


@numba.njit(cache=True)
def expected_kernel(
    edge: NDArray[np.float64],
    shear: NDArray[np.float64],
    floor_edge: NDArray[np.float64],
    floor_shear: NDArray[np.float64],
    scale: NDArray[np.float64],
    steady: NDArray[np.bool_],
    ready_from: int,
    gate: NDArray[np.float64],
    expected: NDArray[np.float64],
    judged: NDArray[np.float64],
    floor: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``expected = edge + scale·shear``; ``judged`` the same where the plan is steady from
    sample ``ready_from`` on and the spindle ``gate`` (1/0 per sample; empty: none) is not
    below 0.5, else 0; ``floor = floor_edge + scale·floor_shear`` where the plan is not steady
    under the same conditions, else 0 (decision 1674)."""
    gated = gate.shape[0] > 0
    for k in range(edge.shape[0]):
        e = edge[k] + scale[k] * shear[k]
        expected[k] = e
        ok = k >= ready_from and not (gated and gate[k] < 0.5)
        judged[k] = e if steady[k] and ok else 0.0
        floor[k] = floor_edge[k] + scale[k] * floor_shear[k] if ok and not steady[k] else 0.0


@numba.njit(cache=True)
def calibration_kernel(
    speed: NDArray[np.float64],
    torque: NDArray[np.float64],
    in_cut: NDArray[np.bool_],
    edge: NDArray[np.float64],
    shear: NDArray[np.float64],
    min_cal: float,
    per_rev: float,
    revs: float,
    settle: float,
    end: float,
    gate: NDArray[np.float64],
    use: NDArray[np.bool_],
) -> tuple[int, float]:  # pragma: no cover - compiled
    """The K_tc calibration's window over one chunk (:meth:`~millsense.online.plan_sync.
    PlanSync._calibrate`): the revolutions in cut counted from ``revs`` (``|speed| / per_rev``
    per sample in cut with ``edge + shear`` at least ``min_cal``, summed in sample order as
    ``cumsum`` sums), and ``use`` the samples to average: in cut, heavy, beyond ``settle``
    revolutions, a finite ``torque``, the spindle ``gate`` (empty: none) not below 0.5, and
    before the window's ``end`` is reached. Returns the sample where the count reaches ``end``
    (−1: not in this chunk) and the count at the chunk's last sample."""
    gated = gate.shape[0] > 0
    k_done = -1
    total = 0.0
    counted = revs
    for k in range(speed.shape[0]):
        take = in_cut[k] and edge[k] + shear[k] >= min_cal
        total += abs(speed[k]) / per_rev if take else 0.0
        counted = revs + total
        if k_done < 0 and counted >= end:
            k_done = k
        use[k] = (
            take
            and counted > settle
            and math.isfinite(torque[k])
            and not (gated and not gate[k] >= 0.5)  # as `gate >= 0.5` (NaN: not at speed)
            and k_done < 0
        )
    return k_done, counted


#: :func:`torque_cut_gate_kernel`'s state: [mode, angle in the revolution, Σ torque, samples,
#: previous revolution's mean, lowest |speed| before the spindle was first at speed, revolutions
#: counted], then ``AIR_SLOTS`` air levels of ``AIR_SLOT`` values each: [speed (rad a sample),
#: revolutions, mean, M2 (Welford), revolution count when last used] (decision 1723), then the
#: samples opened on seed 002's premise (a stream that started at speed; decision 1725).
CUT_MODE, CUT_ANGLE, CUT_SUM, CUT_SAMPLES, CUT_PREVIOUS, CUT_LOWEST, CUT_COUNT = range(7)
AIR_SLOTS, AIR_SLOT = 6, 5
AIR_W, AIR_N, AIR_MEAN, AIR_M2, AIR_USED = range(AIR_SLOT)
CUT_AIR_TABLE = 7
CUT_PREMISE_SAMPLES = CUT_AIR_TABLE + AIR_SLOTS * AIR_SLOT
CUT_GATE_STATE = CUT_PREMISE_SAMPLES + 1
#: Its modes: start undecided; the stream started at speed (seed 002's premise: the gate is the
#: spindle's); air after the spindle's start; a rise above the air seen; in the steady cut.
CUT_UNDECIDED, CUT_PREMISE, CUT_AIR, CUT_ONSET, CUT_OPEN = 0, 1, 2, 3, 4
#: Revolutions whose speeds differ by at most this fraction share an air level (decision 1723).
AIR_SPEED_TOL = 0.02
#: A spindle that ran below this fraction of its new speed while off speed has started again (a
#: stop, a tool change); a speed change (an S word, an override: 3000 -> 8000 rev/min runs down
#: to 0.375 of the new speed) is not a start (decision 1723; decision 1706 took half).
START_BELOW = 0.1


@numba.njit(cache=True, inline="always")
def _air_slot(state: NDArray[np.float64], w: float) -> int:
    """The air table's slot of speed ``w`` (within ``AIR_SPEED_TOL``), or -1."""
    for i in range(AIR_SLOTS):
        o = CUT_AIR_TABLE + i * AIR_SLOT
        if state[o + AIR_N] > 0.0 and abs(state[o + AIR_W] - w) <= AIR_SPEED_TOL * w:
            return i
    return -1


@numba.njit(cache=True, inline="always")
def _air_join(state: NDArray[np.float64], w: float, m: float) -> None:
    """Revolution mean ``m`` at speed ``w`` joins the air level of its speed (Welford); a new
    speed takes an empty slot, or the one used least recently."""
    i = _air_slot(state, w)
    if i < 0:
        i, oldest = 0, math.inf
        for j in range(AIR_SLOTS):
            used = state[CUT_AIR_TABLE + j * AIR_SLOT + AIR_USED]
            if state[CUT_AIR_TABLE + j * AIR_SLOT + AIR_N] == 0.0:
                i = j
                break
            if used < oldest:
                i, oldest = j, used
        o = CUT_AIR_TABLE + i * AIR_SLOT
        state[o : o + AIR_SLOT] = 0.0
        state[o + AIR_W] = w
    o = CUT_AIR_TABLE + i * AIR_SLOT
    n = state[o + AIR_N] + 1.0
    d = m - state[o + AIR_MEAN]
    state[o + AIR_MEAN] += d / n
    state[o + AIR_M2] += d * (m - state[o + AIR_MEAN])
    state[o + AIR_N] = n
    state[o + AIR_USED] = state[CUT_COUNT]


@numba.njit(cache=True)
def air_reference(
    state: NDArray[np.float64], w: float, min_air: int
) -> tuple[bool, bool, float, float, float]:
    """The air's torque at speed ``w`` (decision 1723): (known, own, mean a, standard deviation
    s of the revolutions' means, half-width h of what the drag may be).

    - ``own``: the level learnt at this speed from at least ``min_air`` revolutions, h = 0;
    - else from the levels learnt at other speeds (each from at least ``min_air``
      revolutions): between two of them, the straight line through the nearest below and
      above (drag = Coulomb + viscous, linear in speed), h = 0; beyond them, the nearest one's
      level a₁ at speed w₁ scaled by anything from 1 (all Coulomb) to w/w₁ (all viscous):
      a = a₁(1 + w/w₁)/2, h = |a₁|·|w/w₁ − 1|/2. s is the larger of the levels' own.
    - unknown (no level learnt yet): (False, False, 0, 0, 0).
    """
    i = _air_slot(state, w)
    if i >= 0:
        o = CUT_AIR_TABLE + i * AIR_SLOT
        n = state[o + AIR_N]
        if n >= min_air:
            return True, True, state[o + AIR_MEAN], math.sqrt(state[o + AIR_M2] / (n - 1.0)), 0.0
    lo, hi = -1, -1
    for j in range(AIR_SLOTS):
        o = CUT_AIR_TABLE + j * AIR_SLOT
        if j == i or state[o + AIR_N] < min_air:
            continue
        wj = state[o + AIR_W]
        if wj < w and (lo < 0 or wj > state[CUT_AIR_TABLE + lo * AIR_SLOT + AIR_W]):
            lo = j
        elif wj > w and (hi < 0 or wj < state[CUT_AIR_TABLE + hi * AIR_SLOT + AIR_W]):
            hi = j
    if lo < 0 and hi < 0:
        return False, False, 0.0, 0.0, 0.0
    s = 0.0
    for j in (lo, hi):
        if j >= 0:
            o = CUT_AIR_TABLE + j * AIR_SLOT
            s = max(s, math.sqrt(state[o + AIR_M2] / (state[o + AIR_N] - 1.0)))
    if lo >= 0 and hi >= 0:
        ol, oh = CUT_AIR_TABLE + lo * AIR_SLOT, CUT_AIR_TABLE + hi * AIR_SLOT
        wl, al = state[ol + AIR_W], state[ol + AIR_MEAN]
        frac = (w - wl) / (state[oh + AIR_W] - wl)
        return True, False, al + frac * (state[oh + AIR_MEAN] - al), s, 0.0
    o = CUT_AIR_TABLE + (lo if lo >= 0 else hi) * AIR_SLOT
    a1, r = state[o + AIR_MEAN], w / state[o + AIR_W]
    return True, False, 0.5 * a1 * (1.0 + r), s, 0.5 * abs(a1) * abs(r - 1.0)


@numba.njit(cache=True)
def torque_cut_gate_kernel(
    torque: NDArray[np.float64],
    speed: NDArray[np.float64],
    at_speed: NDArray[np.float64],
    state: NDArray[np.float64],
    min_air: int,
    k_sigma: float,
    rel_tol: float,
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """One chunk of :class:`~millsense.online.gates.TorqueCutGate` (decisions 1706, 1723).

    The spindle's revolutions are counted by integrating |speed|; a revolution every sample of
    which is at speed gives its mean torque m and its speed w, judged at its end (the verdict
    holds for the samples after it). The air's torque at w is :func:`air_reference`'s (a, s,
    h: learnt at w, or from the air learnt at other speeds); margin = max(``k_sigma``·s,
    ``rel_tol``·|a|) + h:
    - in air (after the spindle's start): m > a + margin is a rise (a cut's onset); otherwise m
      joins the air learnt at w; with no air known at any speed yet, m joins it (``min_air``
      revolutions give the air's first spread); m < a − margin below the air learnt at w says
      that level was a cut's (one that began within ``min_air`` revolutions of the spindle
      reaching speed): the level at w restarts from m;
    - after a rise: the next revolution within ``rel_tol``·(m − a) of the previous one opens the
      gate (the cut is steady), one back at the air level returns to air;
    - open: a revolution back at the air level closes it (an exit, a retract).
    A sample off speed restarts the revolution. A spindle that ran below ``START_BELOW`` of its
    new speed while off speed (a stop, a tool change) has started again: in the air, whatever
    the gate was, and the air levels are forgotten. The output is the at-speed flag where the
    gate is open or where the stream started with the spindle at speed (no air seen: the first
    revolutions are the cut's, seed 002's premise), else 0.
    """
    mode = int(state[CUT_MODE])
    for k in range(torque.shape[0]):
        w = abs(speed[k])
        on = at_speed[k] > 0.5
        if not on:
            # the lowest speed since the spindle was last at speed
            state[CUT_LOWEST] = min(state[CUT_LOWEST], w)
            state[CUT_ANGLE : CUT_SAMPLES + 1] = 0.0  # the revolution restarts
            out[k] = 0.0
            continue
        if state[CUT_LOWEST] < math.inf:
            # back at speed: after a start (below START_BELOW of it before) the tool is in the
            # air; a speed change keeps the gate's state; the stream's first samples at speed
            # without a start before them keep seed 002's premise
            if state[CUT_LOWEST] < START_BELOW * w:
                mode = CUT_AIR
                state[CUT_AIR_TABLE:CUT_PREMISE_SAMPLES] = 0.0
            elif mode == CUT_UNDECIDED:
                mode = CUT_PREMISE
            state[CUT_LOWEST] = math.inf
        if mode == CUT_PREMISE or mode == CUT_UNDECIDED:
            out[k] = 1.0
            state[CUT_PREMISE_SAMPLES] += 1.0
            continue
        out[k] = 1.0 if mode == CUT_OPEN else 0.0
        state[CUT_ANGLE] += w
        state[CUT_SUM] += torque[k]
        state[CUT_SAMPLES] += 1.0
        if state[CUT_ANGLE] < 2.0 * math.pi:
            continue
        m = state[CUT_SUM] / state[CUT_SAMPLES]
        w_rev = state[CUT_ANGLE] / state[CUT_SAMPLES]
        state[CUT_ANGLE] -= 2.0 * math.pi
        state[CUT_SUM : CUT_SAMPLES + 1] = 0.0
        state[CUT_COUNT] += 1.0
        known, own, a, s, h = air_reference(state, w_rev, min_air)
        margin = max(k_sigma * s, rel_tol * abs(a)) + h
        at_air = known and m <= a + margin
        if mode == CUT_AIR:
            if known and m > a + margin:
                mode = CUT_ONSET
            elif own and m < a - margin:
                i = _air_slot(state, w_rev)
                state[CUT_AIR_TABLE + i * AIR_SLOT + AIR_N] = 0.0  # a cut's level, not air
                _air_join(state, w_rev, m)
            else:
                _air_join(state, w_rev, m)
        elif mode == CUT_ONSET:
            if at_air:
                mode = CUT_AIR
            elif abs(m - state[CUT_PREVIOUS]) <= rel_tol * (m - a):
                mode = CUT_OPEN
        elif mode == CUT_OPEN and at_air:
            mode = CUT_AIR
        state[CUT_PREVIOUS] = m
    state[CUT_MODE] = mode
