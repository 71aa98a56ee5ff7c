"""Root searches that follow the critical multiplier (decision 0912): the tracked multipliers
are those of the eigenvalue problem, and the roots are crossings of ρ = 1 as Brent's method on
ρ itself finds them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

from millsense.stability import scan
from millsense.stability.milling import immersion_angles, milling_dde
from millsense.stability.modal import ModalModel, Mode
from millsense.stability.sdm import analyse
from millsense.validation.cases.stability import FLUTES, INSPERGER, KN, KT


def _slot(rpm: float, m: int):
    st, ex = immersion_angles(1.0, 1.0, "down")
    return milling_dde(INSPERGER, FLUTES, KT, KN, st, ex, rpm, m)


def _two_dof(rpm: float, m: int):
    two = ModalModel(
        x=(Mode.from_stiffness(922.0, 0.011, 1.34e6),), y=(Mode.from_stiffness(880.0, 0.02, 2e6),)
    )
    st, ex = immersion_angles(0.3, 1.0, "up")
    return milling_dde(two, 3, KT, KN, st, ex, rpm, m)


@pytest.mark.parametrize("m", [20, 40, 100])
def test_tracked_multipliers_equal_the_eigenvalue_problem(m: int) -> None:
    # from a shift 0.1 % off, Rayleigh-quotient iteration and (1-DOF, one delay of m steps) the
    # Floquet characteristic matrix give the dominant multiplier of numpy's eigvals
    for fam in (_slot(9000.0, m), _two_dof(12000.0, m)):
        prep = scan._prepare(fam)
        for w in (2e-4, 5e-4, 1e-3):
            full = scan.monodromies(prep, np.array([w]))
            M = scan.deflate(full)[0]
            ev = np.linalg.eigvals(M)
            mu = complex(ev[np.argmax(np.abs(ev))])
            got = scan._rayleigh(M, mu * (1 + 1e-3), None)
            assert got is not None
            assert abs(got[0] - mu) <= 1e-9 * abs(mu)
            if fam.A0.shape[0] <= scan.FLOQUET_MAX_STATE:
                Phi, Wa, Wb = prep.step_maps(w)
                ok, mu_f = scan._floquet_newton(Phi, Wa, Wb, prep.C, mu * (1 + 1e-3))
                assert ok and abs(mu_f - mu) <= 1e-9 * abs(mu)
                y, res_y = scan._floquet_vector(Phi, Wa, Wb, prep.C, mu_f)
                res = np.linalg.norm(full[0] @ y - mu_f * y)
                assert res <= 1e-12 * np.linalg.norm(full[0]) * np.linalg.norm(y)
                assert res_y <= 1e-12 * np.linalg.norm(y)
                # off the root the residual the Floquet solution reports is M's own
                mu_p = mu_f * (1 + 1e-6)
                y_p, res_p = scan._floquet_vector(Phi, Wa, Wb, prep.C, mu_p)
                exact = np.linalg.norm(full[0] @ y_p - mu_p * y_p)
                assert exact > 1e-9 * np.linalg.norm(y_p)
                assert res_p == pytest.approx(exact, rel=1e-6)


def test_stable_beyond_proves_only_a_dominant_multiplier() -> None:
    # the deflation proof accepts the dominant multiplier below 1 and refuses a smaller one
    fam = _slot(15870.0, 40)
    prep = scan._prepare(fam)
    M = scan.deflate(scan.monodromies(prep, np.array([0.3e-3])))[0]
    ev = np.linalg.eigvals(M)
    order = np.argsort(-np.abs(ev))
    mu1 = complex(ev[order[0]])
    assert abs(mu1) < 1.0
    mu1, v1 = scan._rayleigh(M, mu1, None)  # type: ignore[misc]
    assert scan._stable_beyond(M, mu1, v1)
    # a multiplier that is not dominant (not the conjugate of the dominant one)
    other = next(complex(ev[i]) for i in order[1:] if abs(ev[i] - np.conj(mu1)) > 1e-6)
    got = scan._rayleigh(M, other, None)
    assert got is not None
    assert not scan._stable_beyond(M, got[0], got[1])


@pytest.mark.parametrize(
    ("fam", "guess"),
    [(_slot(15870.0, 40), 0.33e-3), (_slot(9000.0, 80), 0.6e-3), (_two_dof(12000.0, 34), 1e-3)],
)
def test_branch_roots_are_crossings_of_rho(fam, guess: float) -> None:
    # the scan's edges and near_root's crossing: ρ < 1 just below, >= 1 just above (an
    # independent per-depth solver), and within the root tolerance of Brent's method on ρ
    b = scan.unstable_bands(fam, scan.small_gain_depth(fam), 0.01, rtol=2e-4)
    w = b.limit
    assert 0 < w < math.inf
    assert analyse(fam.step_means(w * (1 - 4e-4))).spectral_radius < 1.0
    assert analyse(fam.step_means(w * (1 + 4e-4))).spectral_radius >= 1.0
    f = scan._Scalar(fam)
    ref = scipy.optimize.brentq(lambda x: f(x) - 1.0, 0.8 * w, 1.0001 * w, rtol=2e-4)
    assert w == pytest.approx(ref, rel=5e-4)
    w2, mu2, _ = scan.near_root(fam, 1.01 * w, 2e-4, mu_guess=b.multipliers[0])
    assert w2 == pytest.approx(w, rel=5e-4)
    assert abs(abs(mu2) - 1.0) < 1e-3
