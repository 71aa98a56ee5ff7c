"""Compiled kernels of the z-map stock and the cutter–workpiece engagement.

Grid convention (shared with :mod:`millsense.plan.stock`): ``heights[iy, ix]`` is the top
of material [m] at the cell centre (x0 + (ix + ½) h, y0 + (iy + ½) h); material fills the
column from ``bottom`` up to that height. A point is looked up in the cell that contains it;
points outside the grid hold no material.

Everything here works on plain arrays; the Python modules check the inputs.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TINY = 1e-18


@numba.njit(cache=True)
def sweep_segment(
    heights: np.ndarray,
    x0g: float,
    y0g: float,
    h: float,
    p0x: float,
    p0y: float,
    p0z: float,
    p1x: float,
    p1y: float,
    p1z: float,
    radius: float,
    ball: bool,
) -> None:
    """Lower the z-map to the exact lower envelope of a tool swept along a straight segment.

    The tool tip moves linearly from p0 to p1. For every cell centre q within R of the
    segment in XY the envelope is min over t ∈ [0, 1] of
    flat: z(t) over the t with |q − p(t)| ≤ R (minimum at an end of that t-interval, z is
    linear in t); ball: z(t) + R − √(R² − |q − p(t)|²), a convex function of t whose
    minimiser has the closed form used below. Heights only go down.
    """
    ny, nx = heights.shape
    dx = p1x - p0x
    dy = p1y - p0y
    dz = p1z - p0z
    zlow = min(p0z, p1z)
    r2 = radius * radius
    ix_lo = max(math.ceil((min(p0x, p1x) - radius - x0g) / h - 0.5), 0)
    ix_hi = min(math.floor((max(p0x, p1x) + radius - x0g) / h - 0.5), nx - 1)
    iy_lo = max(math.ceil((min(p0y, p1y) - radius - y0g) / h - 0.5), 0)
    iy_hi = min(math.floor((max(p0y, p1y) + radius - y0g) / h - 0.5), ny - 1)
    if ix_lo > ix_hi or iy_lo > iy_hi:
        return
    a = dx * dx + dy * dy
    vertical = a <= 1e-24
    ra = math.sqrt(a * (a + dz * dz)) if not vertical else 0.0
    la = math.sqrt(a)
    flat_level = (not ball) and dz == 0.0
    for iy in range(iy_lo, iy_hi + 1):
        wy = y0g + (iy + 0.5) * h - p0y
        # x-range of the row inside the swept footprint (stadium: two discs and a band)
        lo = np.inf
        hi = -np.inf
        if wy * wy <= r2:
            half = math.sqrt(r2 - wy * wy)
            lo = min(lo, p0x - half)
            hi = max(hi, p0x + half)
        wy1 = wy - dy
        if wy1 * wy1 <= r2:
            half = math.sqrt(r2 - wy1 * wy1)
            lo = min(lo, p1x - half)
            hi = max(hi, p1x + half)
        if not vertical:
            # 0 ≤ ((x − p0x) dx + wy dy)/a ≤ 1 and |(x − p0x) dy − wy dx| ≤ R √a
            b_lo = -np.inf
            b_hi = np.inf
            if dx != 0.0:
                u0 = (0.0 - wy * dy) / dx
                u1 = (a - wy * dy) / dx
                b_lo = max(b_lo, min(u0, u1))
                b_hi = min(b_hi, max(u0, u1))
            elif not (0.0 <= wy * dy <= a):
                b_hi = -np.inf
            if dy != 0.0:
                v0 = (-radius * la + wy * dx) / dy
                v1 = (radius * la + wy * dx) / dy
                b_lo = max(b_lo, min(v0, v1))
                b_hi = min(b_hi, max(v0, v1))
            elif abs(wy * dx) > radius * la:
                b_hi = -np.inf
            if b_lo <= b_hi:
                lo = min(lo, p0x + b_lo)
                hi = max(hi, p0x + b_hi)
        if lo > hi:
            continue
        jx_lo = max(math.ceil((lo - x0g) / h - 0.5 - 1e-9), ix_lo)
        jx_hi = min(math.floor((hi - x0g) / h - 0.5 + 1e-9), ix_hi)
        if flat_level:
            # flat tool at constant height: the whole row range goes down to z
            zf = np.float32(p0z)
            for ix in range(jx_lo, jx_hi + 1):
                if heights[iy, ix] > zf:
                    heights[iy, ix] = zf
            continue
        for ix in range(jx_lo, jx_hi + 1):
            hz = heights[iy, ix]
            if hz <= zlow:
                continue
            wx = x0g + (ix + 0.5) * h - p0x
            if vertical:
                g = wx * wx + wy * wy
                if g > r2:
                    continue
                if ball:
                    cand = zlow + radius - math.sqrt(r2 - g)
                else:
                    cand = zlow
            else:
                tc = (wx * dx + wy * dy) / a
                e2 = wx * wx + wy * wy - a * tc * tc
                if e2 < 0.0:
                    e2 = 0.0
                if e2 > r2:
                    continue
                rho2 = r2 - e2
                if ball:
                    t = tc - dz * math.sqrt(rho2) / ra
                    if t < 0.0:
                        t = 0.0
                    elif t > 1.0:
                        t = 1.0
                    g = a * (t - tc) * (t - tc) + e2
                    if g > r2:
                        continue
                    cand = p0z + dz * t + radius - math.sqrt(r2 - g)
                else:
                    half = math.sqrt(rho2 / a)
                    t0 = max(tc - half, 0.0)
                    t1 = min(tc + half, 1.0)
                    if t0 > t1:
                        continue
                    cand = p0z + dz * t0 if dz >= 0.0 else p0z + dz * t1
            if cand < hz:
                heights[iy, ix] = cand


@numba.njit(cache=True)
def sweep_path(
    heights: np.ndarray,
    x0g: float,
    y0g: float,
    h: float,
    xs: np.ndarray,
    ys: np.ndarray,
    zs: np.ndarray,
    join: np.ndarray,
    radius: float,
    ball: bool,
    zmax: float,
) -> None:
    """Sweep the tool along the polyline; ``join[k]`` False starts a new piece at step k."""
    for k in range(xs.size):
        if k > 0 and join[k]:
            if min(zs[k - 1], zs[k]) < zmax:
                sweep_segment(
                    heights, x0g, y0g, h, xs[k - 1], ys[k - 1], zs[k - 1],
                    xs[k], ys[k], zs[k], radius, ball,
                )  # fmt: skip
        elif zs[k] < zmax:
            sweep_segment(
                heights, x0g, y0g, h, xs[k], ys[k], zs[k], xs[k], ys[k], zs[k], radius, ball
            )


@numba.njit(cache=True)
def top_surface_from_triangles(
    heights: np.ndarray, x0g: float, y0g: float, h: float, tri: np.ndarray
) -> None:
    """Ray-cast every cell centre vertically against triangles (n, 3, 3); keep the highest hit.

    A centre on a shared edge belongs to both triangles (inclusive barycentric test with a
    relative tolerance), so closed meshes leave no pin-holes. Vertical triangles are skipped:
    a vertical ray never crosses them through their interior.
    """
    ny, nx = heights.shape
    for n in range(tri.shape[0]):
        ax, ay, az = tri[n, 0, 0], tri[n, 0, 1], tri[n, 0, 2]
        bx, by, bz = tri[n, 1, 0], tri[n, 1, 1], tri[n, 1, 2]
        cx, cy, cz = tri[n, 2, 0], tri[n, 2, 1], tri[n, 2, 2]
        det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
        scale = (abs(ax - cx) + abs(bx - cx) + abs(ay - cy) + abs(by - cy)) ** 2
        if abs(det) <= 1e-12 * scale or scale == 0.0:
            continue
        ix_lo = max(math.ceil((min(ax, bx, cx) - x0g) / h - 0.5), 0)
        ix_hi = min(math.floor((max(ax, bx, cx) - x0g) / h - 0.5), nx - 1)
        iy_lo = max(math.ceil((min(ay, by, cy) - y0g) / h - 0.5), 0)
        iy_hi = min(math.floor((max(ay, by, cy) - y0g) / h - 0.5), ny - 1)
        tol = -1e-9
        for iy in range(iy_lo, iy_hi + 1):
            py = y0g + (iy + 0.5) * h
            for ix in range(ix_lo, ix_hi + 1):
                px = x0g + (ix + 0.5) * h
                l1 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / det
                if l1 < tol:
                    continue
                l2 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / det
                if l2 < tol:
                    continue
                l3 = 1.0 - l1 - l2
                if l3 < tol:
                    continue
                z = l1 * az + l2 * bz + l3 * cz
                if z > heights[iy, ix]:
                    heights[iy, ix] = z


@numba.njit(cache=True)
def _height_at(
    heights: np.ndarray, x0g: float, y0g: float, h: float, px: float, py: float, empty: float
) -> float:
    ny, nx = heights.shape
    fx = (px - x0g) / h
    fy = (py - y0g) / h
    if fx < 0.0 or fy < 0.0:
        return empty
    ix = int(fx)
    iy = int(fy)
    if ix >= nx or iy >= ny:
        return empty
    return heights[iy, ix]


@numba.njit(cache=True)
def _runs_to_intervals(
    flags: np.ndarray,
    n_bins: int,
    dphi: float,
    phi_graze: float,
    max_gap: int,
    max_iv: int,
    out: np.ndarray,
    run_s: np.ndarray,
    run_e: np.ndarray,
) -> tuple[int, bool]:
    """Turn engaged bins into intervals.

    Runs separated by at most ``max_gap`` empty bins (a gap narrower than one cell, which the
    grid cannot resolve) are joined; runs lying inside the grazing zones [0, φ_g] or
    [π − φ_g, π] are dropped; beyond ``max_iv`` runs the closest ones are merged.
    """
    n = 0
    b = 0
    while b < n_bins:
        if flags[b]:
            s = b
            while b + 1 < n_bins and flags[b + 1]:
                b += 1
            if n > 0 and s - run_e[n - 1] - 1 <= max_gap:
                run_e[n - 1] = b
            else:
                run_s[n] = s
                run_e[n] = b
                n += 1
        b += 1
    m = 0
    for i in range(n):
        entry = run_s[i] * dphi
        exit_ = (run_e[i] + 1) * dphi
        if not (exit_ <= phi_graze + 1e-12 or entry >= math.pi - phi_graze - 1e-12):
            run_s[m] = run_s[i]
            run_e[m] = run_e[i]
            m += 1
    n = m
    overflow = False
    while n > max_iv:
        overflow = True
        best = 0
        gap = n_bins + 1
        for i in range(n - 1):
            g = run_s[i + 1] - run_e[i]
            if g < gap:
                gap = g
                best = i
        run_e[best] = run_e[best + 1]
        for i in range(best + 1, n - 1):
            run_s[i] = run_s[i + 1]
            run_e[i] = run_e[i + 1]
        n -= 1
    for i in range(n):
        out[i, 0] = run_s[i] * dphi
        out[i, 1] = (run_e[i] + 1) * dphi
    return n, overflow


@numba.njit(cache=True, inline="always")
def _layer_radius(
    layer: int, base: float, dz: float, radius: float, ball: bool
) -> tuple[float, float]:
    """Height above the tip of a layer's middle (the layers from ``base``, ``dz`` thick) and
    the tool's radius there (a ball's below its centre, else ``radius``)."""
    zc = base + (layer + 0.5) * dz
    if ball and zc < radius:
        return zc, math.sqrt(max(radius * radius - (radius - zc) ** 2, 0.0))
    return zc, radius


@numba.njit(cache=True)
def _engage_layers(
    heights: np.ndarray,
    x0g: float,
    y0g: float,
    h: float,
    bottom: float,
    px: float,
    py: float,
    pz: float,
    ux: float,
    uy: float,
    radius: float,
    ball: bool,
    base: float,
    depth: float,
    n_layers: int,
    n_bins: int,
    delta: float,
    eps_z: float,
    max_iv: int,
    iv_out: np.ndarray,
    nv_out: np.ndarray,
    flags: np.ndarray,
    run_s: np.ndarray,
    run_e: np.ndarray,
    sinb: np.ndarray,
    cosb: np.ndarray,
    colh: np.ndarray,
) -> tuple[float, bool]:
    """Engaged intervals of every layer for one tool position and axial depth ``depth``, the
    layers from ``base`` above the tip (the stock bottom when the tip is below it, else 0).

    ``colh`` holds the material tops sampled at radius R + δ per bin (used for every layer
    of a flat tool; a ball samples each layer at its own radius). Returns the top (above the
    tip) of the material seen by engaged bins and an overflow flag.
    """
    dphi = math.pi / n_bins
    dz = depth / n_layers
    top = 0.0
    overflow = False
    vx = -uy  # tool-frame y axis (z × feed)
    vy = ux
    for layer in range(n_layers):
        zc, r = _layer_radius(layer, base, dz, radius, ball)
        zabs = pz + zc
        rs = r + delta
        cosg = (r - 0.5 * h) / rs
        phi_graze = math.acos(cosg) if cosg > -1.0 else math.pi
        if zabs <= bottom + eps_z:
            nv_out[layer] = 0
            continue
        for b in range(n_bins):
            if ball:
                sx = px + rs * (sinb[b] * ux + cosb[b] * vx)
                sy = py + rs * (sinb[b] * uy + cosb[b] * vy)
                hz = _height_at(heights, x0g, y0g, h, sx, sy, -np.inf)
            else:
                hz = colh[b]
            flags[b] = hz > zabs + eps_z
        max_gap = math.floor(h / (rs * dphi) + 1e-9)
        n, ovf = _runs_to_intervals(
            flags, n_bins, dphi, phi_graze, max_gap, max_iv, iv_out[layer], run_s, run_e
        )
        nv_out[layer] = n
        overflow = overflow or ovf
        for i in range(n):
            b0 = round(iv_out[layer, i, 0] / dphi)
            b1 = round(iv_out[layer, i, 1] / dphi)
            for b in range(b0, b1):
                if flags[b]:
                    if ball:
                        sx = px + rs * (sinb[b] * ux + cosb[b] * vx)
                        sy = py + rs * (sinb[b] * uy + cosb[b] * vy)
                        hz = _height_at(heights, x0g, y0g, h, sx, sy, -np.inf) - pz
                    else:
                        hz = colh[b] - pz
                    if hz > top:
                        top = hz
    return top, overflow


@numba.njit(cache=True)
def _peak_resultant(
    iv: np.ndarray,
    nv: np.ndarray,
    base: float,
    depth: float,
    radius: float,
    ball: bool,
    theta: np.ndarray,
    kbeta: float,
    krc_ratio: float,
    sin0: np.ndarray,
    cos0: np.ndarray,
    period: float,
    fx: np.ndarray,
    fy: np.ndarray,
) -> float:
    """Peak over spindle angle of |F_xy| / (K_tc c) [m] for the mechanistic model.

    Per flute j and layer ℓ in the engagement: dF_t = sin φ Δz, dF_r = ρ sin φ Δz (h db =
    c sin φ Δz for flat and ball layers), projected as in
    :func:`millsense.process.forces.milling_forces`. Spindle angles φ0_a = a P/n over one
    period P (``sin0``/``cos0`` hold their sines and cosines); each interval maps to a range
    of a, so only engaged edge points are visited.
    """
    n_layers = nv.size
    n = sin0.size
    step = period / n
    dz = depth / n_layers
    two_pi = 2.0 * math.pi
    for a in range(n):
        fx[a] = 0.0
        fy[a] = 0.0
    for layer in range(n_layers):
        m = nv[layer]
        if m == 0:
            continue
        zc, r = _layer_radius(layer, base, dz, radius, ball)
        sk = min(r / radius, 1.0)
        for j in range(theta.size):
            c = theta[j] + kbeta * zc  # φ = φ0 − c
            sc = math.sin(c)
            cc = math.cos(c)
            for i in range(m):
                e0 = iv[layer, i, 0]
                w = iv[layer, i, 1] - e0
                lo = c + e0
                lo = lo - two_pi * math.floor(lo / two_pi)
                for piece in range(2):
                    if piece == 0:
                        p_lo = lo
                        p_hi = min(lo + w, two_pi)
                    else:
                        if lo + w <= two_pi:
                            break
                        p_lo = 0.0
                        p_hi = lo + w - two_pi
                    a0 = max(math.ceil(p_lo / step - 1e-9), 0)
                    a1 = min(math.floor(p_hi / step + 1e-9), n - 1)
                    for a in range(a0, a1 + 1):
                        s = sin0[a] * cc - cos0[a] * sc
                        if s <= 0.0:
                            continue
                        co = cos0[a] * cc + sin0[a] * sc
                        dft = s * dz
                        dfr = krc_ratio * s * dz
                        fx[a] += -dft * co - dfr * sk * s
                        fy[a] += dft * s - dfr * sk * co
    peak = 0.0
    for a in range(n):
        res = math.sqrt(fx[a] * fx[a] + fy[a] * fy[a])
        if res > peak:
            peak = res
    return peak


@numba.njit(cache=True)
def _areas(
    iv: np.ndarray, nv: np.ndarray, base: float, depth: float, radius: float, ball: bool
) -> tuple[float, float]:
    """Projected engaged area Σ Δz r (cos entry − cos exit) and contact area
    Σ (Δz / sin κ) r (exit − entry) over layers and intervals [m²]."""
    n_layers = nv.size
    dz = depth / n_layers
    proj = 0.0
    contact = 0.0
    for layer in range(n_layers):
        _, r = _layer_radius(layer, base, dz, radius, ball)
        sk = max(min(r / radius, 1.0), 1e-12)
        for i in range(nv[layer]):
            a = float(iv[layer, i, 0])
            b = float(iv[layer, i, 1])
            proj += dz * r * (math.cos(a) - math.cos(b))
            contact += dz * r / sk * (b - a)
    return proj, contact


@numba.njit(cache=True)
def cut_and_engage(
    heights: np.ndarray,
    x0g: float,
    y0g: float,
    h: float,
    bottom: float,
    zmax: float,
    xs: np.ndarray,
    ys: np.ndarray,
    zs: np.ndarray,
    fdx: np.ndarray,
    fdy: np.ndarray,
    join: np.ndarray,
    has_prev: bool,
    prev_x: float,
    prev_y: float,
    prev_z: float,
    radius: float,
    ball: bool,
    n_layers: int,
    n_bins: int,
    delta: float,
    eps_z: float,
    theta: np.ndarray,
    kbeta: float,
    krc_ratio: float,
    n_gain_angles: int,
    gain_period: float,
    iv_out: np.ndarray,
    nv_out: np.ndarray,
    depth_out: np.ndarray,
    base_out: np.ndarray,
    gain_out: np.ndarray,
    area_out: np.ndarray,
    contact_out: np.ndarray,
) -> int:
    """Per step: sweep the tool from the previous step to this one, then sample engagement.

    The axial depth is the part of the flutes inside the stock: from the tip, or from the
    stock bottom where the tip is below it (``base_out``: that bottom's height above the tip).

    Returns the number of steps whose interval count overflowed ``iv_out``'s capacity.
    """
    n_steps = xs.size
    max_iv = iv_out.shape[2]
    flags = np.zeros(n_bins, dtype=np.bool_)
    run_s = np.zeros(n_bins, dtype=np.int64)
    run_e = np.zeros(n_bins, dtype=np.int64)
    sin0 = np.empty(n_gain_angles)
    cos0 = np.empty(n_gain_angles)
    for a in range(n_gain_angles):
        sin0[a] = math.sin(a * gain_period / n_gain_angles)
        cos0[a] = math.cos(a * gain_period / n_gain_angles)
    sinb = np.empty(n_bins)
    cosb = np.empty(n_bins)
    for b in range(n_bins):
        sinb[b] = math.sin((b + 0.5) * math.pi / n_bins)
        cosb[b] = math.cos((b + 0.5) * math.pi / n_bins)
    colh = np.empty(n_bins)
    fxw = np.zeros(n_gain_angles)
    fyw = np.zeros(n_gain_angles)
    n_overflow = 0
    for k in range(n_steps):
        # 1. material removal up to the current position (tool body occupies it now)
        if k == 0:
            if has_prev and join[0]:
                if min(prev_z, zs[0]) < zmax:
                    sweep_segment(
                        heights, x0g, y0g, h, prev_x, prev_y, prev_z,
                        xs[0], ys[0], zs[0], radius, ball,
                    )  # fmt: skip
            elif zs[0] < zmax:
                sweep_segment(
                    heights, x0g, y0g, h, xs[0], ys[0], zs[0], xs[0], ys[0], zs[0], radius, ball
                )
        elif join[k]:
            if min(zs[k - 1], zs[k]) < zmax:
                sweep_segment(
                    heights, x0g, y0g, h, xs[k - 1], ys[k - 1], zs[k - 1],
                    xs[k], ys[k], zs[k], radius, ball,
                )  # fmt: skip
        elif zs[k] < zmax:
            sweep_segment(
                heights, x0g, y0g, h, xs[k], ys[k], zs[k], xs[k], ys[k], zs[k], radius, ball
            )
        depth_out[k] = 0.0
        base_out[k] = 0.0
        gain_out[k] = 0.0
        for layer in range(n_layers):
            nv_out[k, layer] = 0
        if zs[k] >= zmax:
            continue
        # 2. top of material just outside the tool, front half, at the full radius
        ux = fdx[k]
        uy = fdy[k]
        rs = radius + delta
        a0 = 0.0
        for b in range(n_bins):
            sx = xs[k] + rs * (sinb[b] * ux - cosb[b] * uy)
            sy = ys[k] + rs * (sinb[b] * uy + cosb[b] * ux)
            colh[b] = _height_at(heights, x0g, y0g, h, sx, sy, -np.inf)
            hz = colh[b] - zs[k]
            if hz > a0:
                a0 = hz
        # the flutes below the stock bottom cut nothing: the layers start at the bottom
        base = max(bottom - zs[k], 0.0)
        if a0 <= base + eps_z:
            continue
        # 3. layers over a0, then once over the top of the engaged material if lower
        top, ovf = _engage_layers(
            heights, x0g, y0g, h, bottom, xs[k], ys[k], zs[k], ux, uy, radius, ball, base,
            a0 - base, n_layers, n_bins, delta, eps_z, max_iv, iv_out[k], nv_out[k], flags,
            run_s, run_e, sinb, cosb, colh,
        )  # fmt: skip
        depth = a0 - base
        if top <= base + eps_z:
            for layer in range(n_layers):
                nv_out[k, layer] = 0
            continue
        if nv_out[k, n_layers - 1] == 0 and top - base < depth * (1.0 - 0.5 / n_layers):
            depth = top - base
            _top2, ovf = _engage_layers(
                heights, x0g, y0g, h, bottom, xs[k], ys[k], zs[k], ux, uy, radius, ball,
                base, depth, n_layers, n_bins, delta, eps_z, max_iv, iv_out[k], nv_out[k],
                flags, run_s, run_e, sinb, cosb, colh,
            )  # fmt: skip
        any_iv = False
        for layer in range(n_layers):
            if nv_out[k, layer] > 0:
                any_iv = True
        if not any_iv:
            continue
        if ovf:
            n_overflow += 1
        depth_out[k] = depth
        base_out[k] = base
        gain_out[k] = _peak_resultant(
            iv_out[k], nv_out[k], base, depth, radius, ball, theta, kbeta, krc_ratio,
            sin0, cos0, gain_period, fxw, fyw,
        )  # fmt: skip
        area_out[k], contact_out[k] = _areas(iv_out[k], nv_out[k], base, depth, radius, ball)
    return n_overflow
