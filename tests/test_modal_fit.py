"""Automated modal fitting (millsense.ident.modal_fit) and its plots."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from millsense.core.errors import InputDataError
from millsense.ident.modal_fit import FittedMode, fit_batch, fit_modes
from millsense.stability.modal import Mode, frf_sum

# three modes in α/β form (Eq. 3.13) with velocity residues, one sign-changing residue
TRUE = [
    Mode.from_residues(40.0, 0.03, 2000.0, 5.0),
    Mode.from_residues(55.0, 0.02, 6000.0, -8.0),
    Mode.from_residues(120.0, 0.05, -9000.0, 20.0),
]
F = np.arange(10.0, 200.0, 0.5)


def test_noiseless_fit_recovers_modes_exactly() -> None:
    fit = fit_modes((F, frf_sum(TRUE, F)), (10.0, 200.0), max_modes=6)
    assert fit.diagram is not None and fit.diagram.selected == 3  # lowest exact order
    assert len(fit.modes) == 3
    for m, t in zip(fit.to_modes(), TRUE, strict=True):
        # exact data, exact model class: round-off only
        assert m.omega == pytest.approx(t.omega, rel=1e-7)
        assert m.zeta == pytest.approx(t.zeta, rel=1e-6)
        assert m.alpha == pytest.approx(t.alpha, rel=1e-6)
        assert m.beta == pytest.approx(t.beta, rel=1e-5, abs=1e-6)
    assert abs(fit.residual) < 1e-8 and fit.rms_error < 1e-8


@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")  # companion form, on purpose
def test_state_space_is_modal_blocks_and_well_conditioned() -> None:
    fit = fit_modes((F, frf_sum(TRUE, F)), (10.0, 200.0), n_modes=3)
    ss = fit.state_space()
    a_ss, b_ss, c_ss, d_ss = ss.dense()
    A, B, C = a_ss, b_ss.reshape(-1, 1), c_ss.reshape(1, -1)
    assert A.shape == (6, 6)
    off = A.copy()
    for k in range(0, 6, 2):
        off[k : k + 2, k : k + 2] = 0
    assert np.all(off == 0)  # block diagonal 2×2
    # realisation reproduces Eq. 3.13: C (sI − A)⁻¹ B + D against the modal sum
    s = 2j * np.pi * F
    h_ss = np.array([(C @ np.linalg.solve(si * np.eye(6) - A, B))[0, 0] for si in s])
    assert np.max(np.abs(h_ss + d_ss - frf_sum(TRUE, F)) / np.abs(frf_sum(TRUE, F))) < 1e-8
    assert np.max(np.abs(ss.frf(F) - h_ss - d_ss)) < 1e-9 * np.max(np.abs(h_ss))
    # well conditioned: eigenvector matrix of the modal form vs the companion form of the
    # same transfer function (Aslan Appendix A is a scaled companion form)
    num, den = scipy.signal.ss2tf(A, B, C, np.array([[d_ss]]))
    a_comp = scipy.signal.tf2ss(num[0], den)[0]
    cond_modal = np.linalg.cond(np.linalg.eig(A)[1])
    cond_comp = np.linalg.cond(np.linalg.eig(a_comp)[1])
    assert cond_modal < 1.1  # 2×2 rotation blocks: near-orthogonal eigenvectors
    assert cond_comp > 1e6  # companion form: Vandermonde eigenvectors


def test_mode_round_trip_alpha_beta() -> None:
    for t in TRUE:
        m = FittedMode.from_mode(t).to_mode()
        assert (m.omega, m.zeta, m.alpha, m.beta) == pytest.approx(
            (t.omega, t.zeta, t.alpha, t.beta), rel=1e-12, abs=1e-12
        )
        # and the pole/residue FRF equals Mode.frf (Eq. 3.13)
        assert np.allclose(FittedMode.from_mode(t).frf(F), t.frf(F), rtol=1e-12, atol=0)


def test_noisy_fit_with_stabilisation_and_band() -> None:
    rng = np.random.default_rng(0)
    extra = Mode.from_residues(400.0, 0.03, 5e5, 0.0)  # outside the band: a residual term
    h = frf_sum([*TRUE, extra], F)
    h = h * (1 + 0.01 * (rng.standard_normal(len(F)) + 1j * rng.standard_normal(len(F))))
    fit = fit_modes((F, h), (20.0, 180.0), max_modes=8)
    assert len(fit.modes) == 3
    for m, t in zip(fit.to_modes(), TRUE, strict=True):
        # 1 % complex noise on 320 lines: frequency to 0.2 %, damping to 5 %
        assert m.omega == pytest.approx(t.omega, rel=2e-3)
        assert m.zeta == pytest.approx(t.zeta, rel=0.05)
    fb = F[(F >= 20) & (F <= 180)]
    db = 20 * np.log10(np.abs(fit.frf(fb)) / np.abs(frf_sum([*TRUE, extra], fb)))
    assert float(np.max(np.abs(db))) < 0.5  # against the truth, not the noisy data
    labels = fit.diagram.labels if fit.diagram else ()
    assert sum(lb == "s" for lb in labels[3]) >= 2  # order 4: true modes already stable


def test_fit_from_simulated_multisine_h1() -> None:
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.validation.cases.ident import simulate_modes

    fs, n_per = 1000.0, 2000
    u, _ = multisine_signal(fs, n_per, 5.0, 250.0, 5, rms=1.0)
    y = simulate_modes(TRUE, u, fs)
    y = y + np.random.default_rng(1).normal(0, 0.02, len(y))
    est = multisine_frf(u, y, fs, n_per)
    fit = fit_modes(est, (10.0, 200.0), max_modes=6)
    assert [round(m.natural_frequency_hz) for m in fit.modes] == [40, 55, 120]
    for m, t in zip(fit.to_modes(), TRUE, strict=True):
        # FOH simulation of Eq. 3.13 is exact for the piecewise-linear input: 0.5 %/8 %
        assert m.omega == pytest.approx(t.omega, rel=5e-3)
        assert m.zeta == pytest.approx(t.zeta, rel=0.08)


def test_batch_and_errors() -> None:
    h = frf_sum(TRUE, F)
    fits = fit_batch([(F, h), (F, 2 * h)], (10.0, 200.0), max_modes=5)
    # linear in the data: doubling the FRF doubles α, leaves ω unchanged
    assert fits[1].modes[1].alpha == pytest.approx(2 * fits[0].modes[1].alpha, rel=1e-6)
    assert fits[1].modes[1].omega == pytest.approx(fits[0].modes[1].omega, rel=1e-9)
    with pytest.raises(InputDataError, match=r"FRF 1 of the batch: only 3 FRF lines"):
        fit_batch([(F, h), (F[:3], h[:3])], (10.0, 200.0))
    with pytest.raises(InputDataError, match=r"band must satisfy"):
        fit_modes((F, h), (200.0, 10.0))


def test_plots_written(tmp_path: object) -> None:
    from pathlib import Path

    from millsense.report.ident_plots import plot_frf_fit, plot_stabilisation

    h = frf_sum(TRUE, F)
    fit = fit_modes((F, h), (10.0, 200.0), max_modes=5)
    p1 = Path(str(tmp_path)) / "frf.png"
    p2 = Path(str(tmp_path)) / "stab.png"
    plot_frf_fit((F, h), fit, p1, truth=(F, h), title="test")
    plot_stabilisation(fit, p2, (F, h))
    # a real figure, not an empty canvas: PNGs of several tens of kB
    assert p1.stat().st_size > 20_000 and p2.stat().st_size > 20_000


def test_quick_ident_validation_cases_pass() -> None:
    from millsense.validation import run_case, select_cases

    cases = [
        c
        for c in select_cases("ident.*", quick_only=True)
        if c.func.__module__ == "millsense.validation.cases.ident"  # items 1-2 only
    ]
    assert len(cases) == 2  # h1_input_noise_bias, stepped_sine_exact
    for c in cases:
        res = run_case(c)
        assert res.passed, (c.id, res)
