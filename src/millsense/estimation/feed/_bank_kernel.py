"""One compiled call per chunk for every feed-axis estimator of a machine (decision 1652).

Each :class:`~millsense.estimation.feed.estimator.FeedAxisEstimator` on its own spends ≈ 50 ns
a sample in its steady-state Kalman filter (Aslan Eq. 3.21–3.29 in the real modal form of
:func:`~millsense.estimation.kalman.lti_filter.run_lti`): its output ``y = H z + J u`` is a
chain of 19–27 dependent additions, and the processor waits on each one. The ten filters of a
five-axis machine (a moving and an at-rest model per axis, decision 0106) are run by one call,
:func:`modal_bank`, whose output sums take the samples of a block side by side (vector
instructions, see its docstring) once the states of the block are known. Each filter's
arithmetic is unchanged, operation for operation and in the same order (a 1×1 modal block is a
2×2 block with zero coupling, whose product adds 0): the outputs are bit-identical to the
estimators run one by one, up to the sign of an exact zero.

The C3 torque (``_c3_kernel``), the fixed-lag smoother
(:func:`~millsense.estimation.kalman.smoother.fixed_lag_series`), the at-rest weight
(:func:`~millsense.estimation.feed._condition_kernels.rest_weight_kernel`) and the blend of the
two models (:func:`~millsense.estimation.feed._condition_kernels.highpass_blend`) are the same
compiled functions the single-axis blocks call (the C3 torque evaluates its friction's
speed-only terms once per distinct speed of the chunk, see ``_c3_kernel``).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.estimation.feed._condition_kernels import highpass_blend, rest_weight_kernel
from millsense.estimation.feed.estimator import _c3_kernel
from millsense.estimation.kalman.smoother import fixed_lag_series

#: samples of a filter's state trajectory held at once by :func:`modal_bank` (its
#: (N, block) buffer stays in the first-level cache)
STATE_BLOCK = 128


@numba.njit(cache=True)
def modal_bank(
    lti: NDArray[np.float64],
    pairs: NDArray[np.float64],
    n_states: NDArray[np.int64],
    z: NDArray[np.float64],
    u: NDArray[np.float64],
    y0: NDArray[np.float64],
    y1: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """F single-input, two-output modal filters over a chunk (``u``, ``y0``, ``y1`` (F, n);
    ``z`` (F, N) updated in place), :func:`~millsense.estimation.kalman.lti_filter.run_lti`'s
    arithmetic in its order.

    ``lti`` (9, F, N) = [h0, h1, g, a0, b0, a1, b1, j0, j1] (j0, j1 in column 0, the pair
    coefficients in columns 0 … N/2 − 1; :func:`pairs_of` packs ``pairs`` (F, N/2, 6) = [a0,
    b0, a1, b1, g[2b], g[2b+1]] from it): ``y_r = Σ_i h_r[i]·z[i] + j_r·u`` summed in the
    order of i, then ``z⁺[2b] = a0[b]·z[2b] + b0[b]·z[2b+1] + g[2b]·u`` and ``z⁺[2b+1] =
    a1[b]·z[2b] + b1[b]·z[2b+1] + g[2b+1]·u`` per pair of states (a 2×2 block of the modal
    form: a0 = diag, b0 = off, a1 = off, b1 = diag; two 1×1 blocks: the coupling 0, whose
    product adds 0).

    The outputs are not on the recursion's path: a filter's states are advanced over a block
    of :data:`STATE_BLOCK` samples first (the trajectory kept), then every output sum of the
    block is formed with the loop over the samples innermost, four states a pass (``acc[k] =
    acc[k] + h[i]·z_i[k] + … + h[i+3]·z_{i+3}[k]``, left to right: the same additions in the
    same order as the one-sample sum), so the sums of the samples run side by side in vector
    instructions instead of one chain of 19–27 dependent additions a sample. The recursion
    itself stays scalar, filter by filter. (The filters side by side instead, states (N, F)
    with the loop over the filters innermost, measured 1.1–2× slower: numba leaves LLVM's SLP
    vectoriser off, the loop over ten filters is too short for the loop vectoriser, and
    padding every filter to 27 states almost triples the arithmetic.)
    """
    nf = z.shape[0]
    n = u.shape[1]
    block = max(1, min(STATE_BLOCK, n))
    traj = np.empty((z.shape[1], block))
    acc0 = np.empty(block)
    acc1 = np.empty(block)
    for f in range(nf):
        m = n_states[f]
        zf = z[f]
        cf = pairs[f]
        h0 = lti[0, f]
        h1 = lti[1, f]
        j0 = lti[7, f, 0]
        j1 = lti[8, f, 0]
        for k0 in range(0, n, block):
            nb = min(block, n - k0)
            for k in range(nb):
                uf = u[f, k0 + k]
                for b in range((m + 1) // 2):
                    i = 2 * b
                    z0 = zf[i]
                    z1 = zf[i + 1]
                    traj[i, k] = z0
                    traj[i + 1, k] = z1
                    zf[i] = cf[b, 0] * z0 + cf[b, 1] * z1 + (0.0 + cf[b, 4] * uf)
                    zf[i + 1] = cf[b, 2] * z0 + cf[b, 3] * z1 + (0.0 + cf[b, 5] * uf)
            for k in range(nb):
                acc0[k] = 0.0
                acc1[k] = 0.0
            i = 0
            while i + 4 <= m:
                p0, p1, p2, p3 = h0[i], h0[i + 1], h0[i + 2], h0[i + 3]
                q0, q1, q2, q3 = h1[i], h1[i + 1], h1[i + 2], h1[i + 3]
                t0, t1, t2, t3 = traj[i], traj[i + 1], traj[i + 2], traj[i + 3]
                for k in range(nb):
                    acc0[k] = acc0[k] + p0 * t0[k] + p1 * t1[k] + p2 * t2[k] + p3 * t3[k]
                    acc1[k] = acc1[k] + q0 * t0[k] + q1 * t1[k] + q2 * t2[k] + q3 * t3[k]
                i += 4
            while i < m:
                p0 = h0[i]
                q0 = h1[i]
                t0 = traj[i]
                for k in range(nb):
                    acc0[k] += p0 * t0[k]
                    acc1[k] += q0 * t0[k]
                i += 1
            for k in range(nb):
                y0[f, k0 + k] = acc0[k] + j0 * u[f, k0 + k]
                y1[f, k0 + k] = acc1[k] + j1 * u[f, k0 + k]


def pairs_of(lti: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`modal_bank`'s per-pair coefficients (F, N/2, 6) = [a0, b0, a1, b1, g[2b],
    g[2b+1]] from ``lti`` (9, F, N), each pair's six read together."""
    nf, nz = lti.shape[1], lti.shape[2]
    out = np.empty((nf, nz // 2, 6))
    out[:, :, :4] = lti[3:7, :, : nz // 2].transpose(1, 2, 0)
    out[:, :, 4] = lti[2, :, 0::2]
    out[:, :, 5] = lti[2, :, 1::2]
    return out


@numba.njit(cache=True)
def bank_kernel(
    current: NDArray[np.float64],
    speed: NDArray[np.float64],
    position: NDArray[np.float64],
    axis_of: NDArray[np.int64],
    c3_of: NDArray[np.int64],
    c3_state: NDArray[np.float64],
    c3_drive: NDArray[np.float64],
    fric_mode: NDArray[np.int64],
    fric: NDArray[np.float64],
    sos: NDArray[np.float64],
    lti: NDArray[np.float64],
    pairs: NDArray[np.float64],
    n_states: NDArray[np.int64],
    z: NDArray[np.float64],
    taps_t: NDArray[np.float64],
    hist_pred: NDArray[np.float64],
    hist_innov: NDArray[np.float64],
    rw_state: NDArray[np.float64],
    rw_drive: NDArray[np.float64],
    rw_hist: NDArray[np.float64],
    width: NDArray[np.int64],
    moving_of: NDArray[np.int64],
    at_rest_of: NDArray[np.int64],
    channel: NDArray[np.float64],
    recent: NDArray[np.float64],
    out: NDArray[np.float64],
) -> bool:  # pragma: no cover - compiled
    """The blended loads of every axis for one chunk; False if a position is not finite.

    Per axis a (rows of ``current``, ``speed``, ``position``, (A, n)): ``rw_*`` and ``width``
    are the at-rest weight's state (:func:`rest_weight_kernel`), ``moving_of[a]`` and
    ``at_rest_of[a]`` its two filters. Per C3 stage c (``_c3_kernel``): its axis ``axis_of[c]``,
    state, drive, friction mode and parameters and low-pass; per filter f: its stage
    ``c3_of[f]``, the modal filter (``lti``, ``pairs``, ``n_states``, the state ``z`` (F, N),
    :func:`modal_bank`); the smoother's taps (F, 1, 1, L + 1) and histories. Per output channel c
    (``channel[c]`` = [axis, moving gain, at-rest gain, renaming factor, started], ``recent``
    (C, W) the blend's window, W = 0 blending whole): ``out[c]`` (C, n).
    """
    n = current.shape[1]
    n_axes = current.shape[0]
    nf = c3_of.shape[0]
    w = np.empty((n_axes, n))
    for a in range(n_axes):
        ok = rest_weight_kernel(position[a], rw_state[a], rw_drive[a], rw_hist[a], width[a], w[a])
        if not ok:
            return False
    # the C3 torque of every stage (a stage shared by filters whose drive models are equal)
    n_c3 = c3_state.shape[0]
    torque = np.empty((n_c3, n))
    for c in range(n_c3):
        a = axis_of[c]
        _c3_kernel(current[a], speed[a], c3_state[c], c3_drive[c], fric_mode[c], fric[c], sos[c],
                   torque[c])  # fmt: skip
    tau = np.empty((nf, n))
    for f in range(nf):
        tau[f] = torque[c3_of[f]]
    # the Kalman filters
    y0 = np.empty((nf, n))
    y1 = np.empty((nf, n))
    modal_bank(lti, pairs, n_states, z, tau, y0, y1)
    # the smoothers
    smoothed = np.empty((nf, n))
    e = np.empty(taps_t.shape[3] - 1 + n)
    acc = np.empty(n)
    for f in range(nf):
        fixed_lag_series(y0[f], y1[f], taps_t[f, 0, 0], hist_pred[f, :, 0], hist_innov[f, 0], e,
                         acc, smoothed[f])  # fmt: skip
    # the two models of each axis blended (decision 0129), renamed
    n_win = recent.shape[1]
    mov = np.empty(n)
    rest = np.empty(n)
    blend = np.empty(n)
    for c in range(out.shape[0]):
        a = int(channel[c, 0])
        gm, gr, factor = channel[c, 1], channel[c, 2], channel[c, 3]
        sm, sr = smoothed[moving_of[a]], smoothed[at_rest_of[a]]
        for k in range(n):
            mov[k] = gm * sm[k]
            rest[k] = gr * sr[k]
        if n_win == 0:
            for k in range(n):
                blend[k] = mov[k] + w[a, k] * (rest[k] - mov[k])
        else:
            if channel[c, 4] == 0.0:
                recent[c, :] = rest[0] - mov[0]
                channel[c, 4] = 1.0
            highpass_blend(mov, rest, w[a], recent[c], blend)
        if factor == 1.0:
            out[c, :] = blend
        else:
            for k in range(n):
                out[c, k] = factor * blend[k]
    return True
