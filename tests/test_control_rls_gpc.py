"""RLS (Munasinghe Eq. 3.27-3.31) and GPC (Aslan App. G, Eq. 6.8-6.14) against independent
computations: long division, App. G's printed coefficients, a simulated CARIMA plant."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.control.gpc import GPC, diophantine, diophantine_direct
from millsense.control.rls import ConstantTraceRLS, force_model_constraints, project
from millsense.core.errors import ConfigError

A2 = [-1.2, 0.36]  # two poles at 0.6: an overdamped drive + cut, as Aslan's plant
B3 = [0.2, 0.1, 0.05]


@pytest.mark.parametrize("a", [A2, [-0.5, 0.2, -0.1], [0.3]])
def test_recursion_equals_long_division(a: list[float]) -> None:
    pred = diophantine(a, B3, 6)
    for j in range(1, 7):
        e, f = diophantine_direct(a, j)
        np.testing.assert_allclose(pred.e[j - 1, :j], e, rtol=0, atol=1e-12)
        np.testing.assert_allclose(pred.f[j - 1], f, rtol=0, atol=1e-12)
        # and the identity itself: E_j·AΔ + z^-j F_j = 1
        at = np.convolve(np.r_[1.0, a], [1.0, -1.0])
        lhs = np.convolve(e, at)
        lhs[j : j + f.size] += f
        np.testing.assert_allclose(lhs, np.r_[1.0, np.zeros(lhs.size - 1)], atol=1e-12)


def test_app_g_printed_coefficients() -> None:
    """Aslan App. G (digest §2.10, the f30 typo corrected) for the second-order plant."""
    a1, a2 = A2
    b0, b1, b2 = B3
    p = diophantine(A2, B3, 4)
    f10, f11, f12 = 1 - a1, a1 - a2, a2
    np.testing.assert_allclose(p.f[0], [f10, f11, f12], atol=1e-15)
    e1 = f10
    f20, f21, f22 = f11 - e1 * (a1 - 1), f12 - e1 * (a2 - a1), e1 * a2
    np.testing.assert_allclose(p.f[1], [f20, f21, f22], atol=1e-15)
    e2 = f20
    f30 = f21 - e2 * (a1 - 1)  # "f21 − e2 − (a1 − 1)" in the source: a product
    e3 = f30
    np.testing.assert_allclose(p.e[3, :4], [1, e1, e2, e3], atol=1e-14)
    # step-response gains g0..g3
    g = [b0, b1 + e1 * b0, b2 + e1 * b1 + e2 * b0, e1 * b2 + e2 * b1 + e3 * b0]
    np.testing.assert_allclose(p.step_response, g, atol=1e-14)
    # the free-response coefficients of past increments, rows j = 1..4
    past = [(b1, b2), (b2 + e1 * b1, e1 * b2), (e1 * b2 + e2 * b1, e2 * b2),
            (e2 * b2 + e3 * b1, e3 * b2)]  # fmt: skip
    for j, (gjj, gjj1) in enumerate(past):
        np.testing.assert_allclose(p.g[j, j + 1 : j + 3], [gjj, gjj1], atol=1e-14)


def _plant(a: list[float], b: list[float], u: np.ndarray) -> np.ndarray:
    """A·F(t) = B·u(t−1), noise-free, from rest."""
    y = np.zeros(u.size)
    for t in range(u.size):
        acc = 0.0
        for i, bi in enumerate(b):
            if t - 1 - i >= 0:
                acc += bi * u[t - 1 - i]
        for i, ai in enumerate(a):
            if t - 1 - i >= 0:
                acc -= ai * y[t - 1 - i]
        y[t] = acc
    return y


def test_predictor_is_exact_on_the_plant() -> None:
    # F̂(t+j) = G_j Δu(t+j−1) + F_j F(t) equals the plant's output when the moves are known
    rng = np.random.default_rng(3)
    u = np.cumsum(rng.normal(size=60))
    y = _plant(A2, B3, u)
    du = np.diff(np.r_[0.0, u])
    p = diophantine(A2, B3, 4)
    t = 30
    for j in range(1, 5):
        gj = p.g[j - 1]
        pred = sum(gj[i] * du[t + j - 1 - i] for i in range(gj.size))
        pred += p.f[j - 1] @ y[t : t - 3 : -1]
        assert pred == pytest.approx(y[t + j], abs=1e-9)


def test_closed_loop_reaches_the_reference_and_nu1_closed_form() -> None:
    ctl = GPC(n2=4, nu=1, lam=0.25)
    g = diophantine(A2, B3, 4).step_response
    n = 80
    u = np.zeros(n)  # u[t] is applied after the output y[t] is measured
    du = np.zeros(n)
    for t in range(n):
        y = _plant(A2, B3, u[: t + 1])  # outputs up to y[t] (they depend on u[: t] only)
        y_past = np.r_[y[::-1], np.zeros(3)][:3]  # y[t], y[t−1], y[t−2]
        du_past = np.r_[du[:t][::-1], np.zeros(2)][:2]  # Δu[t−1], Δu[t−2]
        du[t] = ctl.move(A2, B3, y_past, du_past, 1.0)
        if t == 0:
            # Nu = 1: Δu = Σ g_j (r − f_j) / (Σ g_j² + λ); from rest the free response is 0
            assert du[0] == pytest.approx(g.sum() / (g @ g + 0.25), rel=1e-12)
        u[t] = (u[t - 1] if t else 0.0) + du[t]
    y = _plant(A2, B3, u)
    # the integrator of the CARIMA model: no steady-state error (Munasinghe Eq. 3.32)
    assert y[-10:] == pytest.approx(1.0, abs=1e-6)


def test_gpc_bad_settings() -> None:
    with pytest.raises(ConfigError, match="Nu"):
        GPC(n2=2, nu=3)
    with pytest.raises(ConfigError, match="λ"):
        GPC(lam=-1.0)


def test_rls_identifies_the_arx_model_with_constant_trace() -> None:
    rng = np.random.default_rng(0)
    u = 1.0 + 0.3 * rng.standard_normal(600)  # a feed override around 100 %
    y = _plant(A2, B3, u) + 0.002 * rng.standard_normal(600)
    rls = ConstantTraceRLS([0.01] * 5, delta=0.0, p0=10.0)  # θ̂₀ and P₀ of seed 002
    late = []
    for t in range(3, 600):
        phi = [-y[t - 1], -y[t - 2], u[t - 1], u[t - 2], u[t - 3]]
        rls.update(phi, y[t])
        if t >= 400:
            late.append(rls.theta.copy())
        # Eq. 3.30: the trace after each step is c1 + n·c2, c1 = tr(P0) = 50 (decision 1601)
        assert np.trace(rls.P) == pytest.approx(50.0 * (1 + 5e-4), rel=1e-12)
    # the ARX parameters within 0.02 over revolutions 400-600 (noise 0.2 % of the output); a
    # constant trace keeps tracking, so single estimates wander around them
    np.testing.assert_allclose(np.mean(late, axis=0), [*A2, *B3], atol=0.02)


def test_rls_dead_zone_freezes_the_estimate() -> None:
    rls = ConstantTraceRLS([0.5, 0.5], delta=0.1)
    before = rls.theta.copy(), rls.P.copy()
    err = rls.update([1.0, 0.0], 0.5 + 0.15)  # |error| 0.15 ≤ 2δ = 0.2: α = 0 (Eq. 3.31)
    assert err == pytest.approx(0.15)
    np.testing.assert_array_equal(rls.theta, before[0])
    np.testing.assert_array_equal(rls.P, before[1])
    rls.update([1.0, 0.0], 0.5 + 0.3)  # outside: updates
    assert rls.theta[0] > 0.5 and rls.updates == 1
    # a NaN never enters
    assert np.isnan(rls.update([np.nan, 0.0], 1.0)) and rls.updates == 1


def test_projection_is_the_nearest_point_in_the_p_inverse_metric() -> None:
    # decision 1657: an estimate outside {Gθ ≤ h} goes to the nearest point of the set in
    # ‖·‖_{P⁻¹}; checked against a dense search of the feasible set (box b ≥ 0, a₁ ∈ [−1, 0],
    # a₂ = 0) on a P with strong correlations
    g, h = force_model_constraints(2, 3)
    rng = np.random.default_rng(1)
    m = rng.standard_normal((5, 5))
    p = m @ m.T + 0.1 * np.eye(5)
    hinv = np.linalg.inv(p)
    for _ in range(20):
        theta = rng.normal(0.0, 1.0, 5)
        x = project(theta, p, g, h)
        assert np.all(g @ x <= h + 1e-9)
        d = x - theta
        best = float(d @ hinv @ d)
        # no feasible point nearer: random feasible points and small feasible moves from x
        near = x + 0.01 * rng.standard_normal((4000, 5))
        far = np.column_stack([-rng.uniform(0, 1, 4000), np.zeros(4000),
                               rng.exponential(1.0, (4000, 3))])  # fmt: skip
        cand = np.vstack([near, far])
        cand[:, 0] = np.clip(cand[:, 0], -1.0, 0.0)
        cand[:, 1] = 0.0
        cand[:, 2:] = np.maximum(cand[:, 2:], 0.0)
        dc = cand - theta
        assert np.min(np.einsum("ij,jk,ik->i", dc, hinv, dc)) >= best - 1e-9
    # an estimate inside is left alone
    inside = np.array([-0.3, 0.0, 0.5, 0.2, 0.0])
    np.testing.assert_array_equal(project(inside, p, g, h), inside)


def test_constrained_rls_stays_physical_on_a_disturbance() -> None:
    # a force step at a constant feed (an engagement jump) is explained by the unconstrained
    # RLS with a's and b's of either sign; the constrained one keeps a₂ = 0, a₁ ∈ [−1, 0], b ≥ 0
    g, h = force_model_constraints(2, 3)
    free = ConstantTraceRLS([0.0, 0.0, 0.8, 0.0, 0.0], delta=0.005)
    held = ConstantTraceRLS([0.0, 0.0, 0.8, 0.0, 0.0], delta=0.005, constraints=(g, h))
    y = [1.0, 1.0, 1.0, 0.6, 0.7, 1.3, 2.6, 2.8]
    u = [1.25, 1.25, 1.25, 1.25, 1.5, 1.5, 1.35, 1.5]
    bad = False
    for t in range(3, len(y)):
        phi = [-y[t - 1], -y[t - 2], u[t - 1], u[t - 2], u[t - 3]]
        free.update(phi, y[t])
        held.update(phi, y[t])
        assert np.all(g @ held.theta <= h + 1e-9)
        bad |= not bool(np.all(g @ free.theta <= h + 1e-9))
    assert bad  # the unconstrained estimate did leave the set
    with pytest.raises(ConfigError, match="constraints"):
        ConstantTraceRLS([0.0, 0.0], constraints=(g, h))
