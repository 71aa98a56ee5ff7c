"""Spectral radius of a depth family at many depths at once, and the unstable bands in depth.

Batched evaluation
------------------
:func:`spectral_radii` computes the monodromy matrices of one speed at ``K`` depths in one
compiled pass (:func:`monodromies`: the Van Loan block matrices of the steps in the cut, their
exponentials, the step weights and the products of the step maps; an out-of-cut step has the
same block matrix at every depth, so its exponential is taken once per speed), and the ``K``
eigenvalue problems in one batched LAPACK call, after removing the delayed samples no step uses
(:func:`deflate`, same non-zero multipliers). The arithmetic is that of
:func:`millsense.stability.sdm.discretize` and :func:`~millsense.stability.sdm.monodromy`
(first-order semi-discretisation, Insperger & Stépán 2011 ch. 3), bit for bit.

The grid of the scan does not need ρ itself at most depths, only decisions about it (its sign,
and whether it is a sampled local maximum in ``[hump, 1)`` or minimum in ``[1, 1/hump)``):
:func:`grid_bounds` bounds ρ from powers of the monodromy matrix (:func:`radius_bounds`) and
computes it exactly only where the bounds leave a decision open (decision 0911).

Root searches (decision 0912)
-----------------------------
Brent's method between two grid depths, and :func:`near_root` at the finer discretisations,
need values at single depths one after the other. They follow the multiplier that is critical
at the unstable end of the bracket instead of solving the eigenvalue problem each time
(:class:`_Branch`): by Rayleigh-quotient iteration on the monodromy matrix
(:func:`_rayleigh`), or, for a structure of up to :data:`FLOQUET_MAX_STATE` states and one
delay of exactly ``m`` steps, as a root of ``det(μ I − P(μ))`` with ``P(μ)`` the map of the
Floquet solution ``x(t + T) = μ x(t)`` over one period (:func:`_floquet_newton`: ``m``
products of ``n × n`` factors, the monodromy matrix is never built). The answer is then
verified exactly: at the stable end of Brent's final bracket ρ < 1 is proven (the tracked
multiplier deflated and the rest bounded by :func:`radius_bounds`, :func:`_stable_beyond`,
or ρ by an eigenvalue problem), at the unstable end the multiplier of modulus >= 1 is checked
on the monodromy matrix (residual of its eigenvector); if anything fails, Brent's method runs
on ρ itself. The reported depth is within the root tolerance of a depth where ρ − 1 changes
sign, as before; it is not bit for bit the depth of Brent's method on ρ.

Unstable bands (the robust search, issue 14)
---------------------------------------------
The set of unstable depths at one speed need not be one interval above the limit: at low
radial immersion a period-doubling (flip) lobe makes an unstable band below a stable band
(an island). :func:`unstable_bands` therefore does not follow a boundary; it scans:

1. start at the small-gain depth (:func:`small_gain_depth`), below which the continuous
   DDE is provably stable, and evaluate ρ on the geometric grid ``w_k = w_0 q^k`` up to the
   ceiling (``q`` = ``ratio``, default 1.1);
2. every sign change of ρ − 1 between neighbouring grid depths is refined by Brent's method;
3. every sampled local maximum of ρ with ``hump <= ρ < 1`` (default 0.8) is maximised over
   its two neighbouring grid intervals; if the maximum reaches 1 the band it reveals is
   refined on both sides (and symmetrically, local minima with ``1 <= ρ < 1/hump`` reveal
   narrow stable islands).

What it cannot see (decision 0901): an unstable band narrower than the grid ratio ``q`` (10 %
of its depth) that lies wholly between two grid depths AND leaves no local maximum of the
sampled ρ above ``hump``, i.e. a band of a multiplier that is not the dominant one at either
neighbouring grid depth. Such a band is also narrower than any depth a user can hold on a
machine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import NDArray

from millsense.stability.milling import DepthFamily
from millsense.stability.sdm import _expm_one, _propagate, delay_split, expm_stack

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Default ratio of neighbouring depths of the scan grid (decision 0901).
SCAN_RATIO = 1.1
#: Sampled local maxima of ρ at or above this are maximised to look for a narrow band.
HUMP = 0.8


@dataclass(frozen=True)
class _Prepared:
    """Depth-independent parts of :func:`monodromies` for one family.

    ``cut`` marks the steps where some tooth is in the cut (``H`` not zero); on the other
    steps the Van Loan block matrix is the same at every depth (``A = A0``, no delayed
    input), so its exponential ``free_ex`` is computed once per family, not once per depth.
    """

    family: DepthFamily
    BHC: FloatArray  # (m, n, n)
    BH: FloatArray  # (m, J, n, p)
    lags: NDArray[np.int64]
    fr: FloatArray
    C: FloatArray
    g: FloatArray
    cut: NDArray[np.bool_]  # (m,)
    free_ex: FloatArray  # (k, k) exponential of an out-of-cut step's block matrix
    a0_norm: float  # max |A0 h|
    #: dominant multiplier at the depths where ρ was computed exactly (seeds the tracking of
    #: :func:`_branch_root`)
    known_mu: dict[float, complex] = field(default_factory=dict)

    def step_maps(self, w: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(Phi, Wa, Wb)`` of the family at depth ``w`` [m] (:func:`_step_maps`)."""
        fam = self.family
        return _step_maps(
            np.ascontiguousarray(fam.A0), self.BHC, self.BH, self.cut, self.free_ex,
            self.a0_norm, float(w), float(fam.h), self.fr,
        )  # fmt: skip


def _van_loan_free(family: DepthFamily) -> FloatArray:
    """Block matrix of :func:`monodromies` for a step with no delayed input, times ``h``."""
    n = family.A0.shape[0]
    J, p = family.H.shape[1], family.C.shape[0]
    h = family.h
    k = n + 2 * p * J
    big = np.zeros((k, k))
    big[:n, :n] = family.A0 * h
    for j in range(J):
        big[n + j * p : n + (j + 1) * p, n + p * J + j * p : n + p * J + (j + 1) * p] = (
            np.eye(p) * h
        )
    return big


def _prepare(family: DepthFamily) -> _Prepared:
    h = family.h
    splits = [delay_split(float(t), h) for t in family.delays]
    if any(r < 1 for r, _ in splits):
        raise ValueError("every delay must be at least one step h; use more steps per period")
    cut = np.any(family.H != 0.0, axis=(1, 2, 3))
    free = _van_loan_free(family)
    return _Prepared(
        family,
        np.einsum("nd,mde,ek->mnk", family.Bd, family.H.sum(axis=1), family.C),
        np.einsum("nd,mjde->mjne", family.Bd, family.H),
        np.array([r for r, _ in splits], dtype=np.int64),
        np.array([f for _, f in splits]),
        np.ascontiguousarray(family.C),
        np.zeros((family.H.shape[0], family.A0.shape[0])),
        cut,
        expm_stack(free[None])[0] if not cut.all() else free,
        float(np.max(np.abs(family.A0 * h))),
    )


@numba.njit(cache=True)
def _step_maps_into(
    A0: FloatArray,
    BHC: FloatArray,
    BH: FloatArray,
    cut: NDArray[np.bool_],
    free_ex: FloatArray,
    a0_norm: float,
    wk: float,
    h: float,
    fr: FloatArray,
    A: FloatArray,
    Phi: FloatArray,
    Wa: FloatArray,
    Wb: FloatArray,
    big: FloatArray,
    ex: FloatArray,
    tmp: FloatArray,
    escale: FloatArray,
) -> None:  # pragma: no cover - compiled
    """The step maps ``Phi``, ``Wa``, ``Wb`` at depth ``wk``: the arithmetic of ``discretize``
    (``big`` holds the constant ``h I`` blocks of the Van Loan matrix on entry)."""
    m, n = BHC.shape[0], A0.shape[0]
    J, p = BH.shape[1], BH.shape[3]
    free = False
    for i in range(m):
        if not cut[i]:
            free = True
    # block scaling as discretize: the largest |A h| over all steps, |E_j h| per delay
    anorm = 0.0
    for i in range(m):
        if cut[i]:
            for a in range(n):
                for b in range(n):
                    A[i, a, b] = A0[a, b] - wk * BHC[i, a, b]
                    anorm = max(anorm, abs(A[i, a, b] * h))
    if free:
        anorm = max(anorm, a0_norm)
    anorm = max(anorm, 1e-3)
    for j in range(J):
        en = 0.0
        for i in range(m):
            if cut[i]:
                for a in range(n):
                    for b in range(p):
                        en = max(en, abs(wk * BH[i, j, a, b] * h))
        escale[j] = en / anorm if en > anorm else 1.0
    for i in range(m):
        if not cut[i]:
            Phi[i] = free_ex[:n, :n]
            Wa[i] = 0.0
            Wb[i] = 0.0
            continue
        for a in range(n):
            for b in range(n):
                big[a, b] = A[i, a, b] * h
            for j in range(J):
                for b in range(p):
                    big[a, n + j * p + b] = wk * BH[i, j, a, b] * h / escale[j]
        _expm_one(big, ex, tmp)
        Phi[i] = ex[:n, :n]
        for j in range(J):
            for a in range(n):
                for b in range(p):
                    G0 = ex[a, n + j * p + b]
                    G1 = ex[a, n + p * J + j * p + b]
                    Wa[i, j, a, b] = escale[j] * ((1.0 + fr[j]) * G0 - G1 / h)
                    Wb[i, j, a, b] = escale[j] * (G1 / h - fr[j] * G0)


@numba.njit(cache=True)
def _step_maps(
    A0: FloatArray,
    BHC: FloatArray,
    BH: FloatArray,
    cut: NDArray[np.bool_],
    free_ex: FloatArray,
    a0_norm: float,
    wk: float,
    h: float,
    fr: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - compiled
    """``(Phi, Wa, Wb)`` at one depth (:func:`_step_maps_into`)."""
    A, Phi, Wa, Wb, big, ex, tmp, escale = _step_workspace(BHC.shape[0], A0.shape[0], BH, h)
    _step_maps_into(
        A0, BHC, BH, cut, free_ex, a0_norm, wk, h, fr, A, Phi, Wa, Wb, big, ex, tmp, escale,
    )  # fmt: skip
    return Phi, Wa, Wb


@numba.njit(cache=True)
def _step_workspace(
    m: int, n: int, BH: FloatArray, h: float
) -> tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray
]:  # pragma: no cover - compiled
    """Work arrays of :func:`_step_maps_into` for ``m`` steps of ``n`` states: ``A``, ``Phi``,
    ``Wa``, ``Wb``, the Van Loan block matrix with its constant ``h`` entries set, its
    exponential, a scratch matrix and the block scales."""
    J, p = BH.shape[1], BH.shape[3]
    k = n + 2 * p * J
    big = np.zeros((k, k))
    for j in range(J):
        for b in range(p):
            big[n + j * p + b, n + p * J + j * p + b] = h
    return (
        np.empty((m, n, n)), np.empty((m, n, n)), np.zeros((m, J, n, p)),
        np.zeros((m, J, n, p)), big, np.empty((k, k)), np.empty((k, k)), np.empty(J),
    )  # fmt: skip


@numba.njit(cache=True)
def _monodromies_kernel(
    A0: FloatArray,
    BHC: FloatArray,
    BH: FloatArray,
    cut: NDArray[np.bool_],
    free_ex: FloatArray,
    a0_norm: float,
    w: FloatArray,
    h: float,
    fr: FloatArray,
    lags: NDArray[np.int64],
    C: FloatArray,
    g: FloatArray,
) -> FloatArray:  # pragma: no cover - compiled
    """Monodromy matrices (K, N, N): the arithmetic of ``discretize`` + ``monodromy`` per depth."""
    K = w.shape[0]
    n = A0.shape[0]
    J, p = BH.shape[1], C.shape[0]
    R = 0
    for j in range(J):
        R = max(R, lags[j])
    N = n + R * p
    out = np.empty((K, N, N))
    A, Phi, Wa, Wb, big, ex, tmp, escale = _step_workspace(BHC.shape[0], n, BH, h)
    for kk in range(K):
        _step_maps_into(
            A0, BHC, BH, cut, free_ex, a0_norm, w[kk], h, fr, A, Phi, Wa, Wb, big, ex, tmp,
            escale,
        )  # fmt: skip
        out[kk] = _propagate(Phi, Wa, Wb, lags, C, g)[:, :N]
    return out


def monodromies(family: DepthFamily | _Prepared, depths: FloatArray) -> FloatArray:
    """Monodromy matrices (K, N, N) of ``family`` at ``depths`` (K,) [m].

    Same step maps as ``discretize(family.step_means(w))`` for each depth (module docstring),
    bit for bit, in one compiled pass: the matrix exponentials are taken only on the steps in
    the cut, the out-of-cut steps reuse the one exponential of :class:`_Prepared` (the same
    block matrix at every depth), and the block scaling uses the norm over all steps as
    ``discretize`` does.
    """
    prep = family if isinstance(family, _Prepared) else _prepare(family)
    fam = prep.family
    return _monodromies_kernel(
        np.ascontiguousarray(fam.A0),
        prep.BHC,
        prep.BH,
        prep.cut,
        prep.free_ex,
        prep.a0_norm,
        np.ascontiguousarray(np.atleast_1d(np.asarray(depths, dtype=float))),
        float(fam.h),
        prep.fr,
        prep.lags,
        prep.C,
        prep.g,
    )


def deflate(M: FloatArray) -> FloatArray:
    """``M`` (K, N, N) without the indices whose columns are zero in every matrix of the batch.

    A zero column ``j`` (a delayed sample no step uses: its tooth is out of the cut) makes
    ``M`` block lower triangular after moving ``j`` last, ``[[M11, 0], [m21, 0]]``, so the
    eigenvalues of ``M`` are those of ``M11`` (row and column ``j`` removed) plus a zero.
    Repeated until no zero column is left; the non-zero multipliers are unchanged and the
    eigenvalue problem shrinks (about ``n + p m·(cut fraction)`` unknowns).
    """
    return _deflated(M)[0]


def _deflated(M: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
    """:func:`deflate` and the indices of ``M`` it keeps."""
    keep = np.arange(M.shape[1])
    sub = M
    while True:
        nz = np.any(sub != 0.0, axis=(0, 1))
        if nz.all() or not nz.any():
            return (sub, keep) if nz.any() else (sub[:, :0, :0], keep[:0])
        keep = keep[nz]
        sub = M[:, keep][:, :, keep]


def spectral_radii(
    family: DepthFamily | _Prepared, depths: FloatArray
) -> tuple[FloatArray, ComplexArray]:
    """Spectral radius ρ (K,) and dominant multiplier μ (K,) at ``depths`` [m]."""
    w = np.atleast_1d(np.asarray(depths, dtype=float))
    if w.size == 0:
        return np.zeros(0), np.zeros(0, dtype=complex)
    r, mu = _dominant(deflate(monodromies(family, w)))
    if isinstance(family, _Prepared):
        family.known_mu.update(zip(w.tolist(), mu.tolist(), strict=True))
    return r, mu


def _dominant(M: FloatArray) -> tuple[FloatArray, ComplexArray]:
    """ρ and μ of a batch of (deflated) monodromy matrices (one batched eigenvalue call)."""
    if M.shape[1] == 0:
        return np.zeros(M.shape[0]), np.zeros(M.shape[0], dtype=complex)
    ev = np.linalg.eigvals(M)
    idx = np.argmax(np.abs(ev), axis=1)
    mu = ev[np.arange(M.shape[0]), idx].astype(np.complex128)
    return np.abs(mu), mu


#: At most this many squarings (powers ``M^(2^s)``, s <= 14) bound ρ in :func:`radius_bounds`.
BOUND_SQUARINGS = 14
#: Squaring stops once the bounds are this close (relative), about what separates ρ at two
#: neighbouring grid depths.
BOUND_WIDTH = 2e-4
#: Relative widening of every bound before it proves anything (rounding of the powers: the
#: relative error of ``fl(M^k)`` is at most about ``k N ε`` times the growth of the
#: normalised squares, and the ``1/k``-th root divides it by ``k`` again).
BOUND_MARGIN = 1e-5


@numba.njit(cache=True)
def _radius_bounds(
    M: FloatArray,
    below: float,
    above: float,
    width: float,
    squarings: int,
    left_lo: float,
    left_hi: float,
) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    K, N = M.shape[0], M.shape[1]
    lo = np.zeros(K)
    hi = np.full(K, np.inf)
    P = np.empty((N, N))
    Q = np.empty((N, N))  # the buffers of the powers, reused (no allocation per squaring)
    for i in range(K):
        llo, lhi = (left_lo, left_hi) if i == 0 else (lo[i - 1], hi[i - 1])
        P[:, :] = M[i]
        logs = 0.0
        kpow = 1.0
        for s in range(squarings + 1):
            ss = 0.0
            for a in range(N):
                for b in range(N):
                    ss += P[a, b] * P[a, b]
            nrm = np.sqrt(ss)
            if nrm == 0.0:
                hi[i] = 0.0
                break
            tr = 0.0
            for a in range(N):
                tr += P[a, a]
            hi[i] = min(hi[i], np.exp((np.log(nrm) + logs) / kpow))
            if abs(tr) >= 1e-6 * nrm:  # a trace lost in rounding proves nothing
                lo[i] = max(lo[i], np.exp((np.log(abs(tr) / N) + logs) / kpow))
            if hi[i] < below or lo[i] > above or hi[i] - lo[i] <= width * hi[i]:
                break
            # apart from the left neighbour by more than its own width, with a known sign:
            # the next matrix separates itself from this one in turn
            if hi[i] < 1.0 or lo[i] >= 1.0:
                gap = max(lo[i] - lhi, llo - hi[i])
                if gap > 0.0 and hi[i] - lo[i] <= gap:
                    break
            if s == squarings:
                break
            for a in range(N):
                for b in range(N):
                    P[a, b] = P[a, b] / nrm
            np.dot(P, P, Q)
            P, Q = Q, P
            logs = 2.0 * (logs + np.log(nrm))
            kpow *= 2.0
    return lo, hi


def radius_bounds(
    M: FloatArray,
    below: float = 0.0,
    above: float = math.inf,
    width: float = BOUND_WIDTH,
    squarings: int = BOUND_SQUARINGS,
    left: tuple[float, float] = (math.nan, math.nan),
) -> tuple[FloatArray, FloatArray]:
    """Lower and upper bounds (K,) of the spectral radius of ``M`` (K, N, N) by squaring.

    For every ``k``: ``ρ ≤ ||M^k||_F^(1/k)`` (any norm bounds the spectral radius; Gelfand's
    formula makes it tight as k grows) and ``ρ ≥ (|tr M^k| / N)^(1/k)`` (``tr M^k = Σ μ_i^k``
    over the N multipliers); ``k = 1, 2, 4, …, 2^squarings``, each power normalised (its
    scale kept as a logarithm). Squaring stops for a matrix once its upper bound is below
    ``below``, its lower bound above ``above`` or the two within ``width`` (relative), or
    (grid order, ``M[i - 1]`` the left neighbour of ``M[i]``, ``left`` the bounds of the
    one before ``M[0]``) once the sign of ρ − 1 is known and the interval lies apart from
    its left neighbour's by more than its own width. A squaring costs 1/100 (N ≈ 20) to
    1/20 (N ≈ 100) of a nonsymmetric eigenvalue problem. The bounds are as computed (no
    margin for rounding: :data:`BOUND_MARGIN`).
    """
    K = M.shape[0]
    if M.shape[1] == 0:
        return np.zeros(K), np.zeros(K)
    lo, hi = _radius_bounds(
        np.ascontiguousarray(M),
        float(below),
        float(above),
        float(width),
        int(squarings),
        float(left[0]),
        float(left[1]),
    )
    return np.asarray(lo), np.asarray(hi)


def grid_bounds(
    family: DepthFamily | _Prepared,
    depths: FloatArray,
    hump: float,
    left: tuple[float, float] = (math.nan, math.nan),
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Bounds ``lo <= ρ <= hi`` at the grid depths of :func:`unstable_bands`.

    From :func:`radius_bounds`, widened by :data:`BOUND_MARGIN`; where they do not decide
    the sign of ρ − 1, ρ is computed exactly (then ``lo = hi = ρ``). ``left``: the bounds at
    the grid depth before ``depths[0]``. Returns (lo, hi, exact).
    """
    M = deflate(monodromies(family, depths))
    below = hump * (1.0 - BOUND_MARGIN)
    above = (1.0 / hump) * (1.0 + BOUND_MARGIN)
    lo, hi = radius_bounds(M, below, above, left=left)
    lo = lo * (1.0 - BOUND_MARGIN)
    hi = hi * (1.0 + BOUND_MARGIN)
    exact = ~((hi < 1.0) | (lo >= 1.0))  # undecided, or not finite (eigvals then raises)
    if exact.any():
        r, mu = _dominant(M[exact])
        lo[exact] = r
        hi[exact] = r
        if isinstance(family, _Prepared):
            ws = np.atleast_1d(np.asarray(depths, dtype=float))[exact]
            family.known_mu.update(zip(ws.tolist(), mu.tolist(), strict=True))
    return lo, hi, exact


def _humps_and_dips(
    lo: FloatArray, hi: FloatArray, hump: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]:
    """(peak possible, peak proven, dip possible, dip proven) at every interior grid index
    ``1 .. n−2`` at once (element ``i − 1`` is index ``i``).

    A peak is ``R[i] >= R[i±1]`` with ``hump <= R[i] < 1``, a dip ``R[i] <= R[i±1]`` with
    ``1 <= R[i] < 1/hump`` (module docstring, step 3), judged on intervals ``[lo, hi]`` that
    hold ρ; with exact values (``lo = hi``) possible and proven are the plain comparisons.
    """
    c, j, k = slice(1, -1), slice(None, -2), slice(2, None)
    peak_pos = (hi[c] >= hump) & (lo[c] < 1.0) & (hi[c] >= lo[j]) & (hi[c] >= lo[k])
    peak_pro = (lo[c] >= hump) & (hi[c] < 1.0) & (lo[c] >= hi[j]) & (lo[c] >= hi[k])
    dip_pos = (hi[c] >= 1.0) & (lo[c] < 1.0 / hump) & (lo[c] <= hi[j]) & (lo[c] <= hi[k])
    dip_pro = (lo[c] >= 1.0) & (hi[c] < 1.0 / hump) & (hi[c] <= lo[j]) & (hi[c] <= lo[k])
    return peak_pos, peak_pro, dip_pos, dip_pro


@dataclass(frozen=True)
class StructureGain:
    """Largest singular value σ(ω) of the structure's receptance on a frequency grid.

    Attributes
    ----------
    omega : (F,) angular frequencies [rad/s], dense around every damped natural frequency.
    sigma : (F,) largest singular value of ``C (iω − A0)⁻¹ Bd`` [m/N].
    """

    omega: FloatArray
    sigma: FloatArray

    @property
    def peak(self) -> float:
        """||G||∞ [m/N]."""
        return float(self.sigma.max())

    def loop_gain(self, delays: FloatArray) -> float:
        """L2 gain of the LTI part of the regenerative loop per unit of ``w ||H||`` [m/N].

        One delay τ: ``max_ω |1 − e^{−iωτ}| σ(ω)`` (the loop ``G·H(t)·(1 − D)`` is stable
        with its cyclic permutation ``(1 − D)·G·H(t)``, whose LTI part is one transfer
        function); several delays: ``2 ||G||∞``.
        """
        if len(delays) == 1:
            tau = float(delays[0])
            # |1 − e^{−iωτ}| = 2 |sin(ωτ/2)| (a real sine instead of a complex exponential)
            return float(np.max(2.0 * np.abs(np.sin(0.5 * tau * self.omega)) * self.sigma))
        return 2.0 * self.peak


def structure_gain(family: DepthFamily) -> StructureGain:
    """:class:`StructureGain` of a family's structure (``A0``, ``Bd``, ``C``; speed-independent).

    The grid holds the damped natural frequencies of ``A0`` with ±5 % around them in steps of
    0.025 % (light damping puts the peak within ζω of them) and 8000 points up to 3× the
    highest.
    """
    lam = np.linalg.eigvals(family.A0)
    wn = np.unique(np.abs(lam.imag[lam.imag > 0]))
    wmax = float(max(np.max(np.abs(lam)), 1.0))
    grid = np.concatenate(
        [np.linspace(0.0, 3 * wmax, 8000)] + [w * (1 + np.linspace(-0.05, 0.05, 401)) for w in wn]
    )
    grid = np.unique(grid)
    n = family.A0.shape[0]
    s = 1j * grid
    G = family.C @ np.linalg.solve(s[:, None, None] * np.eye(n) - family.A0, family.Bd)
    return StructureGain(grid, np.linalg.svd(G, compute_uv=False)[:, 0])


def structure_peak_gain(family: DepthFamily) -> float:
    """Largest singular value of the structure's receptance over frequency, ||G||∞ [m/N]."""
    return structure_gain(family).peak


def small_gain_depth(family: DepthFamily, peak_gain: float | StructureGain | None = None) -> float:
    """Depth [m] below which the milling DDE is stable by the small-gain theorem.

    The regenerative loop is ``r = G F``, ``F = −w Σ_j H_j(t) [r(t) − r(t − τ_j)]``; it is
    stable when ``w · max_t Σ_j ||H_j(t)|| · γ < 1`` with ``γ`` the gain of the LTI part
    (:meth:`StructureGain.loop_gain`; ``2 ||G||∞`` when only the peak ``peak_gain`` is
    given). The step means of H stand for max_t (they are within one step of it), and the
    scan checks ρ < 1 there anyway.
    """
    sg = structure_gain(family) if peak_gain is None else peak_gain
    gamma = sg.loop_gain(family.delays) if isinstance(sg, StructureGain) else 2.0 * sg
    hn = np.linalg.norm(family.H, ord=2, axis=(-2, -1)).sum(axis=1).max()
    if not (gamma > 0 and hn > 0):
        return math.inf
    return float(1.0 / (gamma * hn))


@dataclass(frozen=True)
class Bands:
    """Unstable depth intervals at one speed and discretisation.

    Attributes
    ----------
    unstable : sorted (start, end) intervals [m]; ``end`` is ``inf`` when the band reaches
        the ceiling of the search.
    multipliers : critical multiplier at each ``start``.
    ceiling : largest depth searched [m].
    evaluations : spectral radii computed.
    """

    unstable: list[tuple[float, float]]
    multipliers: list[complex]
    ceiling: float
    evaluations: int

    @property
    def limit(self) -> float:
        """Lowest unstable depth [m] (inf if none below the ceiling)."""
        return self.unstable[0][0] if self.unstable else math.inf

    def stable_bands(self) -> list[tuple[float, float]]:
        """Stable intervals above the limit, up to the ceiling: [(lo, hi)] [m]."""
        out = []
        for (_, b), (a2, _) in zip(self.unstable[:-1], self.unstable[1:], strict=True):
            out.append((b, a2))
        if self.unstable and math.isfinite(self.unstable[-1][1]):
            out.append((self.unstable[-1][1], self.ceiling))
        return out


class _Scalar:
    """ρ at single depths with a cache (for Brent and the hump maximisation).

    ``branch`` holds multipliers found by :func:`_branch_root` at the ends of its final
    bracket (on the unstable side one of modulus >= 1, on the stable side the dominant one,
    proven): the critical multiplier reported there without an eigenvalue problem; ``tracked``
    counts the multipliers computed by :func:`_rayleigh` instead of an eigenvalue problem.
    """

    def __init__(self, family: DepthFamily | _Prepared) -> None:
        self.family = family if isinstance(family, _Prepared) else _prepare(family)
        self.cache: dict[float, tuple[float, complex]] = {}
        self.branch: dict[float, complex] = {}
        self.tracked = 0

    def __call__(self, w: float) -> float:
        if w not in self.cache:
            r, mu = spectral_radii(self.family, np.array([w]))
            self.cache[w] = (float(r[0]), complex(mu[0]))
        return self.cache[w][0]

    def mu(self, w: float) -> complex:
        if w not in self.cache and w in self.branch:
            return self.branch[w]
        self(w)
        mu = self.cache[w][1]
        if not (math.isfinite(mu.real) and math.isfinite(mu.imag)):
            mu = self.family.known_mu.get(w, mu)
        return mu

    def evaluations(self) -> int:
        """Multipliers computed here: eigenvalue problems and tracked branches."""
        return sum(1 for v in self.cache.values() if np.isfinite(v[1].real)) + self.tracked


#: The root searches follow the critical multiplier by Rayleigh-quotient iteration instead of
#: solving the eigenvalue problem (decision 0912) from this size of the (deflated) monodromy
#: matrix on.
TRACK_MIN_SIZE = 1
#: Up to this size the iteration runs compiled with its own LU (about 6x cheaper than the
#: eigenvalue problem at 22 unknowns); above it LAPACK's LU is faster than the loops.
TRACK_COMPILED_SIZE = 56
#: Up to this size of the structure's state, with one delay of exactly ``m`` steps (uniform
#: pitch), the branch is followed on the n × n characteristic matrix ``μ I − P(μ)`` of the
#: Floquet solution (:func:`_floquet_newton`, O(m n³) per value) instead of the monodromy
#: matrix (O(m² n) to build, O(N³) to factorise).
FLOQUET_MAX_STATE = 4
#: A tracked multiplier is accepted once ``||M v − μ v|| <= TRACK_RESIDUAL ||M||_F``.
TRACK_RESIDUAL = 1e-13


@numba.njit(cache=True)
def _lu_complex(S: ComplexArray, piv: NDArray[np.int64]) -> bool:  # pragma: no cover
    """In-place LU with partial pivoting of a complex matrix; False if a pivot is zero."""
    N = S.shape[0]
    for c in range(N):
        p = c
        big = abs(S[c, c])
        for r in range(c + 1, N):
            a = abs(S[r, c])
            if a > big:
                big = a
                p = r
        piv[c] = p
        if big == 0.0:
            return False
        if p != c:
            for j in range(N):
                t = S[c, j]
                S[c, j] = S[p, j]
                S[p, j] = t
        inv = 1.0 / S[c, c]
        for r in range(c + 1, N):
            f = S[r, c] * inv
            S[r, c] = f
            if f != 0.0:
                for j in range(c + 1, N):
                    S[r, j] -= f * S[c, j]
    return True


@numba.njit(cache=True)
def _lu_solve_complex(
    S: ComplexArray, piv: NDArray[np.int64], b: ComplexArray
) -> ComplexArray:  # pragma: no cover - compiled
    """Solve with the factors of :func:`_lu_complex`."""
    N = S.shape[0]
    x = b.copy()
    for c in range(N):
        p = piv[c]
        if p != c:
            t = x[c]
            x[c] = x[p]
            x[p] = t
    for r in range(N):
        acc = x[r]
        for j in range(r):
            acc -= S[r, j] * x[j]
        x[r] = acc
    for r in range(N - 1, -1, -1):
        acc = x[r]
        for j in range(r + 1, N):
            acc -= S[r, j] * x[j]
        x[r] = acc / S[r, r]
    return x


@numba.njit(cache=True)
def _rayleigh_small(
    M: FloatArray, sigma: complex, v: ComplexArray, tol: float
) -> tuple[bool, complex, ComplexArray]:  # pragma: no cover - compiled
    """:func:`_rayleigh` compiled, with its own LU (no call overhead for small matrices)."""
    N = M.shape[0]
    S = np.empty((N, N), dtype=np.complex128)
    piv = np.empty(N, dtype=np.int64)
    nv = 0.0
    for i in range(N):
        nv += v[i].real ** 2 + v[i].imag ** 2
    v = v / math.sqrt(nv)
    Mv = np.empty(N, dtype=np.complex128)
    mu = sigma
    for _outer in range(4):
        for a in range(N):
            for b in range(N):
                S[a, b] = M[a, b]
            S[a, a] -= sigma
        if not _lu_complex(S, piv):
            return False, mu, v
        prev = np.inf
        for _inner in range(3):
            x = _lu_solve_complex(S, piv, v)
            nx = 0.0
            for i in range(N):
                nx += x[i].real ** 2 + x[i].imag ** 2
            nx = math.sqrt(nx)
            if not (nx > 0.0 and nx < np.inf):
                return False, mu, v
            v = x / nx
            for a in range(N):
                acc = 0j
                for b in range(N):
                    acc += M[a, b] * v[b]
                Mv[a] = acc
            mu = 0j
            for a in range(N):
                mu += np.conj(v[a]) * Mv[a]
            res = 0.0
            for a in range(N):
                d = Mv[a] - mu * v[a]
                res += d.real**2 + d.imag**2
            res = math.sqrt(res)
            if res <= tol:
                return True, mu, v
            if res > 0.1 * prev:
                break
            prev = res
        sigma = mu
    return False, mu, v


def _rayleigh(
    M: FloatArray, sigma: complex, v: ComplexArray | None
) -> tuple[complex, ComplexArray] | None:
    """Eigenpair of ``M`` near ``sigma`` by shifted inverse / Rayleigh-quotient iteration.

    Solves ``(M − σ I) x = v`` with one complex LU factorisation per shift (Golub & Van
    Loan, *Matrix Computations*, 4th ed., §7.6.1 and §8.2.3), the estimate the Rayleigh
    quotient ``μ = vᴴ M v`` of the normalised iterate; the shift moves to ``μ`` when the
    residual stops falling fast. Accepted when ``||M v − μ v|| <= TRACK_RESIDUAL ||M||_F``
    (``μ`` is then an exact multiplier of a matrix within that distance of ``M``, the
    backward error of an eigenvalue solver); None if that is not reached in 4 shifts.
    """
    N = M.shape[0]
    tol = TRACK_RESIDUAL * float(np.sqrt(np.sum(M * M)))
    if v is None or v.shape[0] != N:
        v = np.asarray(np.random.default_rng(0).standard_normal(N), dtype=np.complex128)
    if N <= TRACK_COMPILED_SIZE:
        ok, mu_s, v_s = _rayleigh_small(np.ascontiguousarray(M), complex(sigma), v, tol)
        return (complex(mu_s), v_s) if ok else None
    v = v / np.linalg.norm(v)
    Mc = M.astype(np.complex128)
    diag = np.arange(N)
    for _ in range(4):
        S = Mc.copy()
        S[diag, diag] -= sigma
        lu, piv, info = _ZGETRF(S, overwrite_a=1)
        if info != 0:
            return None
        prev = math.inf
        for _ in range(3):
            x, info = _ZGETRS(lu, piv, v)
            nx = float(np.linalg.norm(x))
            if info != 0 or not (nx > 0 and math.isfinite(nx)):
                return None
            v = x / nx
            Mv = Mc @ v
            mu = complex(np.vdot(v, Mv))
            r = Mv - mu * v
            res = math.sqrt(float(np.vdot(r, r).real))
            if res <= tol:
                return mu, v
            if res > 0.1 * prev:
                break
            prev = res
        sigma = mu
    return None


_ZGETRF, _ZGETRS = scipy.linalg.lapack.get_lapack_funcs(
    ("getrf", "getrs"), (np.zeros(1, dtype=np.complex128),)
)


@numba.njit(cache=True)
def _floquet_map(
    Phi: FloatArray, Wa: FloatArray, Wb: FloatArray, C: FloatArray, mu: complex
) -> tuple[bool, ComplexArray]:  # pragma: no cover - compiled
    """``P(μ) = Π_i (I − Wb_i C / μ)⁻¹ (Φ_i + Wa_i C / μ)`` over the period (one delay of
    exactly ``m`` steps); False if a factor is singular.

    The step maps are those of the first-order semi-discretisation (Insperger & Stépán 2011,
    ch. 3; :mod:`millsense.stability.sdm`): ``x_{i+1} = Φ_i x_i + Wa_i C x_{i−m} +
    Wb_i C x_{i−m+1}``. An eigenvector of the monodromy matrix for ``μ ≠ 0`` is a discrete
    Floquet solution, ``x_{i+m} = μ x_i`` for every ``i``, so ``C x_{i−m} = C x_i / μ`` and
    each step becomes ``(I − Wb_i C/μ) x_{i+1} = (Φ_i + Wa_i C/μ) x_i``: ``μ`` is a multiplier
    exactly when ``μ x_0 = P(μ) x_0`` has a solution ``x_0 ≠ 0``, i.e. ``det(μ I − P(μ)) = 0``.
    """
    m, n = Phi.shape[0], Phi.shape[1]
    p = C.shape[0]
    P = np.zeros((n, n), dtype=np.complex128)
    for a in range(n):
        P[a, a] = 1.0
    L = np.empty((n, n), dtype=np.complex128)
    Q = np.empty((n, n), dtype=np.complex128)
    piv = np.empty(n, dtype=np.int64)
    col = np.empty(n, dtype=np.complex128)
    T = np.empty((n, n), dtype=np.complex128)
    inv = 1.0 / mu
    for i in range(m):
        for a in range(n):
            for b in range(n):
                la = 0.0
                ra = 0.0
                for c in range(p):
                    la += Wb[i, 0, a, c] * C[c, b]
                    ra += Wa[i, 0, a, c] * C[c, b]
                L[a, b] = -la * inv
                Q[a, b] = Phi[i, a, b] + ra * inv
            L[a, a] += 1.0
        if not _lu_complex(L, piv):
            return False, P
        for a in range(n):
            for b in range(n):
                acc = 0j
                for c in range(n):
                    acc += Q[a, c] * P[c, b]
                T[a, b] = acc
        for b in range(n):
            for a in range(n):
                col[a] = T[a, b]
            x = _lu_solve_complex(L, piv, col)
            for a in range(n):
                P[a, b] = x[a]
    return True, P


@numba.njit(cache=True)
def _floquet_det(
    Phi: FloatArray, Wa: FloatArray, Wb: FloatArray, C: FloatArray, mu: complex
) -> tuple[bool, complex]:  # pragma: no cover - compiled
    """``det(μ I − P(μ))`` (:func:`_floquet_map`); False if ``P(μ)`` does not exist."""
    ok, P = _floquet_map(Phi, Wa, Wb, C, mu)
    if not ok:
        return False, 0j
    n = P.shape[0]
    S = -P
    for a in range(n):
        S[a, a] += mu
    piv = np.empty(n, dtype=np.int64)
    if not _lu_complex(S, piv):
        return True, 0j
    d = 1.0 + 0j
    for a in range(n):
        d *= S[a, a]
        if piv[a] != a:
            d = -d
    return True, d


@numba.njit(cache=True)
def _floquet_newton(
    Phi: FloatArray, Wa: FloatArray, Wb: FloatArray, C: FloatArray, sigma: complex
) -> tuple[bool, complex]:  # pragma: no cover - compiled
    """The multiplier near ``sigma`` as a root of ``det(μ I − P(μ))`` by the secant method
    (from ``σ`` and ``σ (1 + 1e-7)``); converged when the step is below ``1e-14 |μ|``."""
    x0 = sigma
    ok, f0 = _floquet_det(Phi, Wa, Wb, C, x0)
    if not ok:
        return False, x0
    if f0 == 0:
        return True, x0
    x1 = sigma * (1.0 + 1e-7)
    for _ in range(40):
        ok, f1 = _floquet_det(Phi, Wa, Wb, C, x1)
        if not ok:
            return False, x1
        if f1 == 0:
            return True, x1
        if f1 == f0:
            return False, x1
        step = f1 * (x1 - x0) / (f1 - f0)
        x0, f0 = x1, f1
        x1 = x1 - step
        if not (abs(x1) > 0.0 and abs(x1) < np.inf):
            return False, x1
        if abs(step) <= 1e-14 * abs(x1):
            return True, x1
    return False, x1


@numba.njit(cache=True)
def _floquet_vector(
    Phi: FloatArray, Wa: FloatArray, Wb: FloatArray, C: FloatArray, mu: complex
) -> tuple[ComplexArray, float]:  # pragma: no cover - compiled
    """Eigenvector ``y = [x_0, C x_{-1}, …, C x_{-m}]`` of the monodromy matrix ``M`` for the
    multiplier ``μ`` (``C x_{-k} = C x_{m−k} / μ`` along the Floquet solution through the null
    vector ``x_0`` of ``μ I − P(μ)``), and the residual ``||M y − μ y||``.

    The history rows of ``M y − μ y`` vanish by construction; its state rows are
    ``(I − Wb_{m−1} C/μ)(x_m − μ x_0)`` (the last step reads ``C x_0`` where the Floquet
    solution has ``C x_m / μ``), so the residual needs no ``M``."""
    m, n = Phi.shape[0], Phi.shape[1]
    p = C.shape[0]
    _, P = _floquet_map(Phi, Wa, Wb, C, mu)
    S = -P
    for a in range(n):
        S[a, a] += mu
    _, _, vh = np.linalg.svd(S)
    x = np.conj(vh[n - 1])
    out = np.empty(n + m * p, dtype=np.complex128)
    out[:n] = x
    L = np.empty((n, n), dtype=np.complex128)
    piv = np.empty(n, dtype=np.int64)
    inv = 1.0 / mu
    for i in range(m):
        for c in range(p):  # C x_i / μ is the sample of lag m − i
            acc = 0j
            for b in range(n):
                acc += C[c, b] * x[b]
            out[n + (m - i - 1) * p + c] = acc * inv
        rhs = np.zeros(n, dtype=np.complex128)
        for a in range(n):
            acc = 0j
            for b in range(n):
                la = 0.0
                ra = 0.0
                for c in range(p):
                    la += Wb[i, 0, a, c] * C[c, b]
                    ra += Wa[i, 0, a, c] * C[c, b]
                L[a, b] = -la * inv
                acc += (Phi[i, a, b] + ra * inv) * x[b]
            L[a, a] += 1.0
            rhs[a] = acc
        _lu_complex(L, piv)
        x = _lu_solve_complex(L, piv, rhs)
    r = x - mu * out[:n]
    res = 0.0
    for a in range(n):
        acc = r[a]
        for b in range(n):
            la = 0.0
            for c in range(p):
                la += Wb[m - 1, 0, a, c] * C[c, b]
            acc -= la * inv * r[b]
        res += acc.real**2 + acc.imag**2
    return out, np.sqrt(res)


class _Lost(Exception):
    """The tracked multiplier could not be computed (the caller solves exactly instead)."""


def _stable_beyond(M: FloatArray, mu: complex, v: ComplexArray) -> bool:
    """True if ``μ`` is proven dominant and so ρ(M) = |μ| < 1, for an eigenpair ``(μ, v)``.

    The real invariant subspace of ``μ`` (``v``, and ``v̄`` for a complex μ) is rotated to the
    first coordinates by an orthogonal ``Q``: ``Qᵀ M Q = [[T11, T12], [E, T22]]`` with ``E``
    of the order of the eigenpair's residual. The other multipliers are those of ``T22``
    (within the backward error ``||E||`` that an eigenvalue solver also allows), bounded
    above by :func:`radius_bounds` (``||T22^k||^(1/k)``, widened by
    :data:`BOUND_MARGIN`). False whenever that does not prove every one of them below
    ``|μ|`` (the caller then solves the eigenvalue problem).
    """
    if not abs(mu) < 1.0:
        return False
    N = M.shape[0]
    if abs(mu.imag) > REAL_TOL * abs(mu):
        basis = np.stack([v.real, v.imag], axis=1)
    else:
        k = int(np.argmax(np.abs(v)))
        vr = (v * (np.conj(v[k]) / abs(v[k]))).real
        basis = vr[:, None]
    d = basis.shape[1]
    if N <= d + 1:
        return False
    Q, R = np.linalg.qr(basis, mode="complete")
    if abs(R[d - 1, d - 1]) <= 1e-8 * abs(R[0, 0]):
        return False
    T = Q.T @ M @ Q
    nm = float(np.sqrt(np.sum(M * M)))
    if float(np.sqrt(np.sum(T[d:, :d] ** 2))) > 1e3 * TRACK_RESIDUAL * nm:
        return False
    below = abs(mu) / (1.0 + BOUND_MARGIN)
    _, hi = radius_bounds(np.ascontiguousarray(T[None, d:, d:]), below=below, above=math.inf)
    return bool(hi[0] * (1.0 + BOUND_MARGIN) < abs(mu))


#: |Im μ| / |μ| below this makes a tracked multiplier real in :func:`_stable_beyond`.
REAL_TOL = 1e-9


def _with(
    pair: tuple[FloatArray, ComplexArray], mu: complex
) -> tuple[FloatArray, complex, ComplexArray]:
    """``(M, μ, v)`` for :func:`_stable_beyond` from a ``(M, v)`` pair."""
    return pair[0], mu, pair[1]


class _Branch:
    """``|μ(w)| − 1`` of one multiplier branch, followed from depth to depth
    (:func:`_floquet_newton` where ``floquet``, else :func:`_rayleigh`; module docstring).

    Where ``f`` already holds ρ exactly, that value stands in (at the bracket ends of a scan:
    ρ ≥ |μ|, so the sign is that of the branch on the unstable side and of ρ − 1 on the
    stable one). ``values`` maps every depth asked to (modulus, multiplier, exact).
    """

    def __init__(self, f: _Scalar, mu: complex) -> None:
        self.f = f
        self.sigma = mu
        self.v: ComplexArray | None = None
        self.values: dict[float, tuple[float, complex, bool]] = {}
        self.pairs: dict[float, tuple[FloatArray, ComplexArray]] = {}
        self.full: dict[float, tuple[FloatArray, NDArray[np.int64]]] = {}
        prep = f.family
        self.floquet = (
            prep.family.A0.shape[0] <= FLOQUET_MAX_STATE
            and prep.lags.size == 1
            and int(prep.lags[0]) == prep.BHC.shape[0]
        )
        self.maps: dict[float, tuple[FloatArray, FloatArray, FloatArray]] = {}
        self.fvec: dict[float, ComplexArray] = {}

    def __call__(self, w: float) -> float:
        if w not in self.values:
            if w in self.f.cache:
                r, mu = self.f.cache[w]
                self.values[w] = (r, mu, True)
            elif self.floquet:
                prep = self.f.family
                maps = prep.step_maps(w)
                ok, mu = _floquet_newton(maps[0], maps[1], maps[2], prep.C, complex(self.sigma))
                if not ok:
                    raise _Lost
                self.f.tracked += 1
                self.sigma = mu
                self.values[w] = (abs(mu), mu, False)
                self.maps[w] = maps
            else:
                full = monodromies(self.f.family, np.array([w]))
                Md, keep = _deflated(full)
                M = Md[0]
                got = _rayleigh(M, self.sigma, self.v)
                if got is None:
                    raise _Lost
                self.f.tracked += 1
                self.sigma, self.v = got
                self.values[w] = (abs(got[0]), got[0], False)
                self.pairs[w] = (M, got[1])
                self.full[w] = (full[0], keep)
        return self.values[w][0] - 1.0

    def verified(self, x: float, rtol: float, xtol: float) -> bool:
        """True if ρ − 1 provably changes sign between ``x`` and an evaluated depth within
        Brent's final bracket (``xtol + rtol |x|``): the depth on the stable side gets ρ
        exactly (one eigenvalue problem) unless :func:`_stable_beyond` proves the tracked
        multiplier dominant there first, the one on the unstable side has a multiplier of
        modulus >= 1 (tracked or exact); the tracked multipliers are recorded (``f.branch``)."""
        side = self.values[x][0] >= 1.0
        other = [w for w, v in self.values.items() if (v[0] >= 1.0) != side]
        if not other:
            return False
        y = min(other, key=lambda w: abs(w - x))
        if abs(y - x) > 2.0 * (xtol + rtol * abs(x)):
            return False
        stable, unstable = (y, x) if side else (x, y)
        if not self.values[stable][2]:
            mu_s = self.values[stable][1]
            if self._pair(stable) and _stable_beyond(*_with(self.pairs[stable], mu_s)):
                self.f.branch[stable] = mu_s  # the dominant multiplier
            elif self.f(stable) >= 1.0:
                return False
        if not self.values[unstable][2]:
            ok = self._floquet_checked(unstable) if unstable in self.maps else True
            if not ok:
                return False
            self.f.branch[unstable] = self.values[unstable][1]
        return True

    def _floquet_checked(self, w: float) -> bool:
        """The Floquet eigenvector at ``w`` in ``fvec`` if ``||M y − μ y|| <= TRACK_RESIDUAL
        |μ| ||y||`` (:func:`_floquet_vector`; ``|μ| <= ||M||_F``, so this is at least as strict
        as the Rayleigh-quotient criterion)."""
        if w in self.fvec:
            return True
        mu = self.values[w][1]
        Phi, Wa, Wb = self.maps[w]
        yv, res = _floquet_vector(Phi, Wa, Wb, self.f.family.C, mu)
        ny = float(np.linalg.norm(yv))
        if not (ny > 0 and math.isfinite(ny) and res <= TRACK_RESIDUAL * abs(mu) * ny):
            return False
        self.fvec[w] = yv
        return True

    def _pair(self, w: float) -> bool:
        """The deflated monodromy matrix and the tracked eigenvector at ``w`` in ``pairs``.

        Rayleigh-quotient tracking has them already; a multiplier of :func:`_floquet_newton`
        gets its eigenvector from the Floquet solution (:func:`_floquet_vector`), accepted
        when ``||M v − μ v|| <= TRACK_RESIDUAL ||M||_F`` on the monodromy matrix itself
        (so it is a multiplier of the discretisation as an eigenvalue solver would give it).
        """
        if w in self.pairs:
            return True
        if w not in self.maps or not self._floquet_checked(w):
            return False
        mu = self.values[w][1]
        yv = self.fvec[w]
        full = monodromies(self.f.family, np.array([w]))
        Md, keep = _deflated(full)
        M = Md[0]
        v = yv[keep]
        nv = float(np.linalg.norm(v))
        if not (nv > 0 and math.isfinite(nv)):
            return False
        v = v / nv
        res = float(np.linalg.norm(M @ v - mu * v))
        if not res <= TRACK_RESIDUAL * float(np.sqrt(np.sum(M * M))):
            return False
        self.pairs[w] = (M, v)
        self.full[w] = (full[0], keep)
        return True

    def full_vector(self, w: float) -> ComplexArray | None:
        """Eigenvector of the full (undeflated) monodromy matrix for the tracked multiplier
        at ``w``: the kept part is the tracked one; the removed indices ``R`` (their columns
        vanish outside ``R``, :func:`deflate`) follow from ``(μ I − M_RR) v_R = M_RK v_K``."""
        if w in self.maps:
            return self.fvec[w] if self._floquet_checked(w) else None
        if w not in self.values or not self._pair(w):
            return None
        Mf, keep = self.full[w]
        mu, v = self.values[w][1], self.pairs[w][1]
        out = np.zeros(Mf.shape[0], dtype=np.complex128)
        out[keep] = v
        rem = np.setdiff1d(np.arange(Mf.shape[0]), keep)
        if rem.size:
            try:
                out[rem] = np.linalg.solve(
                    mu * np.eye(rem.size) - Mf[np.ix_(rem, rem)], Mf[np.ix_(rem, keep)] @ v
                )
            except np.linalg.LinAlgError:
                return None
        return out


def _branch_root(f: _Scalar, a: float, b: float, rtol: float, unstable_end: float) -> float:
    """A crossing ρ = 1 in ``[a, b]`` (ρ − 1 of opposite signs at the ends) to ``rtol``.

    Brent's method on the branch of the multiplier that is dominant at ``unstable_end`` (the
    end where ρ >= 1), each value from the previous one (:class:`_Branch`) instead of an
    eigenvalue problem, then verified exactly (:meth:`_Branch.verified`); Brent's method on
    ρ itself when the branch is lost, the verification fails or the matrix is small
    (:data:`TRACK_MIN_SIZE`). Either way the result lies within ``rtol`` of a depth where ρ − 1
    changes sign.
    """
    xtol = 1e-13

    def exact() -> float:
        return float(scipy.optimize.brentq(lambda x: f(x) - 1.0, a, b, rtol=rtol, xtol=xtol))

    seed = f.mu(unstable_end) if unstable_end in f.cache else complex("nan")
    if not (math.isfinite(seed.real) and math.isfinite(seed.imag)) or abs(seed) < 1.0:
        return exact()
    if _tracked_size(f) < TRACK_MIN_SIZE:
        return exact()
    br = _Branch(f, seed)
    try:
        x = float(scipy.optimize.brentq(br, a, b, rtol=rtol, xtol=xtol))
    except _Lost:
        return exact()
    return x if br.verified(x, rtol, xtol) else exact()


def _tracked_size(f: _Scalar) -> int:
    """Size of the deflated monodromy matrix of ``f``'s family (columns never used removed)."""
    prep = f.family
    fam = prep.family
    n, p = fam.A0.shape[0], fam.C.shape[0]
    return n + p * int(prep.lags.max()) if prep.cut.all() else n + p * int(prep.cut.sum()) + p


def _golden_probe(f: _Scalar, a: float, x: float, b: float, sign: float) -> float:
    """Golden-section search for max ρ (sign −1) or min ρ (sign +1) in (a, b) around x.

    Stops as soon as ρ crosses 1 (the band or island is then proven) or the bracket is
    below 1e-3 of the depth.
    """
    g = 0.381966011250105
    fx = sign * f(x)
    while b - a > 1e-3 * a:
        if (sign < 0 and -fx >= 1.0) or (sign > 0 and fx < 1.0):
            break
        u = x + g * (b - x) if (b - x) > (x - a) else x - g * (x - a)
        fu = sign * f(u)
        if fu < fx:
            if u > x:
                a = x
            else:
                b = x
            x, fx = u, fu
        elif u > x:
            b = u
        else:
            a = u
    return x


def unstable_bands(
    family: DepthFamily,
    w_start: float,
    ceiling: float,
    ratio: float = SCAN_RATIO,
    hump: float = HUMP,
    rtol: float = 1e-4,
    stop_after_first: float = math.inf,
    floor: float = 1e-9,
) -> Bands:
    """Unstable depth bands of ``family`` between ``w_start`` and ``ceiling`` [m] (module doc).

    Parameters
    ----------
    family : the DDE at one speed.
    w_start : first depth of the grid [m] (e.g. :func:`small_gain_depth`); if it is unstable
        the grid is extended downwards until a stable depth or ``floor``.
    ceiling : largest depth searched [m].
    ratio : grid ratio q > 1.
    hump : sampled local maxima of ρ in ``[hump, 1)`` are maximised to look for a narrow band.
    rtol : relative tolerance of the band edges.
    stop_after_first : once the lowest band is found at depth ``w``, search only up to
        ``min(ceiling, stop_after_first · w)`` (the bands worth reporting lie near the limit).
    floor : smallest depth considered [m].
    """
    f = _Scalar(family)
    family = f.family  # type: ignore[assignment]
    ceiling = float(ceiling)
    lo = min(float(w_start), ceiling)
    count_batch = 0
    # extend downwards while the first depth is unstable
    r0, mu0 = spectral_radii(family, np.array([lo]))
    count_batch += 1
    while r0[0] >= 1.0:
        lo /= ratio**4
        if lo < floor:
            return Bands([(0.0, math.inf)], [complex(mu0[0])], ceiling, count_batch)
        r0, mu0 = spectral_radii(family, np.array([lo]))
        count_batch += 1
    ws = [lo]
    los = [float(r0[0])]
    his = [float(r0[0])]
    exact = [True]
    top = ceiling
    chunk = 8
    while ws[-1] < top:
        k = np.arange(1, chunk + 1)
        new = np.minimum(ws[-1] * ratio**k, top)
        new = new[np.concatenate([[True], np.diff(new) > 0])]
        lo_b, hi_b, ex = grid_bounds(family, new, hump, (los[-1], his[-1]))
        count_batch += new.size
        ws.extend(float(v) for v in new)
        los.extend(float(v) for v in lo_b)
        his.extend(float(v) for v in hi_b)
        exact.extend(bool(v) for v in ex)
        if math.isfinite(stop_after_first) and top == ceiling:
            hit = np.flatnonzero(np.asarray(los) >= 1.0)  # the sign of ρ − 1 is decided
            if hit.size:
                top = min(ceiling, stop_after_first * ws[int(hit[0])])
                keep = np.asarray(ws) <= top
                if not keep.all():
                    ws = [w for w, kk in zip(ws, keep, strict=True) if kk]
                    los = [v for v, kk in zip(los, keep, strict=True) if kk]
                    his = [v for v, kk in zip(his, keep, strict=True) if kk]
                    exact = [v for v, kk in zip(exact, keep, strict=True) if kk]
                    if ws[-1] < top:
                        r, _ = spectral_radii(family, np.array([top]))
                        count_batch += 1
                        ws.append(top)
                        los.append(float(r[0]))
                        his.append(float(r[0]))
                        exact.append(True)
    W = np.asarray(ws)
    L = np.asarray(los)
    H = np.asarray(his)
    # the sampled humps and dips need ρ where the bounds do not decide them, and Brent the
    # values at both ends of a sign change: computed in one batch; every decision is then
    # that of exact values (grid_bounds)
    unst = L >= 1.0
    need = np.zeros(W.size, dtype=bool)
    change = np.flatnonzero(unst[:-1] != unst[1:])
    need[change] = True
    need[change + 1] = True
    pp, pr, dp, dr = _humps_and_dips(L, H, hump)
    for i in np.flatnonzero((pp & ~pr) | (dp & ~dr)).tolist():
        need[i : i + 3] = True  # grid index i + 1 and its neighbours
    need &= ~np.asarray(exact)
    if need.any():
        r, _ = spectral_radii(family, W[need])
        L[need] = r
        H[need] = r
        exact = list(np.asarray(exact) | need)
    for w, r, ex_ in zip(W, L, exact, strict=True):
        if ex_:  # bounds stand in for ρ only in the grid decisions, never for Brent
            f.cache.setdefault(float(w), (float(r), complex("nan")))
    edges: list[tuple[float, int]] = []  # (depth, +1 entering instability / -1 leaving)

    def root(a: float, b: float, unstable_end: float) -> float:
        return _branch_root(f, a, b, rtol, unstable_end)

    for c in change.tolist():
        a, b = float(W[c]), float(W[c + 1])
        edges.append((root(a, b, b if unst[c + 1] else a), 1 if unst[c + 1] else -1))
    # narrow humps (bands) and dips (islands) between grid depths
    _, peaks, _, dips = _humps_and_dips(L, H, hump)
    for j in np.flatnonzero(peaks | dips).tolist():
        sign = -1.0 if peaks[j] else 1.0
        i = j + 1  # grid index
        a, b = float(W[i - 1]), float(W[i + 1])
        x = _golden_probe(f, a, float(W[i]), b, sign)
        fx = f(x)
        if (sign < 0 and fx >= 1.0) or (sign > 0 and fx < 1.0):
            e1, e2 = root(a, x, x if sign < 0 else a), root(x, b, x if sign < 0 else b)
            kind = 1 if sign < 0 else -1
            edges.extend([(e1, kind), (e2, -kind)])
    edges.sort()
    unstable: list[tuple[float, float]] = []
    mults: list[complex] = []
    start: float | None = None
    for w, kind in edges:
        if kind > 0 and start is None:
            start = w
        elif kind < 0 and start is not None:
            unstable.append((start, w))
            mults.append(f.mu(start))
            start = None
    if start is not None:
        unstable.append((start, math.inf))
        mults.append(f.mu(start))
    return Bands(unstable, mults, float(W[-1]), count_batch + f.evaluations())


def near_root(
    family: DepthFamily,
    guess: float,
    rtol: float = 2e-4,
    lo: float = 0.975,
    hi: float = 0.999,
    mu_guess: complex | None = None,
    vector_out: list[ComplexArray] | None = None,
) -> tuple[float, complex, int]:
    """Crossing ρ = 1 of ``family`` near ``guess`` [m]: (depth, multiplier, evaluations).

    For a finer discretisation of a boundary already found by :func:`unstable_bands`
    (first-order SDM converges from above, so the bracket starts at ``[lo, hi]·guess`` and
    widens geometrically on whichever side the crossing lies). It does not look for other
    crossings far below the guess: the scan at the coarser discretisation did.

    ``mu_guess``: the critical multiplier of the coarser discretisation at ``guess``. The
    bracket and Brent's method then follow that multiplier's branch (:class:`_Branch`,
    decision 0912), and the final bracket is verified exactly
    as in :func:`_branch_root` (ρ < 1 by an eigenvalue problem on the stable side, a
    multiplier of modulus >= 1 on the unstable one); if the branch is lost or the check
    fails, the search is repeated on ρ itself. ``vector_out``: receives the eigenvector of
    the returned multiplier in the full discrete state when the branch gave it.
    """
    f = _Scalar(family)
    if (
        mu_guess is not None
        and math.isfinite(mu_guess.real)
        and math.isfinite(mu_guess.imag)
        and _tracked_size(f) >= TRACK_MIN_SIZE
    ):
        br = _Branch(f, mu_guess)
        try:
            got = _near_root_on(br, guess, rtol, lo, hi)
        except _Lost:
            got = None
        if got is not None and br.verified(got, rtol, 1e-13):
            mu = f.mu(got)
            if vector_out is not None and mu == br.values[got][1]:
                vec = br.full_vector(got)
                if vec is not None:
                    vector_out.append(vec)
            return got, mu, f.evaluations()
    got = _near_root_on(lambda x: f(x) - 1.0, guess, rtol, lo, hi)
    if got is None:
        return math.nan, complex("nan"), f.evaluations()
    return got, f.mu(got), f.evaluations()


def _near_root_on(
    g: Callable[[float], float], guess: float, rtol: float, lo: float, hi: float
) -> float | None:
    """The bracket search and Brent's method of :func:`near_root` on ``g`` (ρ − 1 or a
    branch's ``|μ| − 1``); None if no bracket is found in 60 widenings."""
    a, b = guess * lo, guess * hi
    ra = g(a)
    # g(b) only matters when g(a) < 0: otherwise the bracket moves below a at once
    rb = g(b) if ra < 0.0 else math.nan
    step = 1.03
    for _ in range(60):
        if ra < 0.0 <= rb:
            break
        if ra >= 0.0:
            b, rb = a, ra
            a = a / step
            ra = g(a)
        else:
            a, ra = b, rb
            b = b * step
            rb = g(b)
        step = min(step * 1.5, 2.0)
    else:
        return None
    return float(scipy.optimize.brentq(g, a, b, rtol=rtol, xtol=1e-13))
