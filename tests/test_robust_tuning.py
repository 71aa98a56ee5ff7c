"""Robust feed-estimator design for position-dependent modes (issue 7): tuning.tune_robust."""

from __future__ import annotations

import math

import numpy as np
import pydantic
import pytest
from scipy import integrate

from millsense.core.config import FeedAxisConfig, FeedEstimatorConfig
from millsense.estimation.feed import tuning
from millsense.estimation.feed.estimator import FeedAxisModel, measurement_model
from millsense.estimation.kalman.design import StateSpaceModel, augment_disturbance, design_kalman
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.estimation.kalman.smoother import FixedLagSmoother
from millsense.simulator.machine_file import simulator_machine
from millsense.validation.cases._thesis_models import aslan_disturbance_modes

DT = 1e-4


def _meas(fit: RationalFit) -> StateSpaceModel:
    return measurement_model(fit, 600.0, DT)


def test_mode_family_scales_frequencies_and_keeps_static_gain() -> None:
    # Table 3.4 Y: κ·p, κ·ρ keeps every term's static gain ρ/(−p) + c.c. (closed form), so the
    # family's DC gain equals the nominal one to rounding, and the members span exactly ±2 %
    fit = RationalFit.from_modes(aslan_disturbance_modes("y"))
    fam = tuning.mode_family(fit, 0.02, 5)
    assert len(fam) == 5
    f0 = np.abs(fit.complex_poles)
    assert np.abs(fam[0].complex_poles) / f0 == pytest.approx(np.full(len(f0), 0.98), rel=1e-12)
    assert np.abs(fam[-1].complex_poles) / f0 == pytest.approx(np.full(len(f0), 1.02), rel=1e-12)
    assert fam[2].complex_poles == pytest.approx(fit.complex_poles, rel=1e-15)
    g0 = fit.continuous_frf([0.0])[0]
    for m in fam:
        assert m.continuous_frf([0.0])[0] == pytest.approx(g0, rel=1e-12)


def test_robust_fit_is_the_cauchy_mean_of_a_mode_with_uncertain_frequency() -> None:
    # closed form checked by quadrature: E_ε[ρ/(s − p − j|p|ε) + c.c.] with ε ~ Cauchy(0, γ)
    # equals the robust_fit term (pole moved left by γ|p|), at several s = j2πf
    p, rho, gamma = complex(-0.004 * 2 * math.pi * 86.0, 2 * math.pi * 86.0), 3.0 - 40.0j, 0.01
    fit = RationalFit(np.array([p]), np.array([rho]), np.zeros(0), np.zeros(0), 1.0, 0.0)
    rob = tuning.robust_fit(fit, gamma)
    for f in (40.0, 84.0, 86.0, 88.5, 200.0):
        s = 2j * math.pi * f

        def term(eps: float, part: int, s: complex = s) -> float:
            w = gamma / (math.pi * (eps**2 + gamma**2))
            h = rho / (s - p - 1j * abs(p) * eps) + np.conj(rho) / (
                s - np.conj(p) + 1j * abs(p) * eps
            )
            return float((h.real if part == 0 else h.imag) * w)

        re = integrate.quad(term, -np.inf, np.inf, args=(0,), limit=400, epsabs=1e-12)[0]
        im = integrate.quad(term, -np.inf, np.inf, args=(1,), limit=400, epsabs=1e-12)[0]
        expected = rob.continuous_frf([f])[0] - 1.0
        assert complex(re, im) == pytest.approx(expected, rel=1e-6, abs=1e-9)


def test_estimator_frf_matches_the_streaming_smoother() -> None:
    # independent: run the streaming fixed-lag smoother on a 37 Hz cosine and read the complex
    # amplitude of its realigned output by least squares (steady state: 2 s, the slowest filter
    # pole has decayed by e⁻⁸; agreement to 1e-6 means the analytic smoother is exact)
    fit = RationalFit.from_modes(aslan_disturbance_modes("x"))
    d = design_kalman(augment_disturbance(_meas(fit)), 2000.0 * DT, 0.03)
    f0, lag, n = 37.0, 60, 30000
    k = np.arange(n)
    out = FixedLagSmoother(d, lag).process(np.cos(2 * math.pi * f0 * k * DT)[:, None])[:, 0]
    t = k[20000 : n - lag] * DT
    basis = np.column_stack([np.cos(2 * math.pi * f0 * t), np.sin(2 * math.pi * f0 * t)])
    c = np.linalg.lstsq(basis, out[20000 + lag :], rcond=None)[0]
    measured = complex(c[0], -c[1])
    assert tuning.estimator_frf(d, [f0], lag)[0] == pytest.approx(measured, rel=1e-6)
    # lag 0 is the filtered estimate of KalmanDesign.filter (the per-frequency solve)
    ref = d.filter("filtered").frf([f0, 150.0])[:, 0, 0]
    assert tuning.estimator_frf(d, [f0, 150.0]) == pytest.approx(ref, rel=1e-10)


def test_flatness_bound_closed_form() -> None:
    # two constant plants |Φ| = 1 and 2: the best gain is 1/√2 and both members sit
    # ½·20·log10(2) = 3.0103 dB off; a 1.8× pair stays inside ±3 dB everywhere
    f = np.linspace(0.0, 100.0, 101)
    worst, band = tuning.flatness_bound(np.array([np.ones(101), 2 * np.ones(101)]), f, 50.0)
    assert worst == pytest.approx(10 * math.log10(2.0), rel=1e-12)
    assert band == 1.0
    worst, band = tuning.flatness_bound(np.array([np.ones(101), 1.8 * np.ones(101)]), f, 50.0)
    assert worst == pytest.approx(10 * math.log10(1.8), rel=1e-12) and band == 100.0


def test_robust_design_beats_the_nominal_design_on_the_family() -> None:
    # Table 3.4 Z (ζ 0.3 % at 183 Hz: at −2 % it enters the 180 Hz band): the design on the
    # identified modes keeps a common ±3 dB band of only ~43 Hz over modes ±2 %, the robust one
    # (Q and design damping) reaches the LTI limit of flatness_bound, ~144 Hz; its worst
    # deviation to 180 Hz over the family is lower, yet never below the bound (no LTI estimator
    # can beat it). Numbers from this grid: robust 143.6 Hz / 11.7 dB, nominal 42.8 / 13.9 dB.
    fit = RationalFit.from_modes(aslan_disturbance_modes("z"))
    kw = dict(shift=0.02, n_family=5, q_per_decade=2, bounds=(100.0, 1e4), f_max_hz=400.0)
    rob = tuning.tune_robust(fit, _meas, 0.05, damping_fractions=(0.0, 0.25, 0.5), **kw)
    nom = tuning.tune_robust(fit, _meas, 0.05, damping_fractions=(0.0,), **kw)
    assert nom.damping == 0.0 and rob.damping > 0.0
    assert rob.worst_db < nom.worst_db - 1.0
    assert rob.bandwidth_hz > 3.0 * nom.bandwidth_hz
    assert (
        rob.bandwidth_hz <= rob.bound_band_hz + 0.1 and rob.bandwidth_hz > 0.98 * rob.bound_band_hz
    )
    assert rob.worst_db >= rob.bound_db - 1e-9
    assert rob.noise_gain <= math.sqrt(10.0)


def test_mode_shift_pct_key_default_and_nominal_switch() -> None:
    # [axes.x.estimator] mode_shift_pct: default 0 = nominal tune_q (damping 0; decision
    # "Robust feed estimator ... default nominal"); 2 % = robust: with q fixed by the user only
    # the design damping is chosen, from the tried fractions of δ
    assert FeedEstimatorConfig().mode_shift_pct == 0.0
    with pytest.raises(pydantic.ValidationError):
        FeedEstimatorConfig(mode_shift_pct=-1.0)
    cfg = simulator_machine("quaser-ux600").axes["x"]
    fixed = FeedAxisConfig.model_validate(
        cfg.model_dump() | {"estimator": {"q_nm2_s": 800.0, "mode_shift_pct": 2.0}}
    )
    m = FeedAxisModel.from_config("x", fixed, sample_rate_hz=1e4)
    assert m.q == 800.0
    assert m.design_damping in [f * 0.02 for f in tuning.DAMPING_FRACTIONS]
    off = FeedAxisConfig.model_validate(
        cfg.model_dump() | {"estimator": {"q_nm2_s": 800.0, "mode_shift_pct": 0.0}}
    )
    m0 = FeedAxisModel.from_config("x", off, sample_rate_hz=1e4)
    assert m0.design_damping == 0.0 and m0.q == 800.0
