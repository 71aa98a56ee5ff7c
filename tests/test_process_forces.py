"""Mechanistic force model: closed forms, identification, runout, pitch, ball end, stats."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.process.closed_forms import (
    fit_slot_coefficients,
    identify_coefficients_from_slot,
    slot_average_forces,
)
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import chip_thickness, edge_forces, milling_forces
from millsense.process.geometry import EndMill

K6 = CuttingCoefficients(ktc=700e6, krc=300e6, kac=100e6, kte=25e3, kre=35e3, kae=10e3)


def _rev(n: int) -> np.ndarray:
    return np.linspace(0.0, 2 * math.pi, n, endpoint=False)


@pytest.mark.parametrize(
    "tool",
    [
        EndMill(10e-3, 4, helix_rad=0.52),
        EndMill(10e-3, 3),
        EndMill(10e-3, 4, pitch_angles_rad=tuple(np.radians([80.0, 100.0, 80.0, 100.0]))),
    ],
)
def test_slot_average_equals_closed_form(tool: EndMill) -> None:
    # benchmarks.md §3 closed forms; the sliced model averaged over a revolution must agree
    # to 0.1 % (residual: angular sampling and the disc midpoint rule). Variable pitch keeps
    # the same average because the chip loads c_j sum to N c.
    f = milling_forces(tool, K6, Engagement.slot(), 0.1e-3, 3e-3, _rev(7200), n_discs=100)
    ref = slot_average_forces(tool.n_flutes, 3e-3, 0.1e-3, K6)
    got = f.average()[:3]
    for g, r in zip(got, ref, strict=True):
        assert g == pytest.approx(float(r), rel=1e-3)


def test_mean_torque_and_power_slot() -> None:
    # Closed form: T̄ = R N a (K_tc c/π + K_te/2) for a slot (mean of sin φ over [0, π] per
    # tooth and revolution); power = T Ω exactly.
    tool = EndMill(12e-3, 2, helix_rad=0.3)
    f = milling_forces(tool, K6, Engagement.slot(), 0.08e-3, 2e-3, _rev(7200), n_discs=60)
    r, n, a, c = 6e-3, 2, 2e-3, 0.08e-3
    ref = r * n * a * (K6.ktc * c / math.pi + K6.kte / 2)
    assert f.average()[3] == pytest.approx(ref, rel=1e-3)
    omega = 1000.0
    assert np.allclose(f.power_w(omega), f.torque_nm * omega, rtol=0, atol=1e-12)


def test_identification_round_trip_with_noise() -> None:
    # Noise σ = 1 N on each average; 6 feeds 0.05–0.30 mm. Each coefficient must be within
    # 4 reported standard errors of the truth, and those standard errors below 3 % (the
    # regression is well conditioned for this feed range).
    rng = np.random.default_rng(7)
    feeds = np.linspace(0.05e-3, 0.30e-3, 6)
    tool = EndMill(10e-3, 4, helix_rad=0.52)
    avgs = np.array(
        [
            milling_forces(tool, K6, Engagement.slot(), c, 3e-3, _rev(3600), 40).average()[:3]
            for c in feeds
        ]
    )
    noisy = avgs + rng.normal(0.0, 1.0, avgs.shape)
    fit = fit_slot_coefficients(feeds, noisy[:, 0], noisy[:, 1], noisy[:, 2], 4, 3e-3)
    truth = np.array(K6.as_tuple())
    got = np.array(fit.coefficients.as_tuple())
    assert np.all(np.abs(got - truth) < 4 * fit.std_errors)
    assert np.all(fit.std_errors / np.abs(truth) < 0.03)
    assert np.all(fit.r_squared > 0.99)
    # Without noise the round trip is exact to the sliced model's 0.1 %.
    exact = identify_coefficients_from_slot(feeds, avgs[:, 0], avgs[:, 1], avgs[:, 2], 4, 3e-3)
    assert np.allclose(exact.as_tuple(), truth, rtol=2e-3)


def test_runout_chip_thickness_closed_form() -> None:
    # Derived closed form (Lee Eq. 2.4/2.5 in our convention,
    # docs/decisions/0010-process-angle-and-runout-convention.md):
    # h_j = c sin φ_j − 2ρ sin(π/N) sin(θ_j − π/N + ψ − λ) when every flute cuts.
    rho, lam, c = 4e-6, 0.7, 0.1e-3
    tool = EndMill(10e-3, 4, helix_rad=0.6, runout_offset_m=rho, runout_angle_rad=lam)
    discs = tool.discs(2e-3, 5)
    phi = np.linspace(0.0, 2 * math.pi, 721)
    h = chip_thickness(tool, Engagement.slot(), c, phi, discs)
    imm = tool.immersion_angles(phi, discs)
    theta = tool.flute_angles_rad[None, :, None]
    psi = discs.lag_rad[None, None, :]
    closed = c * np.sin(imm) - 2 * rho * math.sin(math.pi / 4) * np.sin(
        theta - math.pi / 4 + psi - lam
    )
    ok = (np.mod(imm, 2 * math.pi) < math.pi) & (closed > 2 * rho)  # all flutes cutting
    assert ok.sum() > 1000
    assert np.max(np.abs(h[ok] - closed[ok])) < 1e-12


def test_runout_flute_skips_cut() -> None:
    # 2 flutes, ρ = 60 µm at flute 0 (λ = 0), c = 50 µm < 2ρ: flute 1 never reaches the
    # surface (h = 0) and flute 0 removes the whole feed per revolution, h = 2c sin φ.
    tool = EndMill(10e-3, 2, runout_offset_m=60e-6, runout_angle_rad=0.0)
    discs = tool.discs(1e-3, 1)
    phi = np.linspace(0.0, 2 * math.pi, 3601)
    h = chip_thickness(tool, Engagement.slot(), 50e-6, phi, discs)
    assert np.max(h[:, 1, 0]) == 0.0
    inside = np.mod(phi, 2 * math.pi) <= math.pi
    assert np.allclose(h[inside, 0, 0], 2 * 50e-6 * np.sin(phi[inside]), atol=1e-15)


def test_variable_pitch_chip_load_proportional_to_pitch() -> None:
    # Flute j removes the material left by flute j-1, which passed p_j earlier: chip load
    # c_j = N c p_j/(2π). Peak chip thickness (at φ_j = 90°) and mean tangential force per
    # flute (no edge terms) are proportional to p_j.
    pitches = np.radians([70.0, 110.0, 85.0, 95.0])
    tool = EndMill(10e-3, 4, pitch_angles_rad=tuple(pitches))
    discs = tool.discs(1e-3, 1)
    phi = _rev(36000)
    c = 0.1e-3
    k = CuttingCoefficients(ktc=800e6, krc=250e6)
    dft, _, _, h = edge_forces(tool, k, Engagement.slot(), c, phi, discs)
    c_j = 4 * c * pitches / (2 * math.pi)
    assert np.allclose(h[:, :, 0].max(axis=0), c_j, rtol=1e-7)
    mean_ft = dft[:, :, 0].mean(axis=0)
    assert np.allclose(mean_ft / mean_ft.sum(), pitches / pitches.sum(), rtol=1e-6)


def test_ball_end_slot_averages() -> None:
    # Ball end, a = R, no edge terms. Since h db = c sin φ dz, F̄y equals the flat value
    # N a K_tc c/4; F̄x = −(N c/4)(K_rc ∫ sin κ dz − K_ac ∫ cos κ dz)
    #                 = −(N c/4)(K_rc π R/4 − K_ac R/2);
    # F̄z = (N c/π)(K_rc ∫cos κ dz + K_ac ∫ sin κ dz) = (N c/π)(K_rc R/2 + K_ac π R/4).
    r, n, c = 5e-3, 2, 0.1e-3
    k = CuttingCoefficients(ktc=700e6, krc=300e6, kac=100e6)
    tool = EndMill(2 * r, n, shape="ball")
    f = milling_forces(tool, k, Engagement.slot(), c, r, _rev(1440), n_discs=4000)
    fx, fy, fz, _ = f.average()
    assert fy == pytest.approx(n * r * k.ktc * c / 4, rel=1e-3)
    assert fx == pytest.approx(-n * c / 4 * (k.krc * math.pi * r / 4 - k.kac * r / 2), rel=1e-3)
    assert fz == pytest.approx(
        n * c / math.pi * (k.krc * r / 2 + k.kac * math.pi * r / 4), rel=1e-3
    )


def test_ball_chip_thickness_scales_with_sin_kappa() -> None:
    # Altintas ball end: h = c sin φ sin κ; at the disc centre z, sin κ = R(z)/R.
    tool = EndMill(10e-3, 2, shape="ball")
    discs = tool.discs(2e-3, 4)
    h = chip_thickness(tool, Engagement.slot(), 0.1e-3, np.array([math.pi / 2]), discs)
    z = discs.z_m
    sin_k = np.sqrt(5e-3**2 - (5e-3 - z) ** 2) / 5e-3
    assert np.allclose(h[0, 0, :], 0.1e-3 * sin_k, rtol=1e-12)


def test_tooth_period_and_revolution_stats() -> None:
    # Uniform pitch: every tooth period has the same mean, equal to the closed form; two
    # revolutions sampled → exactly 2 revolutions and 2N tooth periods.
    tool = EndMill(10e-3, 3, helix_rad=0.5)
    phi = np.linspace(0.0, 4 * math.pi, 7200, endpoint=False)
    f = milling_forces(tool, K6, Engagement.slot(), 0.1e-3, 2e-3, phi, n_discs=40)
    per_tooth = f.per_tooth_period()
    per_rev = f.per_revolution()
    assert per_tooth.mean_fy_n.size == 6 and per_rev.mean_fy_n.size == 2
    ref = slot_average_forces(3, 2e-3, 0.1e-3, K6)[1]
    assert np.allclose(per_tooth.mean_fy_n, float(ref), rtol=2e-3)
    assert np.allclose(per_rev.peak_resultant_n, f.resultant_n().max(), rtol=1e-12)


def test_aslan_resultant_ratio() -> None:
    # Aslan Eq. 5.34: no edge terms, K_rc = 0.5 K_tc → F_res = √1.25 F_t for a single
    # straight tooth in cut (exact, per sample).
    k = CuttingCoefficients(ktc=758e6, krc=379e6)
    tool = EndMill(10e-3, 1)
    phi = np.linspace(0.1, 3.0, 50)
    f = milling_forces(tool, k, Engagement.slot(), 0.2e-3, 1e-3, phi, n_discs=1)
    ft = f.torque_nm / 5e-3
    assert np.allclose(f.resultant_n() / ft, math.sqrt(1.25), rtol=1e-12)


def test_engagement_constructors_and_errors() -> None:
    # benchmarks.md §1: down milling enters at arccos(2a/D − 1), up milling exits at
    # arccos(1 − 2a/D).
    e = Engagement.radial(2.5e-3, 10e-3, "down")
    assert e.layers[0][0] == pytest.approx((math.acos(-0.5), math.pi))
    e = Engagement.radial(2.5e-3, 10e-3, "up")
    assert e.layers[0][0] == pytest.approx((0.0, math.acos(0.5)))
    with pytest.raises(ConfigError, match="radial_depth_m"):
        Engagement.radial(12e-3, 10e-3)
    with pytest.raises(ConfigError, match="pitch_angles_rad"):
        EndMill(10e-3, 2, pitch_angles_rad=(1.0, 1.0))
    # Layers: lower half slotting, upper half out of cut → half the slot force.
    two = Engagement.from_intervals([[(0.0, math.pi)], []])
    tool = EndMill(10e-3, 2)
    full = milling_forces(tool, K6, Engagement.slot(), 0.1e-3, 2e-3, _rev(720), 10)
    half = milling_forces(tool, K6, two, 0.1e-3, 2e-3, _rev(720), 10)
    assert np.allclose(half.fy_n, 0.5 * full.fy_n, rtol=1e-12)
    # Wrapping interval (3π/2, 5π/2) covers φ = 0.
    wrap = Engagement.from_intervals([(1.5 * math.pi, 2.5 * math.pi)])
    ins = wrap.inside(np.array([[0.1], [math.pi]]), np.array([0.5]))
    assert ins[:, 0].tolist() == [True, False]
