"""Stability lobes: critical depth, chatter frequency and bifurcation type per spindle speed.

SDM lobes find, at each speed, the smallest depth where the spectral radius of the monodromy
matrix reaches 1 by a ROOT SEARCH (bracket, then Brent), not by a grid scan:

1. at the first speed, start at ``depth_start`` and step UP geometrically (factor ``growth``,
   default 1.25) until ρ ≥ 1 or ``depth_max`` (stepping DOWN first if the start is unstable);
   then Brent's method on ρ(w) − 1 in the last bracket;
2. at the next speeds (continuation), predict the depth g from the last two speeds, probe
   ρ(0.85 g): if unstable, do the full search of 1. from below the probe; otherwise bracket
   in g(1 ± 3 %) (moved along the secant of ρ if the root is not inside) and apply Brent.

ρ(w) need not be monotonic in w (at low immersion flip and Hopf lobes cross; stable islands
exist above the boundary), so the answer is the first crossing met by the upward search: an unstable
band lying wholly below the probe's depth (85 % of the prediction) and not containing the
probe could be missed. Neighbouring speeds share the lower envelope, which is continuous
except where a new lobe dips in, so this is rarely an issue on a fine speed grid; lower
``growth`` or ``depth_start`` for a more careful search.

Chatter frequency from the critical multiplier μ (period T of the DDE, f_T = 1/T)::

    f_c = ± f_T arg(μ) / (2π) + k f_T,    k integer,

an infinite family (the monodromy matrix cannot tell them apart); the branch reported is the
positive one where the structure's receptance is largest (the vibration that grows is the one
the structure amplifies most; with one mode that is the branch nearest the mode). For a
flip, arg μ = π and f_c = f_T/2 + k f_T.

Richardson extrapolation: first-order SDM converges as O(m⁻²) (benchmarks.md §1), so with
depths w₁ at m and w₂ at 2m the extrapolated depth is ``w₂ + (w₂ − w₁)/3``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from millsense.stability.milling import DepthFamily
from millsense.stability.sdm import classify_multiplier, discretize, monodromy, multipliers

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CriticalPoint:
    """Stability boundary at one speed.

    Attributes
    ----------
    depth : critical depth [m] (inf if stable up to ``depth_max``, 0 if unstable at the floor).
    multiplier : critical multiplier μ (|μ| ≈ 1).
    bifurcation : ``"hopf"``, ``"flip"``, ``"fold"`` or ``"none"``.
    evaluations : spectral radii computed.
    """

    depth: float
    multiplier: complex
    bifurcation: str
    evaluations: int


def dominant_multiplier(family: DepthFamily, depth: float) -> complex:
    """Largest-modulus multiplier of ``family`` at ``depth`` [m]."""
    return complex(multipliers(monodromy(discretize(family.step_means(depth))))[0])


def critical_depth(
    family: DepthFamily,
    depth_start: float,
    depth_max: float,
    depth_floor: float = 1e-7,
    growth: float = 1.25,
    rtol: float = 1e-4,
) -> CriticalPoint:
    """Smallest depth where the spectral radius reaches 1 (module docstring for the search).

    Parameters
    ----------
    family : the DDE at one speed (:func:`millsense.stability.milling.milling_dde`).
    depth_start : first depth tried [m].
    depth_max : give up above this depth [m] (returns inf).
    depth_floor : give up below this depth [m] (returns 0).
    growth : geometric bracketing factor (> 1).
    rtol : relative tolerance of the Brent search on the depth.
    """
    count = 0

    def rho(w: float) -> float:
        nonlocal count
        count += 1
        return abs(dominant_multiplier(family, w))

    lo = max(depth_start, depth_floor)
    r_lo = rho(lo)
    while r_lo >= 1.0:
        lo /= growth
        if lo < depth_floor:
            return CriticalPoint(0.0, complex("nan"), "none", count)
        r_lo = rho(lo)
    hi = lo
    while True:
        hi = min(hi * growth, depth_max)
        if rho(hi) >= 1.0:
            break
        if hi >= depth_max:
            return CriticalPoint(math.inf, complex("nan"), "none", count)
        lo = hi
    root = scipy.optimize.brentq(lambda w: rho(w) - 1.0, lo, hi, rtol=rtol, xtol=1e-12)
    mu = dominant_multiplier(family, root)
    return CriticalPoint(float(root), mu, classify_multiplier(mu), count)


class _Rho:
    """Spectral radius of a depth family with a cache of the multipliers evaluated."""

    def __init__(self, family: DepthFamily) -> None:
        self.family = family
        self.mu: dict[float, complex] = {}

    def __call__(self, w: float) -> float:
        if w not in self.mu:
            self.mu[w] = dominant_multiplier(self.family, w)
        return abs(self.mu[w])

    def point(self, root: float) -> CriticalPoint:
        mu = self.mu[root] if root in self.mu else dominant_multiplier(self.family, root)
        return CriticalPoint(float(root), mu, classify_multiplier(mu), len(self.mu))


def critical_depth_near(
    family: DepthFamily,
    guess: float,
    depth_max: float,
    halfwidth: float = 0.004,
    rtol: float = 3e-4,
    max_step: float = 1.5,
) -> CriticalPoint:
    """Critical depth known to lie near ``guess`` [m]: secant-guided bracket, then Brent.

    Evaluates ρ at ``guess (1 ± halfwidth)``; while the pair does not bracket ρ = 1 it moves
    the pair towards the secant prediction of the crossing (1 % beyond it, at most a factor
    ``max_step`` per move). Used where the boundary is predicted (continuation in speed, a
    second discretisation); it does not look for another crossing far below the guess.
    """
    rho = _Rho(family)
    a, b = guess * (1 - halfwidth), guess * (1 + halfwidth)
    ra, rb = rho(a), rho(b)
    for _ in range(40):
        if ra < 1.0 <= rb:
            root = scipy.optimize.brentq(lambda w: rho(w) - 1.0, a, b, rtol=rtol, xtol=1e-12)
            return rho.point(root)
        slope = (rb - ra) / (b - a)
        pred = a + (1.0 - ra) / slope if slope > 0 else math.nan
        if ra >= 1.0:  # crossing below a
            w = pred * 0.99 if np.isfinite(pred) else a / max_step
            w = min(max(w, a / max_step), a / 1.005)
            b, rb = a, ra
            a, ra = w, rho(w)
            if a < 1e-9:
                return CriticalPoint(0.0, complex("nan"), "none", len(rho.mu))
        else:  # crossing above b
            w = pred * 1.01 if np.isfinite(pred) else b * max_step
            w = max(min(w, b * max_step), b * 1.005)
            if b >= depth_max:
                return CriticalPoint(math.inf, complex("nan"), "none", len(rho.mu))
            a, ra = b, rb
            b, rb = min(w, depth_max), rho(min(w, depth_max))
    return critical_depth(family, guess / 2, depth_max, rtol=rtol)


def chatter_frequency(
    mu: complex, period: float, compliance: Callable[[FloatArray], FloatArray], f_max: float
) -> float:
    """Chatter frequency [Hz] from the critical multiplier (module docstring).

    Parameters
    ----------
    mu : critical multiplier.
    period : principal period T of the DDE [s].
    compliance : structural receptance magnitude [m/N] at given frequencies [Hz]; the
        branch ``± f_T arg(μ)/2π + k f_T`` where the structure is most compliant is chosen.
    f_max : highest frequency considered [Hz].
    """
    if not np.isfinite(mu.real):
        return math.nan
    fT = 1.0 / period
    base = abs(math.atan2(mu.imag, mu.real)) / (2 * math.pi) * fT
    k = np.arange(0, int(f_max / fT) + 2)
    cands = np.concatenate([base + k * fT, -base + k * fT])
    cands = cands[(cands > 0) & (cands <= f_max + fT)]
    return float(cands[np.argmax(compliance(cands))])


@dataclass(frozen=True)
class LobeResult:
    """A lobe diagram.

    Attributes
    ----------
    rpm : spindle speeds [rev/min].
    critical_depth_m : critical axial depth [m].
    chatter_hz : chatter frequency [Hz].
    bifurcation : per speed ``"hopf"``, ``"flip"``, ``"fold"`` or ``"none"``.
    evaluations : spectral radii computed (cost measure).
    """

    rpm: FloatArray
    critical_depth_m: FloatArray
    chatter_hz: FloatArray
    bifurcation: list[str]
    evaluations: int = 0

    @property
    def min_index(self) -> int:
        return int(np.nanargmin(self.critical_depth_m))

    @property
    def min_depth_m(self) -> float:
        return float(self.critical_depth_m[self.min_index])

    @property
    def min_depth_rpm(self) -> float:
        return float(self.rpm[self.min_index])


def sdm_lobes(
    family_at: Callable[[float, int], DepthFamily],
    rpm: Sequence[float] | FloatArray,
    compliance: Callable[[FloatArray], FloatArray],
    f_max: float,
    steps_per_period: int = 20,
    depth_max: float = 0.05,
    depth_start: float = 1e-5,
    extrapolate: bool = False,
    progress: Callable[[int], None] | None = None,
    steps_per_cycle: float = 0.0,
    rtol: float = 3e-4,
    refine: float = 2.0,
) -> LobeResult:
    """SDM lobe diagram: root search of the critical depth at every speed.

    Parameters
    ----------
    family_at : ``(rpm, steps_per_period) -> DepthFamily`` (e.g. a partial of
        :func:`millsense.stability.milling.milling_dde`).
    rpm : spindle speeds [rev/min].
    compliance : structural receptance magnitude [m/N] at frequencies [Hz], picks the
        chatter-frequency branch (:func:`chatter_frequency`), e.g.
        ``lambda f: np.abs(structure.frf(f)).max(axis=(-2, -1))``.
    f_max : highest chatter frequency considered [Hz] (e.g. twice the highest mode).
    steps_per_period : SDM steps per period m.
    depth_max : largest depth searched [m].
    depth_start : first depth tried at the first speed [m].
    extrapolate : also solve at ``2m`` (bracket seeded by the ``m`` result) and return the
        Richardson-extrapolated depth ``w₂ + (w₂ − w₁)/3`` (O(m⁻²) convergence).
    progress : called with the index of each finished speed.
    steps_per_cycle : also use at least this many steps per cycle of the chatter vibration
        found at ``m`` (:func:`chatter_frequency`): at low speeds a period holds many vibration
        cycles, and at large depths the cutting stiffness raises the vibration frequency, and a
        fixed ``m`` per period is then too coarse for the Richardson extrapolation to be in its
        asymptotic range. When the first solution at ``m`` violates it, ``m`` is raised and the
        speed solved again. 0 disables.
    rtol : relative tolerance of each root search (the extrapolated depth carries about
        twice this).
    refine : ratio of the second discretisation to the first (``m2 = ceil(refine m)``);
        the extrapolation is ``w₂ + (w₂ − w₁)/((m₂/m)² − 1)``.
    """
    speeds = np.asarray(rpm, dtype=float)
    depth = np.full(speeds.shape, np.nan)
    freq = np.full(speeds.shape, np.nan)
    kinds: list[str] = []
    evals = 0
    prev = math.nan
    trend = 1.0
    prev_f = math.nan  # chatter frequency at the previous speed [Hz]
    ratio = 0.985  # w(2m) / w(m) at the previous speed
    for i, n in enumerate(speeds):
        m = steps_per_period
        fam = family_at(float(n), m)
        if steps_per_cycle > 0 and np.isfinite(prev_f) and prev_f * fam.h * steps_per_cycle > 1.0:
            # neighbouring speeds chatter at similar frequencies: size m from the last one
            m = math.ceil(m * steps_per_cycle * prev_f * fam.h)
            fam = family_at(float(n), m)
        if np.isfinite(prev) and prev > 0:
            # continuation: predict from the last two speeds, probe 15 % below the prediction
            # for a lower crossing, then refine in a ±3 % bracket
            guess = prev * trend
            probe = 0.85 * guess
            evals += 1
            if abs(dominant_multiplier(fam, probe)) >= 1.0:
                cp = critical_depth(fam, probe / 1.25, depth_max, rtol=3 * rtol)
            else:
                cp = critical_depth_near(fam, guess, depth_max, 0.03, 3 * rtol)
        else:
            cp = critical_depth(fam, depth_start, depth_max, rtol=3 * rtol)
        evals += cp.evaluations
        if steps_per_cycle > 0 and 0 < cp.depth < math.inf:
            f_eff = chatter_frequency(cp.multiplier, fam.period, compliance, f_max)
            if f_eff * fam.h * steps_per_cycle > 1.1:
                m = math.ceil(m * steps_per_cycle * f_eff * fam.h)
                fam = family_at(float(n), m)
                cp = critical_depth_near(fam, 0.99 * cp.depth, depth_max, 0.02, rtol)
                evals += cp.evaluations
        if extrapolate and 0 < cp.depth < math.inf:
            m2 = math.ceil(refine * m)
            fam2 = family_at(float(n), m2)
            cp2 = critical_depth_near(fam2, ratio * cp.depth, depth_max, rtol=rtol)
            evals += cp2.evaluations
            if 0 < cp2.depth < math.inf:
                ratio = cp2.depth / cp.depth
                w = cp2.depth + (cp2.depth - cp.depth) / ((m2 / m) ** 2 - 1.0)
                cp = CriticalPoint(w, cp2.multiplier, cp2.bifurcation, cp.evaluations)
                fam = fam2
        depth[i] = cp.depth
        freq[i] = chatter_frequency(cp.multiplier, fam.period, compliance, f_max)
        kinds.append(cp.bifurcation)
        if 0 < cp.depth < math.inf:
            trend = float(np.clip(cp.depth / prev, 0.85, 1.2)) if np.isfinite(prev) else 1.0
            prev = cp.depth
        else:
            trend = 1.0
        if progress is not None:
            progress(i)
    return LobeResult(speeds, depth, freq, kinds, evals)
