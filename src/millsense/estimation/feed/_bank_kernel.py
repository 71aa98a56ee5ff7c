"""One compiled call per chunk for every feed-axis estimator of a machine (decision 1652).

Each :class:`~millsense.estimation.feed.estimator.FeedAxisEstimator` on its own spends ≈ 50 ns
a sample in its steady-state Kalman filter (Aslan Eq. 3.21–3.29 in the real modal form of
:func:`~millsense.estimation.kalman.lti_filter.run_lti`): its output ``y = H z + J u`` is a
chain of 19–27 dependent additions, and the processor waits on each one. The ten filters of a
five-axis machine (a moving and an at-rest model per axis, decision 0106) are independent, so
:func:`bank_kernel` runs them side by side: the states of all filters are columns of one array
(padded with zero states to the largest filter) and every step loops over the filters
innermost, which the compiler turns into vector instructions. Each filter's arithmetic is
unchanged, operation for operation and in the same order (a padded state adds the product
0·0 = 0 to a sum; a 1×1 modal block is a 2×2 block with zero coupling, whose product adds 0):
the outputs are bit-identical to the estimators run one by one, up to the sign of an exact
zero.

The C3 torque (``_c3_kernel``), the fixed-lag smoother's
FIR (:func:`~millsense.estimation.kalman.smoother.fixed_lag_output`), the at-rest weight
(:func:`~millsense.estimation.feed._condition_kernels.rest_weight_kernel`) and the blend of the
two models (:func:`~millsense.estimation.feed._condition_kernels.highpass_blend`) are the same
compiled functions the single-axis blocks call.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.estimation.feed._condition_kernels import highpass_blend, rest_weight_kernel
from millsense.estimation.feed.estimator import _c3_kernel
from millsense.estimation.kalman.smoother import fixed_lag_output


@numba.njit(cache=True)
def modal_bank(
    lti: NDArray[np.float64],
    n_states: NDArray[np.int64],
    z: NDArray[np.float64],
    u: NDArray[np.float64],
    y0: NDArray[np.float64],
    y1: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """F single-input, two-output modal filters over a chunk (``u``, ``y0``, ``y1`` (F, n);
    ``z`` (F, N) updated in place), :func:`~millsense.estimation.kalman.lti_filter.run_lti`'s
    arithmetic in its order, the filters side by side within each sample.

    ``lti`` (9, F, N) = [h0, h1, g, a0, b0, a1, b1, j0, j1] (j0, j1 in column 0, the pair
    coefficients in columns 0 … N/2 − 1): ``y_r = Σ_i h_r[i]·z[i] + j_r·u`` summed in the
    order of i, then ``z⁺[2b] = a0[b]·z[2b] + b0[b]·z[2b+1] + g[2b]·u`` and ``z⁺[2b+1] =
    a1[b]·z[2b] + b1[b]·z[2b+1] + g[2b+1]·u`` per pair of states (a 2×2 block of the modal
    form: a0 = diag, b0 = off, a1 = off, b1 = diag; two 1×1 blocks: the coupling 0, whose
    product adds 0). The filters' sums are independent chains the processor overlaps.
    """
    nf = z.shape[0]
    for k in range(u.shape[1]):
        for f in range(nf):
            m = n_states[f]
            uf = u[f, k]
            acc0 = 0.0
            acc1 = 0.0
            for i in range(m):
                zi = z[f, i]
                acc0 += lti[0, f, i] * zi
                acc1 += lti[1, f, i] * zi
            y0[f, k] = acc0 + lti[7, f, 0] * uf
            y1[f, k] = acc1 + lti[8, f, 0] * uf
            for b in range((m + 1) // 2):
                i = 2 * b
                z0 = z[f, i]
                z1 = z[f, i + 1]
                z[f, i] = lti[3, f, b] * z0 + lti[4, f, b] * z1 + (0.0 + lti[2, f, i] * uf)
                z[f, i + 1] = lti[5, f, b] * z0 + lti[6, f, b] * z1 + (0.0 + lti[2, f, i + 1] * uf)


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
    ``c3_of[f]``, the modal filter
    (``lti``, ``n_states``, the state ``z`` (F, N), :func:`modal_bank`); the smoother's taps
    (F, 1, 1, L + 1) and histories. Per output channel c
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
    modal_bank(lti, n_states, z, tau, y0, y1)
    # the smoothers
    smoothed = np.empty((nf, n))
    y = np.empty((n, 2))
    for f in range(nf):
        for k in range(n):
            y[k, 0] = y0[f, k]
            y[k, 1] = y1[f, k]
        s = fixed_lag_output(y, taps_t[f], hist_pred[f], hist_innov[f])
        for k in range(n):
            smoothed[f, k] = s[k, 0]
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
