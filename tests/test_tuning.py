"""Automatic tuning of the disturbance Kalman filter (R from an air cut, Q by optimisation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.estimation.feed.estimator import measurement_model
from millsense.estimation.feed.tuning import _design, air_cut_variance, noise_gain, tune_q
from millsense.estimation.kalman.design import bandwidth_3db, compensated_frf
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.validation.cases._thesis_models import aslan_disturbance_modes


def test_air_cut_variance_removes_trend_and_offset() -> None:
    # white noise σ = 0.3 N·m on a 1.7 N·m friction level with a 0.3 Hz drift: R = σ² = 0.09
    # within 4 % (sampling error of a variance over 20 000 samples is ~1 %)
    rng = np.random.default_rng(0)
    n = 20000
    t = np.arange(n) / 1e4
    x = 1.7 + 0.5 * np.sin(2 * math.pi * 0.3 * t) + rng.normal(0, 0.3, n)
    assert air_cut_variance(x) == pytest.approx(0.09, rel=0.04)


def test_air_cut_variance_rejects_short_record() -> None:
    with pytest.raises(InputDataError):
        air_cut_variance(np.zeros(10))


def test_noise_gain_equals_impulse_response_energy() -> None:
    # independent: run the frozen-gain filter on a unit impulse and sum the squared outputs
    model = measurement_model(RationalFit.from_modes(aslan_disturbance_modes("c")), 600.0, 1e-4)
    d = _design(model, 5000.0, 0.2)
    filt = d.filter("filtered")
    x = np.zeros(filt.n_states)
    h = []
    for k in range(20000):
        u = 1.0 if k == 0 else 0.0
        h.append(float(filt.h[0] @ x + filt.j[0, 0] * u))
        x = filt.f @ x + filt.g[:, 0] * u
    assert noise_gain(d) == pytest.approx(math.sqrt(sum(v * v for v in h)), rel=1e-6)


def test_tune_q_is_the_best_admissible_grid_point_or_better() -> None:
    # the optimiser's Q must (a) respect the noise limit and (b) give a bandwidth at least that
    # of every admissible point of a fresh grid (optimality up to the grid), on the C axis
    # Table 3.4 model with R of Eq. 3.30
    model = measurement_model(RationalFit.from_modes(aslan_disturbance_modes("c")), 600.0, 1e-4)
    r = 1.4903
    res = tune_q(model, r, bounds=(10.0, 1e6), n_grid=11)
    assert res.noise_gain <= math.sqrt(10.0) + 1e-9
    f = np.linspace(0, 1000, 2001)
    for q in np.geomspace(10.0, 1e6, 7):
        d = _design(model, float(q), r)
        if noise_gain(d) <= math.sqrt(10.0):
            assert res.bandwidth_hz >= bandwidth_3db(f, compensated_frf(model, d, f)) - 1e-6
    # and it beats the thesis's hand-tuned Q = 10 000 with the same R (Eq. 3.30), whose noise
    # gain is inside the limit as well
    d_thesis = _design(model, 1e4, r)
    if noise_gain(d_thesis) <= math.sqrt(10.0):
        assert res.bandwidth_hz >= bandwidth_3db(f, compensated_frf(model, d_thesis, f)) - 1e-6
