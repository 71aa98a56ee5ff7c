"""Steady-state Kalman toolkit: discretisation, gains, statistics, runtime, FRF helpers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, linalg, signal

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.estimation.kalman.block import KalmanBlock
from millsense.estimation.kalman.design import (
    StateSpaceModel,
    augment_disturbance,
    bandwidth_3db,
    compensated_frf,
    continuous_kalman_filter,
    design_kalman,
    discretize_zoh,
    van_loan,
)
from millsense.estimation.kalman.lti_filter import LinearFilter, StreamingFilter, real_modal_form
from millsense.streaming.block import Chunk
from millsense.validation.cases._thesis_models import aslan_disturbance_model, aslan_r_q

DT = 1e-4


def _c_axis_design():
    m = aslan_disturbance_model("c")
    r, q = aslan_r_q("c")
    return m, design_kalman(augment_disturbance(m), q, r, dt=DT)


def _small_design(q: float = 1e4, r: float = 0.5):
    m = aslan_disturbance_model("c", slice(2))
    return m, design_kalman(augment_disturbance(m), q, r, dt=DT)


def _simulate(design, n: int, seed: int):
    """Sample the discrete augmented model (x⁺ = A x + w, y = C x + v) with scipy's dlsim."""
    rng = np.random.default_rng(seed)
    lam, vec = np.linalg.eigh(design.qd)
    sq = vec @ np.diag(np.sqrt(np.clip(lam, 0.0, None)))
    nx = design.n_states
    xi = rng.standard_normal((n, nx))
    sys = (design.a, sq, np.eye(nx), np.zeros((nx, nx)), DT)
    _, _, x = signal.dlsim(sys, xi, x0=np.zeros(nx))
    v = rng.standard_normal(n) * np.sqrt(design.r[0, 0])
    y = x @ design.c[0] + v
    return x, y


def _batch_se_of_mean(x: np.ndarray, n_batches: int = 20) -> float:
    """Standard error of the mean of a correlated sequence by batch means."""
    b = x[: len(x) // n_batches * n_batches].reshape(n_batches, -1).mean(axis=1)
    return float(b.std(ddof=1) / np.sqrt(n_batches))


def test_zoh_matches_numerical_integral() -> None:
    m = aslan_disturbance_model("c")
    d = discretize_zoh(m, DT)
    # B_d = ∫₀^dt e^{Aτ} B dτ, integrated numerically (independent of the block-expm trick)
    bd, _ = integrate.quad_vec(lambda t: linalg.expm(m.a * t) @ m.b, 0.0, DT, epsabs=1e-14)
    np.testing.assert_allclose(d.b, bd, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(d.a, linalg.expm(m.a * DT), rtol=1e-12, atol=1e-14)


def test_van_loan_matches_numerical_integral() -> None:
    aug = augment_disturbance(aslan_disturbance_model("c"))
    q = 1e4
    ad, qd = van_loan(aug.a, aug.g, q, DT)

    def integrand(t: float) -> np.ndarray:
        e = linalg.expm(aug.a * t)
        return e @ aug.g @ (q * aug.g.T) @ e.T

    ref, _ = integrate.quad_vec(integrand, 0.0, DT, epsabs=1e-16, epsrel=1e-12)
    # closed form check of the dominant entry: the random walk accumulates q·dt
    assert qd[-1, -1] == pytest.approx(q * DT, rel=1e-12)
    np.testing.assert_allclose(qd, ref, rtol=1e-8, atol=1e-12 * np.max(np.abs(ref)))
    np.testing.assert_allclose(ad, linalg.expm(aug.a * DT), rtol=1e-12, atol=1e-14)


def test_steady_gain_is_limit_of_riccati_recursion() -> None:
    _, d = _c_axis_design()
    # iterate the discrete covariance recursion (prior form) from P = Q_d
    p = d.qd.copy()
    c, r = d.c, d.r
    for _ in range(30000):
        s = c @ p @ c.T + r
        p = d.a @ (p - p @ c.T @ np.linalg.solve(s, c @ p)) @ d.a.T + d.qd
    kf = p @ c.T @ np.linalg.inv(c @ p @ c.T + r)
    # the recursion converges geometrically (slowest closed-loop pole 0.9986): after 30000
    # steps the remaining difference is round-off
    np.testing.assert_allclose(d.p_prior, p, rtol=1e-7, atol=1e-9 * np.max(np.abs(p)))
    np.testing.assert_allclose(d.k_filter, kf, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(d.k_predictor, d.a @ kf, rtol=1e-7, atol=1e-9)
    assert np.max(np.abs(np.linalg.eigvals(d.closed_loop))) < 1.0


def test_innovation_is_white_with_predicted_covariance() -> None:
    _, d = _small_design()
    n = 200_000
    _, y = _simulate(d, n, seed=3)
    sf = StreamingFilter(d.filter("predicted", innovation=True))
    e = sf.process(y)[:, -1][2000:]
    s_theory = d.innovation_covariance[0, 0]
    # variance of a white Gaussian sample: relative SE sqrt(2/N); 4 SE
    tol = 4 * np.sqrt(2.0 / len(e))
    assert np.var(e) / s_theory == pytest.approx(1.0, abs=tol)
    # normalised autocorrelation at lags 1..20 is N(0, 1/N) for a white sequence; 4.5 sigma
    e0 = e - e.mean()
    denom = float(e0 @ e0)
    rho = np.array([float(e0[k:] @ e0[:-k]) / denom for k in range(1, 21)])
    assert np.max(np.abs(rho)) < 4.5 / np.sqrt(len(e))


def test_filtered_error_variance_matches_posterior_covariance() -> None:
    _, d = _small_design()
    x, y = _simulate(d, 200_000, seed=5)
    est = StreamingFilter(d.filter("filtered")).process(y)[:, 0]
    err2 = (x[:, -1] - est)[5000:] ** 2
    theory = d.p_filtered[-1, -1]
    # tolerance: 4 standard errors of the mean squared error (batch means, correlated errors)
    assert np.mean(err2) == pytest.approx(theory, abs=4 * _batch_se_of_mean(err2))


def test_modal_and_dense_kernels_agree_and_are_chunk_invariant() -> None:
    _, d = _c_axis_design()
    filt = d.filter("filtered", np.eye(d.n_states), innovation=True)
    y = np.random.default_rng(0).normal(size=3000) + np.sin(np.arange(3000) * 0.05)
    dense = StreamingFilter(filt, "dense").process(y)
    modal = StreamingFilter(filt, "modal")
    assert modal.realisation == "modal"
    whole = modal.process(y)
    # same system in another basis: agreement to round-off relative to the signal size
    np.testing.assert_allclose(whole, dense, rtol=0, atol=1e-9 * np.max(np.abs(dense)))
    for size in (1, 7, 100):
        modal.reset()
        parts = [modal.process(y[i : i + size]) for i in range(0, len(y), size)]
        np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_real_modal_form_reproduces_matrix() -> None:
    _, d = _c_axis_design()
    t, diag, off, partner = real_modal_form(d.closed_loop)
    mm = np.diag(diag)
    for i, j in enumerate(partner):
        if j != i:
            mm[i, j] = off[i]
    np.testing.assert_allclose(t @ mm @ np.linalg.inv(t), d.closed_loop, atol=1e-10)


def test_filter_frf_matches_sine_response() -> None:
    # the LTI filter's FRF must equal the steady-state amplitude/phase of its time response
    _, d = _c_axis_design()
    filt = d.filter("filtered")
    f0 = 83.0
    k = np.arange(40000)
    y = np.cos(2 * np.pi * f0 * k * DT)
    out = StreamingFilter(filt).process(y)[:, 0][20000:]
    h = filt.frf(f0)[0, 0, 0]
    expect = np.abs(h) * np.cos(2 * np.pi * f0 * k[20000:] * DT + np.angle(h))
    np.testing.assert_allclose(out, expect, atol=1e-6 * np.abs(h))


def test_harmonic_augmentation_has_resonator_transfer() -> None:
    m = aslan_disturbance_model("c", slice(1))
    ft = 120.0
    aug = augment_disturbance(m, harmonic_hz=ft)
    assert aug.n_states == 5
    # τ_AC / w_AC = s / (s² + ω_t²) (Aslan Eq. 3.18); read from (sI − A_exp)⁻¹ L
    s = 2j * np.pi * 37.0
    w = 2 * np.pi * ft
    tf = aug.disturbance @ np.linalg.solve(s * np.eye(5) - aug.a, aug.g[:, 1])
    assert tf[0] == pytest.approx(s / (s**2 + w**2), rel=1e-12)
    # the plant sees τ_DC + τ_AC through B: measurement from w_DC is Φ_d(s)/s
    tf_dc = aug.c @ np.linalg.solve(s * np.eye(5) - aug.a, aug.g[:, 0])
    assert tf_dc[0] == pytest.approx(m.frf(37.0)[0, 0, 0] / s, rel=1e-10)
    # a filter designed with it is stable and reproduces a constant disturbance
    d = design_kalman(aug, np.diag([1e4, 1e6]), 0.5, dt=DT)
    assert np.max(np.abs(np.linalg.eigvals(d.closed_loop))) < 1.0
    assert compensated_frf(m, d, [0.0])[0] == pytest.approx(1.0, abs=1e-9)


def test_discrete_design_approaches_continuous_eq_3_26() -> None:
    # with R_c = R·dt the sampled-data filter tends to the ZOH-discretised Kalman-Bucy filter of
    # Aslan Eq. 3.26 as dt → 0; at 10 kHz the compensated FRFs agree closely below 150 Hz
    m, d = _c_axis_design()
    r, q = aslan_r_q("c")
    _, filt = continuous_kalman_filter(augment_disturbance(m), q, r * DT, DT)
    f = np.linspace(0.0, 150.0, 151)
    hd = compensated_frf(m, d, f)
    hc = compensated_frf(m, filt, f)
    # magnitudes within 0.5 dB (0.06 linear); the Eq. 3.26 form is one sample behind in phase
    assert np.max(np.abs(np.abs(hd) - np.abs(hc))) < 0.06


def test_static_gain_of_compensated_frf_is_one() -> None:
    # the random-walk state makes the steady state exact: τ̂_a = τ_a for a constant disturbance
    m, d = _c_axis_design()
    assert compensated_frf(m, d, [0.0])[0] == pytest.approx(1.0, abs=1e-9)


def test_bandwidth_3db_of_first_order_lowpass() -> None:
    fc = 100.0
    f = np.linspace(0.0, 1000.0, 100001)
    h = 1.0 / (1.0 + 1j * f / fc)
    # |H| = −3 dB where 1 + (f/fc)² = 10^0.3: f = fc·sqrt(10^0.3 − 1) (closed form)
    expect = fc * np.sqrt(10**0.3 - 1.0)
    assert bandwidth_3db(f, h) == pytest.approx(expect, abs=0.02)
    # a resonance above +3 dB also ends the band
    h2 = 1.0 / (1 - (f / 300.0) ** 2 + 2j * 0.05 * f / 300.0)
    bw = bandwidth_3db(f, h2)
    assert 20 * np.log10(abs(1.0 / (1 - (bw / 300.0) ** 2 + 2j * 0.05 * bw / 300.0))) == (
        pytest.approx(3.0, abs=0.01)
    )


def test_model_and_design_reject_bad_input() -> None:
    with pytest.raises(ValueError, match="inconsistent shapes"):
        StateSpaceModel(np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.zeros((1, 1)))
    aug = augment_disturbance(aslan_disturbance_model("c", slice(1)))
    with pytest.raises(ValueError, match="dt"):
        design_kalman(aug, 1.0, 1.0)
    with pytest.raises(ValueError, match="shape"):
        design_kalman(aug, np.eye(3), 1.0, dt=DT)
    with pytest.raises(ValueError, match="expected"):
        StreamingFilter(
            LinearFilter(np.eye(1) * 0.5, np.ones((1, 2)), np.ones((1, 1)), np.zeros((1, 2)), DT)
        ).process(np.ones(4))


def _block_chunks(block: KalmanBlock, y: np.ndarray, size: int) -> np.ndarray:
    block.reset(1.0 / DT)
    out = []
    for i in range(0, len(y), size):
        ch = Chunk(i, 1.0 / DT, 0.0, {"c/torque": y[i : i + size]})
        out.append(block.process(ch).channels["c/tau_a_est"])
    return np.concatenate(out)


@pytest.mark.parametrize("lag", [0, 60])
def test_kalman_block_chunk_size_invariant(lag: int) -> None:
    _, d = _c_axis_design()
    block = KalmanBlock(
        "kalman_c",
        ["c/torque"],
        [ChannelInfo("c/tau_a_est", "N*m", "C-axis disturbance estimate")],
        d,
        lag=lag,
    )
    y = np.random.default_rng(2).normal(size=1500) + 2.0
    whole = _block_chunks(block, y, len(y))
    for size in (1, 7, 100):
        # filter: bitwise; smoother: lfilter's FIR state is exact too (same operations)
        np.testing.assert_allclose(_block_chunks(block, y, size), whole, rtol=0, atol=1e-12)
    assert block.delay_samples == lag


def test_kalman_block_checks_rate_and_channels() -> None:
    _, d = _c_axis_design()
    out = [ChannelInfo("c/tau_a_est", "N*m")]
    block = KalmanBlock("k", ["c/torque"], out, d)
    with pytest.raises(ConfigError, match="designed for 10000 Hz"):
        block.reset(5000.0)
    with pytest.raises(ConfigError, match="input channels"):
        KalmanBlock("k", ["a", "b"], out, d)


def test_measurement_includes_feedthrough_by_default() -> None:
    # decision "C_exp = [C D]": with D ≠ 0 the disturbance state enters the measurement directly
    m = StateSpaceModel.from_arrays([[-10.0]], [1.0], [2.0], 0.3761)
    assert augment_disturbance(m).c[0].tolist() == [2.0, 0.3761]
    assert augment_disturbance(m, feedthrough=False).c[0].tolist() == [2.0, 0.0]
    # and the compensated FRF of a filter designed on [C D] is exactly 1 at DC
    d = design_kalman(augment_disturbance(m), 100.0, 0.1, dt=DT)
    assert compensated_frf(m, d, [0.0])[0] == pytest.approx(1.0, abs=1e-9)


def test_noise_on_all_states_gives_spindle_form() -> None:
    # Aslan Eq. 5.20 with Q_s = q·I (Table 5.2): Γ = I, so Q_d is full rank and
    # tr Q_d = q·∫ tr(e^{Aτ}e^{Aᵀτ}) dτ; Taylor series of the integrand to second order:
    # q·(n·dt + tr(A)·dt² + tr(A² + 2AAᵀ + Aᵀ²)·dt³/6) + O(dt⁴)
    m = aslan_disturbance_model("c", slice(2))
    aug = augment_disturbance(m, noise_on_all_states=True)
    assert aug.g.shape == (5, 5)
    d = design_kalman(aug, 2e4, 0.378, dt=DT)
    a = aug.a
    f2 = np.trace(a @ a + 2 * a @ a.T + a.T @ a.T)
    expect = 2e4 * (5 * DT + np.trace(a) * DT**2 + f2 * DT**3 / 6)
    assert np.trace(d.qd) == pytest.approx(expect, rel=1e-7)
    assert np.linalg.matrix_rank(d.qd) == 5
    assert compensated_frf(m, d, [0.0])[0] == pytest.approx(1.0, abs=1e-6)


def test_output_covariance_equals_impulse_response_sum() -> None:
    # Independent check: W = Σ_k F^k G Σ Gᵀ (F^k)ᵀ summed directly, for a filter with a pole at
    # −0.999 (where scipy's default bilinear Lyapunov solver divides by F + I ≈ 0) and a
    # lightly damped pair near z = 1.

    r, th = 0.999, 0.01
    f = np.array(
        [
            [-0.999, 0.0, 0.0],
            [0.0, r * np.cos(th), -r * np.sin(th)],
            [0.0, r * np.sin(th), r * np.cos(th)],
        ]
    )
    g = np.array([[1.0], [0.5], [-0.2]])
    h = np.array([[0.3, 1.0, 0.7]])
    j = np.array([[0.1]])
    filt = LinearFilter(f, g, h, j, 1e-4)
    sigma = np.array([[2.0]])
    w = np.zeros((3, 3))
    fk = np.eye(3)
    for _ in range(40000):  # |λ|^40000 < 1e-17
        w += fk @ g @ sigma @ g.T @ fk.T
        fk = fk @ f
    expected = h @ w @ h.T + j @ sigma @ j.T
    np.testing.assert_allclose(filt.output_covariance(sigma), expected, rtol=1e-9)


def test_filter_frf_in_the_eigenbasis_equals_the_direct_solve() -> None:
    """``LinearFilter.frf`` evaluates in the eigenbasis of F (O(n) per frequency) and falls back
    to the direct solve for a defective F (a Jordan block: eigenvectors nearly parallel); both
    against ``H (zI − F)⁻¹ G + J`` solved frequency by frequency in the test."""
    from millsense.estimation.kalman.lti_filter import LinearFilter

    rng = np.random.default_rng(4)
    n = 12
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    good = q @ np.diag(rng.uniform(-0.95, 0.95, n)) @ q.T
    jordan = 0.9 * np.eye(n) + np.diag(np.ones(n - 1), 1)  # one eigenvalue, one eigenvector
    f_hz = np.linspace(1.0, 2400.0, 300)
    for fmat in (good, jordan):
        lf = LinearFilter(fmat, rng.normal(size=(n, 2)), rng.normal(size=(3, n)),
                          rng.normal(size=(3, 2)), 2e-4)  # fmt: skip
        z = np.exp(2j * np.pi * f_hz * lf.dt)
        want = np.array([lf.h @ np.linalg.solve(zi * np.eye(n) - lf.f, lf.g) + lf.j for zi in z])
        got = lf.frf(f_hz)
        assert got.shape == (300, 3, 2)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_state_space_frf_is_the_per_frequency_solve_bit_for_bit() -> None:
    """``StateSpaceModel.frf`` solves all frequencies in one batched LU call (the Q tuning
    evaluates it hundreds of times); LAPACK's gesv runs per frequency as in a loop of single
    solves, so the result is the loop's to the last bit (tolerance 0), continuous and discrete,
    with exact zeros in A (their signs reach the LU)."""
    rng = np.random.default_rng(11)
    f_hz = np.linspace(0.5, 1000.0, 97)
    for dt in (None, 1e-4):
        a = rng.normal(size=(14, 14)) * 300.0
        a[rng.random((14, 14)) < 0.4] = 0.0
        m = StateSpaceModel(a, rng.normal(size=(14, 2)), rng.normal(size=(3, 14)),
                            rng.normal(size=(3, 2)), dt)  # fmt: skip
        s = 2j * np.pi * f_hz if dt is None else np.exp(2j * np.pi * f_hz * dt)
        want = np.array([m.c @ np.linalg.solve(si * np.eye(14) - m.a, m.b) + m.d for si in s])
        got = m.frf(f_hz)
        assert got.shape == (97, 3, 2)
        assert np.array_equal(got.view(np.float64), want.view(np.float64))
    # a given plant FRF (what a tuning passes for every Q it tries) changes nothing
    m, d = _c_axis_design()
    h = compensated_frf(m, d, f_hz)
    assert np.array_equal(h, compensated_frf(m, d, f_hz, plant_frf=m.frf(f_hz)))
