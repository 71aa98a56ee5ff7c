"""Time-varying measurement Kalman filter (İlme Eq. 3.6–3.14)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.estimation.kalman.time_varying import TimeVaryingKalman


def _ilme_like(n: int, seed: int):
    """Rows H_k that rotate with an angle, as İlme's H(φ_k); 2 measurements, 4 parameters."""
    rng = np.random.default_rng(seed)
    phi = np.cumsum(np.full(n, 2 * np.pi * 0.013))
    h = np.empty((n, 2, 4))
    h[:, 0] = np.column_stack([np.sin(phi), np.cos(phi), np.sin(2 * phi), 1 + 0 * phi])
    h[:, 1] = np.column_stack([-np.cos(phi), np.sin(phi), np.cos(3 * phi), 0.5 + 0 * phi])
    q_true = np.array([700.0, 350.0, 25.0, 35.0])
    z = np.einsum("kmn,n->km", h, q_true) + rng.normal(scale=0.5, size=(n, 2))
    return h, z, q_true


def test_zero_process_noise_equals_batch_least_squares() -> None:
    # with Φ = I and Q = 0 the Kalman filter is recursive least squares: its estimate after N
    # samples is the regularised batch solution (P0⁻¹ + Σ HᵀR⁻¹H)⁻¹ (P0⁻¹ x0 + Σ HᵀR⁻¹z)
    h, z, _ = _ilme_like(3000, 1)
    r = 0.25
    p0 = 100.0
    x0 = np.array([1.0, 2.0, 3.0, 4.0])
    kf = TimeVaryingKalman(4, 0.0, r, x0=x0, p0=p0, n_measurements=2)
    out = kf.process(z, h)
    hh = h.reshape(-1, 4)
    info = np.eye(4) / p0 + hh.T @ hh / r
    ref = np.linalg.solve(info, x0 / p0 + hh.T @ z.reshape(-1) / r)
    np.testing.assert_allclose(out.x[-1], ref, rtol=1e-8)
    pinv = np.linalg.inv(info)
    np.testing.assert_allclose(kf.p, pinv, rtol=0, atol=1e-8 * np.max(np.abs(pinv)))
    np.testing.assert_allclose(out.z_est[-1], h[-1] @ out.x[-1], rtol=1e-12)


def test_nan_measurement_is_skipped() -> None:
    # a NaN sample is a prediction only: with Q = 0 that equals deleting the sample
    h, z, _ = _ilme_like(500, 2)
    z_nan = z.copy()
    z_nan[100:140, 0] = np.nan
    keep = np.ones(500, dtype=bool)
    keep[100:140] = False
    a = TimeVaryingKalman(4, 0.0, 0.25, n_measurements=2).process(z_nan, h)
    b = TimeVaryingKalman(4, 0.0, 0.25, n_measurements=2).process(z[keep], h[keep])
    np.testing.assert_allclose(a.x[-1], b.x[-1], rtol=1e-9)


def test_random_walk_tracks_a_step_in_the_parameters() -> None:
    h, z, q_true = _ilme_like(6000, 3)
    z[3000:] += np.einsum("kmn,n->km", h[3000:], np.array([100.0, 0.0, 0.0, 0.0]))
    kf = TimeVaryingKalman(4, 1e-2, 0.25, n_measurements=2)
    out = kf.process(z, h)
    # after 3000 samples of information the estimate is within the noise (σ 0.5 over
    # thousands of samples gives errors ≪ 1) of the true values before and after the step
    np.testing.assert_allclose(out.x[2999], q_true, atol=1.0)
    np.testing.assert_allclose(out.x[-1], q_true + np.array([100.0, 0, 0, 0]), atol=1.0)


def test_chunk_size_invariance() -> None:
    h, z, _ = _ilme_like(700, 4)
    kf = TimeVaryingKalman(4, 1e-3, 0.25, n_measurements=2)
    whole = kf.process(z, h).x
    for size in (1, 7, 100):
        kf.reset()
        parts = [kf.process(z[i : i + size], h[i : i + size]).x for i in range(0, 700, size)]
        np.testing.assert_allclose(np.concatenate(parts), whole, rtol=1e-12, atol=1e-12)


def test_single_measurement_shapes_and_errors() -> None:
    kf = TimeVaryingKalman(2, 0.0, 1.0)
    h = np.column_stack([np.ones(50), np.arange(50.0)])
    out = kf.process(3.0 + 0.5 * np.arange(50.0), h)
    assert out.x.shape == (50, 2) and out.z_est.shape == (50, 1)
    # noiseless line: estimate converges to (3, 0.5) (exact data, weak prior 1e6)
    np.testing.assert_allclose(out.x[-1], [3.0, 0.5], atol=1e-4)
    with pytest.raises(ValueError, match="expected"):
        kf.process(np.ones(5), np.ones((4, 2)))
