"""Compiled kernels of the engagement monitor: revolution harmonics and the per-revolution
Levenberg–Marquardt fit of :mod:`millsense.monitoring.torque_spectrum` (same equations as its
numpy functions ``g_coeff``, ``l_coeff``, ``_basis`` and ``_project``, which the tests compare)."""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
IntArray = NDArray[np.int64]


@numba.njit(cache=True)
def revolution_harmonics(x: FloatArray, ang: FloatArray, n_flutes: int, out: ComplexArray) -> None:
    """out[0] = mean(x e^{−iφ}), out[k] = mean(x e^{−ikNφ}) for k = 1 … len(out) − 1."""
    nk = out.shape[0]
    for j in range(nk):
        out[j] = 0.0
    n = x.shape[0]
    for s in range(n):
        b = complex(math.cos(ang[s]), -math.sin(ang[s]))
        out[0] += x[s] * b
        bn = b**n_flutes
        z = bn
        for j in range(1, nk):
            out[j] += x[s] * z
            z *= bn
    for j in range(nk):
        out[j] /= n


@numba.njit(cache=True)
def _g(m: float, st: float, ex: float) -> complex:
    if m == 0.0:
        return complex(ex - st, 0.0) / (2.0 * math.pi)
    e1 = complex(math.cos(m * st), -math.sin(m * st))
    e2 = complex(math.cos(m * ex), -math.sin(m * ex))
    return (e1 - e2) / complex(0.0, m) / (2.0 * math.pi)


@numba.njit(cache=True)
def _l(m: float, d: float, kb: float) -> complex:
    if m == 0.0:
        return complex(d, 0.0)
    a = m * kb * d
    return (1.0 - complex(math.cos(a), -math.sin(a))) / complex(0.0, m * kb)


@numba.njit(cache=True)
def _least_squares(
    a: ComplexArray, b: ComplexArray, x: ComplexArray, edge: bool
) -> tuple[float, float]:
    """Real amplitudes (α, β) minimising |x − α a − β b|² (β = 0 without the edge term): the
    2×2 normal equations of the seed 004 harmonic fit, shared by the fit and its residual."""
    aa = 0.0
    ab = 0.0
    bb = 0.0
    ax = 0.0
    bx = 0.0
    for j in range(x.shape[0]):
        aa += a[j].real ** 2 + a[j].imag ** 2
        bb += b[j].real ** 2 + b[j].imag ** 2
        ab += (a[j].conjugate() * b[j]).real
        ax += (a[j].conjugate() * x[j]).real
        bx += (b[j].conjugate() * x[j]).real
    alpha = 0.0
    beta = 0.0
    if edge:
        det = aa * bb - ab * ab
        if det > 0:
            alpha = (bb * ax - ab * bx) / det
            beta = (aa * bx - ab * ax) / det
    elif aa > 0:
        alpha = ax / aa
    return alpha, beta


@numba.njit(cache=True)
def _projected_residual(
    xn: ComplexArray, a: ComplexArray, b: ComplexArray, alpha: float, beta: float, res: FloatArray
) -> float:
    """``xn − α a − β b`` into ``res`` (real parts, then imaginary parts); returns ½‖res‖²."""
    n = xn.shape[0]
    cost = 0.0
    for j in range(n):
        r = xn[j] - alpha * a[j] - beta * b[j]
        res[j] = r.real
        res[n + j] = r.imag
        cost += r.real**2 + r.imag**2
    return 0.5 * cost


@numba.njit(cache=True)
def _fit_basis(
    p: FloatArray, x: ComplexArray, k: FloatArray, kb: float, edge: bool
) -> tuple[ComplexArray, ComplexArray, float, float]:
    """The two harmonic bases A_k, B_k at p = (d_a, θ_st, θ_ex) and the real least-squares
    amplitudes α, β of x ≈ α A + β B (β = 0 without the edge term)."""
    n = x.shape[0]
    a = np.empty(n, dtype=np.complex128)
    b = np.empty(n, dtype=np.complex128)
    d, st, ex = p[0], p[1], p[2]
    for j in range(n):
        lk = _l(k[j], d, kb)
        a[j] = (_g(k[j] - 1.0, st, ex) - _g(k[j] + 1.0, st, ex)) / complex(0.0, 2.0) * lk
        b[j] = _g(k[j], st, ex) * lk
    alpha, beta = _least_squares(a, b, x, edge)
    return a, b, alpha, beta


@numba.njit(cache=True)
def residual(
    p: FloatArray, xn: ComplexArray, k: FloatArray, kb: float, edge: bool, res: FloatArray
) -> float:
    """Projected residual of the harmonics ``xn`` for p = (d_a, θ_st, θ_ex) (real and
    imaginary parts in ``res``); returns ½‖res‖²."""
    a, b, alpha, beta = _fit_basis(p, xn, k, kb, edge)
    return _projected_residual(xn, a, b, alpha, beta, res)


@numba.njit(cache=True)
def _orders(k: FloatArray) -> tuple[FloatArray, IntArray]:
    """The distinct orders m ∈ {k−1, k, k+1} of the harmonics ``k`` and, per harmonic, the
    index of each of its three orders in that list (rows: k−1, k, k+1)."""
    n = k.shape[0]
    m = np.empty(3 * n)
    idx = np.empty((3, n), dtype=np.int64)
    count = 0
    for j in range(n):
        for o in range(3):
            v = k[j] + (o - 1.0)
            found = -1
            for q in range(count):
                if m[q] == v:
                    found = q
                    break
            if found < 0:
                m[count] = v
                found = count
                count += 1
            idx[o, j] = found
    return m[:count].copy(), idx


@numba.njit(cache=True)
def _phases(m: FloatArray, ang: float, out: ComplexArray) -> None:
    """out = e^{−i m·ang} (as :func:`_g` computes them)."""
    for q in range(m.shape[0]):
        out[q] = complex(math.cos(m[q] * ang), -math.sin(m[q] * ang))


@numba.njit(cache=True)
def _lengths(k: FloatArray, d: float, kb: float, out: ComplexArray) -> None:
    """out_j = L(k_j) at depth d (:func:`_l`)."""
    for j in range(k.shape[0]):
        out[j] = _l(k[j], d, kb)


@numba.njit(cache=True)
def _g_of(m: float, e1: complex, e2: complex, st: float, ex: float) -> complex:
    """:func:`_g` from its two phases e1 = e^{−i m θ_st}, e2 = e^{−i m θ_ex}."""
    if m == 0.0:
        return complex(ex - st, 0.0) / (2.0 * math.pi)
    return (e1 - e2) / complex(0.0, m) / (2.0 * math.pi)


@numba.njit(cache=True)
def _residual_from(
    m: FloatArray,
    idx: IntArray,
    e1: ComplexArray,
    e2: ComplexArray,
    lk: ComplexArray,
    st: float,
    ex: float,
    xn: ComplexArray,
    edge: bool,
    a: ComplexArray,
    b: ComplexArray,
    res: FloatArray,
) -> float:
    """:func:`residual` from precomputed phases and lengths (same operations in the same
    order, so the same result bit for bit)."""
    n = xn.shape[0]
    for j in range(n):
        i_lo, i_k, i_hi = idx[0, j], idx[1, j], idx[2, j]
        g_lo = _g_of(m[i_lo], e1[i_lo], e2[i_lo], st, ex)
        g_hi = _g_of(m[i_hi], e1[i_hi], e2[i_hi], st, ex)
        a[j] = (g_lo - g_hi) / complex(0.0, 2.0) * lk[j]
        b[j] = _g_of(m[i_k], e1[i_k], e2[i_k], st, ex) * lk[j]
    alpha, beta = _least_squares(a, b, xn, edge)
    return _projected_residual(xn, a, b, alpha, beta, res)


@numba.njit(cache=True)
def lm_fit(
    p0: FloatArray,
    xn: ComplexArray,
    k: FloatArray,
    kb: float,
    edge: bool,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    max_iter: int,
) -> tuple[FloatArray, float]:
    """Levenberg–Marquardt with forward-difference Jacobian and box bounds (clipping).

    The residual is :func:`residual`; its phases e^{−i m θ_st}, e^{−i m θ_ex} and lengths
    L(k) are kept for the current point, so a Jacobian column recomputes only the factor its
    parameter enters (d_a: L; θ_st, θ_ex: their phases) — the same numbers as a full
    evaluation, with a third of the sines and cosines."""
    n = xn.shape[0]
    m, idx = _orders(k)
    nm = m.shape[0]
    p = p0.copy()
    for i in range(3):
        p[i] = min(max(p[i], lo[i]), hi[i])
    r = np.empty(2 * n)
    rt = np.empty(2 * n)
    jac = np.empty((2 * n, 3))
    wa = np.empty(n, dtype=np.complex128)
    wb = np.empty(n, dtype=np.complex128)
    e1 = np.empty(nm, dtype=np.complex128)  # at p
    e2 = np.empty(nm, dtype=np.complex128)
    lk = np.empty(n, dtype=np.complex128)
    f1 = np.empty(nm, dtype=np.complex128)  # at a trial or perturbed point
    f2 = np.empty(nm, dtype=np.complex128)
    fl = np.empty(n, dtype=np.complex128)
    _phases(m, p[1], e1)
    _phases(m, p[2], e2)
    _lengths(k, p[0], kb, lk)
    cost = _residual_from(m, idx, e1, e2, lk, p[1], p[2], xn, edge, wa, wb, r)
    lam = 1e-3
    for _ in range(max_iter):
        for i in range(3):
            h = 1e-7 * scale[i]
            q = p.copy()
            q[i] = q[i] + h if q[i] + h <= hi[i] else q[i] - h
            step = q[i] - p[i]
            if i == 0:
                _lengths(k, q[0], kb, fl)
                _residual_from(m, idx, e1, e2, fl, q[1], q[2], xn, edge, wa, wb, rt)
            elif i == 1:
                _phases(m, q[1], f1)
                _residual_from(m, idx, f1, e2, lk, q[1], q[2], xn, edge, wa, wb, rt)
            else:
                _phases(m, q[2], f2)
                _residual_from(m, idx, e1, f2, lk, q[1], q[2], xn, edge, wa, wb, rt)
            for j in range(2 * n):
                jac[j, i] = (rt[j] - r[j]) / step
        jtj = jac.T @ jac
        g = jac.T @ r
        improved = False
        for _t in range(8):
            mm = jtj.copy()
            for i in range(3):
                mm[i, i] += lam * (jtj[i, i] + 1e-30)
            dp = np.linalg.solve(mm, -g)
            q = p + dp
            for i in range(3):
                q[i] = min(max(q[i], lo[i]), hi[i])
            _phases(m, q[1], f1)
            _phases(m, q[2], f2)
            _lengths(k, q[0], kb, fl)
            c2 = _residual_from(m, idx, f1, f2, fl, q[1], q[2], xn, edge, wa, wb, rt)
            if c2 < cost:
                small = True
                for i in range(3):
                    if abs(q[i] - p[i]) > 1e-7 * scale[i]:
                        small = False
                p = q
                r[:] = rt
                e1[:] = f1
                e2[:] = f2
                lk[:] = fl
                rel = (cost - c2) / max(cost, 1e-300)
                cost = c2
                lam = max(lam * 0.3, 1e-12)
                improved = True
                if small or rel < 1e-8:
                    return p, cost
                break
            lam *= 10.0
        if not improved:
            break
    return p, cost


@numba.njit(cache=True)
def amplitudes(
    p: FloatArray, x: ComplexArray, k: FloatArray, kb: float, edge: bool, model_abs: FloatArray
) -> tuple[float, float, complex, complex]:
    """Real amplitudes α, β of x ≈ α A + β B at p = (d_a, θ_st, θ_ex), |α A_k + β B_k| for the
    first len(model_abs) harmonics, and G_1, L_2 (for the runout)."""
    a, b, alpha, beta = _fit_basis(p, x, k, kb, edge)
    d, st, ex = p[0], p[1], p[2]
    for j in range(model_abs.shape[0]):
        model_abs[j] = abs(alpha * a[j] + beta * b[j])
    return alpha, beta, _g(1.0, st, ex), _l(2.0, d, kb)


@numba.njit(cache=True, error_model="numpy")
def grid_costs(
    x: ComplexArray, a: ComplexArray, b: ComplexArray, edge: bool, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """Projected misfit Σ|x − αA − βB|² of every grid row of the bases ``a``, ``b`` (rows ×
    harmonics; ``b`` unused without the edge term), as :func:`..torque_spectrum._project`
    does along the last axis; a singular row gives +inf."""
    rows, m = a.shape
    for j in range(rows):
        aa = 0.0
        ax = 0.0
        bb = 0.0
        ab = 0.0
        bx = 0.0
        for i in range(m):
            aa += a[j, i].real ** 2 + a[j, i].imag ** 2
            ax += (a[j, i].conjugate() * x[i]).real
            if edge:
                bb += b[j, i].real ** 2 + b[j, i].imag ** 2
                ab += (a[j, i].conjugate() * b[j, i]).real
                bx += (b[j, i].conjugate() * x[i]).real
        if edge:
            det = aa * bb - ab * ab
            alpha = (bb * ax - ab * bx) / det
            beta = (aa * bx - ab * ax) / det
        else:
            alpha = ax / aa
            beta = 0.0
        c = 0.0
        for i in range(m):
            r = x[i] - alpha * a[j, i]
            if edge:
                r -= beta * b[j, i]
            c += r.real**2 + r.imag**2
        out[j] = c if math.isfinite(c) else math.inf
