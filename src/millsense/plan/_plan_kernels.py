"""Compiled kernels of the virtual plan: masked force sums, per-step statistics, matching.

Plain arrays only; :mod:`millsense.plan.predict` and :mod:`millsense.plan.virtual_plan` check
the inputs and document the equations.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TWO_PI = 2.0 * math.pi

#: Columns of the per-step statistics (see :func:`step_stats`).
N_STATS = 21


@numba.njit(cache=True)
def masked_sums(
    phi: np.ndarray,
    disc_layer: np.ndarray,
    intervals: np.ndarray,
    n_intervals: np.ndarray,
    weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """Sum the elemental forces of the edge points inside each signature's engagement.

    phi (A, K) immersion of edge point k at angle a; disc_layer (K,) engagement layer of the
    point; intervals (S, L, M, 2) entry/exit; n_intervals (S, L); weights (A, K, C);
    out (S, A, C) accumulated.
    """
    n_sig = intervals.shape[0]
    n_ang = phi.shape[0]
    n_k = phi.shape[1]
    n_c = weights.shape[2]
    for s in range(n_sig):
        for a in range(n_ang):
            for k in range(n_k):
                layer = disc_layer[k]
                m = n_intervals[s, layer]
                if m == 0:
                    continue
                p = phi[a, k]
                inside = False
                for i in range(m):
                    entry = intervals[s, layer, i, 0]
                    width = intervals[s, layer, i, 1] - entry
                    d = p - entry
                    d -= _TWO_PI * math.floor(d / _TWO_PI)
                    if d <= width:
                        inside = True
                        break
                if inside:
                    for c in range(n_c):
                        out[s, a, c] += weights[a, k, c]


@numba.njit(cache=True)
def step_stats(
    shear: np.ndarray,
    edge: np.ndarray,
    sig: np.ndarray,
    factor: np.ndarray,
    scale: float,
    cos_t: np.ndarray,
    sin_t: np.ndarray,
    out: np.ndarray,
) -> None:
    """Statistics over one period of every step, in the machine frame.

    shear, edge (S, A, 4): F_x, F_y, F_z, torque in the tool feed frame; step n has force
    scale·factor[n]·shear[sig[n]] + edge[sig[n]], rotated by the feed angle. Steps with
    sig < 0 are left as zero. Columns of out (n, N_STATS):
    0–3 mean F_X, F_Y, F_Z, T; 4–7 their shear parts; 8/9 F_X at max |F_X| and its shear part;
    10/11 F_Y; 12/13 F_Z; 14 peak XY resultant; 15/16 F_X, F_Y at that peak; 17/18 their shear
    parts; 19/20 peak torque and its shear part.
    """
    n = sig.shape[0]
    n_ang = shear.shape[1]
    for j in range(n):
        s = sig[j]
        if s < 0:
            continue
        f = factor[j] * scale
        ct = cos_t[j]
        st = sin_t[j]
        sx = 0.0
        sy = 0.0
        sz = 0.0
        stq = 0.0
        shx = 0.0
        shy = 0.0
        shz = 0.0
        shq = 0.0
        bx = -1.0
        by = -1.0
        bz = -1.0
        br = -1.0
        bt = -1e300
        for a in range(n_ang):
            ax = f * shear[s, a, 0]
            ay = f * shear[s, a, 1]
            az = f * shear[s, a, 2]
            aq = f * shear[s, a, 3]
            tx = ax + edge[s, a, 0]
            ty = ay + edge[s, a, 1]
            tz = az + edge[s, a, 2]
            tq = aq + edge[s, a, 3]
            mx = tx * ct - ty * st
            my = tx * st + ty * ct
            ahx = ax * ct - ay * st
            ahy = ax * st + ay * ct
            sx += mx
            sy += my
            sz += tz
            stq += tq
            shx += ahx
            shy += ahy
            shz += az
            shq += aq
            if abs(mx) > bx:
                bx = abs(mx)
                out[j, 8] = mx
                out[j, 9] = ahx
            if abs(my) > by:
                by = abs(my)
                out[j, 10] = my
                out[j, 11] = ahy
            if abs(tz) > bz:
                bz = abs(tz)
                out[j, 12] = tz
                out[j, 13] = az
            r = math.sqrt(mx * mx + my * my)
            if r > br:
                br = r
                out[j, 14] = r
                out[j, 15] = mx
                out[j, 16] = my
                out[j, 17] = ahx
                out[j, 18] = ahy
            if tq > bt:
                bt = tq
                out[j, 19] = tq
                out[j, 20] = aq
        inv = 1.0 / n_ang
        out[j, 0] = sx * inv
        out[j, 1] = sy * inv
        out[j, 2] = sz * inv
        out[j, 3] = stq * inv
        out[j, 4] = shx * inv
        out[j, 5] = shy * inv
        out[j, 6] = shz * inv
        out[j, 7] = shq * inv


@numba.njit(cache=True)
def match_rows(
    px: np.ndarray,
    py: np.ndarray,
    pz: np.ndarray,
    rx: np.ndarray,
    ry: np.ndarray,
    rz: np.ndarray,
    start: int,
    tol: float,
    max_ahead: int,
    out: np.ndarray,
) -> None:
    """Forward search of each sample on the polyline of rows (see VirtualPlan.match)."""
    n = rx.shape[0]
    last = start
    for i in range(px.shape[0]):
        out[i] = -1
        stop = min(n - 1, last + max_ahead)
        for r in range(last, stop + 1):
            if r == n - 1:
                cx = rx[r]
                cy = ry[r]
                cz = rz[r]
                t = 0.0
            else:
                dx = rx[r + 1] - rx[r]
                dy = ry[r + 1] - ry[r]
                dz = rz[r + 1] - rz[r]
                ll = dx * dx + dy * dy + dz * dz
                t = 0.0
                if ll > 0.0:
                    t = ((px[i] - rx[r]) * dx + (py[i] - ry[r]) * dy + (pz[i] - rz[r]) * dz) / ll
                    t = min(max(t, 0.0), 1.0)
                cx = rx[r] + t * dx
                cy = ry[r] + t * dy
                cz = rz[r] + t * dz
            if abs(px[i] - cx) <= tol and abs(py[i] - cy) <= tol and abs(pz[i] - cz) <= tol:
                hit = r + 1 if t >= 1.0 else r
                out[i] = hit
                last = hit
                break


@numba.njit(cache=True)
def look_ahead_flags(
    t: np.ndarray,
    in_cut: np.ndarray,
    area: np.ndarray,
    chip: np.ndarray,
    row: int,
    span_s: float,
    rise: float,
) -> tuple[int, bool, bool, bool, int, int]:
    """The look-ahead verdict over the rows after ``row`` up to ``t[row] + span_s`` (see
    VirtualPlan.look_ahead: rising, leaving the cut, entering a cavity; decision 0063), in one
    pass over the rows: (flag, rising, leaving, cavity, event row or −1, end row exclusive).
    A row is in cut where ``in_cut`` is non-zero (NaN included, as numpy's cast to bool)."""
    n = t.shape[0]
    end = np.searchsorted(t, t[row] + span_s, side="right")
    end = max(min(end, n), row + 1)
    now_cut = in_cut[row] != 0
    a_hi = (1 + rise) * area[row]
    c_hi = (1 + rise) * chip[row]
    a_lo = (1 - rise) * area[row]
    first_rise = -1
    last_cut = -1
    for i in range(row + 1, end):
        cut = in_cut[i] != 0
        if cut:
            last_cut = i
            if first_rise < 0 and (not now_cut or area[i] >= a_hi or chip[i] >= c_hi):
                first_rise = i
    leaving = False
    cavity = False
    first_hold = -1
    if now_cut and end > row + 1:
        # leaving: rows after the last row in cut (the cut never resumes within the horizon);
        # cavity: a row out of cut or with the area dropped, before the cut resumes
        leaving = last_cut < end - 1
        for i in range(row + 1, last_cut + 1):
            if in_cut[i] == 0 or area[i] <= a_lo:
                cavity = True
                first_hold = i
                break
        if first_hold < 0 and leaving:
            first_hold = max(last_cut + 1, row + 1)
    rising = first_rise >= 0
    if leaving or cavity:
        return 2, rising, leaving, cavity, first_hold, end
    if rising:
        return 1, rising, leaving, cavity, first_rise, end
    return 0, rising, leaving, cavity, -1, end
