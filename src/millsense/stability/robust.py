"""Robust SDM lobe diagram: the lowest unstable depth at every speed, bands, refined minima.

Per speed (:func:`solve_speed`, issue 14):

1. **Scan** (:func:`millsense.stability.scan.unstable_bands`): ρ on a geometric depth grid
   (ratio 1.08) from the small-gain depth upwards, every sign change refined by Brent, narrow
   humps of ρ maximised. The lowest crossing is the limit, whatever the lobe structure; the
   stable bands (islands) between unstable bands up to ``bands_up_to`` × the limit are kept.
   No continuation in speed decides anything: the previous speed only sizes ``m``
   (decision 0901).
2. **Steps per cycle**: ``m`` is raised to ``steps_per_cycle`` steps per cycle of the chatter
   vibration (sized from the previous speed, checked at this one; if raised, the scan is
   repeated from 0.85 × the limit at the new ``m``).
3. **Adaptive Richardson** (decision 0902): depths ``w₁`` at ``m`` and ``w₂`` at ``2m``
   (first-order SDM converges as O(m⁻²), benchmarks.md §1), ``w* = w₂ + (w₂ − w₁)/3``; the
   correction ``|w₂ − w*| / w*`` estimates the error of ``w₂`` and bounds that of ``w*`` in
   the asymptotic range. While it exceeds ``tol``, ``m`` is doubled (up to ``m_max``). The
   depth reported is ``min(w*, w₂)`` (never above a depth the finer discretisation calls
   unstable) and its ``tolerance`` is the last correction.
4. **Chatter frequency from the critical eigenvector** (decision 0903): the multiplier μ
   gives the frequency only modulo the period frequency f_T (``f = arg μ/(2πT) + l f_T``);
   the eigenvector of μ holds the tool-tip displacement over one delay, and the harmonic
   ``l`` carrying most of its energy is the branch reported.

The chart (:func:`robust_lobes`) then refines every local minimum of the depth over speed on
nested grids (5× finer each level) down to 1 rev/min (decision 0904), so the reported
minimum does not depend on the user's speed step.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from millsense.stability.lobes import LobeResult, chatter_frequency
from millsense.stability.milling import DepthFamily
from millsense.stability.scan import (
    Bands,
    StructureGain,
    monodromies,
    near_root,
    small_gain_depth,
    structure_gain,
    unstable_bands,
)
from millsense.stability.sdm import classify_multiplier

FloatArray = NDArray[np.float64]
FamilyAt = Callable[[float, int], DepthFamily]

#: Default relative tolerance of the reported depths (estimated error bound, decision 0902).
TOLERANCE = 0.01
#: Stable islands are searched up to this multiple of the limit in a chart (all of
#: ``depth_max`` for a single speed).
BANDS_UP_TO = 3.0


def _eigenvector(M: FloatArray, mu: complex) -> NDArray[np.complex128] | None:
    """Eigenvector of ``M`` for its known eigenvalue ``mu`` by inverse iteration.

    Two solves with ``M − σ I``, ``σ = μ (1 + 1e-10)`` (Golub & Van Loan, *Matrix
    Computations*, 4th ed., §7.6.1): the component of any other eigenvalue ``λ`` shrinks by
    ``(|σ − μ| / |λ − σ|)²`` — one LU factorisation instead of a full eigendecomposition.
    Returns None if the solve fails (the caller then uses ``numpy.linalg.eig``).
    """
    N = M.shape[0]
    sigma = mu * (1.0 + 1e-10) if mu != 0 else 1e-300
    b = np.asarray(np.random.default_rng(0).standard_normal(N), dtype=np.complex128)
    try:
        lu = scipy.linalg.lu_factor(M - sigma * np.eye(N), check_finite=False)
    except (ValueError, np.linalg.LinAlgError):
        return None
    v = b
    for _ in range(2):
        v = scipy.linalg.lu_solve(lu, v / np.linalg.norm(v), check_finite=False)
        if not np.all(np.isfinite(v)) or not np.any(v):
            return None
    return np.asarray(v / np.linalg.norm(v), dtype=np.complex128)


def eigen_chatter_frequency(
    family: DepthFamily,
    depth: float,
    f_max: float,
    mu: complex | None = None,
    vector: NDArray[np.complex128] | None = None,
) -> float:
    """Chatter frequency [Hz] from the critical eigenvector of the monodromy matrix.

    The discrete state is ``[x_0, C x_{-1}, ..., C x_{-R}]``: the eigenvector of the dominant
    multiplier μ holds the tool-tip displacement ``d(t_k)``, ``t_k = −k h``, of the Floquet
    solution ``d(t) = Σ_l c_l exp(i 2π (f₀ + l/T) t)``, ``f₀ = arg μ / (2π T)``. The power of
    each harmonic ``l`` is the squared projection of ``d`` on ``exp(i 2π (f₀ + l/T) t_k)``
    (orthogonal over one period for uniform pitch); powers of ``±f`` are added (a real
    vibration) and the frequency of most power up to ``f_max`` is returned.

    ``mu``: the dominant multiplier at ``depth`` if already known (the root search computed
    it); its eigenvector then comes from inverse iteration (:func:`_eigenvector`).
    ``vector``: that eigenvector if the root search already has it (the branch it followed,
    decision 0912); then no monodromy matrix is built here.
    """
    if not (0 < depth < math.inf):
        return math.nan
    vv = None
    usable = mu is not None and math.isfinite(mu.real) and math.isfinite(mu.imag)
    if usable and vector is not None and np.all(np.isfinite(vector)) and np.any(vector):
        vv = np.asarray(vector / np.linalg.norm(vector), dtype=np.complex128)
    else:
        M = monodromies(family, np.array([depth]))[0]
        if usable:
            assert mu is not None
            vv = _eigenvector(M, complex(mu))
    if vv is None:
        M = monodromies(family, np.array([depth]))[0]
        ev, vec = np.linalg.eig(M)
        i = int(np.argmax(np.abs(ev)))
        mu, vv = complex(ev[i]), vec[:, i]
    assert mu is not None
    v = vv
    n, p = family.A0.shape[0], family.C.shape[0]
    R = (v.size - n) // p
    d = np.empty((R + 1, p), dtype=complex)
    d[0] = family.C @ v[:n]
    d[1:] = v[n:].reshape(R, p)
    d = d[:-1] if R >= 1 else d  # R samples over one delay (one period for uniform pitch)
    t = -np.arange(d.shape[0]) * family.h
    T = family.period
    fT = 1.0 / T
    f0 = math.atan2(mu.imag, mu.real) / (2 * math.pi) * fT
    lmax = int(f_max / fT) + 2
    ls = np.arange(-lmax, lmax + 1)
    f = f0 + ls * fT
    # remove the growth/decay over the window (|μ| ≈ 1 at the limit; exact for any |μ|)
    growth = np.exp(math.log(max(abs(mu), 1e-300)) / T * t)
    basis = np.exp(2j * np.pi * f[:, None] * t[None, :]) * growth[None, :]
    coef = basis.conj() @ d  # (L, p)
    power = np.sum(np.abs(coef) ** 2, axis=1)
    fa = np.round(np.abs(f), 9)
    keep = (fa > 0) & (fa <= f_max + fT)
    uniq = np.unique(fa[keep])
    tot = np.array([power[keep][fa[keep] == u].sum() for u in uniq])
    return float(uniq[int(np.argmax(tot))])


@dataclass(frozen=True)
class SpeedSolution:
    """Stability at one spindle speed.

    Attributes
    ----------
    rpm : spindle speed [rev/min].
    depth : lowest unstable depth [m]; inf when stable up to ``ceiling``, 0 when unstable at
        the floor.
    multiplier : critical multiplier.
    bifurcation : ``"hopf"``, ``"flip"``, ``"fold"`` or ``"none"``.
    chatter_hz : chatter frequency [Hz] (critical eigenvector).
    tolerance : estimated relative error bound of ``depth`` (NaN without extrapolation).
    steps : SDM steps per tooth period of the finest discretisation used.
    bands : unstable depth bands [m] at ``steps`` (the first starts near ``depth``).
    ceiling : largest depth searched [m].
    evaluations : spectral radii computed.
    """

    rpm: float
    depth: float
    multiplier: complex
    bifurcation: str
    chatter_hz: float
    tolerance: float
    steps: int
    bands: list[tuple[float, float]]
    ceiling: float
    evaluations: int

    def stable_bands(self) -> list[tuple[float, float]]:
        """Stable intervals [m] above the limit up to the searched ceiling (islands)."""
        b = Bands(self.bands, [], self.ceiling, 0)
        return b.stable_bands()


def compliance_of(family: DepthFamily) -> Callable[[FloatArray], FloatArray]:
    """Largest receptance magnitude of the family's structure at frequencies [Hz]."""

    def comp(f: FloatArray) -> FloatArray:
        s = 2j * np.pi * np.atleast_1d(np.asarray(f, dtype=float))
        n = family.A0.shape[0]
        G = family.C @ np.linalg.solve(s[:, None, None] * np.eye(n) - family.A0, family.Bd)
        return np.asarray(np.abs(G).max(axis=(-2, -1)))

    return comp


def _cycle_steps(m: int, f_hz: float, family: DepthFamily, steps_per_cycle: float) -> int:
    """``m`` raised so that a cycle of ``f_hz`` spans at least ``steps_per_cycle`` steps."""
    if steps_per_cycle <= 0 or not math.isfinite(f_hz):
        return m
    need = f_hz * family.h * steps_per_cycle
    return math.ceil(m * need) if need > 1.1 else m


def solve_speed(
    family_at: FamilyAt,
    rpm: float,
    f_max: float,
    steps_per_period: int,
    depth_max: float,
    peak_gain: float | StructureGain,
    steps_per_cycle: float = 10.0,
    extrapolate: bool = True,
    tol: float = TOLERANCE,
    m_max: int = 160,
    bands_up_to: float = BANDS_UP_TO,
    prev_chatter_hz: float = math.nan,
    rtol: float = 2e-4,
) -> SpeedSolution:
    """Lowest unstable depth, bands and chatter frequency at one speed (module docstring).

    Parameters
    ----------
    family_at : ``(rpm, m) -> DepthFamily``.
    rpm : spindle speed [rev/min].
    f_max : highest chatter frequency considered [Hz].
    steps_per_period : SDM steps per tooth period m (at least).
    depth_max : largest depth searched [m].
    peak_gain : the structure's gain (:func:`~millsense.stability.scan.structure_gain`), or
        its peak receptance [m/N] (then the small-gain depth uses ``2 ||G||∞``).
    steps_per_cycle : at least this many steps per chatter cycle (0 disables).
    extrapolate : Richardson extrapolation with adaptive m.
    tol : tolerance of the extrapolated depth (estimated relative error bound).
    m_max : largest m of the adaptive refinement.
    bands_up_to : islands are searched up to this multiple of the limit (inf: ``depth_max``).
    prev_chatter_hz : chatter frequency at a neighbouring speed (sizes m before the scan).
    rtol : relative tolerance of the root searches.
    """
    evals = 0
    m = steps_per_period
    fam = family_at(rpm, m)
    m = _cycle_steps(m, prev_chatter_hz, fam, steps_per_cycle)
    if m != steps_per_period:
        fam = family_at(rpm, m)
    w0 = small_gain_depth(fam, peak_gain)
    bands = unstable_bands(fam, w0, depth_max, stop_after_first=bands_up_to, rtol=1.5 * rtol)
    evals += bands.evaluations
    w1 = bands.limit
    if not (0 < w1 < math.inf):
        kind = "none"
        return SpeedSolution(
            rpm, w1, complex("nan"), kind, math.nan, 0.0, m, bands.unstable, bands.ceiling, evals
        )
    # sizing m needs only the order of the chatter frequency: the cheap branch of largest
    # receptance (the eigenvector decides the reported frequency at the end)
    f1 = chatter_frequency(bands.multipliers[0], fam.period, compliance_of(fam), f_max)
    m_new = _cycle_steps(m, f1, fam, steps_per_cycle)
    if m_new != m:
        m = m_new
        fam = family_at(rpm, m)
        bands = unstable_bands(fam, 0.85 * w1, depth_max, stop_after_first=bands_up_to, rtol=rtol)
        evals += bands.evaluations
        if not (0 < bands.limit < math.inf):
            return SpeedSolution(
                rpm,
                bands.limit,
                complex("nan"),
                "none",
                math.nan,
                0.0,
                m,
                bands.unstable,
                bands.ceiling,
                evals,
            )
        w1 = bands.limit
    mu = bands.multipliers[0]
    depth, tolerance, steps, fam_final, root = w1, math.nan, m, fam, w1
    vector: NDArray[np.complex128] | None = None
    if extrapolate:
        islands = len(bands.unstable) > 1
        while True:
            m2 = 2 * m
            fam2 = family_at(rpm, m2)
            got_vector: list[NDArray[np.complex128]] = []
            if islands:
                b2 = unstable_bands(
                    fam2, 0.9 * w1, depth_max, stop_after_first=bands_up_to, rtol=rtol
                )
                evals += b2.evaluations
                w2 = b2.limit
                mu2 = b2.multipliers[0] if b2.multipliers else complex("nan")
            else:
                w2, mu2, count = near_root(fam2, w1, rtol, mu_guess=mu, vector_out=got_vector)
                evals += count
            if not (0 < w2 < math.inf):
                break
            ext = w2 + (w2 - w1) / 3.0
            tolerance = abs(w2 - ext) / ext
            depth, steps, fam_final, root, mu = min(ext, w2), m2, fam2, w2, mu2
            vector = got_vector[0] if got_vector else None
            if islands:
                bands = b2
            if tolerance <= tol or 2 * m2 > m_max:
                break
            m, w1 = m2, w2
    f_c = eigen_chatter_frequency(fam_final, root, f_max, mu, vector)
    unst = [(depth, bands.unstable[0][1]), *bands.unstable[1:]] if bands.unstable else []
    return SpeedSolution(
        rpm,
        depth,
        mu,
        classify_multiplier(mu),
        f_c,
        tolerance,
        steps,
        unst,
        bands.ceiling,
        evals,
    )


@dataclass(frozen=True)
class LobeMinimum:
    """A local minimum of the lobe diagram refined over speed.

    Attributes
    ----------
    rpm : speed of the minimum [rev/min] (to ``step`` rev/min).
    depth : critical depth there [m].
    bifurcation : type at the minimum.
    chatter_hz : chatter frequency [Hz].
    step : final speed resolution [rev/min].
    """

    rpm: float
    depth: float
    bifurcation: str
    chatter_hz: float
    step: float


@dataclass(frozen=True)
class RobustLobeResult(LobeResult):
    """A :class:`LobeResult` with the bands, tolerances and refined minima of issue 14.

    Attributes (besides :class:`LobeResult`'s)
    ------------------------------------------
    solutions : per speed :class:`SpeedSolution`.
    minima : refined local minima, lowest first.
    """

    solutions: list[SpeedSolution] = field(default_factory=list)
    minima: list[LobeMinimum] = field(default_factory=list)

    @property
    def min_depth_m(self) -> float:
        if self.minima:
            return min(self.minima[0].depth, float(np.nanmin(self.critical_depth_m)))
        return float(self.critical_depth_m[self.min_index])

    @property
    def min_depth_rpm(self) -> float:
        if self.minima and self.minima[0].depth <= float(np.nanmin(self.critical_depth_m)):
            return self.minima[0].rpm
        return float(self.rpm[self.min_index])


def _local_minima(d: FloatArray) -> list[int]:
    """Indices of local minima of a finite-valued sequence (plateaus give their first index)."""
    out = []
    n = d.size
    for i in range(n):
        if not np.isfinite(d[i]) or d[i] <= 0:
            continue
        left = d[i - 1] if i > 0 else np.inf
        right = d[i + 1] if i < n - 1 else np.inf
        left = np.inf if not np.isfinite(left) else left
        right = np.inf if not np.isfinite(right) else right
        if d[i] < left and d[i] <= right:
            out.append(i)
    return out


def refine_minimum(
    solve: Callable[[float], SpeedSolution],
    rpm: FloatArray,
    sols: list[SpeedSolution],
    i: int,
    finest: float = 1.0,
    factor: float = 5.0,
) -> LobeMinimum:
    """Refine the local minimum at index ``i`` on nested grids down to ``finest`` rev/min.

    Each level evaluates the grid of spacing ``s/factor`` between the neighbours of the best
    speed found so far (``s`` the current spacing); a narrow lobe between two grid speeds of
    the chart is met there as long as it shows as a local minimum of the coarser level.
    """
    best = sols[i]
    lo_n = float(rpm[max(i - 1, 0)])
    hi_n = float(rpm[min(i + 1, rpm.size - 1)])
    spacing = max(float(rpm[i]) - lo_n, hi_n - float(rpm[i]), finest)
    known: dict[float, SpeedSolution] = {float(rpm[i]): best}
    r_min, r_max = float(rpm.min()), float(rpm.max())
    while spacing > finest:
        spacing = max(spacing / factor, finest)
        centre = best.rpm
        grid = centre + spacing * np.arange(-(factor - 1), factor)
        grid = grid[(grid >= max(lo_n, r_min)) & (grid <= min(hi_n, r_max))]
        for n in grid:
            key = round(float(n), 6)
            if key not in known:
                known[key] = solve(float(n))
            s = known[key]
            if 0 < s.depth < best.depth:
                best = s
        lo_n, hi_n = best.rpm - spacing, best.rpm + spacing
    return LobeMinimum(best.rpm, best.depth, best.bifurcation, best.chatter_hz, spacing)


def robust_lobes(
    family_at: FamilyAt,
    rpm: Sequence[float] | FloatArray,
    f_max: float,
    steps_per_period: int = 20,
    depth_max: float = 0.05,
    steps_per_cycle: float = 10.0,
    extrapolate: bool = True,
    tol: float = TOLERANCE,
    m_max: int = 160,
    bands_up_to: float = BANDS_UP_TO,
    refine_minima: bool = True,
    finest_rpm: float = 1.0,
    progress: Callable[[int], None] | None = None,
) -> RobustLobeResult:
    """Robust SDM lobe diagram (module docstring); parameters as :func:`solve_speed`.

    ``refine_minima`` refines every local minimum down to ``finest_rpm`` rev/min (needs at
    least two speeds); ``bands_up_to`` = inf searches islands up to ``depth_max``.
    """
    speeds = np.asarray(rpm, dtype=float)
    gain = structure_gain(family_at(float(speeds[0]), steps_per_period))
    prev_f = math.nan

    def solve(n: float, pf: float, bands: float) -> SpeedSolution:
        return solve_speed(
            family_at,
            n,
            f_max,
            steps_per_period,
            depth_max,
            gain,
            steps_per_cycle,
            extrapolate,
            tol,
            m_max,
            bands,
            pf,
        )

    sols: list[SpeedSolution] = []
    for i, n in enumerate(speeds):
        s = solve(float(n), prev_f, bands_up_to)
        sols.append(s)
        if math.isfinite(s.chatter_hz):
            prev_f = s.chatter_hz
        if progress is not None:
            progress(i)
    depth = np.array([s.depth for s in sols])
    minima: list[LobeMinimum] = []
    if refine_minima and speeds.size > 1:
        for i in _local_minima(depth):
            pf = sols[i].chatter_hz

            def one(n: float, pf: float = pf) -> SpeedSolution:
                return solve(n, pf, 1.0)

            minima.append(refine_minimum(one, speeds, sols, i, finest_rpm))
        minima.sort(key=lambda mn: mn.depth)
    evals = sum(s.evaluations for s in sols)
    return RobustLobeResult(
        speeds,
        depth,
        np.array([s.chatter_hz for s in sols]),
        [s.bifurcation for s in sols],
        evals,
        solutions=sols,
        minima=minima,
    )
