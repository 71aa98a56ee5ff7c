"""Spectral radius of a depth family at many depths at once, and the unstable bands in depth.

Batched evaluation
------------------
:func:`spectral_radii` computes the monodromy matrices of one speed at ``K`` depths in one
pass: the Van Loan block matrices of all ``K·m`` steps go through one compiled matrix
exponential, the ``K`` products of the step maps through one compiled loop, and the ``K``
eigenvalue problems through one batched LAPACK call. The arithmetic is that of
:func:`millsense.stability.sdm.discretize` and :func:`~millsense.stability.sdm.monodromy`
(first-order semi-discretisation, Insperger & Stépán 2011 ch. 3); only the Python overhead per
depth is gone.

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
from dataclasses import dataclass

import numba
import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from millsense.stability.milling import DepthFamily
from millsense.stability.sdm import _propagate, delay_split, expm_stack

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Default ratio of neighbouring depths of the scan grid (decision 0901).
SCAN_RATIO = 1.1
#: Sampled local maxima of ρ at or above this are maximised to look for a narrow band.
HUMP = 0.8


@numba.njit(cache=True)
def _propagate_batch(
    Phi: FloatArray,
    Wa: FloatArray,
    Wb: FloatArray,
    lags: NDArray[np.int64],
    C: FloatArray,
    g: FloatArray,
) -> FloatArray:  # pragma: no cover - compiled
    """Monodromy matrices (K, N, N) of K step-map sets (K, m, ...)."""
    K = Phi.shape[0]
    first = _propagate(Phi[0], Wa[0], Wb[0], lags, C, g)
    N = first.shape[0]
    out = np.empty((K, N, N))
    out[0] = first[:, :N]
    for k in range(1, K):
        out[k] = _propagate(Phi[k], Wa[k], Wb[k], lags, C, g)[:, :N]
    return out


@dataclass(frozen=True)
class _Prepared:
    """Depth-independent parts of :func:`monodromies` for one family."""

    family: DepthFamily
    BHC: FloatArray  # (m, n, n)
    BH: FloatArray  # (m, J, n, p)
    lags: NDArray[np.int64]
    fr: FloatArray
    C: FloatArray
    g: FloatArray


def _prepare(family: DepthFamily) -> _Prepared:
    h = family.h
    splits = [delay_split(float(t), h) for t in family.delays]
    if any(r < 1 for r, _ in splits):
        raise ValueError("every delay must be at least one step h; use more steps per period")
    return _Prepared(
        family,
        np.einsum("nd,mde,ek->mnk", family.Bd, family.H.sum(axis=1), family.C),
        np.einsum("nd,mjde->mjne", family.Bd, family.H),
        np.array([r for r, _ in splits], dtype=np.int64),
        np.array([f for _, f in splits]),
        np.ascontiguousarray(family.C),
        np.zeros((family.H.shape[0], family.A0.shape[0])),
    )


def monodromies(family: DepthFamily | _Prepared, depths: FloatArray) -> FloatArray:
    """Monodromy matrices (K, N, N) of ``family`` at ``depths`` (K,) [m].

    Same step maps as ``discretize(family.step_means(w))`` for each depth (module docstring).
    """
    prep = family if isinstance(family, _Prepared) else _prepare(family)
    fam = prep.family
    w = np.asarray(depths, dtype=float)
    K = w.size
    m, J = fam.H.shape[0], fam.H.shape[1]
    n = fam.A0.shape[0]
    p = fam.C.shape[0]
    h = fam.h
    k = n + 2 * p * J
    big = np.zeros((K, m, k, k))
    A = fam.A0[None, None] - w[:, None, None, None] * prep.BHC[None]  # (K, m, n, n)
    big[:, :, :n, :n] = A * h
    anorm = np.maximum(np.max(np.abs(A * h), axis=(1, 2, 3)), 1e-3)  # (K,)
    escale = np.ones((K, J))
    for j in range(J):
        Ej = w[:, None, None, None] * prep.BH[None, :, j] * h  # (K, m, n, p)
        en = np.max(np.abs(Ej), axis=(1, 2, 3))
        escale[:, j] = np.where(en > anorm, en / anorm, 1.0)
        big[:, :, :n, n + j * p : n + (j + 1) * p] = Ej / escale[:, j, None, None, None]
        big[:, :, n + j * p : n + (j + 1) * p, n + p * J + j * p : n + p * J + (j + 1) * p] = (
            np.eye(p) * h
        )
    ex = expm_stack(big.reshape(K * m, k, k)).reshape(K, m, k, k)
    Phi = np.ascontiguousarray(ex[:, :, :n, :n])
    Wa = np.empty((K, m, J, n, p))
    Wb = np.empty((K, m, J, n, p))
    for j in range(J):
        G0 = ex[:, :, :n, n + j * p : n + (j + 1) * p]
        G1 = ex[:, :, :n, n + p * J + j * p : n + p * J + (j + 1) * p]
        sc = escale[:, j, None, None, None]
        Wa[:, :, j] = sc * ((1.0 + prep.fr[j]) * G0 - G1 / h)
        Wb[:, :, j] = sc * (G1 / h - prep.fr[j] * G0)
    return _propagate_batch(Phi, Wa, Wb, prep.lags, prep.C, prep.g)


def spectral_radii(
    family: DepthFamily | _Prepared, depths: FloatArray
) -> tuple[FloatArray, ComplexArray]:
    """Spectral radius ρ (K,) and dominant multiplier μ (K,) at ``depths`` [m]."""
    w = np.atleast_1d(np.asarray(depths, dtype=float))
    if w.size == 0:
        return np.zeros(0), np.zeros(0, dtype=complex)
    ev = np.linalg.eigvals(monodromies(family, w))
    idx = np.argmax(np.abs(ev), axis=1)
    mu = ev[np.arange(w.size), idx].astype(np.complex128)
    return np.abs(mu), mu


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
            return float(np.max(np.abs(1.0 - np.exp(-1j * self.omega * tau)) * self.sigma))
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
    """ρ at single depths with a cache (for Brent and the hump maximisation)."""

    def __init__(self, family: DepthFamily | _Prepared) -> None:
        self.family = family if isinstance(family, _Prepared) else _prepare(family)
        self.cache: dict[float, tuple[float, complex]] = {}

    def __call__(self, w: float) -> float:
        if w not in self.cache:
            r, mu = spectral_radii(self.family, np.array([w]))
            self.cache[w] = (float(r[0]), complex(mu[0]))
        return self.cache[w][0]

    def mu(self, w: float) -> complex:
        self(w)
        return self.cache[w][1]


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
    rs = [float(r0[0])]
    top = ceiling
    chunk = 8
    while ws[-1] < top:
        k = np.arange(1, chunk + 1)
        new = np.minimum(ws[-1] * ratio**k, top)
        new = new[np.concatenate([[True], np.diff(new) > 0])]
        r, _ = spectral_radii(family, new)
        count_batch += new.size
        ws.extend(float(v) for v in new)
        rs.extend(float(v) for v in r)
        if math.isfinite(stop_after_first) and top == ceiling:
            hit = np.flatnonzero(np.asarray(rs) >= 1.0)
            if hit.size:
                top = min(ceiling, stop_after_first * ws[int(hit[0])])
                keep = np.asarray(ws) <= top
                if not keep.all():
                    ws = [w for w, kk in zip(ws, keep, strict=True) if kk]
                    rs = [v for v, kk in zip(rs, keep, strict=True) if kk]
                    if ws[-1] < top:
                        r, _ = spectral_radii(family, np.array([top]))
                        count_batch += 1
                        ws.append(top)
                        rs.append(float(r[0]))
    W = np.asarray(ws)
    R = np.asarray(rs)
    for w, r in zip(W, R, strict=True):
        f.cache.setdefault(float(w), (float(r), complex("nan")))
    edges: list[tuple[float, int]] = []  # (depth, +1 entering instability / -1 leaving)

    def root(a: float, b: float) -> float:
        return float(scipy.optimize.brentq(lambda x: f(x) - 1.0, a, b, rtol=rtol, xtol=1e-13))

    for i in range(len(W) - 1):
        a_unst, b_unst = R[i] >= 1.0, R[i + 1] >= 1.0
        if a_unst != b_unst:
            edges.append((root(W[i], W[i + 1]), 1 if b_unst else -1))
    # narrow humps (bands) and dips (islands) between grid depths
    for i in range(1, len(W) - 1):
        peak = R[i] >= R[i - 1] and R[i] >= R[i + 1]
        dip = R[i] <= R[i - 1] and R[i] <= R[i + 1]
        if peak and hump <= R[i] < 1.0:
            sign = -1.0
        elif dip and 1.0 <= R[i] < 1.0 / hump:
            sign = 1.0
        else:
            continue
        a, b = float(W[i - 1]), float(W[i + 1])
        x = _golden_probe(f, a, float(W[i]), b, sign)
        fx = f(x)
        if (sign < 0 and fx >= 1.0) or (sign > 0 and fx < 1.0):
            e1, e2 = root(a, x), root(x, b)
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
    evals = count_batch + sum(1 for v in f.cache.values() if np.isfinite(v[1].real))
    return Bands(unstable, mults, float(W[-1]), evals)


def near_root(
    family: DepthFamily, guess: float, rtol: float = 2e-4, lo: float = 0.975, hi: float = 0.999
) -> tuple[float, complex, int]:
    """Crossing ρ = 1 of ``family`` near ``guess`` [m]: (depth, multiplier, evaluations).

    For a finer discretisation of a boundary already found by :func:`unstable_bands`
    (first-order SDM converges from above, so the bracket starts at ``[lo, hi]·guess`` and
    widens geometrically on whichever side the crossing lies). It does not look for other
    crossings far below the guess: the scan at the coarser discretisation did.
    """
    f = _Scalar(family)
    a, b = guess * lo, guess * hi
    ra, rb = f(a), f(b)
    step = 1.03
    for _ in range(60):
        if ra < 1.0 <= rb:
            break
        if ra >= 1.0:
            b, rb = a, ra
            a = a / step
            ra = f(a)
        else:
            a, ra = b, rb
            b = b * step
            rb = f(b)
        step = min(step * 1.5, 2.0)
    else:
        return math.nan, complex("nan"), len(f.cache)
    w = float(scipy.optimize.brentq(lambda x: f(x) - 1.0, a, b, rtol=rtol, xtol=1e-13))
    return w, f.mu(w), len(f.cache)
