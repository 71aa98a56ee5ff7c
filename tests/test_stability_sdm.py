"""Semi-discretisation solver: regression values and closed forms (benchmarks.md §2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.stability import sdm


def _hayes(h: float = 0.1, m: int = 1) -> sdm.StepMeans:
    return sdm.step_means_from_callables(
        np.array([[-1.0]]), [np.array([[-1.0]])], [1.0], h, m, c=np.array([1.0])
    )


def test_hayes_spectral_radius_regression() -> None:
    # benchmarks.md §2: SemiDiscretizationMethod.jl, one step of 0.1 -> 0.941189374166563
    assert sdm.analyse(_hayes()).spectral_radius == pytest.approx(0.941189374166563, abs=1e-9)


def test_hayes_map_over_a_unit_period_is_the_tenth_power() -> None:
    # autonomous equation: 10 identical steps give the 10th power of the one-step multiplier
    rho1 = sdm.analyse(_hayes()).spectral_radius
    rho10 = sdm.analyse(_hayes(0.1, 10)).spectral_radius
    assert rho10 == pytest.approx(rho1**10, rel=1e-9)


def test_hayes_fixed_point() -> None:
    # x* = 1 / (1 - a - b) = 0.5 at every node (benchmarks.md §2)
    xs = sdm.fixed_point(_hayes(0.1, 10))
    np.testing.assert_allclose(xs[:, 0], 0.5, atol=1e-12)


def test_delayed_mathieu_regression() -> None:
    # benchmarks.md §2: 628 steps of 0.01 -> 0.5131596340374617 (tolerance 1e-9)
    d, e, b0, a1 = 3.0, 2.0, -0.15, 0.1
    sm = sdm.step_means_from_callables(
        lambda t: np.array([[0.0, 1.0], [-(d + e * math.cos(t)), -a1]]),
        [np.array([[0.0, 0.0], [b0, 0.0]])],
        [2 * math.pi],
        0.01,
        628,
        c=lambda t: np.array([0.0, math.sin(2 * t)]),
        quad_points=4,
    )
    assert sdm.analyse(sm).spectral_radius == pytest.approx(0.5131596340374617, abs=1e-9)


def test_no_delay_term_reduces_to_ode_exponential() -> None:
    # B = 0: the monodromy's state block is exp(A T); eigenvalues exp(λ T)
    A = np.array([[0.0, 1.0], [-4.0, -0.2]])
    sm = sdm.step_means_from_callables(A, [np.zeros((2, 2))], [0.5], 0.05, 20)
    M = sdm.monodromy(sdm.discretize(sm))
    lam = np.linalg.eigvals(A)
    assert sdm.analyse(sm).spectral_radius == pytest.approx(
        math.exp(lam.real.max() * 1.0), rel=1e-12
    )
    assert M.shape == (2 + 10, 2 + 10)


def test_expm_stack_matches_scipy() -> None:
    # the compiled scaling-and-squaring Taylor exponential against scipy's Padé
    import scipy.linalg

    rng = np.random.default_rng(1)
    M = rng.normal(size=(5, 6, 6)) * np.array([0.1, 1.0, 5.0, 30.0, 200.0])[:, None, None]
    ref = np.stack([scipy.linalg.expm(x) for x in M])
    np.testing.assert_allclose(sdm.expm_stack(M), ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_classification() -> None:
    # real negative -> period doubling, complex pair -> Hopf, real positive -> fold
    assert sdm.classify_multiplier(-1.0 + 0j) == "flip"
    assert sdm.classify_multiplier(complex(0.3, 0.95)) == "hopf"
    assert sdm.classify_multiplier(1.0 + 0j) == "fold"


def test_delay_shorter_than_a_step_is_rejected() -> None:
    sm = sdm.step_means_from_callables(np.array([[-1.0]]), [np.array([[-1.0]])], [0.05], 0.1, 3)
    with pytest.raises(ValueError, match="at least one step"):
        sdm.discretize(sm)


def test_fractional_delay_split() -> None:
    # tau/h = 628.318...: r = 628, f = 0.318...; exact multiples snap to f = 0
    r, f = sdm.delay_split(2 * math.pi, 0.01)
    assert (r, f) == (628, pytest.approx(0.3185307179586, abs=1e-9))
    assert sdm.delay_split(1.0, 0.1) == (10, 0.0)
