"""ZOA and Tlusty closed forms (benchmarks.md §1, §3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.stability.modal import ModalModel, Mode, OrientedMode, oriented_frf
from millsense.stability.zoa import (
    directional_factors,
    orthogonal_curves,
    tlusty_limit,
    zoa_lobes,
    zoa_milling_curves,
)

K = 0.03993 * (2 * math.pi * 922.0) ** 2
ONE_DOF = ModalModel(x=(Mode.from_stiffness(922.0, 0.011, K),))


def test_directional_factors_check_values() -> None:
    # benchmarks.md §3, k_r = 0.212, values printed to 3 decimals
    np.testing.assert_allclose(
        directional_factors(0.0, math.pi, 0.212), [[-0.666, -math.pi], [math.pi, -0.666]], atol=6e-4
    )
    np.testing.assert_allclose(
        directional_factors(math.pi / 2, math.pi, 0.212),
        [[0.667, -1.359], [1.783, -1.333]],
        atol=6e-4,
    )


def test_zoa_slotting_minimum_is_closed_form() -> None:
    # benchmarks.md §1: 2kζ(1+ζ)/h̄, h̄ = N K_n / 4 -> 0.2981 mm
    exact = 2 * K * 0.011 * 1.011 / (2 * 2e8 / 4)
    curves = zoa_milling_curves(ONE_DOF, 2, 6e8, 2e8, 0.0, math.pi, 5000.0)
    assert curves.min_depth(5000.0, 25000.0)[0] == pytest.approx(exact, rel=2e-4)
    assert exact * 1e3 == pytest.approx(0.2981, rel=5e-4)


def test_zoa_lobe_envelope_at_speeds() -> None:
    # the envelope on a speed grid never dips below the absolute limit and touches it (±0.5 %)
    exact = 2 * K * 0.011 * 1.011 / (2 * 2e8 / 4)
    res = zoa_lobes(ONE_DOF, 2, 6e8, 2e8, 0.0, math.pi, np.linspace(5000, 25000, 401))
    assert np.nanmin(res.critical_depth_m) >= exact * (1 - 1e-4)
    assert np.nanmin(res.critical_depth_m) == pytest.approx(exact, rel=5e-3)
    # chatter above the natural frequency, ω_n √(1+2ζ) at the minimum (Tlusty)
    assert res.chatter_hz[res.min_index] == pytest.approx(922 * math.sqrt(1.022), rel=5e-3)


def test_tlusty_single_mode() -> None:
    # b_lim = 2kζ(1+ζ)/K_f at ω_n √(1+2ζ) (benchmarks.md §3)
    md = Mode.from_stiffness(500.0, 0.02, 3e7)
    f = np.linspace(300, 700, 400001)
    b, fc = tlusty_limit(md.frf(f), f, 2e9)
    assert b == pytest.approx(2 * 3e7 * 0.02 * 1.02 / 2e9, rel=1e-6)
    assert fc == pytest.approx(500 * math.sqrt(1.04), abs=0.01)


def test_two_mode_orthogonal_example() -> None:
    # benchmarks.md §3: 7.19 mm at about 253 Hz (± 1 %)
    modes = [
        OrientedMode(Mode.from_stiffness(250.0, 0.012, 2.26e8), math.radians(30.0)),
        OrientedMode(Mode.from_stiffness(150.0, 0.010, 2.13e8), math.radians(-45.0)),
    ]
    f = np.linspace(50.0, 600.0, 55001)
    G = oriented_frf(modes, f)
    b, fc = tlusty_limit(G, f, 1e9)
    assert b * 1e3 == pytest.approx(7.19, rel=0.01)
    assert fc == pytest.approx(253.0, rel=0.01)
    # the lobe bottoms touch the absolute limit
    assert orthogonal_curves(G, f, 1e9, 1000.0).min_depth(1000.0, 20000.0)[0] == pytest.approx(
        b, rel=1e-9
    )
