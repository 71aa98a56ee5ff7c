"""Spindle torque observer (issue 7 item 3): identification, observer block, force factor."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from millsense.bench.spindle_commissioning import identify_spindle
from millsense.estimation.kalman.design import StateSpaceModel
from millsense.estimation.kalman.rational_fit import RationalFit, fit_rational
from millsense.estimation.spindle_observer import (
    RESULTANT_FACTOR,
    SpindleTorqueObserver,
    compensated,
    design_observer,
    tune_spindle_q,
)
from millsense.models.modal_ss import ModalStateSpace
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.simulator.spindle import SpindleDriveSim, discrete_disturbance_frf
from millsense.streaming.block import Chunk

FS = 10_000.0


@pytest.fixture(scope="module")
def ident_r1() -> object:
    # simulated at the velocity-loop rate, where the torque is necessarily held over the
    # velocity period: the loop is then exactly LTI, and discrete_disturbance_frf (the ZOH
    # algebra) is its exact FRF to compare the identified model with
    p = SpindleDriveParams.aslan_quaser()
    return identify_spindle(p, velocity_period_s=p.velocity_period_s, current_noise_a=0.0,
                            n_periods=5, sample_rate_hz=1.0 / p.velocity_period_s)  # fmt: skip


def test_rational_fit_keeps_real_poles() -> None:
    # a mode plus a real pole (what a PI loop adds): fitted exactly from noise-free lines
    # (relative RMS error < 1e-6), which fit_modes (complex pairs only) cannot do
    f = np.linspace(1.0, 500.0, 300)
    s = 2j * np.pi * f
    h = 30.0 / (s + 60.0) + (2e4 + 5 * s) / (s**2 + 2 * 0.05 * 900 * s + 900.0**2) + 0.01
    fit = fit_rational(f, h, n_pairs=2)
    assert len(fit.real_poles) >= 1
    assert np.max(np.abs(fit.frf(f) - h) / np.abs(h)) < 1e-6


def test_rational_from_modes_and_realisation_match_table_frf() -> None:
    # pole-residue form and the block realisation reproduce ModalStateSpace.frf (Eq. 3.13)
    modes = ModalStateSpace.from_modes([45.3, 98.9], [0.14, 0.052], [-11820, -1126], [-244, -65.5])
    rf = RationalFit.from_modes(modes)
    f = np.array([0.0, 20.0, 50.0, 120.0])
    np.testing.assert_allclose(rf.frf(f), modes.frf(f), rtol=1e-10)
    np.testing.assert_allclose(rf.continuous_model().frf(f)[:, 0, 0], modes.frf(f), rtol=1e-10)


def test_warped_fit_is_exact_for_a_discrete_system() -> None:
    # Tustin is exact on the warped axis: a 3rd-order discrete system at 5 kHz, fitted from its
    # FRF up to 0.499·fs, is reproduced to 1e-6 relative up to Nyquist
    fs = 5000.0
    b, a = signal.cheby1(3, 1.0, 700.0, fs=fs)
    f = np.linspace(2.0, 0.499 * fs, 600)
    _, h = signal.freqz(b, a, worN=f, fs=fs)
    fit = fit_rational(f, h, n_pairs=2, warped_fs_hz=fs)
    model = fit.discrete_model(1 / fs)
    assert isinstance(model, StateSpaceModel)
    np.testing.assert_allclose(model.frf(f)[:, 0, 0], h, rtol=1e-6)


def test_identified_g_dtau_matches_the_sampled_loop(ident_r1: object) -> None:
    # noise-free simulated sweep → 20-state model within 1 % of the exact sampled-loop FRF
    # (machine.spindle.discrete_disturbance_frf, built independently from the ZOH matrices)
    params = SpindleDriveParams.aslan_quaser()
    f = np.arange(2.0, 2490.0, 7.0)
    true = discrete_disturbance_frf(SpindleDriveSim(params, 5000.0), f)
    model = ident_r1.model  # type: ignore[attr-defined]
    assert model.n_states == 20
    rel = np.abs(model.frf(f)[:, 0, 0] - true) / np.abs(true)
    assert rel.max() < 0.01


def test_tuned_observer_flat_to_nyquist(ident_r1: object) -> None:
    # Nelder-Mead Q_s (one start to keep the test short): the true sampled G_dτ times the
    # observer stays within ±3 dB from 1 Hz to 2500 Hz (Aslan C11)
    params = SpindleDriveParams.aslan_quaser()
    model = ident_r1.model  # type: ignore[attr-defined]
    tun = tune_spindle_q(model, 1e-4, starts=((-12.0, 2.0),))
    assert tun.design.n_states == 21
    f = np.arange(1.0, 2500.5, 3.0)
    h = compensated(discrete_disturbance_frf(SpindleDriveSim(params, 5000.0), f), tun.design, f)
    assert np.max(np.abs(20 * np.log10(np.abs(h)))) < 3.0


def test_observer_block_decimates_holds_and_is_chunk_invariant(ident_r1: object) -> None:
    # the observer runs on every second stream sample (I_nom updates every 0.2 ms) and holds:
    # equal to the filter run on y[::2] repeated twice, for any chunking
    model = ident_r1.model  # type: ignore[attr-defined]
    d = design_observer(model, 1e-12, 100.0, 1e-4)
    rng = np.random.default_rng(2)
    y = rng.normal(size=500)
    from millsense.estimation.kalman.lti_filter import StreamingFilter

    ref = np.repeat(StreamingFilter(d.filter("filtered")).process(y[::2])[:, 0], 2)[:500]

    def run(step: int) -> np.ndarray:
        b = SpindleTorqueObserver(d, FS, tool_radius_m=0.01)
        b.reset(FS)
        outs = [
            b.process(Chunk(s, FS, 0.0, {"spindle/current_cmd": y[s : s + step]})).channels
            for s in range(0, len(y), step)
        ]
        tau = np.concatenate([o["spindle/torque_est"] for o in outs])
        frc = np.concatenate([o["spindle/force_resultant_est"] for o in outs])
        np.testing.assert_allclose(frc, RESULTANT_FACTOR * tau / 0.01)
        return tau

    for step in (1, 7, 100, 500):
        np.testing.assert_allclose(run(step), ref, rtol=1e-12, atol=1e-12)


def test_resultant_factor_exact_under_its_assumptions() -> None:
    # Eq. 5.34: one flute in cut, zero helix, no edge forces, K_rc = 0.5 K_tc: the resultant is
    # exactly √1.25 · torque / r at every angle in the cut (independent: process.forces)
    tool = EndMill(diameter_m=0.02, n_flutes=1)
    coeffs = CuttingCoefficients(ktc=758e6, krc=379e6)
    phi = np.linspace(0.1, 3.0, 25)
    f = milling_forces(tool, coeffs, Engagement.slot(), 0.2e-3, 4e-3, phi, n_discs=4)
    cut = f.torque_nm > 1e-9
    ratio = f.resultant_n()[cut] / (f.torque_nm[cut] / 0.01)
    np.testing.assert_allclose(ratio, math.sqrt(1.25), rtol=1e-9)
    assert RESULTANT_FACTOR == pytest.approx(1.118, abs=5e-4)


def test_quick_estimation_cases_pass() -> None:
    # the quick validation cases of this package (run_case compares with the seed figure)
    from millsense.validation import run_case, select_cases

    cases = select_cases("estimation.spindle_*", quick_only=True)
    assert cases, "no quick spindle case registered"
    for c in cases:
        r = run_case(c)
        assert r.passed, (c.id, r.measured, r.reference, r.error)


def test_per_sample_frf_is_the_held_models_at_the_velocity_loop_rate() -> None:
    # decision 1699: with one CNC sample per velocity period the torque is held over it, and
    # the per-sample FRF is the ZOH model's (the same matrices, 1e-9)
    from millsense.estimation.spindle_observer import disturbance_model, per_sample_disturbance_frf

    p = SpindleDriveParams.aslan_quaser()
    f = np.arange(3.0, 2499.0, 11.0)
    for r in (0, 1):
        held = disturbance_model(p, r).frf(f)[:, 0, 0]
        per = per_sample_disturbance_frf(p, r, f, 1.0 / p.velocity_period_s)
        assert np.max(np.abs(per / held - 1.0)) < 1e-9


def test_machine_file_observer_model_is_the_identifications() -> None:
    # decision 1699: the commissioned machine file's observer model (G_dτ for a torque that
    # changes every CNC sample, fitted as the identification fits it) equals what the
    # simulated identification (decision 1696: a multisine changing every 10 kHz sample, read at
    # the 0.2 ms instants, noise-free) finds on the machine file's own drive model: within
    # 0.2 dB and 1° from 5 Hz to 2450 Hz (measured 0.05 dB, 0.3°: the identification's 20-state
    # fit against the file's 6-state one; the measured FRF equals per_sample_disturbance_frf
    # to 1e-3 dB), and both refer I_nom to the torque δ = −T_s/2 = −50 µs from the instant
    # (within 1 µs: δ is read from the top five lines). The held-torque model that the file's
    # path used before is 1.8 dB above at 1945 Hz. Decision 1708: the file's drive takes its
    # speed from the encoder's difference over the velocity period; the observer is designed
    # on its loop with the speed at the instant (checked here as above), and the drive with
    # the difference, as the simulated identification measures it, is the exact FRF that the
    # response model takes (1e-3 dB; δ = +T_s/2 there).
    from millsense.core.config import MachineConfig, load_config
    from millsense.estimation.from_config import _spindle_designs
    from millsense.estimation.spindle_observer import (
        disturbance_model,
        disturbance_model_per_sample,
        per_sample_disturbance_frf,
    )

    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    machine = load_config(MachineConfig, root / "src/millsense/data/commissioned/quaser-ux600.toml")
    drive, ranges, _ = _spindle_designs(machine, "test")
    assert drive.speed_from_encoder_difference
    params = replace(drive, speed_from_encoder_difference=False)  # the observer's design loop
    f = np.arange(5.0, 2450.0, 5.0)
    for r, rpm in ((0, 1500.0), (1, 4000.0)):
        measured = identify_spindle(drive, velocity_period_s=drive.velocity_period_s,
                                    speed_rpm=rpm, sample_rate_hz=FS, n_periods=5)  # fmt: skip
        exact = per_sample_disturbance_frf(drive, r, measured.frf.freq_hz, FS)
        assert np.max(np.abs(20 * np.log10(np.abs(measured.frf.h1 / exact)))) < 1e-3
        assert measured.torque_lag_s == pytest.approx(0.5 / FS, abs=1e-6)
        ident = identify_spindle(params, velocity_period_s=params.velocity_period_s,
                                 speed_rpm=rpm, sample_rate_hz=FS, n_periods=5)  # fmt: skip
        exact = per_sample_disturbance_frf(params, r, ident.frf.freq_hz, FS)
        assert np.max(np.abs(20 * np.log10(np.abs(ident.frf.h1 / exact)))) < 1e-3
        lag = ident.torque_lag_s
        assert lag == pytest.approx(-0.5 / FS, abs=1e-6)
        g_id = ident.model.frf(f)[:, 0, 0] * np.exp(-2j * np.pi * f * lag)
        model, file_lag = disturbance_model_per_sample(params, r, FS)
        assert model is ranges[r][0]  # the model the file's observer is designed on
        assert file_lag == pytest.approx(lag, abs=1e-6)
        g_file = model.frf(f)[:, 0, 0] * np.exp(-2j * np.pi * f * file_lag)
        ratio = g_file / g_id
        assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 0.2
        assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 1.0
        k = int(np.argmin(np.abs(f - 1945.0)))
        held = disturbance_model(params, r).frf(f[k : k + 1])[0, 0, 0]
        assert 20 * math.log10(abs(held / g_id[k])) == pytest.approx(1.8, abs=0.1)
