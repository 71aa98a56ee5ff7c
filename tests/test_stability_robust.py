"""Robust SDM lobes (issue 14): batched radii, the band scan, the property test, chatter branch."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from millsense.process.coefficients import CuttingCoefficients
from millsense.stability.lobes import critical_depth
from millsense.stability.milling import immersion_angles, milling_dde
from millsense.stability.modal import ModalModel, Mode
from millsense.stability.robust import eigen_chatter_frequency, robust_lobes, solve_speed
from millsense.stability.scan import (
    monodromies,
    small_gain_depth,
    spectral_radii,
    structure_peak_gain,
    unstable_bands,
)
from millsense.stability.sdm import analyse
from millsense.stability.time_domain import TimeDomainMillingSim
from millsense.validation.cases.stability import FLUTES, FN, INSPERGER, KN, KT


def _family(ratio: float, mode: str, structure: ModalModel = INSPERGER, flutes: int = FLUTES):
    st, ex = immersion_angles(ratio, 1.0, mode)

    def fam(n: float, m: int):
        return milling_dde(structure, flutes, KT, KN, st, ex, n, m)

    return fam


def _rho(fam, w: float) -> float:
    """Independent per-depth spectral radius (sdm.analyse, no batching)."""
    return analyse(fam.step_means(w)).spectral_radius


def test_batched_radii_equal_the_per_depth_solver() -> None:
    # same arithmetic as discretize/monodromy: equal to round-off at 12 depths, 1- and 2-DOF,
    # uniform and variable pitch
    two = ModalModel(
        x=(Mode.from_stiffness(922.0, 0.011, 1.34e6),), y=(Mode.from_stiffness(880.0, 0.02, 2e6),)
    )
    st, ex = immersion_angles(0.3, 1.0, "up")
    fams = [
        _family(1.0, "down")(15870.0, 20),
        milling_dde(two, 3, KT, KN, st, ex, 12000.0, 17),
        milling_dde(two, 4, KT, KN, st, ex, 9000.0, 12, [1.3, 1.8, 1.4, 2 * math.pi - 4.5]),
    ]
    for fam in fams:
        ws = np.geomspace(1e-5, 5e-3, 12)
        r, _ = spectral_radii(fam, ws)
        ref = np.array([_rho(fam, w) for w in ws])
        np.testing.assert_allclose(r, ref, rtol=1e-10, atol=0)
        assert monodromies(fam, ws[:1]).shape[0] == 1


def test_small_gain_depth_is_stable_and_below_the_limit() -> None:
    # small-gain theorem: stable below 1/(2 ||G||inf max||H||); for the Insperger slot case
    # ||G||inf = 1/(2 k ζ sqrt(1-ζ²)) = 3.39e-5 m/N (closed form of a single mode's peak)
    fam = _family(1.0, "down")(15870.0, 40)
    k, z = INSPERGER.x[0].stiffness, INSPERGER.x[0].zeta
    assert structure_peak_gain(fam) == pytest.approx(1 / (2 * k * z * math.sqrt(1 - z * z)), 2e-4)
    w0 = small_gain_depth(fam)
    for w in np.geomspace(w0 / 100, w0, 8):
        assert _rho(fam, w) < 1.0
    assert w0 < 0.3159e-3


def test_narrow_band_below_the_boundary_is_found_half_up_20100() -> None:
    # issue 14 item 3: a/D 0.5 up milling at 20 100 rev/min has an unstable band near
    # 0.90-0.99 mm below a stable band; the x1.25 bracketing reported the limit 38 % high
    fam = _family(0.5, "up")(20100.0, 40)
    old = critical_depth(fam, 1e-5, 0.05).depth
    b = unstable_bands(fam, small_gain_depth(fam), 0.02)
    w = b.limit
    # independent: the lowest depth of a 1 % geometric grid where ρ >= 1
    grid = np.geomspace(0.2e-3, 2.0 * w, 200)
    first = next(g for g in grid if _rho(fam, g) >= 1.0)
    assert w == pytest.approx(first, rel=0.011)
    assert all(_rho(fam, g) < 1.0 for g in grid if g < 0.999 * w)
    assert old > 1.2 * w  # the earlier search stepped over the band
    assert len(b.unstable) >= 2 and b.stable_bands()  # an island above the band


def _random_case(rng: np.random.Generator):
    def mode() -> Mode:
        return Mode.from_stiffness(
            float(rng.uniform(400, 2500)),
            float(rng.uniform(0.008, 0.05)),
            float(10 ** rng.uniform(6, 7.5)),
        )

    two_dof = bool(rng.integers(0, 2))
    structure = ModalModel(x=(mode(),), y=(mode(),) if two_dof else ())
    flutes = int(rng.integers(2, 7))
    ratio = float(10 ** rng.uniform(math.log10(0.02), 0.0))
    md = "up" if rng.integers(0, 2) else "down"
    st, ex = immersion_angles(ratio, 1.0, md)
    kt = float(rng.uniform(4e8, 1.2e9))
    kr = float(rng.uniform(0.1, 0.5)) * kt

    def fam(n: float, m: int):
        return milling_dde(structure, flutes, kt, kr, st, ex, n, m)

    f_max = 2.0 * max(md_.natural_frequency_hz for md_ in structure.modes)
    speeds = np.sort(rng.uniform(3000, 20000, 2))
    return fam, f_max, speeds, (two_dof, flutes, round(ratio, 3), md)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(8))
def test_property_no_unstable_depth_below_the_reported_limit(seed: int) -> None:
    # issue 14 acceptance: for random cases (1- and 2-DOF, up/down, a/D 0.02..1, 2-6 flutes),
    # at every speed ρ on a dense geometric grid (ratio 1.02) below the reported limit is < 1,
    # by a brute-force loop over sdm.analyse at the finest discretisation the chart used
    rng = np.random.default_rng(1000 + seed)
    fam, f_max, speeds, label = _random_case(rng)
    res = robust_lobes(fam, speeds, f_max, 20, 0.02, 10.0, refine_minima=False)
    for sol in res.solutions:
        top = sol.depth if sol.depth < math.inf else sol.ceiling
        fm = fam(sol.rpm, sol.steps)
        grid = np.geomspace(top / 400, top, 300)[:-1]
        bad = [w for w in grid if _rho(fm, w) >= 1.0]
        assert not bad, (label, sol.rpm, sol.depth, bad[:3])
        if 0 < sol.depth < math.inf:
            # and the reported limit is a boundary: unstable just above it
            assert _rho(fm, sol.depth * (1 + 3 * max(sol.tolerance, 1e-3))) >= 1.0, label


def test_chart_flip_lobe_and_islands_at_low_immersion() -> None:
    # a/D = 0.05 down milling (Insperger et al. 2003): the robust chart's lower envelope holds
    # period-doubling points; ZOA (Hopf only) is far above there
    rpm = np.arange(17000.0, 19001.0, 250.0)
    res = robust_lobes(_family(0.05, "down"), rpm, 2 * FN, 20, 0.02, 10.0, refine_minima=False)
    flip = [s for s in res.solutions if s.bifurcation == "flip"]
    assert flip
    s = flip[0]
    # flip chatter: an odd multiple of half the tooth frequency
    k = s.chatter_hz / (s.rpm * FLUTES / 60.0 / 2)
    assert abs(k - round(k)) < 1e-6 and round(k) % 2 == 1
    assert all(0.0 <= t <= 0.01 for t in (x.tolerance for x in res.solutions))


def test_eigenvector_chatter_frequency_hopf_slot() -> None:
    # benchmarks.md §1: 15 870 rev/min slotting chatters at about 932 Hz (time domain 934 Hz)
    fam = _family(1.0, "down")
    sol = solve_speed(fam, 15870.0, 2 * FN, 20, 0.02, structure_peak_gain(fam(15870.0, 20)))
    assert sol.depth * 1e3 == pytest.approx(0.3174, rel=5e-3)
    assert sol.chatter_hz == pytest.approx(932.0, abs=5.0)
    f2 = eigen_chatter_frequency(fam(15870.0, 80), sol.depth, 2 * FN)
    assert f2 == pytest.approx(sol.chatter_hz, abs=2.0)


def _ramped_18900(
    sim: TimeDomainMillingSim, k0: CuttingCoefficients, target: float, hold_rev: int
) -> None:
    """Approach ``target`` × the depth of ``sim`` from half of it by a slow ramp of the
    coefficients (a depth ramp on one straight disc), then hold."""
    sim.set_coefficients(replace(k0, ktc=0.5 * k0.ktc, krc=0.5 * k0.krc))
    sim.run_revolutions(200)
    for k in range(1, 51):
        s = 0.5 + (target - 0.5) * k / 50
        sim.set_coefficients(replace(k0, ktc=s * k0.ktc, krc=s * k0.krc))
        sim.run_revolutions(2)
    sim.run_revolutions(hold_rev)


def test_flip_at_18900_slot_against_the_time_domain() -> None:
    """Decision 0910: at 18 900 rev/min slotting the critical multiplier is a flip (−1) at
    2.80 mm, chatter frequency f_T/2 = 315 Hz (+ k f_T). The time domain confirms the limit and
    the multiplier when the depth is approached slowly; a start at full depth instead jumps to a
    coexisting large-amplitude motion (the tool leaves the cut) well below the linear limit."""
    from millsense.stability.scan import monodromies
    from millsense.validation.cases.stability_time_domain import _K, _td_sim

    fam = _family(1.0, "down")
    n = 18900.0
    sol = solve_speed(fam, n, 2 * FN, 20, 0.02, structure_peak_gain(fam(n, 20)))
    assert sol.bifurcation == "flip"
    assert sol.depth * 1e3 == pytest.approx(2.802, rel=5e-3)  # this chart's converged figure
    assert sol.chatter_hz == pytest.approx(n * FLUTES / 60.0 / 2.0, abs=1e-6)  # 315 Hz
    # below the limit, approached slowly: the tooth-period section settles (period 1)
    sim = _td_sim(1.0, "down", n, sol.depth)
    _ramped_18900(sim, _K, 0.95, 200)
    steps = np.diff(sim.run_revolutions(20).x_m[:: sim.steps_per_rev // FLUTES])
    assert np.max(np.abs(steps)) < 1e-9  # m, against a 50 µm feed per tooth
    # just above: the section's steps grow by the flip multiplier per tooth period; the SDM's
    # (m = 40) at the same depth within 2 %
    sim = _td_sim(1.0, "down", n, sol.depth)
    _ramped_18900(sim, _K, 1.0, 100)
    sim.set_coefficients(replace(_K, ktc=1.03 * _K.ktc, krc=1.03 * _K.krc))
    steps = np.diff(sim.run_revolutions(40).x_m[:: sim.steps_per_rev // FLUTES])
    ratio = float(np.median(steps[21:60] / steps[20:59]))
    mu = np.linalg.eigvals(monodromies(fam(n, 40), np.array([1.03 * sol.depth]))[0])
    mu_max = mu[np.argmax(np.abs(mu))]
    assert abs(mu_max.imag) < 1e-9 and mu_max.real < -1.0  # SDM: a real multiplier below −1
    assert ratio == pytest.approx(mu_max.real, rel=0.02)
    # a start at full depth at 0.8 × the limit chatters: the entry transient (free vibration of
    # the 922 Hz mode) leaves the cut and the motion stays on the large attractor
    sim = _td_sim(1.0, "down", n, 0.8 * sol.depth)
    steps = np.diff(sim.run_revolutions(300).x_m[:: sim.steps_per_rev // FLUTES][-100:])
    assert np.median(np.abs(steps)) > 20e-6


def test_spectral_radius_bounds_hold_and_decide_the_grid_as_exact_radii() -> None:
    # decision 0911: the bounds from repeated squaring contain ρ, and the scan that uses them
    # gives the same bands, edges and multipliers as one that computes ρ at every grid depth
    import millsense.stability.scan as scan

    two = ModalModel(
        x=(Mode.from_stiffness(922.0, 0.011, 1.34e6),), y=(Mode.from_stiffness(880.0, 0.02, 2e6),)
    )
    st, ex = immersion_angles(0.3, 1.0, "up")
    fams = [
        _family(1.0, "down")(15870.0, 20),
        _family(0.05, "down")(18000.0, 20),
        _family(0.5, "up")(20100.0, 40),
        milling_dde(two, 3, KT, KN, st, ex, 12000.0, 17),
    ]
    for fam in fams:
        ws = np.geomspace(small_gain_depth(fam), 0.01, 40)
        M = scan.deflate(monodromies(fam, ws))
        lo, hi = scan.radius_bounds(M)
        r, _ = spectral_radii(fam, ws)
        assert np.all(lo <= r * (1 + 1e-12)) and np.all(r <= hi * (1 + 1e-12))
        # tight enough to order most neighbouring depths (what the scan needs them for)
        apart = (lo[1:] > hi[:-1]) | (hi[1:] < lo[:-1])
        assert np.mean(apart) > 0.8

    def exact_grid(family, depths, hump, left=None):  # ρ everywhere, as before decision 0911
        r, _ = spectral_radii(family, depths)
        return r, r.copy(), np.ones(r.size, dtype=bool)

    for fam in fams:
        w0 = small_gain_depth(fam)
        with_bounds = unstable_bands(fam, w0, 0.02)
        saved = scan.grid_bounds
        scan.grid_bounds = exact_grid
        try:
            exact = unstable_bands(fam, w0, 0.02)
        finally:
            scan.grid_bounds = saved
        assert with_bounds.unstable == exact.unstable
        assert with_bounds.multipliers == exact.multipliers
        assert with_bounds.ceiling == exact.ceiling


def test_chatter_eigenvector_by_inverse_iteration_equals_eig() -> None:
    # the chart passes the multiplier it already has: inverse iteration then replaces
    # numpy.linalg.eig for the eigenvector; the frequency is the same
    fam = _family(1.0, "down")
    for n, w in ((15870.0, 0.33e-3), (18900.0, 2.9e-3), (9000.0, 0.5e-3)):
        f = fam(n, 40)
        mu = spectral_radii(f, np.array([w]))[1][0]
        assert eigen_chatter_frequency(f, w, 2 * FN, mu) == eigen_chatter_frequency(f, w, 2 * FN)
