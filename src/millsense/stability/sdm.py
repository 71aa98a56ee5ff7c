"""First-order semi-discretisation of linear periodic delay-differential equations.

The solver knows delay-differential equations, not milling::

    x'(t) = A(t) x(t) + sum_j B_j(t) x(t - tau_j) + c(t),     A, B_j, c periodic in T,

with ``B_j(t) = E_j(t) C`` (the delayed state enters only through the output ``C x``; milling
and turning builders use this to keep the history short). Problem builders
(:mod:`millsense.stability.milling`) turn a cutting process into such an equation.

Conventions (benchmarks.md §2, they reproduce the SemiDiscretizationMethod.jl regression values
to 1e-9):

* whole steps of exactly ``h``; the map covers ``m`` steps (``m h`` need not equal ``T``);
* ``A(t)``, ``E_j(t)`` and ``c(t)`` are replaced by their mean over each step (exact means
  given by a builder, or Gauss–Legendre quadrature of callables);
* with ``tau_j / h = r_j + f_j`` (``r_j = floor``, ``0 <= f_j < 1``) the delayed state on the
  step ``[t_i, t_i + h]`` is the straight line through the nodes ``x_{i-r_j}`` and
  ``x_{i-r_j+1}`` evaluated at ``t - tau_j`` (so the fractional part ``f_j`` is kept).

On one step, with ``s`` the time since ``t_i``::

    x_{i+1} = Phi_i x_i + sum_j [ ((1+f_j) G0_ij - G1_ij / h) C x_{i-r_j}
                                  + (G1_ij / h - f_j G0_ij) C x_{i-r_j+1} ] + g_i,
    Phi_i = exp(Ā_i h),
    G0_ij = ∫_0^h e^{Ā_i (h-s)} ds Ē_ij,   G1_ij = ∫_0^h e^{Ā_i (h-s)} s ds Ē_ij,
    g_i = ∫_0^h e^{Ā_i (h-s)} ds c̄_i,

all three from one matrix exponential of the block matrix
``[[Ā, Ē, 0, c̄], [0, 0, I, 0], [0, 0, 0, 0], [0, 0, 0, 0]] h`` (Van Loan). The discrete state
is ``y_i = [x_i, C x_{i-1}, ..., C x_{i-R}]``; the monodromy matrix is the product of the ``m``
step maps, built column-block-wise by a compiled kernel (no dense ``(n R)^2`` products).

References
----------
Insperger T., Stépán G., *Semi-discretization for time-delay systems*, Springer 2011, ch. 3
(first-order semi-discretisation). Bachrathy D., Lehotzky D., SemiDiscretizationMethod.jl
(regression values quoted in benchmarks.md §2).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: |Im mu| / |mu| below this counts as a real multiplier (flip or fold).
REAL_MULTIPLIER_TOL = 1e-7


@dataclass(frozen=True)
class StepMeans:
    """A periodic DDE sampled as exact means over ``m`` steps of length ``h``.

    Attributes
    ----------
    A : (m, n, n) mean of ``A(t)`` over each step [1/s].
    E : (m, J, n, p) mean of the delayed input matrices ``E_j(t)`` over each step [1/s].
    C : (p, n) output matrix through which the delayed state enters [-].
    delays : (J,) delays ``tau_j`` [s].
    h : step [s].
    c : (m, n) mean forcing over each step [state unit/s], or None.
    """

    A: FloatArray
    E: FloatArray
    C: FloatArray
    delays: FloatArray
    h: float
    c: FloatArray | None = None

    @property
    def m(self) -> int:
        return int(self.A.shape[0])

    @property
    def n(self) -> int:
        return int(self.A.shape[1])


def delay_split(tau: float, h: float) -> tuple[int, float]:
    """Whole steps ``r = floor(tau/h)`` and fraction ``f = tau/h - r`` (snapped within 1e-9).

    Parameters
    ----------
    tau : delay [s].
    h : step [s].
    """
    q = tau / h
    r = int(np.floor(q + 1e-9 * max(1.0, q)))
    f = max(q - r, 0.0)
    return r, f


def step_means_from_callables(
    A: Callable[[float], FloatArray] | FloatArray,
    B: Sequence[Callable[[float], FloatArray] | FloatArray],
    delays: Sequence[float],
    h: float,
    m: int,
    c: Callable[[float], FloatArray] | FloatArray | None = None,
    t0: float = 0.0,
    quad_points: int = 8,
) -> StepMeans:
    """Step means of ``A``, ``B_j`` and ``c`` by Gauss–Legendre quadrature on every step.

    Parameters
    ----------
    A : ``A(t)`` -> (n, n) [1/s], or a constant (n, n) array.
    B : per delay ``B_j(t)`` -> (n, n) [1/s], or constant arrays.
    delays : delays ``tau_j`` [s].
    h : step [s].
    m : number of steps in the map.
    c : forcing ``c(t)`` -> (n,), a constant (n,) array, or None.
    t0 : time of the first node [s].
    quad_points : Gauss–Legendre points per step (8 integrates smooth coefficients to
        machine precision for the usual ``h``).

    Notes
    -----
    The delayed state enters through ``C``: the columns of ``I`` where any ``B_j`` is non-zero
    (so a second-order system in first-order form keeps only its positions in the history).
    """
    nodes, weights = np.polynomial.legendre.leggauss(quad_points)
    ts = t0 + h * (np.arange(m)[:, None] + 0.5 * (nodes[None, :] + 1.0))  # (m, q)
    w = 0.5 * weights

    def mean_of(
        f: Callable[[float], FloatArray] | FloatArray, shape: tuple[int, ...]
    ) -> FloatArray:
        if not callable(f):
            arr = np.asarray(f, dtype=float)
            return np.broadcast_to(arr, (m, *shape)).copy()
        out = np.zeros((m, *shape))
        for i in range(m):
            for k in range(quad_points):
                out[i] += w[k] * np.asarray(f(float(ts[i, k])), dtype=float)
        return out

    a0 = np.asarray(A(t0) if callable(A) else A, dtype=float)
    n = a0.shape[0]
    A_mean = mean_of(A, (n, n))
    B_mean = np.stack([mean_of(b, (n, n)) for b in B], axis=1)  # (m, J, n, n)
    cols = np.flatnonzero(np.any(B_mean != 0.0, axis=(0, 1, 2)))
    if cols.size == 0:
        cols = np.array([0])
    C = np.eye(n)[cols]
    E = B_mean[..., cols]
    c_mean = None if c is None else mean_of(c, (n,))
    return StepMeans(A_mean, E, C, np.asarray(delays, dtype=float), float(h), c_mean)


@numba.njit(cache=True)
def _matmul_into(a: FloatArray, b: FloatArray, out: FloatArray) -> None:  # pragma: no cover
    # row-by-row (i, q, j) order: the inner loop runs over contiguous memory and skips the
    # zero entries of the sparse Van Loan block matrices; each out[i, j] sums over q in the
    # same order as the textbook (i, j, q) loop, so the result is bit-for-bit the same
    k = a.shape[0]
    for i in range(k):
        for j in range(k):
            out[i, j] = 0.0
        for q in range(k):
            aiq = a[i, q]
            if aiq != 0.0:
                for j in range(k):
                    out[i, j] += aiq * b[q, j]


#: Padé degrees of :func:`_expm_one`, the largest 1-norm each serves with a backward error
#: below the unit round-off (Higham 2005, Table 2.3), and the numerator coefficients.
_PADE_THETA = np.array(
    [1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1, 2.097847961257068e0]
)
_PADE_B = np.array([
    [120.0, 60.0, 12.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0, 0.0, 0.0, 0.0, 0.0],
    [17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0, 0.0, 0.0],
    [17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0, 2162160.0,
     110880.0, 3960.0, 90.0, 1.0],
])  # fmt: skip


@numba.njit(cache=True)
def _solve_into(P: FloatArray, Q: FloatArray, out: FloatArray) -> None:  # pragma: no cover
    """``out = Q⁻¹ P`` by Gaussian elimination with partial pivoting (overwrites Q and P)."""
    k = Q.shape[0]
    for c in range(k):
        piv = c
        big = abs(Q[c, c])
        for r in range(c + 1, k):
            if abs(Q[r, c]) > big:
                big = abs(Q[r, c])
                piv = r
        if piv != c:
            for j in range(k):
                t = Q[c, j]
                Q[c, j] = Q[piv, j]
                Q[piv, j] = t
                t = P[c, j]
                P[c, j] = P[piv, j]
                P[piv, j] = t
        d = Q[c, c]
        for r in range(c + 1, k):
            f = Q[r, c] / d
            if f != 0.0:
                for j in range(c + 1, k):
                    Q[r, j] -= f * Q[c, j]
                for j in range(k):
                    P[r, j] -= f * P[c, j]
    for r in range(k - 1, -1, -1):
        for j in range(k):
            v = P[r, j]
            for q in range(r + 1, k):
                v -= Q[r, q] * out[q, j]
            out[r, j] = v / Q[r, r]


@numba.njit(cache=True)
def _expm_one(M: FloatArray, out: FloatArray, tmp: FloatArray) -> None:  # pragma: no cover
    k = M.shape[0]
    norm = 0.0  # 1-norm
    for b in range(k):
        col = 0.0
        for a in range(k):
            col += abs(M[a, b])
        norm = max(norm, col)
    s = 0
    deg = 0
    while deg < 3 and norm > _PADE_THETA[deg]:
        deg += 1
    if norm > _PADE_THETA[3]:
        s = max(0, int(np.ceil(np.log2(norm / _PADE_THETA[3]))))
        while norm / 2.0**s > _PADE_THETA[3]:
            s += 1
    X = M / (2.0**s)
    b = _PADE_B[deg]
    q = 2 * deg + 3  # degree of the Padé approximant
    # even powers X^2, X^4, ... up to X^(q-1); U = X Σ b_{2i+1} X^{2i}, V = Σ b_{2i} X^{2i}
    npow = (q - 1) // 2
    P = np.empty((npow + 1, k, k))
    P[0] = 0.0
    for a in range(k):
        P[0, a, a] = 1.0
    if npow >= 1:
        _matmul_into(X, X, P[1])
    for i in range(2, npow + 1):
        _matmul_into(P[i - 1], P[1], P[i])
    Ue = np.zeros((k, k))
    V = np.zeros((k, k))
    for i in range(npow + 1):
        for a in range(k):
            for c in range(k):
                Ue[a, c] += b[2 * i + 1] * P[i, a, c]
                V[a, c] += b[2 * i] * P[i, a, c]
    _matmul_into(X, Ue, tmp)
    # (V − U) R = (V + U)
    for a in range(k):
        for c in range(k):
            u = tmp[a, c]
            Ue[a, c] = V[a, c] + u
            V[a, c] = V[a, c] - u
    _solve_into(Ue, V, out)
    for _ in range(s):
        _matmul_into(out, out, tmp)
        out[:, :] = tmp


@numba.njit(cache=True)
def expm_stack(M: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """Matrix exponential of a stack (m, k, k) of small matrices.

    Scaling and squaring with the diagonal Padé approximant of degree 3, 5, 7 or 9 chosen by
    the 1-norm, which is scaled below θ₉ = 2.098 when larger (Higham, *The scaling and
    squaring method for the matrix exponential revisited*, SIAM J. Matrix Anal. Appl. 26,
    2005: backward error below the unit round-off); compiled, as a lobe diagram needs
    hundreds of thousands of these small exponentials. Decision 0912: 4 to 6 matrix
    products and one small solve instead of the 14 products of a degree-14 Taylor
    polynomial at the 2 more squarings its scaling below 1/2 needed.
    """
    out = np.empty_like(M)
    tmp = np.empty(M.shape[1:])
    for i in range(M.shape[0]):
        _expm_one(M[i], out[i], tmp)
    return out


@dataclass(frozen=True)
class DiscreteMap:
    """The semi-discretised step maps of one period.

    Attributes
    ----------
    Phi : (m, n, n) state transition of each step.
    Wa : (m, J, n, p) weight of ``C x_{i-r_j}``.
    Wb : (m, J, n, p) weight of ``C x_{i-r_j+1}``.
    lags : (J,) ``r_j``.
    C : (p, n).
    g : (m, n) forcing contribution of each step (zeros if unforced).
    """

    Phi: FloatArray
    Wa: FloatArray
    Wb: FloatArray
    lags: NDArray[np.int64]
    C: FloatArray
    g: FloatArray

    @property
    def dim(self) -> int:
        """Dimension of the discrete state ``n + R p``."""
        return int(self.Phi.shape[1] + int(self.lags.max()) * self.C.shape[0])


def discretize(sm: StepMeans) -> DiscreteMap:
    """Step maps of the first-order semi-discretisation (module docstring for the equations).

    Parameters
    ----------
    sm : step means of the DDE.

    Raises
    ------
    ValueError
        If a delay is shorter than one step (the scheme would be implicit).
    """
    m, n = sm.m, sm.n
    J = sm.E.shape[1]
    p = sm.C.shape[0]
    h = sm.h
    splits = [delay_split(float(t), h) for t in sm.delays]
    if any(r < 1 for r, _ in splits):
        raise ValueError("every delay must be at least one step h; use more steps per period")
    lags = np.array([r for r, _ in splits], dtype=np.int64)
    fr = np.array([f for _, f in splits])
    forced = sm.c is not None
    k = n + 2 * p * J + (1 if forced else 0)
    big = np.zeros((m, k, k))
    big[:, :n, :n] = sm.A * h
    for j in range(J):
        big[:, :n, n + j * p : n + (j + 1) * p] = sm.E[:, j] * h
        big[:, n + j * p : n + (j + 1) * p, n + p * J + j * p : n + p * J + (j + 1) * p] = (
            np.eye(p) * h
        )
    if forced:
        assert sm.c is not None
        big[:, :n, -1] = sm.c * h
    # The result is linear in each input block E_j (and in c): scale them to the size of A h
    # so that the norm of the block matrix, which sets the number of squarings, is that of
    # A h alone; both G0_j and G1_j carry the factor of E_j back.
    anorm = max(float(np.max(np.abs(big[:, :n, :n]))), 1e-3)
    escale = np.ones(J)
    for j in range(J):
        en = float(np.max(np.abs(big[:, :n, n + j * p : n + (j + 1) * p])))
        if en > anorm:
            escale[j] = en / anorm
            big[:, :n, n + j * p : n + (j + 1) * p] /= escale[j]
    cscale = 1.0
    if forced:
        cn = float(np.max(np.abs(big[:, :n, -1])))
        if cn > anorm:
            cscale = cn / anorm
            big[:, :n, -1] /= cscale
    ex = expm_stack(big)
    Phi = np.ascontiguousarray(ex[:, :n, :n])
    Wa = np.empty((m, J, n, p))
    Wb = np.empty((m, J, n, p))
    for j in range(J):
        G0 = ex[:, :n, n + j * p : n + (j + 1) * p]
        G1 = ex[:, :n, n + p * J + j * p : n + p * J + (j + 1) * p]  # ∫ e^{A(h-s)} s ds E
        Wa[:, j] = escale[j] * ((1.0 + fr[j]) * G0 - G1 / h)
        Wb[:, j] = escale[j] * (G1 / h - fr[j] * G0)
    g = cscale * np.ascontiguousarray(ex[:, :n, -1]) if forced else np.zeros((m, n))
    return DiscreteMap(Phi, Wa, Wb, lags, np.ascontiguousarray(sm.C), g)


@numba.njit(cache=True)
def _product_on_columns(
    M: FloatArray, X: FloatArray, out: FloatArray, n: int, c0: int, cols: int
) -> None:  # pragma: no cover - compiled
    """``out = M X`` on the columns ``[0, n)`` and ``[c0, cols)`` (the others are unused and
    stay zero), skipping the exact zeros of ``M``."""
    for r in range(M.shape[0]):
        for c in range(n):
            out[r, c] = 0.0
        for c in range(c0, cols):
            out[r, c] = 0.0
        for a in range(M.shape[1]):
            v = M[r, a]
            if v != 0.0:
                for c in range(n):
                    out[r, c] += v * X[a, c]
                for c in range(c0, cols):
                    out[r, c] += v * X[a, c]


@numba.njit(cache=True)
def _axpy_on_columns(
    out: FloatArray, w: float, x: FloatArray, n: int, c0: int, cols: int
) -> None:  # pragma: no cover - compiled
    """``out += w x`` on the columns ``[0, n)`` and ``[c0, cols)``."""
    for c in range(n):
        out[c] += w * x[c]
    for c in range(c0, cols):
        out[c] += w * x[c]


@numba.njit(cache=True)
def _propagate(
    Phi: FloatArray,
    Wa: FloatArray,
    Wb: FloatArray,
    lags: NDArray[np.int64],
    C: FloatArray,
    g: FloatArray,
) -> FloatArray:  # pragma: no cover - compiled
    """Product of the step maps, applied to the identity plus one affine column.

    Returns the (N, N + 1) matrix ``[monodromy | affine part]`` with ``N = n + R p``.
    Preallocated buffers; for a small state (n < 6) explicit loops restricted to the columns
    that can be non-zero (those of ``x_0``, the affine one, and the delayed samples used so
    far — a step with lag ``r`` uses the samples ``r − i`` and ``r − i − 1`` steps
    old, so the used ones form a suffix of the history columns that grows by one per step),
    for a larger one BLAS products (faster there despite the zero columns).
    A delayed term whose weights ``Wa[i, j]`` and ``Wb[i, j]`` are both exactly zero (the
    tooth is out of the cut on that step) is skipped: it would add exact zeros.
    """
    m, n, _ = Phi.shape
    J = lags.shape[0]
    p = C.shape[0]
    R = 0
    for j in range(J):
        if lags[j] > R:
            R = lags[j]
    N = n + R * p
    cols = N + 1
    X = np.zeros((n, cols))
    Xn = np.zeros((n, cols))
    cur = np.zeros((p, cols))
    for a in range(n):
        X[a, a] = 1.0
    ring = np.zeros((R, p, cols))  # lag k lives in ring[(ptr + k - 1) % R]
    for k in range(1, R + 1):
        for b in range(p):
            ring[k - 1, b, n + (k - 1) * p + b] = 1.0
    c0 = N  # first history column that may be non-zero in X
    ptr = 0
    for i in range(m):
        # the samples of lag r - i and r - i - 1 (1-based in the history) enter on this step
        for j in range(J):
            if lags[j] - i >= 1:  # the older sample is still one of the initial history
                kmin = max(lags[j] - i - 1, 1)
                c0 = min(c0, n + (kmin - 1) * p)
        if n >= 6:  # BLAS beats the loops from about this size of state on
            cur[:, :] = np.dot(C, X)
            Xn[:, :] = np.dot(Phi[i], X)
        else:
            _product_on_columns(C, X, cur, n, c0, cols)
            _product_on_columns(Phi[i], X, Xn, n, c0, cols)
        for j in range(J):
            active = False
            for a in range(n):
                for b in range(p):
                    if Wa[i, j, a, b] != 0.0 or Wb[i, j, a, b] != 0.0:
                        active = True
            if not active:
                continue
            r = lags[j]
            ia = (ptr + r - 1) % R
            ib = (ptr + r - 2) % R
            for a in range(n):
                for b in range(p):
                    _axpy_on_columns(Xn[a], Wa[i, j, a, b], ring[ia, b], n, c0, cols)
                    later = cur[b] if r == 1 else ring[ib, b]
                    _axpy_on_columns(Xn[a], Wb[i, j, a, b], later, n, c0, cols)
        for a in range(n):
            Xn[a, cols - 1] += g[i, a]
        ptr = (ptr - 1) % R
        ring[ptr] = cur
        X, Xn = Xn, X
    out = np.empty((N, cols))
    out[:n] = X
    for k in range(1, R + 1):
        out[n + (k - 1) * p : n + k * p] = ring[(ptr + k - 1) % R]
    return out


def monodromy(dm: DiscreteMap) -> FloatArray:
    """Monodromy matrix (N, N) of the discrete map over one period."""
    return _propagate(dm.Phi, dm.Wa, dm.Wb, dm.lags, dm.C, dm.g)[:, :-1]


def multipliers(M: FloatArray) -> NDArray[np.complex128]:
    """Eigenvalues of a monodromy matrix, largest modulus first."""
    ev = np.asarray(np.linalg.eigvals(M), dtype=np.complex128)
    return ev[np.argsort(-np.abs(ev))]


def classify_multiplier(mu: complex) -> str:
    """Bifurcation type a critical multiplier ``mu`` (|mu| ≈ 1) would cause.

    Returns ``"hopf"`` (complex pair, secondary Hopf / Neimark–Sacker), ``"flip"`` (real,
    negative: period doubling) or ``"fold"`` (real, positive).
    """
    if abs(mu.imag) > REAL_MULTIPLIER_TOL * max(abs(mu), 1e-300):
        return "hopf"
    return "flip" if mu.real < 0 else "fold"


@dataclass(frozen=True)
class SDMResult:
    """Stability of a periodic DDE from its semi-discretisation.

    Attributes
    ----------
    spectral_radius : largest multiplier modulus [-]; < 1 means asymptotically stable.
    multiplier : the dominant multiplier (complex).
    bifurcation : type of :func:`classify_multiplier` of the dominant multiplier.
    """

    spectral_radius: float
    multiplier: complex
    bifurcation: str


def analyse(sm: StepMeans) -> SDMResult:
    """Spectral radius, dominant multiplier and its bifurcation type for ``sm``."""
    mu = multipliers(monodromy(discretize(sm)))[0]
    return SDMResult(float(abs(mu)), complex(mu), classify_multiplier(complex(mu)))


def fixed_point(sm: StepMeans) -> FloatArray:
    """Periodic solution of the forced map at the ``m + 1`` nodes, shape (m + 1, n).

    Solves ``y_0 = M y_0 + G`` for the composite affine map ``y_m = M y_0 + G`` and steps it
    through the period. Requires ``sm.c`` (a zero forcing gives the zero solution).
    """
    dm = discretize(sm)
    full = _propagate(dm.Phi, dm.Wa, dm.Wb, dm.lags, dm.C, dm.g)
    M, G = full[:, :-1], full[:, -1]
    y0 = np.linalg.solve(np.eye(M.shape[0]) - M, G)
    n, p = sm.n, sm.C.shape[0]
    R = int(dm.lags.max())
    xs = np.empty((sm.m + 1, n))
    xs[0] = y0[:n]
    hist = [y0[n + k * p : n + (k + 1) * p] for k in range(R)]  # C x_{-1}, ..., C x_{-R}
    x = y0[:n]
    for i in range(sm.m):
        outs = [dm.C @ x, *hist]  # lag 0 .. R
        xn = dm.Phi[i] @ x + dm.g[i]
        for j, r in enumerate(dm.lags):
            xn = xn + dm.Wa[i, j] @ outs[r] + dm.Wb[i, j] @ outs[r - 1]
        hist = outs[:R]
        x = xn
        xs[i + 1] = x
    return xs
