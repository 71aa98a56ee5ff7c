"""Fixed-lag smoother (Aslan Appendix B): RTS equivalence, covariance, delay, streaming."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.estimation.kalman.lti_filter import StreamingFilter
from millsense.estimation.kalman.smoother import ASLAN_LAG_SAMPLES, FixedLagSmoother
from test_kalman import DT, _batch_se_of_mean, _c_axis_design, _simulate, _small_design


def _rts_window(design, y: np.ndarray, k: int, lag: int) -> float:
    """Aslan Eq. B.1–B.2 (RTS) over the window k−lag..k, written out independently.

    Forward: steady-state filter from x̂(0|−1) = 0 (the stream's start, as the smoother).
    Backward: x̂_s(t) = x̂(t|t) + K_s (x̂_s(t+1) − A x̂(t|t)), K_s = P_f Aᵀ (A P_f Aᵀ + Q)⁻¹.
    """
    a, c = design.a, design.c
    kf = design.k_filter
    n = design.n_states
    xp = np.zeros(n)
    post = []
    for t in range(k + 1):
        xf = xp + kf[:, 0] * (y[t] - c[0] @ xp)
        post.append(xf)
        xp = a @ xf
    pf = design.p_filtered
    ks = pf @ a.T @ np.linalg.inv(a @ pf @ a.T + design.qd)
    xs = post[k]
    for t in range(k - 1, k - lag - 1, -1):
        xs = post[t] + ks @ (xs - a @ post[t])
    return float(design.disturbance[0] @ xs)


def test_equals_rts_over_a_sliding_window() -> None:
    _, d = _c_axis_design()
    rng = np.random.default_rng(11)
    y = rng.normal(size=400) + np.sin(np.arange(400) * 0.07) * 3.0
    lag = ASLAN_LAG_SAMPLES
    out = FixedLagSmoother(d, lag).process(y)[:, 0]
    for k in (lag, 150, 399):
        # the smoothed value of sample k − lag appears at output index k: delay = lag exactly
        ref = _rts_window(d, y, k, lag)
        assert out[k] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_delay_is_lag() -> None:
    _, d = _c_axis_design()
    sm = FixedLagSmoother(d)
    assert sm.delay_samples == 60
    assert sm.delay_samples * DT * 1e3 == pytest.approx(6.0)  # Aslan Appendix B: 6 ms


def test_lag_zero_is_the_filtered_estimate() -> None:
    _, d = _c_axis_design()
    y = np.random.default_rng(1).normal(size=500)
    a = FixedLagSmoother(d, 0).process(y)[:, 0]
    b = StreamingFilter(d.filter("filtered")).process(y)[:, 0]
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10)


def test_smoothed_error_variance_matches_theory_and_beats_filter() -> None:
    _, d = _small_design()
    x, y = _simulate(d, 200_000, seed=7)
    lag = 60
    sm = FixedLagSmoother(d, lag)
    out = sm.process(y)[:, 0]
    err2 = (x[:-lag, -1] - out[lag:])[5000:] ** 2
    theory = sm.covariance[0, 0]
    # 4 standard errors of the mean (batch means): sample-size tolerance
    assert np.mean(err2) == pytest.approx(theory, abs=4 * _batch_se_of_mean(err2))
    filt = StreamingFilter(d.filter("filtered")).process(y)[:, 0]
    ferr2 = (x[:, -1] - filt)[5000:] ** 2
    assert np.mean(err2) < 0.5 * np.mean(ferr2)  # theory: 1.95 against 7.57
    assert theory < sm.filtered_covariance[0, 0]


def test_smoothed_covariance_decreases_with_lag() -> None:
    _, d = _small_design()
    covs = [FixedLagSmoother(d, lag).covariance[0, 0] for lag in (0, 5, 20, 60)]
    assert np.all(np.diff(covs) < 0)
    # lag 0 is the filtered covariance
    assert covs[0] == pytest.approx(d.p_filtered[-1, -1], rel=1e-10)


def test_chunk_size_invariance() -> None:
    _, d = _c_axis_design()
    y = np.random.default_rng(4).normal(size=1000)
    sm = FixedLagSmoother(d, 60)
    whole = sm.process(y)
    for size in (1, 7, 100):
        sm.reset()
        parts = np.concatenate([sm.process(y[i : i + size]) for i in range(0, len(y), size)])
        np.testing.assert_allclose(parts, whole, rtol=0, atol=1e-12)


def test_negative_lag_rejected() -> None:
    _, d = _small_design()
    with pytest.raises(ValueError, match="lag"):
        FixedLagSmoother(d, -1)
