"""The yamada-a/-b truths (decisions 1711, 1705) and the DOB cases judged on B (issue 12)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.simulator.machine_file import simulated_feed_drive
from millsense.simulator.truth_drive import CoupledDrive
from millsense.simulator.truth_fit_stage import STAGES, fit_stage, free_modes, torsion_like_b_hz
from millsense.simulator.truth_machine import load_truth, read_truth_file


def test_yamada_b_truth_modes_within_the_recorded_fit_error() -> None:
    # the file stores the mechanics to 6 significant digits; the frequencies of the reloaded
    # drive may differ from the fit's by that rounding (< 0.01 %), on top of the recorded error
    fit = read_truth_file("yamada-b-truth-mechanics.toml")["axes"]["x"]["fit"]
    tol_pct = float(fit["max_abs_frequency_error_pct"]) + 0.01
    f, zeta = free_modes(load_truth("yamada-b")["x"].drive)
    target = np.array(fit["target_frequency_hz"])
    assert target[0] == pytest.approx(408.0)  # Table 3-3, machine B
    assert target[1] == pytest.approx(778.5)  # §3.4 screw torsion
    np.testing.assert_allclose(f[:3], target, rtol=tol_pct / 100.0)
    # damping of the axial mode: ζ_k of Table 3-3 (C_kn), within the recorded error + rounding
    tol_z = float(fit["max_abs_damping_error"]) + 1e-4
    assert zeta[0] == pytest.approx(fit["target_damping_ratio"][0], abs=tol_z)


def test_yamada_b_truth_keeps_the_table_3_3_inertias() -> None:
    d = load_truth("yamada-b")["x"].drive
    r = 5e-3 / (2.0 * math.pi)
    # J_rn + M_tn·R² of Table 3-3 (5.2e-5 + 6.6·R²): the fit keeps the inertias (6 digits)
    assert d.inertia == pytest.approx(5.2e-5 + 6.6 * r * r, rel=1e-5)
    assert d.table_mass == pytest.approx(6.6)


@pytest.mark.parametrize("name", ["yamada-a", "yamada-b"])
def test_the_stage_fit_is_deterministic_and_matches_the_file(name: str) -> None:
    d = fit_stage(STAGES[name])
    f_fit, _ = free_modes(d)
    f_file, _ = free_modes(load_truth(name)["x"].drive)
    # same start, same solver: the refit reproduces the stored drive to its 6 digits
    np.testing.assert_allclose(f_fit[:3], f_file[:3], rtol=1e-4)


def test_yamada_b_simulated_drive_is_the_truth_with_its_disturbances() -> None:
    p = simulated_feed_drive("yamada-b", "x")
    truth = load_truth("yamada-b")["x"]
    assert p.plant.a.shape[0] == 2 * truth.drive.n_dof  # the coupled plant, not Eq. 2-1/2-2
    kinds = sorted({t.kind for t in p.periodic})
    assert kinds == [0, 1, 2, 3]  # torque, screw error, motor encoder, scale (§3.6)
    assert p.torque_noise_nm == pytest.approx(0.016 * 0.3)  # the 16 mA calibration × K_t


def test_dob_case_observer_comes_from_identification_not_the_truth() -> None:
    """The Table 4-7 observers use identify drive's parameters on the truth's sweep: they
    differ from every parameter of the truth by more than rounding, and they are the merged
    machine's (the ``identify drive`` path), not a copy of the truth's."""
    from millsense.validation.cases import estimation_dob as dob

    p = dob._identified()
    belief = dob._belief()
    d: CoupledDrive = load_truth("yamada-b")["x"].drive
    truth = load_truth("yamada-b")["x"]
    r = d.transmission
    # the observer's J_r and M_t are the merged (identified) machine's
    assert p.rotor_inertia_kg_m2 == belief.inertia_kg_m2
    assert belief.ball_screw is not None
    assert p.table_mass_kg == belief.ball_screw.table_mass_kg
    # K_t is the nameplate's 0.291 (catalogue −3 %), not the truth's 0.3
    assert p.torque_constant_nm_a == pytest.approx(0.291)
    assert truth.torque_constant == pytest.approx(0.3)
    # identified values are not the truth's (an accidental copy would match to 1e-9)
    j_rot = d.motor_inertia + d.screw_inertia
    assert abs(p.rotor_inertia_kg_m2 / j_rot - 1.0) > 1e-3
    assert abs(p.table_mass_kg / d.table_mass - 1.0) > 1e-3
    k0 = d.transmission_stiffness(0.0)
    assert abs(p.axial_stiffness_n_m / k0 - 1.0) > 1e-3
    # but they are identifications of it: J_r within 15 % (M_t and K_r: the strict test below,
    # a known failure since decision 1790, and a floor here that they are not off by half)
    assert p.rotor_inertia_kg_m2 == pytest.approx(j_rot, rel=0.15)
    assert p.table_mass_kg == pytest.approx(d.table_mass, rel=0.35)
    assert p.axial_stiffness_n_m == pytest.approx(k0, rel=0.35)
    assert r == pytest.approx(p.transmission_m_rad)
    # dead times identified, not read: T_s within 0.02 ms of the truth's 0.2 ms
    assert belief.dead_time_amplifier_ms == pytest.approx(0.2, abs=0.02)
    assert belief.dead_time_amplifier_ms != truth.dead_time_amplifier_s * 1e3
    # the notch's mode is found in the sweep near the truth's torsion (778.5 Hz servo-off; the
    # closed loop moves it, measured 785.3 Hz), not copied from it
    f_notch = dob.torsion_notch_hz()
    assert f_notch == pytest.approx(778.5, rel=0.03)
    assert f_notch != pytest.approx(778.5, abs=1e-6)


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: with the drive sweep designed from the nameplate's J and K_t (decision "
    "1790, 4 % more current) identify drive gives M_t −29 % and K_r −27 % against the truth "
    "(−16 %, −15 % before): the dual-inertia fit depends on the excitation level",
)
def test_dob_case_identified_table_mass_and_stiffness_are_close_to_the_truth() -> None:
    """The dual-inertia FRF fit on a drive with a torsional mode and a bed: M_t within 25 %,
    K_r within 20 % of the truth's (k(0) = 44.3 N/µm), the bounds measured before decision
    1790 (−16 %, −15 %)."""
    from millsense.validation.cases import estimation_dob as dob

    p = dob._identified()
    d: CoupledDrive = load_truth("yamada-b")["x"].drive
    assert p.table_mass_kg == pytest.approx(d.table_mass, rel=0.25)
    assert p.axial_stiffness_n_m == pytest.approx(d.transmission_stiffness(0.0), rel=0.20)


def test_dual_inertia_fit_band_stops_below_the_truths_torsion_only() -> None:
    """fit_dual_inertia ends its band below a mode the model cannot have (the truth's screw
    torsion) and leaves the pure dual-inertia stage's band alone (decision 1705)."""
    from millsense.bench.pipeline import identified_ball_screw_machine
    from millsense.validation.cases.ident_drive import drive_case

    assert drive_case("yamada-b")[0].unmodelled_mode_hz is None  # the file's dual inertia
    notes = identified_ball_screw_machine("yamada-b").axes["x"].notes
    found = [n for n in notes if n.startswith("unmodelled mode at")]
    assert len(found) == 1
    # 778.5 Hz servo-off (the fit's target), moved by the closed loop: within 3 %
    f = float(found[0].split()[3])
    assert f == pytest.approx(778.5, rel=0.03)


def test_yamada_a_torsion_is_bs_coupling_on_as_rotor() -> None:
    # decision 1711: A has B's Ø15 × 5 screw and disk coupling (Table 3-2, §3.1); only the
    # motor's inertia differs. B's own is §3.4's 778.5 Hz exactly; for A by hand:
    # J_s = 1.5655e-5, J_m = 3.8e-5 − J_s = 2.2345e-5 (B: 3.6345e-5) kg·m²,
    # 778.5·√((1/2.2345e-5 + 1/1.5655e-5)/(1/3.6345e-5 + 1/1.5655e-5)) = 848.75 Hz
    assert torsion_like_b_hz(5.2e-5) == pytest.approx(778.5, rel=1e-12)
    assert torsion_like_b_hz(3.8e-5) == pytest.approx(848.75, abs=0.05)


def test_yamada_a_truth_modes_within_the_recorded_fit_error() -> None:
    # the stored mechanics are rounded to 6 digits: the reloaded drive's modes may differ from
    # the fit's by < 0.01 % on top of the recorded error
    fit = read_truth_file("yamada-a-truth-mechanics.toml")["axes"]["x"]["fit"]
    tol_pct = float(fit["max_abs_frequency_error_pct"]) + 0.01
    d = load_truth("yamada-a")["x"].drive
    f, zeta = free_modes(d)
    target = np.array(fit["target_frequency_hz"])
    assert target[0] == pytest.approx(335.0)  # Table 3-3, machine A
    assert target[1] == pytest.approx(torsion_like_b_hz(3.8e-5), abs=0.05)  # chosen torsion
    np.testing.assert_allclose(f[:3], target, rtol=tol_pct / 100.0)
    # the axial mode's damping is ζ_k of Table 3-3 A (C_kn: 0.099 in the digest)
    tol_z = float(fit["max_abs_damping_error"]) + 1e-4
    assert fit["target_damping_ratio"][0] == pytest.approx(0.099)
    assert zeta[0] == pytest.approx(0.099, abs=tol_z)
    # "single anchor" (Table 3-2): fixed at one end, so the axial mode falls along the stroke
    # (stiffer near the fixed bearing); the reloaded drive gives the recorded ends to 0.01 %
    assert d.screw is not None and d.screw.support == "fixed-free"
    lo, hi = free_modes(d, -0.1)[0][0], free_modes(d, 0.1)[0][0]
    assert lo == pytest.approx(fit["free_frequency_at_minus_100mm_hz"][0], rel=1e-4)
    assert hi == pytest.approx(fit["free_frequency_at_plus_100mm_hz"][0], rel=1e-4)
    assert lo > 335.0 > hi
    # the total axial stiffness at position 0 lands near Table 3-3's K_rn = 25.7 N/µm
    # (measured 25.78: the fit aims at the frequency, not at K_rn)
    assert d.transmission_stiffness(0.0) == pytest.approx(25.7e6, rel=0.01)


def test_yamada_a_truth_keeps_the_table_3_3_inertias() -> None:
    d = load_truth("yamada-a")["x"].drive
    r = 5e-3 / (2.0 * math.pi)
    assert d.inertia == pytest.approx(3.8e-5 + 6.2 * r * r, rel=1e-5)
    assert d.table_mass == pytest.approx(6.2)


def test_yamada_a_simulator_runs_the_truth_and_ideal_the_file() -> None:
    from millsense.simulator.commissioning import plant_params
    from millsense.simulator.machine_file import simulator_machine

    truth = load_truth("yamada-a")["x"]
    p = simulated_feed_drive("yamada-a", "x")
    assert p.plant.a.shape[0] == 2 * truth.drive.n_dof  # motor, screw, table, bed
    # thrust ripple and motor torque ripple (0), motor encoder (2), scale (3): §3.6
    assert sorted({t.kind for t in p.periodic}) == [0, 2, 3]
    assert p.torque_constant == pytest.approx(0.3)
    # the CNC's P-P gains are the simulator file's (Table 4-1), not redesigned
    assert (p.kp, p.ki, p.kv) == pytest.approx((8.385e-3, 0.0, 50.0))
    cfg = simulator_machine("yamada-a")
    real, sub = plant_params(cfg, "x")
    ideal, _ = plant_params(cfg, "x", ideal=True)
    assert real.plant.a.shape == (8, 8) and sub == 2  # 20 kHz × 2 substeps
    assert ideal.plant.a.shape == (4, 4)  # Eq. 2-1/2-2: the algorithm checks' plant
