"""Nameplate (belief) machine files apart from the simulator's own (issue 12, decision 0991),
and the acceptance estimators built only through identification (decision 0993)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.config import MachineConfig
from millsense.core.errors import ConfigError
from millsense.core.presets import load_preset, preset_names
from millsense.estimation.from_config import build_estimators
from millsense.simulator.machine_file import (
    simulated_machine_names,
    simulator_machine,
    simulator_machine_path,
)


@pytest.mark.parametrize("name", ["quaser-ux600", "yamada-a", "yamada-b"])
def test_nameplate_is_catalogue_data_with_fixed_errors(name: str) -> None:
    plate, sim = load_preset(MachineConfig, name), simulator_machine(name)
    assert sorted(plate.axes) == sorted(sim.axes)
    for a, ax in plate.axes.items():
        true = sim.axis(a)
        # catalogue errors of decision 0991: K_t within ±5 %, J_e within ±10 %, never exact
        kt = ax.torque_constant_nm_a / true.torque_constant_nm_a - 1
        j = ax.inertia_kg_m2 / true.inertia_kg_m2 - 1
        assert 0.015 < abs(kt) <= 0.05 + 1e-9, (a, kt)
        assert 0.05 < abs(j) <= 0.10 + 1e-9, (a, j)
        assert ax.efficiency != true.efficiency
        # lead, encoder and feedback are exact drawing/CNC data
        assert ax.transmission_m_rad == pytest.approx(true.transmission_m_rad, rel=1e-12)
        assert ax.encoder_counts_rev == true.encoder_counts_rev
        # nothing that only identification gives
        assert ax.friction is None and ax.disturbance_modes is None and ax.ball_screw is None
        assert ax.current_noise_a == 0.0 and not ax.periodic_disturbances
        assert ax.dead_time_amplifier_ms == ax.dead_time_motor_encoder_ms == 0.0


def test_nameplate_servo_gains_are_the_cnc_gains_of_the_simulator() -> None:
    from millsense.simulator.feed_drive import FeedDriveParams

    plate = load_preset(MachineConfig, "quaser-ux600")
    for a in "xyzac":
        p = FeedDriveParams.from_config(simulator_machine("quaser-ux600").axis(a))
        ax = plate.axis(a)
        # the gains the simulated CNC runs (K_p = J·ω_c on Table 3.1 J), to the 5 digits printed
        assert ax.velocity_kp_nm_s_rad == pytest.approx(p.kp, rel=1e-4)
        assert ax.velocity_ki_nm_rad == pytest.approx(p.ki, rel=1e-3)
        assert ax.position_gain_1_s == pytest.approx(p.kv, rel=1e-4)


def test_the_simulator_has_its_own_file_for_every_preset() -> None:
    assert simulated_machine_names() == preset_names(MachineConfig)
    assert simulator_machine_path("quaser-ux600").is_file()
    with pytest.raises(ConfigError, match="no machine 'nosuch' in the simulator"):
        simulator_machine("nosuch")


def test_estimators_on_the_nameplate_refuse_and_name_the_identification() -> None:
    plate = load_preset(MachineConfig, "quaser-ux600")
    with pytest.raises(ConfigError, match=r"axes\.x\.disturbance_modes.*identify path"):
        build_estimators(plate, ["feed"], ["x"], 10_000.0, where="preset quaser-ux600")
    with pytest.raises(ConfigError, match=r"axes\.x\.friction.*identify friction"):
        build_estimators(plate, ["raw"], ["x"], 10_000.0, where="preset quaser-ux600")
    with pytest.raises(ConfigError, match=r"no estimator could be built"):
        build_estimators(plate, ["feed", "raw"], ["x"], 10_000.0, skip_unavailable=True)


def test_simulating_a_file_without_friction_names_it() -> None:
    from millsense.simulator.feed_drive import FeedDriveParams

    with pytest.raises(ConfigError, match="missing table 'friction'"):
        FeedDriveParams.from_config(load_preset(MachineConfig, "quaser-ux600").axis("x"))


def test_commissioning_recordings_carry_no_simulator_torque_constant() -> None:
    from millsense.simulator import commissioning as cm

    rec = cm.acceleration_test(simulator_machine("quaser-ux600"), "x", speeds_rad_s=(10.0,))
    assert "torque_constant_nm_a" not in rec.metadata
    assert np.isfinite(rec.channel("x/current")).all()


@pytest.mark.slow
def test_feed_acceptance_estimator_takes_nothing_from_the_simulator() -> None:
    """The review test of issue 12 for the feed acceptance (estimation_feed_drive): the model
    the cases run is built from the merged machine (nameplate + identified fragments): its K_t,
    r_g, η are the nameplate's and differ from the simulated drive's, J_e and friction are the
    identified ones, Φ_d is the identified path (no modes in the file) and R the air cut's."""
    from millsense.estimation.kalman.rational_fit import RationalFit
    from millsense.validation.cases import estimation_feed_drive as fd

    params, model, sweep = fd._identified("x")
    res = fd._pipeline("x")
    plate = load_preset(MachineConfig, "quaser-ux600").axis("x")
    merged = res.machine.axis("x")
    d = model.drive
    assert d.torque_constant == plate.torque_constant_nm_a != params.torque_constant
    assert d.efficiency == plate.efficiency != params.efficiency
    assert d.transmission == pytest.approx(params.transmission, rel=1e-12)  # the lead is exact
    # J_e identified (with the nameplate K_t: 4 % low like K_t), neither nameplate nor simulator
    assert d.inertia == pytest.approx(merged.inertia_kg_m2, rel=1e-6)
    assert d.inertia == pytest.approx(params.plant.inertia * 0.96, rel=0.03)
    assert d.inertia != plate.inertia_kg_m2
    assert merged.friction is not None and "identify friction" in merged.friction.source
    # Φ_d: the identified rational path of the fragment, the file has no modes
    assert merged.disturbance_modes is None and merged.estimator is not None
    path = merged.estimator.disturbance_path
    assert path is not None and "identify path" in path.source
    fit = RationalFit.from_config(path)
    f = np.linspace(5.0, 250.0, 50)
    assert np.allclose(model.disturbance.frf(f), fit.frf(f), rtol=1e-9, atol=1e-12)
    assert np.allclose(sweep.fit.frf(f), fit.frf(f), rtol=1e-5, atol=1e-8)
    # R from the air cut, not from the simulator's noise level
    assert model.r == merged.estimator.r_nm2
    assert model.r != pytest.approx((params.torque_noise_nm) ** 2, rel=0.05)
