"""Compiled kernels of the engagement monitor: revolution harmonics and the per-revolution
Levenberg–Marquardt fit of :mod:`millsense.monitoring.torque_spectrum` (same equations as its
numpy functions ``g_coeff``, ``l_coeff``, ``_basis`` and ``_project``, which the tests compare)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
IntArray = NDArray[np.int64]


@numba.njit(cache=True, inline="always")
def _over_i(z: complex, m: float) -> complex:
    """z / complex(0, m), the numbers of numba's complex division (CPython's ``_Py_c_quot``:
    ratio 0·sign(m), denominator m, bit for bit with signed zeros, infinities and NaNs) with
    two real divisions instead of three and no branch: the fit's innermost division."""
    r = math.copysign(0.0, m)
    return complex((z.real * r + z.imag) / m, (z.imag * r - z.real) / m)


@numba.njit(cache=True, inline="always")
def _over_real(z: complex, c: float) -> complex:
    """z / c for a real c ≠ 0 as numba divides a complex by it (promoted to complex(c, 0):
    ratio 0/c, denominator c; bit for bit), two real divisions instead of three."""
    r = 0.0 / c
    return complex((z.real + z.imag * r) / c, (z.imag - z.real * r) / c)


@numba.njit(cache=True)
def _g(m: float, st: float, ex: float) -> complex:
    if m == 0.0:
        return _over_real(complex(ex - st, 0.0), 2.0 * math.pi)
    e1 = complex(math.cos(m * st), -math.sin(m * st))
    e2 = complex(math.cos(m * ex), -math.sin(m * ex))
    return _over_real(_over_i(e1 - e2, m), 2.0 * math.pi)


@numba.njit(cache=True)
def _l(m: float, d: float, kb: float) -> complex:
    if m == 0.0:
        return complex(d, 0.0)
    a = m * kb * d
    return _over_i(1.0 - complex(math.cos(a), -math.sin(a)), m * kb)


@numba.njit(cache=True)
def _gram(
    a: ComplexArray, b: ComplexArray, x: ComplexArray, n: int
) -> tuple[float, float, float, float, float]:
    """The real Gram sums of the bases a, b and the data x over their first ``n`` rows: (a·a,
    a·b, b·b, a·x, b·x) with u·v = Σ Re(conj(u_j) v_j) — the normal equations of the harmonic
    fit (:func:`_least_squares`), its Jacobian (:func:`_vp_jacobian`) and the edge test
    (:func:`_mean_informs`)."""
    aa = 0.0
    ab = 0.0
    bb = 0.0
    ax = 0.0
    bx = 0.0
    for j in range(n):
        aa += a[j].real ** 2 + a[j].imag ** 2
        bb += b[j].real ** 2 + b[j].imag ** 2
        ab += (a[j].conjugate() * b[j]).real
        ax += (a[j].conjugate() * x[j]).real
        bx += (b[j].conjugate() * x[j]).real
    return aa, ab, bb, ax, bx


@numba.njit(cache=True)
def _least_squares(
    a: ComplexArray, b: ComplexArray, x: ComplexArray, edge: bool
) -> tuple[float, float]:
    """Real amplitudes (α, β) minimising |x − α a − β b|² (β = 0 without the edge term): the
    2×2 normal equations of the seed 004 harmonic fit, shared by the fit and its residual."""
    aa, ab, bb, ax, bx = _gram(a, b, x, x.shape[0])
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
        a[j] = _over_i(_g(k[j] - 1.0, st, ex) - _g(k[j] + 1.0, st, ex), 2.0) * lk
        b[j] = _g(k[j], st, ex) * lk
    alpha, beta = _least_squares(a, b, x, edge)
    return a, b, alpha, beta


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
def _lengths(k: FloatArray, d: float, kb: float, wt: FloatArray, out: ComplexArray) -> None:
    """out_j = wt_j L(k_j) at depth d (:func:`_l`; ``wt``: the row weights of the fit, 1 for
    every harmonic, decision 1806)."""
    for j in range(k.shape[0]):
        out[j] = wt[j] * _l(k[j], d, kb)


@numba.njit(cache=True)
def _g_of(m: float, e1: complex, e2: complex, st: float, ex: float) -> complex:
    """:func:`_g` from its two phases e1 = e^{−i m θ_st}, e2 = e^{−i m θ_ex}."""
    if m == 0.0:
        return _over_real(complex(ex - st, 0.0), 2.0 * math.pi)
    return _over_real(_over_i(e1 - e2, m), 2.0 * math.pi)


@numba.njit(cache=True)
def _g_all(
    m: FloatArray, e1: ComplexArray, e2: ComplexArray, st: float, ex: float, g: ComplexArray
) -> None:
    """g_q = G of every order m_q (:func:`_g_of`) from the phases at (θ_st, θ_ex)."""
    for q in range(m.shape[0]):
        g[q] = _g_of(m[q], e1[q], e2[q], st, ex)


@numba.njit(cache=True)
def _residual_g(
    idx: IntArray,
    g: ComplexArray,
    lk: ComplexArray,
    xn: ComplexArray,
    edge: bool,
    a: ComplexArray,
    b: ComplexArray,
    res: FloatArray,
) -> float:
    """Projected residual of the harmonics ``xn`` (real and imaginary parts in ``res``;
    returns ½‖res‖²) at a point whose G of every order is ``g`` (:func:`_g_all`): each
    harmonic's basis a, b from its three orders (``idx``) and lengths ``lk``, the least-squares
    α, β, then the projection. Each G is computed once per point, not once per harmonic that
    uses it."""
    _bases_from(idx, g, lk, a, b)
    alpha, beta = _least_squares(a, b, xn, edge)
    return _projected_residual(xn, a, b, alpha, beta, res)


@numba.njit(cache=True, inline="always")
def _bases_from(
    idx: IntArray, g: ComplexArray, lk: ComplexArray, a: ComplexArray, b: ComplexArray
) -> None:
    """The bases A_k = (G_{k−1} − G_{k+1})/2i · L_k and B_k = G_k L_k of :func:`_fit_basis`
    from G of every order ``g`` (indices ``idx``, :func:`_orders`) and the lengths ``lk``."""
    for j in range(lk.shape[0]):
        a[j] = _over_i(g[idx[0, j]] - g[idx[2, j]], 2.0) * lk[j]
        b[j] = g[idx[1, j]] * lk[j]


@numba.njit(cache=True)
def _solve3(mm: FloatArray, g: FloatArray, free: NDArray[np.bool_], dp: FloatArray) -> None:
    """dp = −mm⁻¹ g over the free parameters (Gaussian elimination with partial pivoting on the
    3 × 3 damped normal equations); held parameters get dp = 0."""
    a = np.zeros((3, 4))
    for i in range(3):
        for j in range(3):
            a[i, j] = mm[i, j] if free[i] and free[j] else (1.0 if i == j else 0.0)
        a[i, 3] = -g[i] if free[i] else 0.0
    for c in range(3):
        piv = c
        for r in range(c + 1, 3):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if piv != c:
            for j in range(4):
                t = a[c, j]
                a[c, j] = a[piv, j]
                a[piv, j] = t
        for r in range(c + 1, 3):
            f = a[r, c] / a[c, c]
            for j in range(c, 4):
                a[r, j] -= f * a[c, j]
    for i in range(2, -1, -1):
        acc = a[i, 3]
        for j in range(i + 1, 3):
            acc -= a[i, j] * dp[j]
        dp[i] = acc / a[i, i]


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
    """:func:`lm_fit_weighted` with every row of weight 1 (the tooth-passing harmonics)."""
    return lm_fit_weighted(p0, xn, k, kb, edge, lo, hi, scale, max_iter, np.ones(xn.shape[0]))


@numba.njit(cache=True)
def _phase_run(m: FloatArray, ang: float, out: ComplexArray) -> None:
    """out = e^{−i m·ang} as :func:`_phases`, each order one above the previous one by a
    product with e^{−i·ang} instead of its own cosine and sine (the orders k−1, k, k+1 of the
    tooth harmonics run in steps of 1: one cosine and sine per angle; the recurrence's error
    grows by ≈ 1e-16 a step, 3e-15 at the 31st order)."""
    z = complex(math.cos(ang), -math.sin(ang))
    for q in range(m.shape[0]):
        if q > 0 and m[q] == m[q - 1] + 1.0:
            out[q] = out[q - 1] * z
        else:
            out[q] = complex(math.cos(m[q] * ang), -math.sin(m[q] * ang))


@numba.njit(cache=True)
def _length_run(k: FloatArray, d: float, kb: float, wt: FloatArray, out: ComplexArray) -> None:
    """out_j = wt_j L(k_j) at depth d as :func:`_lengths`, the phases e^{−i k_j kb d} of
    harmonics in equal steps (k = N, 2N, …) by a product with the step's phase instead of their
    own cosine and sine (error as :func:`_phase_run`)."""
    e = 0j
    step = 0j
    delta = math.nan
    for j in range(k.shape[0]):
        if j > 0 and k[j] - k[j - 1] == delta:
            e = e * step
        else:
            e = complex(math.cos(k[j] * kb * d), -math.sin(k[j] * kb * d))
            if j + 1 < k.shape[0]:
                delta = k[j + 1] - k[j]
                step = complex(math.cos(delta * kb * d), -math.sin(delta * kb * d))
        if k[j] == 0.0:
            out[j] = wt[j] * complex(d, 0.0)
        else:
            out[j] = wt[j] * _over_i(1.0 - e, k[j] * kb)


@numba.njit(cache=True)
def _vp_jacobian(
    idx: IntArray, k: FloatArray, kb: float, wt: FloatArray, gc: ComplexArray,
    e1: ComplexArray, e2: ComplexArray, lk: ComplexArray, xn: ComplexArray, edge: bool,
    r: FloatArray, jac: FloatArray,
) -> None:  # fmt: skip
    """The exact Jacobian of the projected residual r(p) = x − Φ Φ⁺ x (real view, Φ = [A B],
    rows ``r`` as :func:`_projected_residual`) at p = (d_a, θ_st, θ_ex) whose G, phases and
    lengths are ``gc``, ``e1``, ``e2``, ``lk`` (variable projection, Golub & Pereyra 1973):
    ∂r/∂p_i = −(I − P) ∂Φ/∂p_i c − Φ (ΦᵀΦ)⁻¹ (∂Φ/∂p_i)ᵀ r, with c = (α, β). The bases'
    derivatives are analytic and need no cosine or sine: ∂L_k/∂d_a = e^{−ik kb d_a} =
    1 − i k kb L_k, ∂G_m/∂θ_st = −e^{−imθ_st}/2π, ∂G_m/∂θ_ex = e^{−imθ_ex}/2π."""
    n = xn.shape[0]
    a = np.empty(n, dtype=np.complex128)
    b = np.empty(n, dtype=np.complex128)
    _bases_from(idx, gc, lk, a, b)
    aa, ab, bb, ax, bx = _gram(a, b, xn, n)
    # (ΦᵀΦ)⁻¹ = [[i11, i12], [i12, i22]] (0 where singular: α = β = 0, as the fit sets them)
    i11 = 0.0
    i12 = 0.0
    i22 = 0.0
    if edge:
        det = aa * bb - ab * ab
        if det > 0:
            i11 = bb / det
            i12 = -ab / det
            i22 = aa / det
    elif aa > 0:
        i11 = 1.0 / aa
    alpha = i11 * ax + i12 * bx
    beta = i12 * ax + i22 * bx
    two_pi = 2.0 * math.pi
    da = np.empty(n, dtype=np.complex128)
    db = np.empty(n, dtype=np.complex128)
    for i in range(3):
        for j in range(n):
            if i == 0:
                dl = wt[j] - complex(0.0, k[j] * kb) * lk[j]
                da[j] = _over_i(gc[idx[0, j]] - gc[idx[2, j]], 2.0) * dl
                db[j] = gc[idx[1, j]] * dl
            elif i == 1:
                da[j] = _over_i(e1[idx[2, j]] - e1[idx[0, j]], 2.0) * lk[j] / two_pi
                db[j] = -e1[idx[1, j]] * lk[j] / two_pi
            else:
                da[j] = _over_i(e2[idx[0, j]] - e2[idx[2, j]], 2.0) * lk[j] / two_pi
                db[j] = e2[idx[1, j]] * lk[j] / two_pi
        # u = ∂Φ c; its projection coefficients M⁻¹Φᵀu and M⁻¹(∂Φ)ᵀr
        au = 0.0
        bu = 0.0
        dar = 0.0
        dbr = 0.0
        for j in range(n):
            u = alpha * da[j] + beta * db[j]
            au += (a[j].conjugate() * u).real
            bu += (b[j].conjugate() * u).real
            dar += da[j].real * r[j] + da[j].imag * r[n + j]
            dbr += db[j].real * r[j] + db[j].imag * r[n + j]
        c1 = i11 * (au - dar) + i12 * (bu - dbr)
        c2 = i12 * (au - dar) + i22 * (bu - dbr)
        # −∂r = u − Φ M⁻¹Φᵀu + Φ M⁻¹(∂Φ)ᵀr
        for j in range(n):
            v = alpha * da[j] + beta * db[j] - c1 * a[j] - c2 * b[j]
            jac[j, i] = -v.real
            jac[n + j, i] = -v.imag


@numba.njit(cache=True)
def _secant_update(
    s_mat: FloatArray, s: FloatArray, g: FloatArray, g_old: FloatArray, jr_new: FloatArray
) -> None:
    """The structured secant update of S ≈ Σ r_j ∇²r_j, the part of the least-squares Hessian
    JᵀJ + S that Gauss–Newton drops (Dennis, Gay & Welsch 1981, NL2SOL): after the step s with
    gradients Jᵀr ``g_old`` → ``g`` and ``jr_new`` = J_oldᵀ r_new, S is sized down by
    τ = min(1, |sᵀy#|/|sᵀSs|) and updated so that (S + ΔS) s = y# = g − ``jr_new`` (symmetric
    rank two, weighted by y = g − ``g_old``); skipped where yᵀs ≤ 0."""
    y = g - g_old
    ys = 0.0
    for i in range(3):
        ys += y[i] * s[i]
    if not ys > 0.0:
        return
    ss_ = s_mat @ s
    sss = 0.0
    syd = 0.0
    for i in range(3):
        sss += s[i] * ss_[i]
        syd += s[i] * (g[i] - jr_new[i])
    if sss != 0.0:
        tau = min(1.0, abs(syd) / abs(sss))
        for i in range(3):
            ss_[i] *= tau
            for c in range(3):
                s_mat[i, c] *= tau
    z = np.empty(3)
    zs = 0.0
    for i in range(3):
        z[i] = g[i] - jr_new[i] - ss_[i]
        zs += z[i] * s[i]
    for i in range(3):
        for c in range(3):
            s_mat[i, c] += (z[i] * y[c] + y[i] * z[c]) / ys - zs * y[i] * y[c] / (ys * ys)


@numba.njit(cache=True)
def _positive_definite(h: FloatArray) -> bool:
    """True if the symmetric 3 × 3 ``h`` is positive definite (its leading minors > 0)."""
    m1 = h[0, 0]
    m2 = h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0]
    m3 = (h[0, 0] * (h[1, 1] * h[2, 2] - h[1, 2] * h[2, 1])
          - h[0, 1] * (h[1, 0] * h[2, 2] - h[1, 2] * h[2, 0])
          + h[0, 2] * (h[1, 0] * h[2, 1] - h[1, 1] * h[2, 0]))  # fmt: skip
    return m1 > 0.0 and m2 > 0.0 and m3 > 0.0


#: Relative cost decrease below which :func:`lm_fit_weighted` stops (an accepted step's, or the
#: one its model predicts for the next step; decision 1692).
LM_REL_DECREASE = 1e-8
#: Step, as a fraction of each parameter's scale, below which it stops.
LM_SMALL_STEP = 1e-7


@numba.njit(cache=True)
def _converged(
    g: FloatArray, h: FloatArray, dp: FloatArray, cost: float, scale: FloatArray
) -> bool:
    """Decision 1692: the fit has converged before it tries the step ``dp`` (the damped solution
    of the model ½‖r‖² + gᵀdp + ½dpᵀh dp) when every component is below
    :data:`LM_SMALL_STEP` of its scale or the decrease the model predicts for it,
    −gᵀdp − ½dpᵀh dp, is below :data:`LM_REL_DECREASE` of the cost: the tests an accepted step
    ends the fit with, applied to the prediction instead of the trial (which at the optimum
    fails eight times with a growing damping before the fit gave up)."""
    small = True
    pred = 0.0
    for i in range(3):
        if abs(dp[i]) > LM_SMALL_STEP * scale[i]:
            small = False
        hd = 0.0
        for c in range(3):
            hd += h[i, c] * dp[c]
        pred -= g[i] * dp[i] + 0.5 * dp[i] * hd
    return small or pred <= LM_REL_DECREASE * cost


@numba.njit(cache=True)
def lm_fit_weighted(
    p0: FloatArray,
    xn: ComplexArray,
    k: FloatArray,
    kb: float,
    edge: bool,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    max_iter: int,
    wt: FloatArray,
) -> tuple[FloatArray, float]:
    """Levenberg–Marquardt with the exact variable-projection Jacobian (:func:`_vp_jacobian`,
    decision 1677) and box bounds (decision 1535: a parameter on a bound whose descent
    direction leaves the box is held for that step — the active set — and the others take the
    step of the reduced system; the rest is clipped).

    The residual is :func:`_residual_g`; its phases e^{−i m θ_st}, e^{−i m θ_ex} and lengths
    L(k) are kept for the current point, and a trial point recomputes only the factors whose
    parameter moved, each by a recurrence (:func:`_phase_run`, :func:`_length_run`). Row j of
    the model is weighted by ``wt[j]`` (``xn`` must be weighted alike; the mean-torque row of
    decision 1806)."""
    n = xn.shape[0]
    m, idx = _orders(k)
    nm = m.shape[0]
    p = p0.copy()
    for i in range(3):
        p[i] = min(max(p[i], lo[i]), hi[i])
    r = np.empty(2 * n)
    rt = np.empty(2 * n)
    jac = np.empty((2 * n, 3))
    jtj = np.empty((3, 3))
    mm = np.empty((3, 3))
    g = np.empty(3)
    dp = np.empty(3)
    q = np.empty(3)
    free = np.empty(3, dtype=np.bool_)
    wa = np.empty(n, dtype=np.complex128)
    wb = np.empty(n, dtype=np.complex128)
    e1 = np.empty(nm, dtype=np.complex128)  # at p
    e2 = np.empty(nm, dtype=np.complex128)
    lk = np.empty(n, dtype=np.complex128)
    f1 = np.empty(nm, dtype=np.complex128)  # at a trial point
    f2 = np.empty(nm, dtype=np.complex128)
    fl = np.empty(n, dtype=np.complex128)
    gc = np.empty(nm, dtype=np.complex128)  # G of every order at p
    gt = np.empty(nm, dtype=np.complex128)  # ... at a trial point
    _phase_run(m, p[1], e1)
    _phase_run(m, p[2], e2)
    _length_run(k, p[0], kb, wt, lk)
    _g_all(m, e1, e2, p[1], p[2], gc)
    cost = _residual_g(idx, gc, lk, xn, edge, wa, wb, r)
    lam = 1e-3
    # the second-order term S ≈ Σ r_j ∇²r_j by the structured secant update (NL2SOL)
    s_mat = np.zeros((3, 3))
    h = np.empty((3, 3))
    g_old = np.empty(3)
    jr_new = np.empty(3)  # old Jacobianᵀ × new residual
    s_step = np.zeros(3)
    have_step = False
    for _ in range(max_iter):
        _vp_jacobian(idx, k, kb, wt, gc, e1, e2, lk, xn, edge, r, jac)
        for i in range(3):
            acc = 0.0
            for j in range(2 * n):
                acc += jac[j, i] * r[j]
            g[i] = acc
            for c in range(i, 3):
                acc = 0.0
                for j in range(2 * n):
                    acc += jac[j, i] * jac[j, c]
                jtj[i, c] = acc
                jtj[c, i] = acc
        if have_step:
            _secant_update(s_mat, s_step, g, g_old, jr_new)
        for i in range(3):
            for c in range(3):
                h[i, c] = jtj[i, c] + s_mat[i, c]
        if not _positive_definite(h):
            for i in range(3):
                for c in range(3):
                    h[i, c] = jtj[i, c]
        # the active set: on a bound with the descent direction −g pointing out of the box
        for i in range(3):
            free[i] = not ((p[i] >= hi[i] and g[i] < 0.0) or (p[i] <= lo[i] and g[i] > 0.0))
        improved = False
        for _t in range(8):
            for i in range(3):
                for c in range(3):
                    mm[i, c] = h[i, c]
                mm[i, i] += lam * (jtj[i, i] + 1e-30)
            _solve3(mm, g, free, dp)
            if _t == 0 and _converged(g, h, dp, cost, scale):
                return p, cost
            for i in range(3):
                q[i] = min(max(p[i] + dp[i], lo[i]), hi[i])
            # a parameter the step leaves where it was (held on its bound: θ_ex = π in down
            # milling) keeps its factors: the same numbers without their sines and cosines
            same_st = q[1] == p[1]
            same_ex = q[2] == p[2]
            if same_st:
                f1[:] = e1
            else:
                _phase_run(m, q[1], f1)
            if same_ex:
                f2[:] = e2
            else:
                _phase_run(m, q[2], f2)
            if q[0] == p[0]:
                fl[:] = lk
            else:
                _length_run(k, q[0], kb, wt, fl)
            if same_st and same_ex:
                gt[:] = gc
            else:
                _g_all(m, f1, f2, q[1], q[2], gt)
            c2 = _residual_g(idx, gt, fl, xn, edge, wa, wb, rt)
            if c2 < cost:
                small = True
                for i in range(3):
                    if abs(q[i] - p[i]) > LM_SMALL_STEP * scale[i]:
                        small = False
                for i in range(3):
                    s_step[i] = q[i] - p[i]
                    g_old[i] = g[i]
                    acc = 0.0
                    for j in range(2 * n):
                        acc += jac[j, i] * rt[j]
                    jr_new[i] = acc
                have_step = True
                p[:] = q
                r[:] = rt
                e1[:] = f1
                e2[:] = f2
                lk[:] = fl
                gc[:] = gt
                rel = (cost - c2) / max(cost, 1e-300)
                cost = c2
                lam = max(lam * 0.3, 1e-12)
                improved = True
                if small or rel < LM_REL_DECREASE:
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


@numba.njit(cache=True)
def grid_costs(
    a_pairs: FloatArray, g_pairs: FloatArray, l_re: FloatArray, l_im: FloatArray, x_re: FloatArray,
    x_im: FloatArray, inv_r11: FloatArray, r12: FloatArray, inv_r22: FloatArray, edge: bool,
    out: FloatArray,
) -> None:  # fmt: skip  # pragma: no cover - compiled
    """Projected misfit |x|² − (q₁·x)² − (q₂·x)² of every grid row from the factors of
    :class:`..torque_spectrum._GridBases`: per depth y = conj(L) x, then per angle pair
    Re(a^H y), Re(g^H y) (columns of ``a_pairs``, ``g_pairs``, whose rows are [Re | Im]) and
    the row's QR factors (``inv_r11`` = 1/r₁₁, 0 where A = 0; ``inv_r22`` = 1/r₂₂, NaN on a
    singular row); without the edge term only q₁. A singular row gives +inf (with the edge
    term). One thread: a multi-threaded BLAS product waits on a loaded host's other
    work. Each pair's sums run over its columns in order, all pairs together (independent
    sums the compiler vectorises; the pairs' matrices stay in cache)."""
    m, n_pairs = a_pairs.shape
    nk = x_re.shape[0]
    xx = 0.0
    for i in range(nk):
        xx += x_re[i] * x_re[i]
    for i in range(nk):
        xx += x_im[i] * x_im[i]
    y = np.empty(m)
    sa = np.empty(n_pairs)
    sb = np.empty(n_pairs)
    for di in range(l_re.shape[0]):
        for i in range(nk):
            lr, li = l_re[di, i], l_im[di, i]
            y[i] = lr * x_re[i] + li * x_im[i]
            y[nk + i] = lr * x_im[i] - li * x_re[i]
        sa[:] = 0.0
        sb[:] = 0.0
        for i in range(m):
            v = y[i]
            row_a = a_pairs[i]
            for p in range(n_pairs):
                sa[p] += row_a[p] * v
            if edge:
                row_g = g_pairs[i]
                for p in range(n_pairs):
                    sb[p] += row_g[p] * v
        base = di * n_pairs
        for p in range(n_pairs):
            r = base + p
            c1 = sa[p] * inv_r11[r]
            c = xx - c1 * c1
            if edge:
                c2 = (sb[p] - r12[r] * c1) * inv_r22[r]
                c -= c2 * c2
            out[r] = c if math.isfinite(c) else math.inf


@numba.njit(cache=True)
def smallest(cost: FloatArray, n: int) -> IntArray:
    """Indices of the ``n`` smallest of ``cost`` in increasing order (ties: the lower index
    first), in one pass: the grid search's starts (:func:`grid_costs`)."""
    n = min(n, cost.shape[0])
    idx = np.empty(n, dtype=np.int64)
    val = np.empty(n)
    count = 0
    for j in range(cost.shape[0]):
        c = cost[j]
        if count == n and not c < val[n - 1]:
            continue
        # insert after every kept value ≤ c (an equal cost keeps the lower index first)
        pos = count if count < n else n - 1
        while pos > 0 and val[pos - 1] > c:
            val[pos] = val[pos - 1]
            idx[pos] = idx[pos - 1]
            pos -= 1
        val[pos] = c
        idx[pos] = j
        if count < n:
            count += 1
    return idx[:count]


#: Decision 1557: revolutions whose relative misfits set the noise level of the local fit, the
#: factor above it that calls a global search, and the revolutions after which one runs anyway.
MISFIT_REVS = 8
MISFIT_JUMP = 2.0
REGRID_REVS = 16
#: Layout of the state of that test (floats): the last :data:`MISFIT_REVS` relative misfits (a
#: ring), how many are known, the ring's next slot and the revolutions whose local fit was kept
#: since the last grid search.
MST_COUNT, MST_NEXT, MST_SINCE = MISFIT_REVS, MISFIT_REVS + 1, MISFIT_REVS + 2
MST_SIZE = MISFIT_REVS + 3


@numba.njit(cache=True)
def note_misfit(state: FloatArray, misfit: float) -> None:
    """Record a revolution's relative misfit in the ring of ``state`` (:data:`MST_COUNT`)."""
    slot = int(state[MST_NEXT])
    state[slot] = misfit
    state[MST_NEXT] = (slot + 1) % MISFIT_REVS
    state[MST_COUNT] = min(state[MST_COUNT] + 1.0, float(MISFIT_REVS))


@numba.njit(cache=True)
def local_fit_holds(state: FloatArray, misfit: float) -> bool:
    """Decision 1557: keep the fit from the previous revolution's solution (no global search)
    when its relative misfit is at most :data:`MISFIT_JUMP` × the median of the last
    :data:`MISFIT_REVS` revolutions' (noise the local fit already lived with, not an engagement
    that changed; NaN among them: no), and a global search ran within :data:`REGRID_REVS`."""
    if state[MST_COUNT] < MISFIT_REVS or state[MST_SINCE] >= REGRID_REVS - 1:
        return False
    v = np.sort(state[:MISFIT_REVS])
    for i in range(MISFIT_REVS):
        if v[i] != v[i]:
            return False
    h = MISFIT_REVS // 2
    med = v[h] if MISFIT_REVS % 2 else (v[h - 1] + v[h]) / 2
    return misfit <= MISFIT_JUMP * med


#: Decision 1704: the running mean of a cut's revolutions' harmonics (a cumulative mean over
#: the first :data:`ANCHOR_REVS` revolutions, then exponential with weight 1/ANCHOR_REVS; √n
#: less noise than one revolution's, in the spindle angle's phase reference, so a steady cut's
#: revolutions add coherently), the fewest revolutions whose mean is searched globally, and
#: the largest distance (d_a in units of the axial pitch, the angles in rad) at which a
#: revolution's fit and the mean's are taken to be in one basin (no second fit).
ANCHOR_REVS = 16
ANCHOR_MIN_REVS = 8
ANCHOR_SAME_DEPTH = 0.1
ANCHOR_SAME_ANGLE = 0.3
#: Revolutions after which the mean is searched globally again even though its fit from the
#: last search still holds (:data:`MISFIT_JUMP` × the relative misfit of that search).
ANCHOR_SEARCH_REVS = 256
#: Layout of that state (floats): revolutions in the mean, 1 once the mean's fit (the anchor)
#: is known, its (d_a, θ_st, θ_ex), the revolutions since the mean was last searched and the
#: relative misfit of that search; then how many revolutions were also fitted from the anchor
#: (a diagnostic).
AST_COUNT, AST_VALID, AST_POINT, AST_SINCE, AST_MISFIT, AST_SECOND = 0, 1, 2, 5, 6, 7
AST_SIZE = 8


@numba.njit(cache=True)
def note_mean(state: FloatArray, mean: ComplexArray, x: ComplexArray) -> None:
    """Add a revolution's harmonics ``x`` to the running mean ``mean`` (:data:`ANCHOR_REVS`)."""
    n = state[AST_COUNT] + 1.0
    state[AST_COUNT] = n
    state[AST_SINCE] += 1.0
    a = 1.0 / min(n, float(ANCHOR_REVS))
    for j in range(mean.shape[0]):
        mean[j] += a * (x[j] - mean[j])


@numba.njit(cache=True)
def forget_mean(state: FloatArray, mean: ComplexArray) -> None:
    """A revolution not evaluated (air, no speed, no feed): the next cut starts a new mean."""
    state[AST_COUNT] = 0.0
    state[AST_VALID] = 0.0
    state[AST_SINCE] = 0.0
    mean[:] = 0.0


@numba.njit(cache=True)
def anchored_fit(
    p0: FloatArray,
    anchor: FloatArray,
    xn: ComplexArray,
    norm: float,
    k: FloatArray,
    kb: float,
    edge: bool,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    accept: float,
) -> tuple[FloatArray, float]:
    """The fit of a revolution's normalised harmonics ``xn`` from the previous revolution's
    solution ``p0`` and, where that misses the ``accept`` misfit and the running mean's fit
    (``anchor``, :data:`AST_POINT`) is known and in another basin, also from the mean's fit:
    the better of the two (decision 1704). The warm start alone holds a noisy revolution in
    the basin the last global search found, even where the revolution's own cost is lower in
    the basin of the cut's averaged harmonics (decision 1698)."""
    p, cost = lm_fit(p0, xn, k, kb, edge, lo, hi, scale, 60)
    if anchor[AST_VALID] == 0.0 or 2.0 * cost / norm <= accept:
        return p, cost
    a = anchor[AST_POINT : AST_POINT + 3]
    if (
        abs(p[0] - a[0]) <= ANCHOR_SAME_DEPTH * scale[0]
        and abs(p[1] - a[1]) <= ANCHOR_SAME_ANGLE
        and abs(p[2] - a[2]) <= ANCHOR_SAME_ANGLE
    ):
        return p, cost
    anchor[AST_SECOND] += 1.0
    pa, ca = lm_fit(a.copy(), xn, k, kb, edge, lo, hi, scale, 60)
    if ca < cost:
        return pa, ca
    return p, cost


#: Layout of the per-revolution accumulator of :func:`ingest_revolutions` (``acc``, floats):
#: fraction of a revolution, revolution index (−1 before the first sample), samples summed,
#: Σ x, Σ |Ω|, Σ |feed|, 1 once a revolution was identified (the next fit starts from it), the
#: phasor e^{−iφ} of the last sample (real, imaginary) and the speed whose per-sample rotation
#: is cached with that rotation (real, imaginary; NaN: none yet).
ACC_FRAC, ACC_REV, ACC_COUNT, ACC_SUM_X, ACC_SUM_SPEED, ACC_SUM_FEED, ACC_HAS_PREV = range(7)
ACC_ZR, ACC_ZI, ACC_STEP_SPEED, ACC_STEP_R, ACC_STEP_I = range(7, 12)
#: ... then the air-cut reference learnt (decision 1806): Σ of the air revolutions' torque
#: samples, their count and the mean speed they were taken at (:func:`mean_cut_torque`).
ACC_AIR_SUM, ACC_AIR_COUNT, ACC_AIR_SPEED = range(12, 15)
ACC_SIZE = 15
#: Columns of the finished revolutions of :func:`ingest_revolutions` (``done``, floats):
#: sample (in the chunk) at which the revolution ended, mean |Ω|, feed per tooth (m), the mean
#: cutting torque T_0 − T_air and its variance factor (:func:`mean_cut_torque`) and the
#: status: :data:`REV_NONE` (not evaluated: air, no speed, no feed), :data:`REV_DONE` (the
#: estimate is in its row of ``est``), :data:`REV_GRID` (the previous revolution's solution
#: does not explain it: the caller runs the grid search, then resumes the scan),
#: :data:`REV_ALIASED` (not evaluated: its highest tooth harmonic is not below the Nyquist
#: frequency, decision 1734).
DONE_AT, DONE_OMEGA, DONE_FEED, DONE_STATUS, DONE_T0_NET, DONE_MEAN_VAR = range(6)
DONE_SIZE = 6
REV_NONE, REV_DONE, REV_GRID, REV_ALIASED = 0.0, 1.0, 2.0, 3.0
#: ``fpar`` of :func:`ingest_revolutions`: minimum mean torque, feed per tooth (m; ≤ 0: from
#: the feed channel), tanβ/r, the accept misfit, radius, axial pitch, the runout cut-off and
#: the air torque given as a setting (N·m; NaN: learnt from the air revolutions, decision 1806).
FPAR_MIN_TORQUE, FPAR_FEED, FPAR_KB, FPAR_ACCEPT, FPAR_RADIUS, FPAR_PITCH, FPAR_RCOND = range(7)
FPAR_AIR_TORQUE = 7
#: ... then the sample rate (Hz), the tool's flutes and 1.0 with the edge term (0.0 without):
#: the scalars of :func:`ingest_revolutions` that :func:`ingest_chunk` reads from ``fpar``.
FPAR_FS, FPAR_FLUTES, FPAR_EDGE = 8, 9, 10
#: ... then the revolutions of one monitoring cycle (Lee: "one monitoring cycle for 3 tool
#: revolutions"; decision 1717): the harmonics are summed over that many revolutions before a
#: fit (1.0: one estimate a revolution).
FPAR_CYCLE = 11
FPAR_SIZE = 12
#: Relative speed difference within which a learnt air-cut torque is used (decision 1806: the
#: air torque depends on the speed, viscous friction; a reference serves the speed it was
#: taken at, and a new speed needs a new air revolution).
AIR_SPEED_TOL = 0.01


@numba.njit(cache=True)
def mean_cut_torque(
    mean_x: float, omega: float, cnt: float, air: bool, acc: FloatArray, fpar: FloatArray
) -> tuple[float, float]:
    """The mean cutting torque T_0 − T_air of a revolution (mean torque ``mean_x``, mean speed
    ``omega``, ``cnt`` samples) and its error variance in units of the revolution's white-noise
    variance σ²/M (decision 1806; Lee Fig. 3.6 step 3 subtracts the air-cut torque): the air
    torque given as a setting (variance factor 1), else the mean of the air revolutions learnt
    at this speed (within :data:`AIR_SPEED_TOL`; factor 1 + M/M_air), else (NaN, 1). An air
    revolution (``air``: the monitor's own air criterion, mean torque below
    ``min_torque_nm``) is added to the reference, which restarts when the speed changed."""
    given = fpar[FPAR_AIR_TORQUE]
    if math.isfinite(given):
        return mean_x - given, 1.0
    if air and omega > 0.0:
        n_air = acc[ACC_AIR_COUNT]
        if n_air > 0 and abs(omega - acc[ACC_AIR_SPEED]) <= AIR_SPEED_TOL * omega:
            acc[ACC_AIR_SPEED] = (acc[ACC_AIR_SPEED] * n_air + omega * cnt) / (n_air + cnt)
            acc[ACC_AIR_SUM] += mean_x * cnt
            acc[ACC_AIR_COUNT] = n_air + cnt
        else:
            acc[ACC_AIR_SPEED] = omega
            acc[ACC_AIR_SUM] = mean_x * cnt
            acc[ACC_AIR_COUNT] = cnt
        return math.nan, 1.0
    n_air = acc[ACC_AIR_COUNT]
    if n_air > 0 and abs(omega - acc[ACC_AIR_SPEED]) <= AIR_SPEED_TOL * omega:
        return mean_x - acc[ACC_AIR_SUM] / n_air, 1.0 + cnt / n_air
    return math.nan, 1.0


#: Fields of :func:`estimate`'s output, in order (SI units).
EST_AXIAL, EST_RADIAL, EST_ENTRY, EST_EXIT, EST_KT, EST_RUNOUT, EST_RUNOUT_ANGLE = range(7)
EST_RELIABILITY, EST_AXIAL_SD, EST_NOTCH, EST_COST, EST_EDGE, EST_EDGE_SOURCE = range(7, 13)
EST_SIZE = 13


@numba.njit(cache=True)
def _runout(
    t1: complex, d: float, radius: float, n_flutes: int, kt: float, g1: complex, l2: complex,
    rcond: float,
) -> complex:  # fmt: skip
    """w = ρ e^{−iλ} from T_1 (:func:`..torque_spectrum._runout_from`)."""
    n = n_flutes
    if n == 1:
        return complex(math.nan, math.nan)
    base = radius * kt * g1 * n
    ab = abs(base)
    if ab == 0 or not math.isfinite(ab):
        return complex(math.nan, math.nan)
    if n >= 3:
        rot = 1.0 - complex(math.cos(2.0 * math.pi / n), -math.sin(2.0 * math.pi / n))
        return t1 / (base * d * rot / 2.0)
    q = t1 / base
    p, s = l2.real, l2.imag
    mat = np.empty((2, 2))
    mat[0, 0] = d + p
    mat[0, 1] = s
    mat[1, 0] = s
    mat[1, 1] = d - p
    rhs = np.empty(2)
    rhs[0] = q.real
    rhs[1] = q.imag
    sol = np.linalg.lstsq(mat, rhs, rcond)[0]
    return complex(sol[0], sol[1])


#: Axial slices of the runout edge model (midpoint rule over 0 … d_a; the integrand turns by
#: at most π/N over the depth searched, so 16 slices resolve it, decision 1540).
RUNOUT_EDGE_SLICES = 16


@numba.njit(cache=True)
def _slice_phases(d: float, kb: float, n: int) -> ComplexArray:
    """e^{i(θ_j + ψ(z_i))} of flute j at the axial slice midpoints z_i (raveled j·nz + i)."""
    nz = RUNOUT_EDGE_SLICES
    out = np.empty(n * nz, dtype=np.complex128)
    for j in range(n):
        for i in range(nz):
            ang = 2.0 * math.pi * j / n + kb * (i + 0.5) * d / nz
            out[j * nz + i] = complex(math.cos(ang), math.sin(ang))
    return out


@numba.njit(cache=True)
def _chip_zero_sines(w: complex, c: float, n: int, ez: ComplexArray, out: FloatArray) -> None:
    """s_j(z) = min(1, max(0, max_m (r_{j−m} − r_j)/(m c))) into ``out`` (raveled as ``ez``):
    flute j's chip h_j = min_m (m c sin φ + r_j − r_{j−m}) (the surface left by the deepest
    earlier flute) is ≤ 0 where sin φ ≤ s_j, with r_j(z) − r = Re(w e^{i(θ_j + ψ(z))}) and
    equal pitch (decision 1540)."""
    nz = RUNOUT_EDGE_SLICES
    rad = np.empty(n)
    for i in range(nz):
        for j in range(n):
            rad[j] = (w * ez[j * nz + i]).real
        for j in range(n):
            v = 0.0
            for m in range(1, n + 1):
                v = max(v, (rad[(j - m) % n] - rad[j]) / (m * c))
            out[j * nz + i] = min(v, 1.0)


@numba.njit(cache=True)
def _boundary_for_mean(v: FloatArray, target: float, upper: float) -> float:
    """g ∈ [0, upper] with mean(min(g, v)) = target (the bound ``upper`` if even it gives a
    mean ≤ target): the piecewise-linear mean solved exactly on the sorted v."""
    m = v.shape[0]
    if np.mean(np.minimum(v, upper)) <= target:
        return upper
    u = np.sort(v)
    below = 0.0
    for k in range(m):
        g = (m * target - below) / (m - k)
        if g <= u[k]:
            return g
        below += u[k]
    return upper


@numba.njit(cache=True)
def _geometric_boundaries(a0: FloatArray, st: float, ex: float) -> tuple[float, float]:
    """The entry θ_st,g ∈ [0, θ_st] and exit θ_ex,g ∈ [θ_ex, π] whose flute means of the
    effective entry max(θ_st,g, a_j) and exit min(θ_ex,g, π − a_j) are the fitted θ_st, θ_ex
    (the tooth-passing harmonics see the mean; decision 1540)."""
    amax = np.max(a0)
    stg = st
    if st < amax:  # the fitted entry is within the band runout can move: mirror of the exit
        stg = math.pi - _boundary_for_mean(math.pi - a0, math.pi - st, math.pi)
    exg = ex
    if ex > math.pi - amax:
        exg = _boundary_for_mean(math.pi - a0, ex, math.pi)
    return stg, exg


@numba.njit(cache=True)
def _edge_t1(
    w: complex, st: float, ex: float, c: float, n: int, ez: ComplexArray, scale: float
) -> complex:
    """:func:`runout_edge_harmonic` with the slice phases ``ez`` and r K_e dz/2π (``scale``)
    given: the limits' phases from sin a_j = s_j, cos a_j = √(1 − s_j²), no other trigonometry."""
    m = ez.shape[0]
    sj = np.empty(m)
    _chip_zero_sines(w, c, n, ez, sj)
    a0 = np.empty(m)
    for q in range(m):
        a0[q] = math.asin(sj[q])
    stg, exg = _geometric_boundaries(a0, st, ex)
    e_st = complex(math.cos(stg), -math.sin(stg))
    e_ex = complex(math.cos(exg), -math.sin(exg))
    tot = 0j
    for q in range(m):
        lo = max(stg, a0[q])
        hi = min(exg, math.pi - a0[q])
        if hi <= lo:
            continue
        ca = math.sqrt(1.0 - sj[q] * sj[q])
        e_lo = e_st if lo == stg else complex(ca, -sj[q])  # e^{−i lo}
        e_hi = e_ex if hi == exg else complex(-ca, -sj[q])  # e^{−i(π − a)} = −e^{ia}
        # ∫_lo^hi e^{−i(φ + θ_j + ψ)} dφ
        tot += (e_lo - e_hi) * complex(0.0, -1.0) * ez[q].conjugate()
    return scale * tot


@numba.njit(cache=True)
def runout_edge_harmonic(
    w: complex, d: float, st: float, ex: float, c: float, kb: float, n: int, radius: float,
    ke: float,
) -> complex:  # fmt: skip
    """T_1 of the edge torque under runout w (decision 1540): the edge force K_e per unit
    length acts only where a flute's chip is > 0, so flute j at height z cuts over
    [max(θ_st,g, a_j), min(θ_ex,g, π − a_j)], sin a_j = s_j (:func:`_chip_zero_sines`), and
    T_1 = (r K_e/2π) Σ_j ∫_0^{d_a} ∫ e^{−i(φ + θ_j + ψ(z))} dφ dz (midpoint rule over
    :data:`RUNOUT_EDGE_SLICES` slices). θ_st,g, θ_ex,g are the boundaries whose flute means
    are the fitted θ_st, θ_ex (:func:`_geometric_boundaries`)."""
    ez = _slice_phases(d, kb, n)
    return _edge_t1(w, st, ex, c, n, ez, radius * ke * (d / RUNOUT_EDGE_SLICES) / (2.0 * math.pi))


@numba.njit(cache=True)
def _runout_with_edge(
    t1: complex, d: float, st: float, ex: float, c: float, kb: float, radius: float,
    n_flutes: int, kt: float, ke: float, g1: complex, l2: complex, rcond: float,
) -> complex:  # fmt: skip
    """w from T_1 = T_1,shear(w) (Eq. 2.18 re-derived, linear) + T_1,edge(w)
    (:func:`runout_edge_harmonic`) for N ≥ 3 and K_e > 0 (decision 1540); otherwise the
    shear-only solution. Broyden's method on (Re w, Im w) from the shear-only solution, with
    a finite-difference Jacobian at the start and step halving while |residual| grows; stops
    at a step below 10⁻⁶ |w| (T_1,edge is nearly homogeneous of degree 1 in w, so a few
    steps suffice)."""
    w = _runout(t1, d, radius, n_flutes, kt, g1, l2, rcond)
    if n_flutes < 3 or not ke > 0.0 or not c > 0.0 or not math.isfinite(abs(w)) or w == 0:
        return w
    rot = 1.0 - complex(math.cos(2.0 * math.pi / n_flutes), -math.sin(2.0 * math.pi / n_flutes))
    lin = radius * kt * g1 * n_flutes * d * rot / 2.0
    tol = 1e-6 * abs(w)
    ez = _slice_phases(d, kb, n_flutes)
    scale = radius * ke * (d / RUNOUT_EDGE_SLICES) / (2.0 * math.pi)

    def resid(v: complex) -> complex:
        return lin * v + _edge_t1(v, st, ex, c, n_flutes, ez, scale) - t1

    f = resid(w)
    h = 1e-4 * abs(w)
    d1 = (resid(w + h) - f) / h  # Jacobian columns: ∂F/∂Re w, ∂F/∂Im w (as complex)
    d2 = (resid(w + 1j * h) - f) / h
    for _ in range(30):
        det = d1.real * d2.imag - d2.real * d1.imag
        if det == 0.0 or not math.isfinite(det):
            break
        step = complex((d2.real * f.imag - d2.imag * f.real) / det,
                       (d1.imag * f.real - d1.real * f.imag) / det)  # fmt: skip
        lam = 1.0
        fn = resid(w + step)
        for _ in range(10):
            if abs(fn) < abs(f):
                break
            lam *= 0.5
            fn = resid(w + lam * step)
        if not abs(fn) < abs(f):
            break
        s = lam * step
        w = w + s
        # Broyden's rank-one update of the 2 × 2 real Jacobian [d1 d2] along s
        y = fn - f
        ss = s.real * s.real + s.imag * s.imag
        corr = (y - (d1 * s.real + d2 * s.imag)) / ss
        d1 = d1 + corr * s.real
        d2 = d2 + corr * s.imag
        f = fn
        if abs(s) <= tol:
            break
    return w


#: :data:`EST_EDGE_SOURCE` values (decision 1806): no edge term fitted (``edge=False``); K_e
#: from the tooth-passing harmonics; K_e from the mean torque (the harmonics and the mean,
#: air torque subtracted, fitted jointly); K_e from the harmonics although they observe it
#: less well than the mean torque would, and no air torque is known (lower reliability: the
#: runout's edge part and K_e may be off).
EDGE_NOT_FITTED, EDGE_FROM_HARMONICS, EDGE_FROM_MEAN, EDGE_UNOBSERVED = 0.0, 1.0, 2.0, 3.0


@numba.njit(cache=True)
def mean_informs_edge(
    p: FloatArray, k: FloatArray, n_harm: int, kb: float, mean_var: float
) -> bool:
    """True where the mean torque T_0 carries more information on the edge amplitude β than
    the tooth-passing harmonics do (decision 1806), from the conditioning of the harmonic
    regression x ≈ α A + β B alone (no data): the harmonics' information on β beyond what α
    explains is the Schur complement b_⊥ = Σ|B|² − (Σ Re Ā B)²/Σ|A|² of the 2 × 2 normal
    equations; each harmonic's real and imaginary parts carry the white-noise variance σ²/2M,
    so the harmonics give 2 b_⊥ per σ²/M. T_0 gives |B_0|²/``mean_var`` (B_0 = G_0 d_a, the
    engaged edge length over 2π r N; ``mean_var`` = T_0's error variance in σ²/M: 1 with a
    given air torque, 1 + M/M_air with one learnt from M_air air-cut samples)."""
    d, st, ex = p[0], p[1], p[2]
    a = np.empty(n_harm, dtype=np.complex128)
    b = np.empty(n_harm, dtype=np.complex128)
    for j in range(n_harm):
        lk = _l(k[j], d, kb)
        a[j] = _over_i(_g(k[j] - 1.0, st, ex) - _g(k[j] + 1.0, st, ex), 2.0) * lk
        b[j] = _g(k[j], st, ex) * lk
    return _mean_informs(a, b, n_harm, d, st, ex, mean_var)


@numba.njit(cache=True)
def _mean_informs(
    a: ComplexArray, b: ComplexArray, n_harm: int, d: float, st: float, ex: float,
    mean_var: float,
) -> bool:  # fmt: skip
    """:func:`mean_informs_edge` from the bases A_k, B_k of the first ``n_harm`` harmonics at
    (d, st, ex) — those :func:`_fit_basis` gives, so that :func:`estimate` computes them once
    for the test and the amplitudes."""
    aa, ab, bb, _, _ = _gram(a, b, a, n_harm)
    b_perp = bb - ab * ab / aa if aa > 0.0 else bb
    b0 = (ex - st) / (2.0 * math.pi) * d
    return b0 * b0 / mean_var > 2.0 * b_perp


@numba.njit(cache=True)
def _weighted_amplitudes(
    p: FloatArray, x: ComplexArray, k: FloatArray, kb: float, wt: FloatArray
) -> tuple[float, float]:
    """Real amplitudes α, β of the weighted least squares wt·x ≈ wt·(α A + β B) at p."""
    n = x.shape[0]
    a = np.empty(n, dtype=np.complex128)
    b = np.empty(n, dtype=np.complex128)
    xw = np.empty(n, dtype=np.complex128)
    d, st, ex = p[0], p[1], p[2]
    for j in range(n):
        lk = wt[j] * _l(k[j], d, kb)
        a[j] = _over_i(_g(k[j] - 1.0, st, ex) - _g(k[j] + 1.0, st, ex), 2.0) * lk
        b[j] = _g(k[j], st, ex) * lk
        xw[j] = wt[j] * x[j]
    return _least_squares(a, b, xw, True)


@numba.njit(cache=True)
def fit_with_mean(
    p0: FloatArray,
    x: ComplexArray,
    t0_net: float,
    mean_var: float,
    k: FloatArray,
    kb: float,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
) -> tuple[FloatArray, float, float]:
    """(d_a, θ_st, θ_ex), α and β fitted to the harmonics ``x`` (orders ``k``) and the mean
    torque T_0 − T_air = ``t0_net`` as one more row, k = 0 of the same model (decision 1806:
    seed 004 Eqs. 2.11-2.13 hold at ω = 0, where Λ(0) = d_a and G(0) = θ_ex − θ_st, and the
    edge part is K_e times the engaged edge length; Lee Fig. 3.6 subtracts the air-cut torque).
    The row is weighted 1/√(2 mean_var) against the harmonics' real and imaginary parts (their
    white-noise variances, :func:`mean_informs_edge`), and the fit starts from ``p0``."""
    n = x.shape[0]
    kj = np.empty(n + 1)
    xj = np.empty(n + 1, dtype=np.complex128)
    wt = np.ones(n + 1)
    kj[0] = 0.0
    wt[0] = 1.0 / math.sqrt(2.0 * mean_var)
    xj[0] = t0_net
    for j in range(n):
        kj[j + 1] = k[j]
        xj[j + 1] = x[j]
    ax = abs(x[0])
    xn = np.empty(n + 1, dtype=np.complex128)
    for j in range(n + 1):
        xn[j] = wt[j] * xj[j] / ax
    p, _ = lm_fit_weighted(p0, xn, kj, kb, True, lo, hi, scale, 60, wt)
    alpha, beta = _weighted_amplitudes(p, xj, kj, kb, wt)
    return p, alpha, beta


@numba.njit(cache=True)
def depth_sd(q: FloatArray, x: ComplexArray, k: FloatArray, kb: float, edge: bool) -> float:
    """Standard deviation of the fitted d_a (m) from the harmonics' own scatter (decision
    1558): the projected residual r(p) of the harmonics at p = (d_a, θ_st, θ_ex) (α, β solved
    at every p: variable projection, whose Jacobian gives the nonlinear parameters' covariance,
    Golub & Pereyra 1973), s² = ‖r‖²/(2K − 3 − n_amplitudes) and Cov = s² (JᵀJ)⁻¹, J the
    exact Jacobian the fit takes (:func:`_vp_jacobian`; decision 1692: forward differences
    before, which differ from it by their truncation, ≈ 10⁻⁷ of the result). +inf where JᵀJ is
    singular or nothing is left to estimate s² from."""
    n = x.shape[0]
    if _depth_sd_undefined(x, edge):
        return math.inf
    kk = k[:n]
    _, idx, e1, e2, g, lk = _point_factors(q, kk, kb)
    return _depth_sd_at(x, kk, kb, edge, idx, e1, e2, g, lk)


@numba.njit(cache=True)
def _depth_sd_undefined(x: ComplexArray, edge: bool) -> bool:
    """:func:`depth_sd` has nothing to estimate s² from (2K − 3 − n_amplitudes < 1) or no
    reference harmonic (|x_0| = 0)."""
    dof = 2 * x.shape[0] - 3 - (2 if edge else 1)
    return dof < 1 or not abs(x[0]) > 0


@numba.njit(cache=True)
def _point_factors(
    q: FloatArray, kk: FloatArray, kb: float
) -> tuple[FloatArray, IntArray, ComplexArray, ComplexArray, ComplexArray, ComplexArray]:
    """At q = (d_a, θ_st, θ_ex), for the harmonics ``kk``: their distinct orders and indices
    (:func:`_orders`), the phases e^{−i m θ_st}, e^{−i m θ_ex} (:func:`_phases`), G of every
    order (:func:`_g_all`) and the lengths L(k) (:func:`_l`): the numbers of
    :func:`_fit_basis`, each G computed once per distinct order."""
    m, idx = _orders(kk)
    nm = m.shape[0]
    e1 = np.empty(nm, dtype=np.complex128)
    e2 = np.empty(nm, dtype=np.complex128)
    g = np.empty(nm, dtype=np.complex128)
    lk = np.empty(kk.shape[0], dtype=np.complex128)
    _phases(m, q[1], e1)
    _phases(m, q[2], e2)
    _g_all(m, e1, e2, q[1], q[2], g)
    for j in range(kk.shape[0]):
        lk[j] = _l(kk[j], q[0], kb)
    return m, idx, e1, e2, g, lk


@numba.njit(cache=True)
def _depth_sd_at(
    x: ComplexArray, kk: FloatArray, kb: float, edge: bool, idx: IntArray, e1: ComplexArray,
    e2: ComplexArray, g: ComplexArray, lk: ComplexArray,
) -> float:  # fmt: skip
    """:func:`depth_sd` from the factors of :func:`_point_factors` at the point (``x`` not
    :func:`_depth_sd_undefined`)."""
    n = x.shape[0]
    n_amp = 2 if edge else 1
    dof = 2 * n - 3 - n_amp
    ax0 = abs(x[0])
    xn = x / ax0
    r = np.empty(2 * n)
    jac = np.empty((2 * n, 3))
    wa = np.empty(n, dtype=np.complex128)
    wb = np.empty(n, dtype=np.complex128)
    wt = np.ones(n)
    cost = _residual_g(idx, g, lk, xn, edge, wa, wb, r)
    _vp_jacobian(idx, kk, kb, wt, g, e1, e2, lk, xn, edge, r, jac)
    jtj = jac.T @ jac
    s2 = 2.0 * cost / dof
    # (JᵀJ)⁻¹[0, 0] by the cofactor of the 3 × 3 matrix
    det = np.linalg.det(jtj)
    if not (det > 0 and math.isfinite(det)):
        return math.inf
    c00 = (jtj[1, 1] * jtj[2, 2] - jtj[1, 2] * jtj[2, 1]) / det
    return math.sqrt(max(s2 * c00, 0.0))


@numba.njit(cache=True)
def estimate(
    p: FloatArray,
    cost: float,
    x: ComplexArray,
    t1: complex,
    feed_per_tooth_m: float,
    k: FloatArray,
    kb: float,
    edge: bool,
    radius: float,
    n_flutes: int,
    axial_pitch: float,
    rcond: float,
    t0_net: float,
    mean_var: float,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    out: FloatArray,
) -> None:
    """The estimate at the fitted p = (d_a, θ_st, θ_ex) (:meth:`..torque_spectrum.
    SpectrumIdentifier.identify`): K_t, K_e from the amplitudes, the runout from T_1, σ
    (Eq. 2.23) over the harmonics below the notch; fields as :data:`EST_AXIAL`…

    With the edge term, where the mean torque observes K_e better than the harmonics do
    (:func:`mean_informs_edge`) and the mean cutting torque ``t0_net`` (T_0 less the air
    torque; NaN: unknown) is given, p, K_t and K_e are refitted with it (:func:`fit_with_mean`,
    decision 1806); without it the harmonics' values are kept and flagged
    (:data:`EST_EDGE_SOURCE`)."""
    d, st, ex = p[0], p[1], p[2]
    if ex < st:
        st, ex = ex, st
    q = np.empty(3)
    q[0] = d
    q[1] = st
    q[2] = ex
    ax0 = abs(x[0])
    norm = 0.0
    for j in range(x.shape[0]):
        v = x[j] / ax0
        norm += v.real * v.real + v.imag * v.imag
    source = EDGE_NOT_FITTED
    # the bases at q and their amplitudes, computed once for the edge test, the estimate and
    # the depth's s.d. (:func:`_fit_basis`' numbers from each order's G, :func:`_point_factors`)
    kk = k[: x.shape[0]]
    _, idx, e1, e2, gq, lk = _point_factors(q, kk, kb)
    a = np.empty(x.shape[0], dtype=np.complex128)
    b = np.empty(x.shape[0], dtype=np.complex128)
    _bases_from(idx, gq, lk, a, b)
    alpha, beta = _least_squares(a, b, x, edge)
    if edge:
        source = EDGE_FROM_HARMONICS
        if _mean_informs(a, b, x.shape[0], d, st, ex, mean_var):
            source = EDGE_UNOBSERVED
            if math.isfinite(t0_net):
                q = fit_with_mean(q, x, t0_net, mean_var, k, kb, lo, hi, scale)[0]
                if q[2] < q[1]:
                    q[1], q[2] = q[2], q[1]
                d, st, ex = q[0], q[1], q[2]
                source = EDGE_FROM_MEAN
    notch = axial_pitch / d
    m = min(max(math.floor(notch), 1), x.shape[0])
    model = np.empty(m)
    if source == EDGE_FROM_MEAN:  # refitted: the bases at the new point
        alpha, beta, g1, l2 = amplitudes(q, x, k, kb, edge, model)
    else:
        for j in range(m):
            model[j] = abs(alpha * a[j] + beta * b[j])
        g1 = _g(1.0, st, ex)
        l2 = _l(2.0, d, kb)
    if source == EDGE_FROM_MEAN:  # the amplitudes of the joint fit, and σ's model with them
        wt = np.ones(x.shape[0] + 1)
        wt[0] = 1.0 / math.sqrt(2.0 * mean_var)
        kj = np.empty(x.shape[0] + 1)
        xj = np.empty(x.shape[0] + 1, dtype=np.complex128)
        kj[0] = 0.0
        xj[0] = t0_net
        kj[1:] = k[: x.shape[0]]
        xj[1:] = x
        alpha, beta = _weighted_amplitudes(q, xj, kj, kb, wt)
        basis = _fit_basis(q, x, k, kb, edge)
        for j in range(m):
            model[j] = abs(alpha * basis[0][j] + beta * basis[1][j])
    rn = radius * n_flutes
    kt = alpha / (rn * feed_per_tooth_m)
    ke = max(beta / rn, 0.0) if edge else 0.0
    w = _runout_with_edge(t1, d, st, ex, feed_per_tooth_m, kb, radius, n_flutes, kt, ke, g1, l2,
                          rcond)  # fmt: skip
    dev = 0.0
    tot = 0.0
    for j in range(m):
        a_j = abs(x[j])
        dev += abs(a_j - model[j])
        tot += a_j
    out[EST_AXIAL] = d
    out[EST_RADIAL] = radius * (math.cos(st) - math.cos(ex))
    out[EST_ENTRY] = st
    out[EST_EXIT] = ex
    out[EST_KT] = kt
    out[EST_RUNOUT] = abs(w)
    out[EST_RUNOUT_ANGLE] = (-math.atan2(w.imag, w.real)) % (2.0 * math.pi)
    out[EST_RELIABILITY] = 1.0 - dev / tot
    if source == EDGE_FROM_MEAN:  # refitted: the factors at the new point
        out[EST_AXIAL_SD] = depth_sd(q, x, k, kb, edge)
    elif _depth_sd_undefined(x, edge):
        out[EST_AXIAL_SD] = math.inf
    else:
        out[EST_AXIAL_SD] = _depth_sd_at(x, kk, kb, edge, idx, e1, e2, gq, lk)
    out[EST_NOTCH] = notch
    out[EST_COST] = 2.0 * cost / norm
    out[EST_EDGE] = beta / rn
    out[EST_EDGE_SOURCE] = source


@numba.njit(cache=True)
def normalised(x: ComplexArray) -> tuple[ComplexArray, float]:
    """x / |x_0| and Σ |x/|x_0||²."""
    ax0 = abs(x[0])
    xn = np.empty_like(x)
    norm = 0.0
    for j in range(x.shape[0]):
        v = x[j] / ax0
        xn[j] = v
        norm += v.real * v.real + v.imag * v.imag
    return xn, norm


@numba.njit(cache=True)
def identify_from(
    p0: FloatArray,
    x: ComplexArray,
    t1: complex,
    feed_per_tooth_m: float,
    k: FloatArray,
    kb: float,
    edge: bool,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    accept: float,
    radius: float,
    n_flutes: int,
    axial_pitch: float,
    rcond: float,
    t0_net: float,
    mean_var: float,
    out: FloatArray,
    anchor: FloatArray,
) -> bool:
    """The common path of the identification: the fit from the previous revolution's solution
    ``p0`` (and from the running mean's fit ``anchor`` where that is known: :func:`anchored_fit`,
    decision 1704); if its relative misfit is at most ``accept``, the estimate into ``out`` and
    True. Otherwise False, with ``out[:3]`` the fitted point and ``out[EST_COST]`` its cost (the
    caller adds the grid starts). ``t0_net``, ``mean_var``: the mean cutting torque and its
    variance factor (:func:`estimate`; NaN: no air torque known)."""
    xn, norm = normalised(x)
    p, cost = anchored_fit(p0, anchor, xn, norm, k[: x.shape[0]], kb, edge, lo, hi, scale,
                           accept)  # fmt: skip
    if 2.0 * cost / norm > accept:
        out[0] = p[0]
        out[1] = p[1]
        out[2] = p[2]
        out[EST_COST] = cost
        return False
    estimate(p, cost, x, t1, feed_per_tooth_m, k, kb, edge, radius, n_flutes, axial_pitch, rcond,
             t0_net, mean_var, lo, hi, scale, out)  # fmt: skip
    return True


#: Samples per block of :func:`_add_harmonics` (its product tables: 2 × 64 × harmonics floats).
HARMONIC_BLOCK = 64


@numba.njit(cache=True)
def _add_harmonics(
    x: FloatArray, zr: FloatArray, zi: FloatArray, a: int, b: int, n_flutes: int,
    sums: ComplexArray,
) -> None:  # fmt: skip
    """sums[0] += Σ x e^{−iφ}, sums[k] += Σ x e^{−ikNφ} over the samples a … b − 1 (``zr``,
    ``zi``: the samples' phasors e^{−iφ}), sample by sample in sample order (a revolution split
    over any chunks gets the same sums bit for bit). A real sample scales the real and imaginary
    parts (the products of the complex form ``x·z`` less its zero terms ``0·Im z``, ``0·Re z``,
    which cannot change a sum that starts at +0; decision 1536).

    Per block of :data:`HARMONIC_BLOCK` samples: the products x·e^{−ikNφ} of every harmonic
    (:func:`_harmonic_products`), then each harmonic's sum over the block in sample order
    (:func:`_add_products`): per sum the operations of one sample at a time, in its order."""
    nk = sums.shape[0]
    sr = np.empty(nk)
    si = np.empty(nk)
    for j in range(nk):
        sr[j] = sums[j].real
        si[j] = sums[j].imag
    blk = max(min(HARMONIC_BLOCK, b - a), 0)  # a short run needs short tables
    qr = np.empty((nk, blk))
    qi = np.empty((nk, blk))
    work = np.empty((5, blk))
    s0 = a
    while s0 < b:
        m = min(blk, b - s0)
        _harmonic_products(x, zr, zi, s0, m, n_flutes, qr, qi, work)
        _add_products(qr, qi, m, sr, si)
        s0 += m
    for j in range(nk):
        sums[j] = complex(sr[j], si[j])


@numba.njit(cache=True, inline="always")
def _harmonic_products(
    x: FloatArray, zr: FloatArray, zi: FloatArray, s0: int, m: int, n_flutes: int,
    qr: FloatArray, qi: FloatArray, work: FloatArray,
) -> None:  # fmt: skip
    """qr[j, t] + i qi[j, t] = x_s e^{−ik_jNφ_s} (k_0 N = 1) for the samples s = s0 + t,
    t < m: the power chain z ← z·e^{−iNφ} in real arithmetic (the products and sums of numba's
    complex product, in its order), harmonic by harmonic across the block's samples: lanes
    the compiler vectorises (the chain of one sample is sequential)."""
    nk = qr.shape[0]
    xs, br, bi, cr, ci = work[0], work[1], work[2], work[3], work[4]
    for t in range(m):
        s = s0 + t
        xs[t] = x[s]
        # e^{−iNφ} by repeated products: numba's complex power beyond a square is the general
        # polar one (hypot, pow, atan2, cos, sin per sample), four times the 2-flute cost
        z = complex(zr[s], zi[s])
        bn = z
        for _ in range(n_flutes - 1):
            bn = bn * z
        br[t] = bn.real
        bi[t] = bn.imag
        cr[t] = bn.real
        ci[t] = bn.imag
        qr[0, t] = x[s] * zr[s]
        qi[0, t] = x[s] * zi[s]
    if nk > 1:
        for t in range(m):
            qr[1, t] = xs[t] * br[t]
            qi[1, t] = xs[t] * bi[t]
    for j in range(2, nk):
        for t in range(m):
            re = cr[t] * br[t] - ci[t] * bi[t]
            im = cr[t] * bi[t] + ci[t] * br[t]
            cr[t] = re
            ci[t] = im
            qr[j, t] = xs[t] * re
            qi[j, t] = xs[t] * im


@numba.njit(cache=True, inline="always")
def _add_products(qr: FloatArray, qi: FloatArray, m: int, sr: FloatArray, si: FloatArray) -> None:
    """sr[j] += Σ_t qr[j, t], si[j] += Σ_t qi[j, t] over t < m, each sum in order of t; four
    harmonics at a time (eight independent sums: their additions overlap instead of waiting
    on one another)."""
    nk = qr.shape[0]
    j = 0
    while j + 3 < nk:
        r0, r1, r2, r3 = sr[j], sr[j + 1], sr[j + 2], sr[j + 3]
        i0, i1, i2, i3 = si[j], si[j + 1], si[j + 2], si[j + 3]
        for t in range(m):
            r0 += qr[j, t]
            r1 += qr[j + 1, t]
            r2 += qr[j + 2, t]
            r3 += qr[j + 3, t]
            i0 += qi[j, t]
            i1 += qi[j + 1, t]
            i2 += qi[j + 2, t]
            i3 += qi[j + 3, t]
        sr[j], sr[j + 1], sr[j + 2], sr[j + 3] = r0, r1, r2, r3
        si[j], si[j + 1], si[j + 2], si[j + 3] = i0, i1, i2, i3
        j += 4
    while j < nk:
        r0 = sr[j]
        i0 = si[j]
        for t in range(m):
            r0 += qr[j, t]
            i0 += qi[j, t]
        sr[j] = r0
        si[j] = i0
        j += 1


@numba.njit(cache=True)
def revolution_phasors(
    speed: FloatArray, i0: int, fs: float, acc: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The spindle angle of the samples ``i0`` … of a chunk from the speed (rad/s): the
    fraction of a revolution, the revolution index and the phasor e^{−i2π·fraction} (real,
    imaginary), continuing from the state in ``acc`` (:data:`ACC_FRAC`, :data:`ACC_REV`, the
    rotation cache of :data:`ACC_STEP_SPEED`; the caller stores the last sample's fraction,
    revolution and phasor back, or those of an earlier sample it will scan again).

    The phasor advances by its rotation per sample, e^{−i|Ω|/f_s}, computed once per speed
    value rather than a cosine and sine per sample (a third of the engagement monitor's time),
    and is set exactly where a revolution starts, so its error stays within a revolution's
    rounding (≈ 10⁻¹³). It is a function of the samples alone: every chunking gives it bit for
    bit (decision 1770)."""
    n = speed.shape[0]
    ang = np.empty(n)
    revs = np.empty(n)
    zr = np.empty(n)
    zi = np.empty(n)
    frac = acc[ACC_FRAC]
    rev = acc[ACC_REV]
    scl = 1.0 / (2.0 * math.pi * fs)
    z = complex(acc[ACC_ZR], acc[ACC_ZI])
    step = complex(acc[ACC_STEP_R], acc[ACC_STEP_I])
    step_speed = acc[ACC_STEP_SPEED]
    for i in range(i0, n):
        exact = rev < 0
        if i > 0 or rev >= 0:
            w = abs(speed[i])
            frac += w * scl
            if w != step_speed:
                step_speed = w
                step = complex(math.cos(w / fs), -math.sin(w / fs))
            z = z * step
        if rev < 0:
            rev = 0.0
        while frac >= 1.0:
            frac -= 1.0
            rev += 1.0
            exact = True
        if exact:
            z = complex(math.cos(2.0 * math.pi * frac), -math.sin(2.0 * math.pi * frac))
        ang[i] = frac
        revs[i] = rev
        zr[i] = z.real
        zi[i] = z.imag
    acc[ACC_STEP_SPEED] = step_speed
    acc[ACC_STEP_R] = step.real
    acc[ACC_STEP_I] = step.imag
    return ang, revs, zr, zi


@numba.njit(cache=True)
def ingest_revolutions(
    x: FloatArray,
    speed: FloatArray,
    feed: FloatArray,
    i0: int,
    fs: float,
    n_flutes: int,
    edge: bool,
    acc: FloatArray,
    sums: ComplexArray,
    prev: FloatArray,
    fpar: FloatArray,
    k: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    scale: FloatArray,
    done: FloatArray,
    done_sums: ComplexArray,
    est: FloatArray,
    orders: FloatArray,
    eq: ComplexArray,
    eqp: FloatArray,
    mstate: FloatArray,
    anchor: FloatArray,
    hmean: ComplexArray,
) -> tuple[int, int]:
    """Spindle angle, revolution boundaries, the revolution's harmonics and its estimate,
    sample by sample from ``i0`` on (the engagement block's per-sample and per-revolution work
    in one call).

    The angle as :func:`.._tooth_kernels.accumulate_revolutions`; the harmonic sums
    ``sums[0] = Σ x e^{−iφ}``, ``sums[k] = Σ x e^{−ikNφ}`` by :func:`_add_harmonics`, in
    sample order, so a revolution split over any chunks gives its coefficients bit for bit.
    When a sample starts a new revolution while samples are summed, the revolution is
    finished: its coefficients (the sums over the count) go to a row of ``done_sums``, its
    sample, means, mean cutting torque (:func:`mean_cut_torque`, which also learns the air
    reference from an air revolution; decision 1806) and status to a row of ``done`` and, if
    the fit from ``prev`` is accepted (:func:`identify_from`), its estimate to that row of
    ``est`` (``prev`` ← its solution). With a monitoring cycle of ``fpar[FPAR_CYCLE]`` = n > 1
    revolutions (decision 1717) the cycle is finished instead: the revolution index's
    ⌊index/n⌋ changes, and its coefficients are the sums over its n revolutions' samples over
    their count, the mean of the revolutions' own (the phasors repeat every revolution).
    With an equaliser (``eqp`` = (grid step Hz, range-switch speed rad/s), ``eq`` the torque
    channel's response on that grid per speed range, rows 0 and 1; decision 1554) each
    coefficient is divided by the response at its frequency ``orders[j]·Ω/2π`` (linear
    interpolation; 1 beyond the grid), so the fit sees the torque, not the estimator's view of it.
    Every evaluated revolution's harmonics enter the running mean ``hmean`` (state ``anchor``,
    :func:`note_mean`; a revolution not evaluated starts a new one), whose fit, once the caller
    has searched it, is the second start of the revolutions' fits (:func:`anchored_fit`,
    decision 1704).
    Returns (revolutions finished, next sample): the scan stops when ``done`` is full or after
    a revolution that needs the grid search."""
    nk = sums.shape[0]
    cap = done.shape[0]
    n = x.shape[0]
    # the angle and revolution of every sample (they do not depend on the estimates)
    ang, revs, zr, zi = revolution_phasors(speed, i0, fs, acc)
    nd = 0
    # a cycle of `cyc` revolutions ends where the revolution index's cycle changes
    cyc = fpar[FPAR_CYCLE]
    cur = acc[ACC_REV] if cyc == 1.0 else float(math.floor(acc[ACC_REV] / cyc))
    run = i0  # first sample not yet summed
    for i in range(i0, n):
        now = revs[i] if cyc == 1.0 else float(math.floor(revs[i] / cyc))
        if now != cur and acc[ACC_COUNT] + (i - run) > 0:
            _sum_run(x, speed, feed, zr, zi, run, i, n_flutes, acc, sums)
            run = i
            if nd == cap or (nd > 0 and done[nd - 1, DONE_STATUS] == REV_GRID):
                # this sample is scanned again on the next call
                if i > i0:
                    acc[ACC_FRAC] = ang[i - 1]
                    acc[ACC_REV] = revs[i - 1]
                    acc[ACC_ZR] = zr[i - 1]
                    acc[ACC_ZI] = zi[i - 1]
                return nd, i
            cnt = acc[ACC_COUNT]
            mean_x = acc[ACC_SUM_X] / cnt
            omega = acc[ACC_SUM_SPEED] / cnt
            c = fpar[FPAR_FEED]
            if c <= 0.0 and omega > 0:
                c = 2 * math.pi * (acc[ACC_SUM_FEED] / cnt) / (n_flutes * omega)
            for j in range(nk):
                done_sums[nd, j] = sums[j] / cnt
                sums[j] = 0.0
            if eq.shape[1] > 1:
                _equalise(done_sums[nd], orders, omega, eq, eqp)
            done[nd, DONE_AT] = i
            done[nd, DONE_OMEGA] = omega
            done[nd, DONE_FEED] = c
            air = mean_x < fpar[FPAR_MIN_TORQUE]
            t0_net, mean_var = mean_cut_torque(mean_x, omega, cnt, air, acc, fpar)
            done[nd, DONE_T0_NET] = t0_net
            done[nd, DONE_MEAN_VAR] = mean_var
            status = REV_NONE
            # a harmonic at or above the Nyquist frequency is another one's alias (decision
            # 1734): the revolution is not evaluated (orders ascend: the last is the highest)
            aliased = omega * orders[nk - 1] >= math.pi * fs
            if (
                mean_x >= fpar[FPAR_MIN_TORQUE]
                and omega > 0
                and c > 0
                and (abs(done_sums[nd, 1]) > 0)
                and not aliased
            ):
                status = REV_GRID
                note_mean(anchor, hmean, done_sums[nd, 1:])
                if acc[ACC_HAS_PREV] > 0:
                    row = est[nd]
                    if identify_from(prev, done_sums[nd, 1:], done_sums[nd, 0], c, k,
                                     fpar[FPAR_KB], edge, lo, hi, scale, fpar[FPAR_ACCEPT],
                                     fpar[FPAR_RADIUS], n_flutes, fpar[FPAR_PITCH],
                                     fpar[FPAR_RCOND], t0_net, mean_var, row,
                                     anchor):  # fmt: skip
                        status = REV_DONE
                    elif local_fit_holds(
                        mstate, 2.0 * row[EST_COST] / normalised(done_sums[nd, 1:])[1]
                    ):
                        # the misfit is the noise's of the last revolutions: the fit from the
                        # previous solution is the estimate, no grid search (decision 1557)
                        mstate[MST_SINCE] += 1.0
                        estimate(row[:3].copy(), row[EST_COST], done_sums[nd, 1:],
                                 done_sums[nd, 0], c, k, fpar[FPAR_KB], edge, fpar[FPAR_RADIUS],
                                 n_flutes, fpar[FPAR_PITCH], fpar[FPAR_RCOND], t0_net, mean_var,
                                 lo, hi, scale, row)  # fmt: skip
                        status = REV_DONE
                    if status == REV_DONE:
                        note_misfit(mstate, row[EST_COST])
                        prev[0] = row[EST_AXIAL]
                        prev[1] = row[EST_ENTRY]
                        prev[2] = row[EST_EXIT]
            else:
                forget_mean(anchor, hmean)
                if aliased and mean_x >= fpar[FPAR_MIN_TORQUE]:
                    status = REV_ALIASED
            done[nd, DONE_STATUS] = status
            acc[ACC_COUNT] = 0.0
            acc[ACC_SUM_X] = 0.0
            acc[ACC_SUM_SPEED] = 0.0
            acc[ACC_SUM_FEED] = 0.0
            nd += 1
        cur = now
    _sum_run(x, speed, feed, zr, zi, run, n, n_flutes, acc, sums)
    if n > i0:
        acc[ACC_FRAC] = ang[n - 1]
        acc[ACC_REV] = revs[n - 1]
        acc[ACC_ZR] = zr[n - 1]
        acc[ACC_ZI] = zi[n - 1]
    return nd, n


#: The parts of :func:`ingest_chunk`'s packed state (:func:`pack_state`): the float parts
#: in the float array, in this order, then the complex parts in the complex array.
PK_ACC, PK_PREV, PK_FPAR, PK_K, PK_LO, PK_HI, PK_SCALE, PK_DONE, PK_EST = range(9)
PK_ORDERS, PK_EQP, PK_ANCHOR = range(9, 12)
PK_SUMS, PK_DONE_SUMS, PK_EQ, PK_HMEAN = range(12, 16)
PK_PARTS = 16
#: Header floats per part: offset in its array, rows, columns.
PK_FIELDS = 3


def pack_state(
    float_parts: Sequence[np.ndarray], complex_parts: Sequence[np.ndarray]
) -> tuple[FloatArray, ComplexArray, list[np.ndarray]]:
    """One float array (a header of every part's offset, rows and columns, then the float parts
    in order) and one complex array (the complex parts) holding copies of the 1-D and 2-D
    ``float_parts`` and ``complex_parts``, and each part's view in them (in order): the state
    the caller keeps, reads and writes, which :func:`_part` and :func:`_part2` view again in a
    kernel."""
    parts = [*float_parts, *complex_parts]
    head = PK_FIELDS * len(parts)
    sizes = [a.size for a in float_parts]
    fst = np.zeros(head + sum(sizes))
    cst = np.zeros(sum(a.size for a in complex_parts), dtype=np.complex128)
    views: list[np.ndarray] = []
    at = {id(fst): head, id(cst): 0}
    for j, a in enumerate(parts):
        buf = fst if j < len(float_parts) else cst
        o = at[id(buf)]
        rows, cols = (1, a.size) if a.ndim == 1 else a.shape
        fst[PK_FIELDS * j : PK_FIELDS * (j + 1)] = (o, rows, cols)
        v = buf[o : o + a.size]
        v[:] = a.ravel()
        views.append(v if a.ndim == 1 else v.reshape(a.shape))
        at[id(buf)] = o + a.size
    return fst, cst, views


@numba.njit(cache=True, inline="always")
def _part(buf: np.ndarray, head: FloatArray, j: int) -> np.ndarray:
    """Part ``j`` of a packed state (:func:`pack_state`), 1-D, in ``buf``."""
    o = int(head[PK_FIELDS * j])
    return buf[o : o + int(head[PK_FIELDS * j + 1]) * int(head[PK_FIELDS * j + 2])]


@numba.njit(cache=True, inline="always")
def _part2(buf: np.ndarray, head: FloatArray, j: int) -> np.ndarray:
    """Part ``j`` of a packed state (:func:`pack_state`), 2-D, in ``buf``."""
    rows = int(head[PK_FIELDS * j + 1])
    cols = int(head[PK_FIELDS * j + 2])
    o = int(head[PK_FIELDS * j])
    return buf[o : o + rows * cols].reshape((rows, cols))


@numba.njit(cache=True)
def ingest_chunk(
    x: FloatArray,
    speed: FloatArray,
    feed: FloatArray,
    i0: int,
    fst: FloatArray,
    cst: ComplexArray,
    mstate: FloatArray,
) -> tuple[int, int]:
    """:func:`ingest_revolutions` with its arrays packed in ``fst`` and ``cst``
    (:func:`pack_state`, parts :data:`PK_ACC` …) and the sample rate, flutes and edge flag in
    its ``fpar`` (:data:`FPAR_FS` …): numba's dispatch unboxes every array argument (≈ 0.12 µs
    each) and types every scalar (≈ 0.3 µs), once per chunk, a third of a short chunk's time
    with the 20 arguments unpacked."""
    fpar = _part(fst, fst, PK_FPAR)
    return ingest_revolutions(
        x, speed, feed, i0, fpar[FPAR_FS], int(fpar[FPAR_FLUTES]), fpar[FPAR_EDGE] > 0.0,
        _part(fst, fst, PK_ACC), _part(cst, fst, PK_SUMS), _part(fst, fst, PK_PREV), fpar,
        _part(fst, fst, PK_K), _part(fst, fst, PK_LO), _part(fst, fst, PK_HI),
        _part(fst, fst, PK_SCALE), _part2(fst, fst, PK_DONE), _part2(cst, fst, PK_DONE_SUMS),
        _part2(fst, fst, PK_EST), _part(fst, fst, PK_ORDERS), _part2(cst, fst, PK_EQ),
        _part(fst, fst, PK_EQP), mstate, _part(fst, fst, PK_ANCHOR), _part(cst, fst, PK_HMEAN),
    )  # fmt: skip


@numba.njit(cache=True)
def _equalise(
    coeff: ComplexArray, orders: FloatArray, omega: float, eq: ComplexArray, eqp: FloatArray
) -> None:
    """Divide each coefficient by the response ``eq`` at its frequency (see
    :func:`ingest_revolutions`)."""
    row = 0 if omega < eqp[1] else 1
    g = eq.shape[1]
    for j in range(coeff.shape[0]):
        pos = orders[j] * omega / (2.0 * math.pi) / eqp[0]
        i = int(pos)
        if i + 1 >= g or pos < 0.0:
            continue
        w = pos - i
        h = eq[row, i] * (1.0 - w) + eq[row, i + 1] * w
        if abs(h) > 0.0:
            coeff[j] = coeff[j] / h


@numba.njit(cache=True)
def _sum_run(
    x: FloatArray, speed: FloatArray, feed: FloatArray, zr: FloatArray, zi: FloatArray, a: int,
    b: int, n_flutes: int, acc: FloatArray, sums: ComplexArray,
) -> None:  # fmt: skip
    """Add the samples a … b − 1 (``zr``, ``zi``: their phasors e^{−iφ}) to the sums."""
    if b <= a:
        return
    # local sums (the same additions in the same order): through ``acc`` every addition
    # waited on the store of the previous one
    sum_x = acc[ACC_SUM_X]
    sum_speed = acc[ACC_SUM_SPEED]
    sum_feed = acc[ACC_SUM_FEED]
    for s in range(a, b):
        sum_x += x[s]
        sum_speed += abs(speed[s])
        sum_feed += abs(feed[s])
    acc[ACC_SUM_X] = sum_x
    acc[ACC_SUM_SPEED] = sum_speed
    acc[ACC_SUM_FEED] = sum_feed
    _add_harmonics(x, zr, zi, a, b, n_flutes, sums)
    acc[ACC_COUNT] += b - a
