"""Disturbance observers of seed 001 (Yamada 2017): MEDOB, DOB, phase-lag delays, modes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import signal

from millsense.estimation.dob.mode_decoupled import (
    VibrationModeObserver,
    modal_coordinates,
    modal_parameters,
)
from millsense.estimation.dob.observers import (
    CurrentLoopModel,
    DriveParameters,
    MEDOBBlock,
    butterworth_analog,
    dob_frf_closed_form,
    dob_model,
    identify_drive_parameters,
    medob_mass_error_frf,
    medob_model,
    medob_observer,
    rigid_sum_frf,
    triple_medob_model,
    zoh_weights,
)
from millsense.estimation.dob.phase_lag import StreamingDelay, split_delay, sync_delays
from millsense.models.ball_screw import dual_inertia_plant, triple_inertia_plant
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine
from millsense.streaming.block import Chunk

FS = 10000.0


@pytest.fixture(scope="module")
def axis():  # type: ignore[no-untyped-def]
    return simulator_machine("yamada-b").axis("x")


@pytest.fixture(scope="module")
def params(axis) -> DriveParameters:  # type: ignore[no-untyped-def]
    return DriveParameters.from_axis_config(axis)


def _plant(p: DriveParameters):  # type: ignore[no-untyped-def]
    return dual_inertia_plant(
        p.rotor_inertia_kg_m2,
        p.lead_m,
        p.table_mass_kg,
        p.axial_stiffness_n_m,
        p.axial_damping_n_s_m,
        p.table_damping_n_s_m,
        p.rotary_damping_nm_s_rad,
    )


def _proportional(p: DriveParameters) -> DriveParameters:
    ac = p.table_damping_n_s_m / p.table_mass_kg
    return dataclasses.replace(p, rotary_damping_nm_s_rad=ac * p.rotor_inertia_kg_m2)


def _ideal_sim(axis, p: DriveParameters, load: np.ndarray, inject=None, vel=0.0):  # type: ignore[no-untyped-def]
    fp = dataclasses.replace(
        FeedDriveParams.from_config(axis, friction="none", periodic=False),
        plant=_plant(p),
        current_bandwidth_hz=1e12,
        encoder_counts_rev=2**50,
        scale_resolution_m=None,
        dead_time_amplifier_s=0.0,
        dead_time_motor_encoder_s=0.0,
        dead_time_scale_s=0.0,
        torque_noise_nm=0.0,
    )
    n = len(load)
    t = np.arange(n) / FS
    w = vel / p.transmission_m_rad
    return FeedDriveSim(fp, FS).advance(w * t, np.full(n, w), load, inject)


F = np.linspace(1.0, 2000.0, 500)


def test_medob_frf_equals_lowpass_analytically(params: DriveParameters) -> None:
    # Yamada §2.3: with exact parameters F̂/F = Q and F̂/I = 0 (round-off only)
    q = butterworth_analog(4, 500.0)
    hf, hi = rigid_sum_frf(
        _plant(params),
        medob_model(params),
        [0, 1],
        F,
        torque_constant_nm_a=params.torque_constant_nm_a,
        transmission_m_rad=params.transmission_m_rad,
        lowpass=q,
    )
    qs = q(2j * np.pi * F)
    assert np.max(np.abs(hf / qs - 1.0)) < 1e-9
    assert np.max(np.abs(hi / qs)) < 1e-9 * params.force_constant_n_a


def test_dob_frf_matches_corrected_eq_2_19(params: DriveParameters) -> None:
    # Eq. 2-19 with the s³ coefficient 2(1+α)ζ_kω_t (digest erratum) is exact
    hf, _ = rigid_sum_frf(
        _plant(params),
        dob_model(params),
        [0],
        F,
        torque_constant_nm_a=params.torque_constant_nm_a,
        transmission_m_rad=params.transmission_m_rad,
    )
    assert np.max(np.abs(hf / dob_frf_closed_form(params, F) - 1.0)) < 1e-9
    # and the DOB is far from flat near the 408 Hz resonance (Yamada C3)
    assert np.max(np.abs(hf)) > 2.0


def test_mass_error_frf_matches_corrected_b4(params: DriveParameters) -> None:
    # Eq. B-4/B-5 with a₂ = 2ω_t{Qαζ_r + …} (digest erratum) is exact for Q = 1.5
    hf, _ = rigid_sum_frf(
        _plant(params),
        medob_model(params, table_mass_factor=1.5),
        [0, 1],
        F,
        torque_constant_nm_a=params.torque_constant_nm_a,
        transmission_m_rad=params.transmission_m_rad,
    )
    assert np.max(np.abs(hf / medob_mass_error_frf(params, 1.5, F) - 1.0)) < 1e-9
    # Q > 1 overestimates at high frequency (Yamada Fig. 4-2): |F̂/F| → Q
    assert abs(abs(hf[-1]) - 1.5) < 0.1


def test_triple_medob_is_exact_and_reduced_is_not() -> None:
    # Eq. 2-49 needs no stiffness; the reduced Eq. 2-65 loses accuracy near the modes
    r = 5e-3 / (2 * math.pi)
    mr, mn, mt = 30.0, 30.0, 6.2
    plant = triple_inertia_plant(mr * r * r, 5e-3, mn, mt, 3.41e8, 3.06e7, 500.0, 800.0)
    f = np.array([50.0, 366.0, 770.0])
    kw = {"torque_constant_nm_a": 0.3, "transmission_m_rad": r}
    full, _ = rigid_sum_frf(plant, triple_medob_model(mr, mn, mt, 0.3 / r), [0, 1, 2], f, **kw)
    red, _ = rigid_sum_frf(
        plant, triple_medob_model(mr, mn, mt, 0.3 / r, reduced="medob"), [0, 2], f, **kw
    )
    assert np.max(np.abs(full - 1.0)) < 1e-9
    assert np.max(np.abs(red - 1.0)) > 0.1


def test_discrete_medob_equals_output_filter_in_time(axis, params: DriveParameters) -> None:
    # module docstring: under proportional damping F̂ = L(z)·F to round-off, any chunking
    p = _proportional(params)
    n = 3000
    t = np.arange(n) / FS
    load = np.where(t < 0.25, 20.0 * signal.chirp(t, 5.0, 0.25, 900.0), 0.0)
    out = _ideal_sim(axis, p, load)  # from rest: the observer's history matches the plant's
    obs = medob_observer(p, FS, cutoff_hz=500.0)
    r = p.transmission_m_rad
    est = obs.process(out["current_cmd"], [r * out["angle"], out["scale"]])
    ref = obs.output_filter(load)
    assert np.max(np.abs(est - ref)) < 1e-8 * np.max(np.abs(ref))
    obs.reset()
    parts = [
        obs.process(out["current_cmd"][s], [r * out["angle"][s], out["scale"][s]])
        for s in np.array_split(np.arange(n), [1, 8, 100, 1777])
    ]
    assert np.array_equal(np.concatenate(parts), est)


def test_block_chunk_invariant(axis, params: DriveParameters) -> None:
    # Block contract: chunks of 1, 7 and the whole record give identical outputs
    n = 400
    rng = np.random.default_rng(1)
    data = {
        "x/current_cmd": rng.standard_normal(n),
        "x/motor_angle": np.cumsum(rng.standard_normal(n)) * 1e-4,
        "x/scale": np.cumsum(rng.standard_normal(n)) * 1e-7,
    }
    outs = []
    for size in (n, 7, 1):
        b = MEDOBBlock("x", params, delays_s=(0.4e-3, 0.0, 0.05e-3))
        b.reset(FS)
        res = [
            b.process(Chunk(k, FS, 0.0, {c: v[k : k + size] for c, v in data.items()}))
            for k in range(0, n, size)
        ]
        outs.append(np.concatenate([r.channels["x/force_medob"] for r in res]))
    assert np.allclose(outs[0], outs[1], rtol=0, atol=1e-9 * np.max(np.abs(outs[0])))
    assert np.allclose(outs[0], outs[2], rtol=0, atol=1e-9 * np.max(np.abs(outs[0])))


def test_sync_delays_table_3_3() -> None:
    # Table 3-3: A (0.35, 0.45, 0.1) → (0.8, 0, 0.35) ms; B (0.2, 0.2, 0.2) → (0.4, 0, 0) ms
    assert np.allclose(sync_delays(0.35e-3, 0.45e-3, 0.1e-3), (0.8e-3, 0.0, 0.35e-3), atol=1e-15)
    assert np.allclose(sync_delays(0.2e-3, 0.2e-3, 0.2e-3), (0.4e-3, 0.0, 0.0), atol=1e-15)


def test_streaming_delay_integer_and_fractional() -> None:
    x = np.sin(np.arange(200) * 0.05)
    d = StreamingDelay(4.0)
    y = np.concatenate([d.process(x[:3]), d.process(x[3:])])
    assert np.array_equal(y[4:], x[:-4])  # whole samples: exact
    assert split_delay(3.2) == (2, pytest.approx(1.2))
    frac = StreamingDelay(3.3)
    h = frac.frf([10.0, 1000.0, 4000.0], FS)
    assert np.allclose(np.abs(h), 1.0, atol=1e-12)  # allpass: unit magnitude everywhere
    # phase delay at 10 Hz is 3.3 samples (Thiran is maximally flat at DC)
    tau = -np.angle(h[0]) / (2 * np.pi * 10.0 / FS)
    assert abs(tau - 3.3) < 1e-4


def test_zoh_weights_series_and_closed_form_agree() -> None:
    # the series branch (x < 1e-3) and the closed form meet at the switch
    dt = 1e-4
    lo = zoh_weights(9.999e-3 / dt * 0.1, dt)
    hi = zoh_weights(1.0001e-3 / dt, dt)
    ref_lo = zoh_weights(1.0e-3 / dt * 0.9999, dt)
    assert lo[0] > 0 and hi[0] > 0
    assert abs(hi[0] / ref_lo[0] - 1.0) < 1e-6
    assert abs(hi[1] / ref_lo[1] - 1.0) < 1e-6
    # a → 0: b₁ = b₀ = T²/2 (the central second difference)
    b1, b0, e = zoh_weights(0.0, dt)
    assert (b1, b0, e) == (dt * dt / 2, dt * dt / 2, 1.0)


def test_current_loop_model_mean_over_sample() -> None:
    # step command: the mean of ω/(s+ω)'s response over the first sample is
    # 1 − (1 − e^{−x})/x (closed form); later samples follow with the same state
    m = CurrentLoopModel(795.77, FS)
    x = 2 * math.pi * 795.77 / FS
    out = np.concatenate([m.process(np.zeros(3)), m.process(np.ones(2)), m.process(np.ones(1))])
    assert abs(out[3] - (1.0 - (1.0 - math.exp(-x)) / x)) < 1e-12
    ia1 = 1.0 - math.exp(-x)
    assert abs(out[4] - (1.0 + (ia1 - 1.0) * (1.0 - math.exp(-x)) / x)) < 1e-12


def test_identification_recovers_ideal_plant(axis, params: DriveParameters) -> None:
    # noise-free plant with a 10 Hz–1 kHz current chirp at 20 mm/s: LS recovers Table 3-3
    n = 12000
    t = np.arange(n) / FS
    inj = 0.1 * signal.chirp(t, 10.0, t[-1], 1000.0, method="logarithmic")
    out = _ideal_sim(axis, params, np.zeros(n), inj, vel=20e-3)
    p = identify_drive_parameters(
        out["current_cmd"],
        out["angle"],
        out["scale"],
        FS,
        torque_constant_nm_a=params.torque_constant_nm_a,
        lead_m=params.lead_m,
        band_hz=(10.0, 1000.0),
    )
    assert abs(p.rotor_mass_kg / params.rotor_mass_kg - 1) < 0.01
    assert abs(p.table_mass_kg / params.table_mass_kg - 1) < 0.02
    assert abs(p.axial_stiffness_n_m / params.axial_stiffness_n_m - 1) < 0.02


def test_modal_parameters_digest_values(params: DriveParameters) -> None:
    # digest §3.2 [derived]: M_vib = 1104 kg, K_vib = 7.32e9 N/m for Machine B
    m = modal_parameters(params)
    assert abs(m.m_vib / 1104.0 - 1) < 0.005
    assert abs(m.k_vib / 7.32e9 - 1) < 0.005
    xr, xv = modal_coordinates(np.array([1.0]), np.array([1.0]), m.alpha)
    assert xr[0] == pytest.approx(1.0) and xv[0] == pytest.approx(0.0)  # rigid motion


def test_vibration_mode_tracks_force_with_exact_parameters(axis, params: DriveParameters) -> None:
    # Eq. 2-44 with exact parameters: only the central-difference error remains
    # (≈ (ωT)²/12 on each term); a 100 Hz, 20 N load is recovered to 1 % of its amplitude
    p = _proportional(params)
    n = 3000
    t = np.arange(n) / FS
    load = 20.0 * np.sin(2 * np.pi * 100.0 * t)
    out = _ideal_sim(axis, p, load, vel=2e-3)
    r = p.transmission_m_rad
    vib = VibrationModeObserver(p, FS, cutoff_hz=500.0)
    est = vib.process(out["current_cmd"], r * out["angle"], out["scale"])
    ref = medob_observer(p, FS, cutoff_hz=500.0).output_filter(load)
    assert np.max(np.abs(est - ref)[1000:]) < 0.2
    vib.reset()
    parts = [
        vib.process(out["current_cmd"][s], r * out["angle"][s], out["scale"][s])
        for s in np.array_split(np.arange(n), [5, 6, 900])
    ]
    assert np.array_equal(np.concatenate(parts), est)


def test_quick_validation_cases_pass() -> None:
    # MEDOB F̂/F = LPF (analytic 1e-9 and simulated sweep 1e-9), Table 4-5 within 0.1 %
    from millsense.validation import run_case, select_cases

    cases = select_cases("estimation.dob.*", quick_only=True)
    assert len(cases) == 3
    for c in cases:
        r = run_case(c)
        assert r.passed, (c.id, r.measured, r.error)
