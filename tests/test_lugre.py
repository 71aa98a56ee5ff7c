"""LuGre friction (Aslan Eq. 3.2–3.9): steady state, pre-sliding, integration decision."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.config import FrictionConfig
from millsense.core.errors import ConfigError
from millsense.models.lugre import LuGre
from millsense.simulator.machine_file import simulator_machine


def axis_lugre(axis: str) -> LuGre:
    return LuGre.from_config(simulator_machine("quaser-ux600").axis(axis).friction)


def test_steady_sliding_torque_is_the_stribeck_curve() -> None:
    # Eq. 3.2–3.4 with dz/dt = 0: τ = sgn(v)·g(v) + σ2·v, e.g. Z at +0.571 rad/s (= v_s):
    # 2.15 + 0.15·e^-1 + 0.065·0.571 (Table 3.2)
    lg = axis_lugre("z")
    assert lg.steady_torque(np.array([0.571]))[0] == pytest.approx(
        2.15 + 0.15 * math.exp(-1.0) + 0.065 * 0.571, rel=1e-12
    )
    for v in (-3.0, -0.2, 0.05, 0.7, 5.0):
        tau, _ = lg.simulate(np.full(200000, v), 1e-5)
        # after 2 s (> 90 bristle time constants g/(|v|σ0)) z is at its steady deflection
        assert tau[-1] == pytest.approx(lg.steady_torque(np.array([v]))[0], rel=1e-9)


def test_presliding_stiffness_is_sigma0() -> None:
    # from rest, a displacement far below z_ss = g/σ0 deflects the bristles elastically:
    # τ ≈ σ0·θ (Eq. 3.2, 3.3 with |v|σ0 z/g ≪ v); X: σ0 = 525 N·m/rad
    lg = axis_lugre("x")
    h, n = 1e-5, 100
    v = np.full(n, 1e-4)  # 1e-8 rad of travel per step, 1e-6 rad in total (z_ss = 3.3e-3)
    tau, z = lg.simulate(v, h)
    theta = 1e-4 * h * n
    assert z[-1] == pytest.approx(theta, rel=1e-3)
    # σ1·dz/dt adds 15·1e-4 N·m, σ2·v 1.75e-5 N·m
    assert tau[-1] == pytest.approx(525.0 * theta + 15.0 * 1e-4 + 0.175 * 1e-4, rel=1e-3)


def test_exact_bristle_update_matches_eq_3_9_for_small_steps() -> None:
    # Aslan Eq. 3.9 (forward Euler) at 0.1 µs against the exact update at 10 µs: same torque
    # history within 0.5 % on a speed reversal (the step ratio is 100)
    lg = axis_lugre("z")
    p = lg.as_array()
    t_fine = np.arange(0, 0.02, 1e-7)
    v_fine = 0.5 * np.sin(2 * math.pi * 50 * t_fine)
    z = 0.0
    tau_euler = np.empty_like(v_fine)
    for k, v in enumerate(v_fine):  # reference only, 2e5 steps
        d = 0 if v >= 0 else 1
        g = p[8 + d] + (p[6 + d] - p[8 + d]) * math.exp(-((v / p[10 + d]) ** 2))
        zdot = v - abs(v) * p[d] * z / g
        z = z + 1e-7 * zdot
        tau_euler[k] = p[d] * z + p[2 + d] * zdot + p[4 + d] * v
    tau_exact, _ = lg.simulate(v_fine[::100], 1e-5)
    np.testing.assert_allclose(tau_exact[10:], tau_euler[::100][10:], atol=0.005 * 2.3)


def test_exact_update_is_stable_where_eq_3_9_diverges() -> None:
    # Decision "LuGre integration": A axis (σ0 = 28 000 N·m/rad, g ≈ 1.57 N·m) at 50 rad/s and
    # 10 µs: |v|σ0·h/g ≈ 8.9 > 2, so forward Euler oscillates with growing amplitude; the exact
    # update lands on z_ss = g/σ0.
    lg = axis_lugre("a")
    p = lg.as_array()
    v, h = 50.0, 1e-5
    g = float(lg.stribeck(np.array([v]))[0])
    z = 0.0
    for _ in range(30):
        z = z + h * (v - abs(v) * p[0] * z / g)
    assert abs(z) > 1e3 * g / p[0]  # Eq. 3.9 blew up
    _, zs = lg.simulate(np.full(30, v), h)
    assert zs[-1] == pytest.approx(g / p[0], rel=1e-12)


def test_quaser_x_static_equals_coulomb_decision() -> None:
    # Decision "Quaser friction rows": τ_stat := τ_coul for X, so g(v) is flat (no inverted
    # Stribeck curve); Z keeps its printed Stribeck drop 2.3 → 2.15 N·m
    gx = axis_lugre("x").stribeck(np.array([0.0, 0.03, 1.0]))
    np.testing.assert_allclose(gx, 1.73, rtol=1e-12)
    gz = axis_lugre("z").stribeck(np.array([0.0, 10.0]))
    np.testing.assert_allclose(gz, [2.3, 2.15], rtol=1e-9)


def test_critical_sigma1_eq_3_8() -> None:
    # digest: Eq. 3.8 gives about 5.2 for X (2·√(0.01366·525) − 0.175 = 5.18)
    assert axis_lugre("x").critical_sigma1(0.01366)[0] == pytest.approx(5.18, abs=0.01)


def test_missing_lugre_key_is_a_config_error() -> None:
    cfg = FrictionConfig(coulomb_nm=(1.0, 1.0), viscous_nm_s_rad=(0.1, 0.1))
    with pytest.raises(ConfigError, match="sigma0_nm_rad"):
        LuGre.from_config(cfg, "m.toml axes.x.friction")


def test_bristles_without_a_stribeck_curve_are_a_flat_lugre() -> None:
    # decision 1695: σ0, σ1 from a presliding test and no resolved Stribeck rise → LuGre with
    # τ_stat = τ_coul, g(v) = τ_coul at every speed (Eq. 3.4), the steady torque Coulomb +
    # viscous (Eq. 3.2 with dz/dt = 0), the bristles' stiffness σ0 at a reversal
    cfg = FrictionConfig(coulomb_nm=(1.7, 1.8), viscous_nm_s_rad=(0.17, 0.15),
                         sigma0_nm_rad=(600.0, 600.0), sigma1_nm_s_rad=(14.0, 14.0))  # fmt: skip
    assert LuGre.configured(cfg)
    lg = LuGre.from_config(cfg)
    v = np.array([-5.0, -0.01, 0.0, 1e-3, 0.3, 5.0])
    np.testing.assert_allclose(lg.stribeck(v), [1.8, 1.8, 1.7, 1.7, 1.7, 1.7], rtol=1e-15)
    np.testing.assert_allclose(
        lg.steady_torque(v[v != 0]), np.sign(v[v != 0]) * lg.stribeck(v[v != 0])
        + np.where(v[v != 0] > 0, 0.17, 0.15) * v[v != 0], rtol=1e-12,
    )  # fmt: skip
    assert not LuGre.configured(FrictionConfig(coulomb_nm=(1.0, 1.0), viscous_nm_s_rad=(0, 0)))


def test_half_a_stribeck_curve_is_a_config_error() -> None:
    cfg = FrictionConfig(coulomb_nm=(1.0, 1.0), viscous_nm_s_rad=(0.1, 0.1),
                         sigma0_nm_rad=(600.0, 600.0), sigma1_nm_s_rad=(14.0, 14.0),
                         static_nm=(1.2, 1.2))  # fmt: skip
    with pytest.raises(ConfigError, match="'static_nm' needs key 'stribeck_velocity_rad_s'"):
        LuGre.from_config(cfg, "m.toml axes.x.friction")
