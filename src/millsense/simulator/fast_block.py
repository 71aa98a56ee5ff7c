"""Compiled per-block helpers of the simulator's coupled loop (issue 12, "a bench fast enough
to use"; decision 1081).

:meth:`millsense.simulator.machine.MachineSimulator._couple_block` runs once per interpolation
period (3 ms = 30 samples). Written with NumPy, every block paid for ~70 small-array
allocations (``np.stack`` of 3×3 rotations, Jacobians and their derivatives, einsums, means) —
more than the feed-drive kernels themselves. These kernels compute the same quantities sample
by sample in one compiled call each, with the same formulas as
:class:`millsense.models.kinematics.TrunnionACMachine` (Aslan Eq. 3.36/3.38/3.39/3.49 in the
drive frames of decision 0078); only the summation order of the 3- and 5-term products may
differ (float round-off, ≤ 1e-15 relative), which the golden tests bound
(``tests/test_simulator_fast.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from millsense.simulator.feed_drive import feed_drive_kernel

_HALF_PI = 0.5 * math.pi


@numba.njit(cache=True)
def trunnion_block(
    q: np.ndarray,
    v: np.ndarray,
    a2: float,
    d4: float,
    v_w: np.ndarray,
    axis: np.ndarray,
    rot: np.ndarray,
    lm: np.ndarray,
) -> None:
    """Per sample of drive positions ``q`` (n, 5) and velocities ``v`` (n, 5): the tool-tip
    velocity ``v_w = J·v`` (n, 3), the tool axis ``[sA·sC, sA·cC, cA]`` (n, 3), the tool-to-
    workpiece rotation ``T = R(A − π/2, C)·R0`` (n, 3, 3) and the load matrix ``Jᵀ·T``
    (n, 5, 3), all in the frames of :class:`~millsense.models.kinematics.TrunnionACMachine`.

    ``J = J_Aslan·diag(R0, 1, 1)``: its first three columns are ``R·R0 = T``, the last two
    ``(∂R/∂θ_A)·rel`` and ``(∂R/∂θ_C)·rel`` with ``rel = p_Aslan − a2·e_z = [−X, −Z − d4, −Y]``
    (Aslan Eq. 3.39/3.47).
    """
    jac = np.empty((3, 5))
    for k in range(q.shape[0]):
        ta = q[k, 3] - _HALF_PI
        tc = q[k, 4]
        ca = math.cos(ta)
        sa = math.sin(ta)
        cc = math.cos(tc)
        sc = math.sin(tc)
        # Aslan's R (Eq. 3.38), rows
        r00, r01, r02 = -cc, -ca * sc, sa * sc
        r10, r11, r12 = sc, -ca * cc, sa * cc
        r20, r21, r22 = 0.0, sa, ca
        # T = R·R0, R0 = [[-1,0,0],[0,0,-1],[0,-1,0]]: columns −R[:,0], −R[:,2], −R[:,1]
        rot[k, 0, 0], rot[k, 0, 1], rot[k, 0, 2] = -r00, -r02, -r01
        rot[k, 1, 0], rot[k, 1, 1], rot[k, 1, 2] = -r10, -r12, -r11
        rot[k, 2, 0], rot[k, 2, 1], rot[k, 2, 2] = -r20, -r22, -r21
        x0 = -q[k, 0]
        x1 = -q[k, 2] - d4
        x2 = -q[k, 1]
        for i in range(3):
            for j in range(3):
                jac[i, j] = rot[k, i, j]
        # ∂R/∂θ_A·rel and ∂R/∂θ_C·rel
        jac[0, 3] = 0.0 * x0 + sa * sc * x1 + ca * sc * x2
        jac[1, 3] = 0.0 * x0 + sa * cc * x1 + ca * cc * x2
        jac[2, 3] = 0.0 * x0 + ca * x1 - sa * x2
        jac[0, 4] = sc * x0 - ca * cc * x1 + sa * cc * x2
        jac[1, 4] = cc * x0 + ca * sc * x1 - sa * sc * x2
        jac[2, 4] = 0.0
        for i in range(3):
            acc = 0.0
            for j in range(5):
                acc += jac[i, j] * v[k, j]
            v_w[k, i] = acc
        for i in range(5):
            for c in range(3):
                acc = 0.0
                for j in range(3):
                    acc += jac[j, i] * rot[k, j, c]
                lm[k, i, c] = acc
        sa_d = math.sin(q[k, 3])
        axis[k, 0] = sa_d * math.sin(tc)
        axis[k, 1] = sa_d * math.cos(tc)
        axis[k, 2] = math.cos(q[k, 3])


@numba.njit(cache=True)
def trunnion_loads(
    rot: np.ndarray, lm: np.ndarray, f_w: np.ndarray, f_machine: np.ndarray, loads: np.ndarray
) -> None:
    """``f_machine = Tᵀ·f_w`` (tool frame) and the drive loads resisting the axes,
    ``loads = −(Jᵀ·T)·f_machine`` (Aslan Eq. 3.49), per sample."""
    for k in range(f_w.shape[0]):
        for i in range(3):
            f_machine[k, i] = (
                rot[k, 0, i] * f_w[k, 0] + rot[k, 1, i] * f_w[k, 1] + rot[k, 2, i] * f_w[k, 2]
            )
        for i in range(5):
            loads[k, i] = -(
                lm[k, i, 0] * f_machine[k, 0]
                + lm[k, i, 1] * f_machine[k, 1]
                + lm[k, i, 2] * f_machine[k, 2]
            )


@numba.njit(cache=True)
def rotate_back(
    rot: np.ndarray, x_p: np.ndarray, y_p: np.ndarray, a: np.ndarray, out: np.ndarray
) -> None:
    """``out = Tᵀ·(a_x·x_p + a_y·y_p)`` per sample: a process-frame vector (the tool modes'
    x, y) in the workpiece frame, then in the tool (drive) frame; first two components."""
    for k in range(a.shape[0]):
        w0 = a[k, 0] * x_p[k, 0] + a[k, 1] * y_p[k, 0]
        w1 = a[k, 0] * x_p[k, 1] + a[k, 1] * y_p[k, 1]
        w2 = a[k, 0] * x_p[k, 2] + a[k, 1] * y_p[k, 2]
        for i in range(2):
            out[k, i] = rot[k, 0, i] * w0 + rot[k, 1, i] * w1 + rot[k, 2, i] * w2


@numba.njit(cache=True)
def trunnion_tip(q: np.ndarray, a2: float, d4: float, out: np.ndarray) -> None:
    """Tool tip (m, workpiece frame) of one pose of drive positions ``q`` (5,), Aslan Eq. 3.38
    in the drive frames: ``P = R(A − π/2, C)·[−X, −Z − d4, −Y] − d4·e_z``."""
    ta = q[3] - _HALF_PI
    tc = q[4]
    ca = math.cos(ta)
    sa = math.sin(ta)
    cc = math.cos(tc)
    sc = math.sin(tc)
    x0 = -q[0]
    x1 = -q[2] - d4
    x2 = -q[1]
    out[0] = -cc * x0 - ca * sc * x1 + sa * sc * x2
    out[1] = sc * x0 - ca * cc * x1 + sa * cc * x2
    out[2] = 0.0 * x0 + sa * x1 + ca * x2 - d4


@numba.njit(cache=True)
def trunnion_tip_error(
    q_ref: np.ndarray, err_q: np.ndarray, a2: float, d4: float, out: np.ndarray
) -> None:
    """``P(q_ref) − P(q_ref − err_q)`` (m, workpiece frame): the tool tip's tracking error."""
    pa = np.empty(3)
    pb = np.empty(3)
    trunnion_tip(q_ref, a2, d4, pa)
    trunnion_tip(q_ref - err_q, a2, d4, pb)
    for i in range(3):
        out[i] = pa[i] - pb[i]


@numba.njit(cache=True)
def block_errors(
    q_end_ref: np.ndarray,
    v_ref: np.ndarray,
    drive: np.ndarray,
    start: int,
    stop: int,
    col_pos: int,
    col_vel: int,
    err_q: np.ndarray,
    err_v: np.ndarray,
) -> None:
    """Tracking errors at the end of a block: ``err_q = q_ref(end) − q(end)`` and the block
    mean of ``v_ref − v`` (``drive`` (n_axes, n, N_OUT) outputs, rows ``start:stop``)."""
    n = stop - start
    for i in range(drive.shape[0]):
        err_q[i] = q_end_ref[i] - drive[i, stop - 1, col_pos]
        sr = 0.0
        sd = 0.0
        for k in range(start, stop):
            sr += v_ref[k, i]
            sd += drive[i, k, col_vel]
        err_v[i] = (sr - sd) / n


@numba.njit(cache=True)
def mean_abs_product(out: np.ndarray, col_a: int, col_b: int) -> float:
    """``mean(|out[:, a]·out[:, b]|)`` (the friction power of a block)."""
    acc = 0.0
    for k in range(out.shape[0]):
        acc += abs(out[k, col_a] * out[k, col_b])
    return acc / out.shape[0]


@numba.njit(cache=True)
def peak_abs(loads: np.ndarray, linear: np.ndarray) -> tuple[float, int, int]:
    """Largest ``|load|`` over the linear axes' columns and its (row, linear column index);
    the first occurrence as ``np.argmax`` of the flattened array."""
    best = -1.0
    bi = 0
    bj = 0
    for k in range(loads.shape[0]):
        jj = 0
        for j in range(loads.shape[1]):
            if linear[j]:
                a = abs(loads[k, j])
                if a > best:
                    best = a
                    bi = k
                    bj = jj
                jj += 1
    return best, bi, bj


@numba.njit(cache=True)
def drives_block(
    states,  # a tuple of FeedDriveSim.kernel_state() tuples of one numba type
    n_done: np.ndarray,
    pos_m: np.ndarray,
    vel_m: np.ndarray,
    loads: np.ndarray,
    noise: np.ndarray,
    out: np.ndarray,
    a: int,
    b: int,
    real: np.ndarray,
    temperature: np.ndarray,
    fric_base: np.ndarray,
    thermal: np.ndarray,
    col_pos: int,
    col_fric: int,
    col_speed: int,
    q_end_ref: np.ndarray,
    v_ref: np.ndarray,
    col_vel: int,
    err_q: np.ndarray,
    err_v: np.ndarray,
) -> None:
    """Every feed drive over samples ``a:b`` in one call: the kernel of each drive (the
    arguments of :meth:`~millsense.simulator.feed_drive.FeedDriveSim.advance_block`), then the
    realism friction drift of
    :meth:`~millsense.simulator.realism.AxisRealism.friction_scale`
    for the next block, then the block's tracking errors (:func:`block_errors` into ``err_q``,
    ``err_v``; ``q_end_ref`` the reference at the block's end, ``v_ref`` (n, n_axes)).

    ``loads`` (n_axes, n) and ``noise`` (n_axes, n) per axis, ``out`` (n_axes, n, N_OUT);
    ``n_done`` the samples each drive has done (advanced in place). ``real`` per axis
    ``[drift on, ripple r, wavelength λ, phase ψ, first, end friction column]``,
    ``temperature`` the axes' temperature rises (K, advanced in place), ``fric_base`` the
    friction arrays before the drift, ``thermal`` ``[R_th (K/W), τ (s), c_T (1/K), block s]``.

    Numba's disk cache of this function holds :func:`feed_drive_kernel` compiled in and is
    invalidated only by a change of this file, not of ``feed_drive.py``: a change of the
    kernel must come with a change here (or a cleared ``__pycache__``), else the cached old
    kernel runs on.
    """
    n = b - a
    for i in range(len(states)):
        st = states[i]
        o = out[i, a:b]
        feed_drive_kernel(
            st[0],
            st[1],
            st[2],
            st[3],
            st[4],
            pos_m[i, a:b],
            vel_m[i, a:b],
            loads[i],
            st[5],
            noise[i, a:b],
            st[6],
            st[7],
            st[8],
            st[9],
            st[10],
            st[11],
            st[12],
            st[13],
            st[14],
            st[15],
            st[16],
            st[17],
            st[18],
            o,
            st[19],
            st[20],
            st[21],
            st[22],
            st[23],
            n_done[i],
            st[24],
            st[25],
            st[26],
            st[27],
            st[28],
            st[29],
            st[30],
        )
        n_done[i] += n
        if real[i, 0] != 0.0:
            q = o[n - 1, col_pos]
            power = mean_abs_product(o, col_fric, col_speed)
            t_ss = thermal[0] * power
            decay = math.exp(-thermal[3] / thermal[1])
            temperature[i] = t_ss + (temperature[i] - t_ss) * decay
            ripple = 1.0 + real[i, 1] * math.sin(2 * math.pi * q / real[i, 2] + real[i, 3])
            sc = (1.0 - thermal[2] * temperature[i]) * ripple
            fric = st[14]
            for c in range(int(real[i, 4]), int(real[i, 5])):
                fric[c] = fric_base[i, c] * sc
    block_errors(q_end_ref, v_ref, out, a, b, col_pos, col_vel, err_q, err_v)
