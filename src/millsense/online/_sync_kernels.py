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
    parts (decision 1674).
    """
    n = rows.shape[0]
    hold = np.full(n, -1, dtype=np.int64)
    for i in range(at.shape[0]):
        hold[at[i]] = matched[i]
    last = edge_table.shape[0] - 1
    cur = row
    for k in range(n):
        if hold[k] >= 0:
            cur = hold[k]
        rows[k] = cur
        r = cur if cur >= 0 else last
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
            and not (gated and gate[k] < 0.5)
            and k_done < 0
        )
    return k_done, counted


#: :func:`torque_cut_gate_kernel`'s state: [mode, angle in the revolution, Σ torque, samples,
#: air revolutions, air mean, air M2 (Welford), previous revolution's mean, lowest |speed| before
#: the spindle was first at speed].
CUT_GATE_STATE = 9
#: Its modes: start undecided; the stream started at speed (seed 002's premise: the gate is the
#: spindle's); air after the spindle's start; a rise above the air seen; in the steady cut.
CUT_UNDECIDED, CUT_PREMISE, CUT_AIR, CUT_ONSET, CUT_OPEN = 0, 1, 2, 3, 4


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
    """One chunk of :class:`~millsense.online.gates.TorqueCutGate` (decision 1706).

    The spindle's revolutions are counted by integrating |speed|; a revolution every sample of
    which is at speed gives its mean torque m, judged at its end (the verdict holds for the
    samples after it):
    - in air (after the spindle's start): with at least ``min_air`` air revolutions (mean
      a, standard deviation s of their means), m > a + max(``k_sigma``·s, ``rel_tol``·|a|) is
      a rise (a cut's onset); otherwise m joins the air's statistics;
    - after a rise: the next revolution within ``rel_tol``·(m − a) of the previous one opens the
      gate (the cut is steady), one back at the air level returns to air;
    - open: a revolution back at the air level closes it (an exit, a retract).
    A sample off speed restarts the revolution, and in air the air's statistics (another speed
    has another drag torque). A spindle that ran below half its new speed while off speed (a
    stop, a tool change) has started again: in the air, whatever the gate was. The output is
    the at-speed flag where the gate is open or where the stream started with the spindle at
    speed (no air seen: the first revolutions are the cut's, seed 002's premise), else 0.
    """
    mode = int(state[0])
    for k in range(torque.shape[0]):
        w = abs(speed[k])
        on = at_speed[k] > 0.5
        if not on:
            # the lowest speed since the spindle was last at speed
            state[8] = min(state[8], w)
            state[1:4] = 0.0  # the revolution restarts
            if mode == CUT_AIR:
                state[4:7] = 0.0  # another speed, another drag torque
            out[k] = 0.0
            continue
        if state[8] < math.inf:
            # back at speed: after a start (below half this speed before) the tool is in the
            # air; a speed change keeps the gate's state; the stream's first samples at speed
            # without a start before them keep seed 002's premise
            if state[8] < 0.5 * w:
                mode = CUT_AIR
                state[4:7] = 0.0
            elif mode == CUT_UNDECIDED:
                mode = CUT_PREMISE
            state[8] = math.inf
        if mode == CUT_PREMISE or mode == CUT_UNDECIDED:
            out[k] = 1.0
            continue
        out[k] = 1.0 if mode == CUT_OPEN else 0.0
        state[1] += w
        state[2] += torque[k]
        state[3] += 1.0
        if state[1] < 2.0 * math.pi:
            continue
        m = state[2] / state[3]
        state[1] -= 2.0 * math.pi
        state[2:4] = 0.0
        n_air = state[4]
        a = state[5]
        s = math.sqrt(state[6] / (n_air - 1.0)) if n_air > 1.0 else 0.0
        margin = max(k_sigma * s, rel_tol * abs(a))
        at_air = n_air >= min_air and m <= a + margin
        if mode == CUT_AIR:
            if n_air >= min_air and m > a + margin:
                mode = CUT_ONSET
            else:
                n_air += 1.0
                d = m - a
                a += d / n_air
                state[6] += d * (m - a)
                state[4] = n_air
                state[5] = a
        elif mode == CUT_ONSET:
            if at_air:
                mode = CUT_AIR
            elif abs(m - state[7]) <= rel_tol * (m - a):
                mode = CUT_OPEN
        elif mode == CUT_OPEN and at_air:
            mode = CUT_AIR
        state[7] = m
    state[0] = mode
