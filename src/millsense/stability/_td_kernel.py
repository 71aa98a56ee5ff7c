"""Compiled inner loop of the time-domain regenerative milling simulation.

Angles and signs follow :mod:`millsense.process.geometry` and :mod:`millsense.process.forces`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TWO_PI = 2.0 * math.pi
#: The surface of a bin no pass has cut yet, m (far below any real surface).
NEVER_CUT_M = -1e30
#: A surface below this is one no pass has cut.
NEVER_CUT_BELOW_M = 0.5 * NEVER_CUT_M


@numba.njit(cache=True)
def td_run(
    n_steps: int,
    step0: int,
    phi0: float,
    dphi: float,
    dt: float,
    f_rev: float,
    feed_x0: float,
    n_base: int,
    flute_theta: np.ndarray,
    radii: np.ndarray,
    lag: np.ndarray,
    bin_offset: np.ndarray,
    sin_kappa: np.ndarray,
    cos_kappa: np.ndarray,
    edge_len: np.ndarray,
    eng: np.ndarray,
    coeffs: np.ndarray,
    ad_x: np.ndarray,
    bd_x: np.ndarray,
    s_x: np.ndarray,
    ad_y: np.ndarray,
    bd_y: np.ndarray,
    s_y: np.ndarray,
    surface: np.ndarray,
    rigid: bool,
    out_f: np.ndarray,
    out_xy: np.ndarray,
    out_h: np.ndarray,
) -> None:
    """Advance the simulation ``n_steps`` steps from global step ``step0`` (in place).

    Parameters (all SI, arrays float64 unless stated)
    ----------
    f_rev, feed_x0, n_base : feed per revolution [m]; the nominal feed position is
        X = feed_x0 + f_rev (n − n_base) Δφ/(2π) [m].
    flute_theta : (N,) cumulative flute angles θ_j [rad].
    radii : (N, D) flute radius at each disc from the spindle axis [m].
    lag : (D,) helix lag ψ [rad].  bin_offset : (N, D) int, bin of flute j, disc d at step 0.
    sin_kappa, cos_kappa, edge_len : (D,) axial immersion and edge length dz/sin κ [m].
    eng : (D, M, 2) engagement intervals (entry, width) [rad]; width < 0 = unused.
    coeffs : (6,) ktc, krc, kac [N/m²], kte, kre, kae [N/m].
    ad_*, bd_* : (m, 2, 2), (m, 2) exact step transition of each mode; s_* : (m, 2) states.
    surface : (D, n_bins) radial coordinate of the surface left at each angle bin [m].
    out_f : (n, 4) F_x, F_y, F_z [N], torque [N·m]; out_xy : (n, 2) displacement [m];
    out_h : (n, N) largest chip thickness of each flute over the discs [m].
    """
    n_fl = flute_theta.shape[0]
    n_d = lag.shape[0]
    n_bins = surface.shape[1]
    n_iv = eng.shape[1]
    ktc, krc, kac, kte, kre, kae = coeffs[0], coeffs[1], coeffs[2], coeffs[3], coeffs[4], coeffs[5]
    for i in range(n_steps):
        n = step0 + i
        # Forces are evaluated at the middle of the step (angle, feed position and a
        # velocity-extrapolated displacement) and held over the step: second order in dt.
        phi = phi0 + (n + 0.5) * dphi
        feed_x = feed_x0 + f_rev * ((n + 0.5 - n_base) * dphi) / _TWO_PI
        x = 0.0
        x_mid = 0.0
        for m in range(s_x.shape[0]):
            x += s_x[m, 0]
            x_mid += s_x[m, 0] + 0.5 * dt * s_x[m, 1]
        y = 0.0
        y_mid = 0.0
        for m in range(s_y.shape[0]):
            y += s_y[m, 0]
            y_mid += s_y[m, 0] + 0.5 * dt * s_y[m, 1]
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tq = 0.0
        for j in range(n_fl):
            hmax = 0.0
            for d in range(n_d):
                a = (phi - flute_theta[j] - lag[d]) % _TWO_PI
                inside = False
                for k in range(n_iv):
                    w = eng[d, k, 1]
                    if w >= 0.0 and (a - eng[d, k, 0]) % _TWO_PI <= w:
                        inside = True
                        break
                if not inside:
                    continue
                su = math.sin(a)
                cu = math.cos(a)
                pos = (feed_x + x_mid) * su + y_mid * cu + radii[j, d]
                b = (n + bin_offset[j, d]) % n_bins
                if surface[d, b] < NEVER_CUT_BELOW_M:
                    # a bin no pass has cut (the rigid pass that lays a disc's surface misses
                    # a bin where a flute's angle rounds onto the edge of the engagement at a
                    # later step): this flute lays it, with no chip (decision 1796)
                    surface[d, b] = pos
                    continue
                h = pos - surface[d, b]
                if h <= 0.0:
                    continue
                surface[d, b] = pos
                if rigid:
                    continue
                hb = h * sin_kappa[d] * edge_len[d]
                eb = edge_len[d]
                dft = ktc * hb + kte * eb
                dfr = krc * hb + kre * eb
                dfa = kac * hb + kae * eb
                rad_out = dfa * cos_kappa[d] - dfr * sin_kappa[d]
                fx += -dft * cu + rad_out * su
                fy += dft * su + rad_out * cu
                fz += dfr * cos_kappa[d] + dfa * sin_kappa[d]
                tq += dft * radii[j, d]
                hn = h * sin_kappa[d]
                if hn > hmax:
                    hmax = hn
            if not rigid:
                out_h[i, j] = hmax
        if rigid:
            continue
        out_f[i, 0] = fx
        out_f[i, 1] = fy
        out_f[i, 2] = fz
        out_f[i, 3] = tq
        out_xy[i, 0] = x
        out_xy[i, 1] = y
        for m in range(s_x.shape[0]):
            q0 = s_x[m, 0]
            q1 = s_x[m, 1]
            s_x[m, 0] = ad_x[m, 0, 0] * q0 + ad_x[m, 0, 1] * q1 + bd_x[m, 0] * fx
            s_x[m, 1] = ad_x[m, 1, 0] * q0 + ad_x[m, 1, 1] * q1 + bd_x[m, 1] * fx
        for m in range(s_y.shape[0]):
            q0 = s_y[m, 0]
            q1 = s_y[m, 1]
            s_y[m, 0] = ad_y[m, 0, 0] * q0 + ad_y[m, 0, 1] * q1 + bd_y[m, 0] * fy
            s_y[m, 1] = ad_y[m, 1, 0] * q0 + ad_y[m, 1, 1] * q1 + bd_y[m, 1] * fy
