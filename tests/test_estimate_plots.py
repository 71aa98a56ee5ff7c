"""Scales of the estimate-vs-truth plot (report.estimate_plots)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.report.estimate_plots import FULL_PERCENTILES, value_limits


def test_value_limits_span_the_cut_not_the_rapid_move_spikes() -> None:
    # a ±50 N cut of 100 000 samples with 20 spikes of 10 kN (inertia at rapid accelerations):
    # the whole-record scale must follow the cut (5 % margin), the full range the spikes
    rng = np.random.default_rng(0)
    est = 50.0 * np.sin(np.arange(100_000) / 30.0) + rng.normal(0, 1.0, 100_000)
    est[::5000] = 1.0e4
    lo, hi = value_limits([est], FULL_PERCENTILES)
    assert -60.0 < lo < -50.0 and 50.0 < hi < 60.0
    lo_all, hi_all = value_limits([est])
    assert hi_all == pytest.approx(1.0e4 + 0.05 * (1.0e4 - est.min()))
    assert lo_all == pytest.approx(est.min() - 0.05 * (1.0e4 - est.min()))


def test_value_limits_of_constant_empty_and_nan_series() -> None:
    assert value_limits([np.full(10, 3.0)]) == (2.0, 4.0)
    assert value_limits([np.empty(0)]) == (-1.0, 1.0)
    assert value_limits([np.array([np.nan, 1.0, 3.0])]) == pytest.approx((0.9, 3.1))
