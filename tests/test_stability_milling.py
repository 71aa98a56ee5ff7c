"""Milling/turning DDE builders against independent computations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.stability.lobes import critical_depth, sdm_lobes
from millsense.stability.milling import (
    immersion_angles,
    milling_dde,
    tooth_delays,
    turning_dde,
    windowed_trig_means,
)
from millsense.stability.modal import ModalModel, Mode, OrientedMode, oriented_frf
from millsense.stability.zoa import orthogonal_curves, zoa_lobes


def test_immersion_angles() -> None:
    # benchmarks.md §1 formulas
    assert immersion_angles(5.0, 10.0, "down") == pytest.approx((math.pi / 2, math.pi))
    assert immersion_angles(1.0, 10.0, "up") == pytest.approx((0.0, math.acos(0.8)))
    with pytest.raises(ValueError):
        immersion_angles(11.0, 10.0, "down")


def test_step_means_are_exact_window_averages() -> None:
    # closed-form step means vs a fine midpoint quadrature of g(φ)·(sin², sin cos, cos²), for
    # steps straddling entry and exit and several revolutions (the decision: average, not sample)
    st, ex = immersion_angles(0.5, 10.0, "down")
    a = np.array([st - 0.05, 3.1, 2.0 * math.pi + st - 0.01, 0.3, 7.0])
    b = a + 0.1
    got = windowed_trig_means(a, b, st, ex)
    for i in range(a.size):
        phi = np.linspace(a[i], b[i], 200001)
        mid = 0.5 * (phi[1:] + phi[:-1])
        g = ((np.mod(mid, 2 * math.pi) > st) & (np.mod(mid, 2 * math.pi) < ex)).astype(float)
        ref = [
            np.mean(g * np.sin(mid) ** 2),
            np.mean(g * np.sin(mid) * np.cos(mid)),
            np.mean(g * np.cos(mid) ** 2),
        ]
        np.testing.assert_allclose(got[i], ref, atol=2e-5)


def test_variable_pitch_delays() -> None:
    # tooth j follows tooth j-1 by p_{j-1}: delays are the rolled pitches over Ω
    omega = 2 * math.pi * 100.0
    p = np.radians([80.0, 100.0, 80.0, 100.0])
    np.testing.assert_allclose(tooth_delays(p, omega), np.roll(p, 1) / omega)
    fam = milling_dde(
        ModalModel(x=(Mode.from_stiffness(900, 0.02, 1e6),)), 4, 6e8, 2e8, 0, math.pi, 6000.0, 10, p
    )
    assert fam.H.shape[1] == 4 and fam.period == pytest.approx(0.01)


def test_two_dof_four_flute_slotting_agrees_with_zoa() -> None:
    # with 4 teeth in a slot the summed directional matrix is almost constant, so SDM and ZOA
    # must agree closely: checks the 2x2 directional matrix (incl. cross terms) of both
    st = ModalModel(
        x=(Mode.from_stiffness(922, 0.011, 1.34e6),), y=(Mode.from_stiffness(700, 0.02, 1.0e6),)
    )
    rpm = np.array([9000.0, 10500.0, 12000.0])

    def fam(n: float, m: int):  # type: ignore[no-untyped-def]
        return milling_dde(st, 4, 6e8, 2e8, 0.0, math.pi, n, m)

    res = sdm_lobes(
        fam, rpm, lambda f: np.abs(st.frf(f)).max(axis=(-2, -1)), 3000.0, 20, extrapolate=True
    )
    z = zoa_lobes(st, 4, 6e8, 2e8, 0.0, math.pi, rpm)
    np.testing.assert_allclose(res.critical_depth_m, z.critical_depth_m, rtol=3e-3)


def test_turning_sdm_converges_to_tlusty() -> None:
    # constant-coefficient DDE: the SDM boundary at a lobe bottom equals Tlusty's 7.19 mm case
    modes = [
        OrientedMode(Mode.from_stiffness(250.0, 0.012, 2.26e8), math.radians(30.0)),
        OrientedMode(Mode.from_stiffness(150.0, 0.010, 2.13e8), math.radians(-45.0)),
    ]
    f = np.linspace(50.0, 600.0, 20001)
    b, n = orthogonal_curves(oriented_frf(modes, f), f, 1e9, 1000.0).min_depth(1000.0, 20000.0)
    cp = critical_depth(turning_dde(modes, 1e9, n, 100), 5e-3, 1.0)
    assert cp.depth == pytest.approx(b, rel=2e-3)
    assert cp.bifurcation == "hopf"
