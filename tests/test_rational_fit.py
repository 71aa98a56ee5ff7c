"""Rational fit: poles far above the fitted band are folded into the constant."""

from __future__ import annotations

import numpy as np

from millsense.estimation.kalman.rational_fit import FAR_POLE_RATIO, RationalFit, fit_rational


def test_far_pole_folded_into_constant() -> None:
    # two in-band modes (40, 120 Hz) plus a real pole at 30 kHz with a residue that is a
    # 5 % constant in band (ρ/(s − p) ≈ −ρ/p): the fit over 3-260 Hz must keep no pole above
    # FAR_POLE_RATIO x 2π·260 rad/s and still match the FRF within 1 % (decision "Rational
    # fit: poles far above the band"; the pole's in-band variation is < 1 % of its value)
    p_far = -2 * np.pi * 30_000.0
    w1, w2 = 2 * np.pi * 40.0, 2 * np.pi * 120.0
    truth = RationalFit(
        np.array([-0.03 * w1 + 1j * w1, -0.02 * w2 + 1j * w2]),
        np.array([-50.0j * 1.0, -200.0j]),
        np.array([p_far]),
        np.array([0.05 * -p_far]),
        1.0,
        0.0,
    )
    f = np.arange(3.0, 261.0, 1.0)
    h = truth.continuous_frf(f)
    fit = fit_rational(f, h)
    limit = FAR_POLE_RATIO * 2 * np.pi * 260.0
    assert np.all(np.abs(fit.real_poles) <= limit)
    assert np.all(np.abs(fit.complex_poles) <= limit)
    err = np.abs(fit.continuous_frf(f) / h - 1)
    assert float(err.max()) < 0.01
