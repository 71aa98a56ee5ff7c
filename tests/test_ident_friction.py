"""Friction identification from simulated constant-velocity moves (Aslan C1)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.ident.friction import coulomb_viscous_from_moves, fit_line
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.rigid_drive import RigidDriveParams, constant_velocity_move


def test_line_fit_exact_on_a_line() -> None:
    w = np.array([2.0, 4.0, 8.0])
    fit = fit_line(w, 1.5 + 0.2 * w)  # closed form: intercept 1.5, slope 0.2
    assert fit.intercept == pytest.approx(1.5, abs=1e-12)
    assert fit.slope == pytest.approx(0.2, abs=1e-12)


def test_one_speed_is_refused() -> None:
    with pytest.raises(InputDataError, match="two speeds"):
        fit_line(np.array([3.0, 3.0]), np.array([1.0, 1.0]))


def test_recovers_table_3_2_friction_from_simulated_moves() -> None:
    axis = simulator_machine("quaser-ux600").axis("x")
    p = RigidDriveParams.from_config(axis)
    speeds, torques = [], []
    for k, w in enumerate((-16.0, -8.0, -4.0, 4.0, 8.0, 16.0)):
        m = constant_velocity_move(p, w, 0.6, 10000.0, seed=k)
        half = slice(3000, None)
        speeds.append(np.mean(m["speed"][half]))
        torques.append(np.mean(axis.torque_constant_nm_a * m["current_cmd"][half]))
    fr = coulomb_viscous_from_moves(np.array(speeds), np.array(torques))
    # Aslan Table 3.2, X: τ_coul (1.73, 1.84) N·m, σ2 (0.175, 0.15) N·m·s/rad. Tolerances: the
    # simulated torque noise (0.28 N·m RMS) averaged over 3000 samples per move.
    assert fr.coulomb_pos == pytest.approx(1.73, abs=0.01)
    assert fr.coulomb_neg == pytest.approx(1.84, abs=0.01)
    assert fr.viscous_pos == pytest.approx(0.175, abs=0.002)
    assert fr.viscous_neg == pytest.approx(0.15, abs=0.002)


# ---------------------------------------------------------------------------------------------
# LuGre static parameters, presliding, spindle (issue 6 item 3)
# ---------------------------------------------------------------------------------------------

import dataclasses  # noqa: E402

from millsense.ident import friction as fr  # noqa: E402
from millsense.models.lugre import LuGre  # noqa: E402
from millsense.models.spindle_plant import SpindleDriveParams  # noqa: E402
from millsense.simulator import commissioning as cm  # noqa: E402
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim  # noqa: E402

_Z = LuGre((475.0, 475.0), (10.0, 10.0), (0.065, 0.082), (2.3, 2.3), (2.15, 2.1), (0.571, 0.222))


def test_stribeck_fit_exact_on_the_steady_curve() -> None:
    w = np.geomspace(0.05, 30.0, 12)
    fit = fr.fit_stribeck(w, _Z.steady_torque(w))
    # closed form: the data are Aslan Eq. 3.4 + σ2 v of the Z row of Table 3.2, no noise
    assert fit.resolved
    assert fit.coulomb == pytest.approx(2.15, rel=1e-6)
    assert fit.static == pytest.approx(2.3, rel=1e-6)
    assert fit.stribeck_velocity == pytest.approx(0.571, rel=1e-5)
    assert fit.viscous == pytest.approx(0.065, rel=1e-6)


def test_stribeck_without_rise_falls_back_to_a_line() -> None:
    w = np.geomspace(0.5, 30.0, 8)
    fit = fr.fit_stribeck(w, 1.73 + 0.175 * w + 1e-4 * np.sin(w))
    # decision "Friction identification": an unresolved rise gives Coulomb + viscous only
    assert not fit.resolved
    assert fit.static == fit.coulomb
    assert fit.coulomb == pytest.approx(1.73, abs=1e-3)
    assert fit.viscous == pytest.approx(0.175, abs=1e-4)
    assert "static_nm" not in fr.LuGreFit(fit, fit).config_table()


def test_constant_speed_samples_give_the_plain_fit() -> None:
    w = np.geomspace(0.05, 30.0, 10)
    tau = _Z.steady_torque(w)
    a = fr.fit_stribeck(w, tau)
    b = fr.fit_stribeck(w, tau, speed_samples=[np.full(50, v) for v in w])
    # the fluctuation model reduces to g(v) when every sample equals the mean
    assert b.stribeck_velocity == pytest.approx(a.stribeck_velocity, rel=1e-6)


def test_steady_segments_find_plateaus() -> None:
    v = np.concatenate([np.linspace(0, 1, 10), np.ones(100), np.linspace(1, -2, 10),
                        -2 * np.ones(60), np.zeros(50)])  # fmt: skip
    segs = fr.steady_segments(v, min_samples=50)
    # two non-zero plateaus: value 1 on samples 9..110 (the ramps' end points join them) and
    # -2 on 119..179; the second half of each is kept
    assert [(s.start, s.stop) for s in segs] == [(60, 111), (149, 180)]


def test_static_parameters_from_noise_free_moves() -> None:
    axis = simulator_machine("quaser-ux600").axis("z")
    p = dataclasses.replace(FeedDriveParams.from_config(axis), torque_noise_nm=0.0)
    from millsense.simulator.feed_drive import constant_velocity_sweep

    sp = np.geomspace(0.1, 30.0, 9)
    speeds = np.concatenate([sp, -sp])
    m, _ = constant_velocity_sweep(p, speeds, 10000.0, duration_s=0.6)
    fit = fr.lugre_static_from_moves(speeds, m)
    # Table 3.2 Z row; without noise only the encoder quantisation and the closed-loop
    # transients remain: 3 % on v_s, 0.5 % on the rest
    assert fit.positive.stribeck_velocity == pytest.approx(0.571, rel=0.03)
    assert fit.negative.stribeck_velocity == pytest.approx(0.222, rel=0.03)
    assert fit.positive.coulomb == pytest.approx(2.15, rel=0.005)
    assert fit.negative.viscous == pytest.approx(0.082, rel=0.005)


def test_presliding_recovers_bristle_stiffness_noise_free() -> None:
    cfg = simulator_machine("quaser-ux600")
    axis = cfg.axis("z")
    p = dataclasses.replace(FeedDriveParams.from_config(axis), torque_noise_nm=0.0,
                            closed_loop=False)  # fmt: skip
    level = 0.5 * 2.3 / axis.torque_constant_nm_a
    inj = np.repeat([1.0, 0.0, -1.0, 0.0, 0.6, -0.6], 400) * level
    z = np.zeros(len(inj))
    res = FeedDriveSim(p, 10000.0).advance(z, z, z, inj)
    static = fr.LuGreFit(*(fr.StribeckFit(c, s, v, q, 0.0, True) for c, s, v, q in
                           ((2.15, 2.3, 0.571, 0.065), (2.1, 2.3, 0.222, 0.082))))  # fmt: skip
    pf = fr.fit_presliding(res["current"], res["angle"], 10000.0, inertia_kg_m2=0.0121,
                           torque_constant_nm_a=1.964, static=static)  # fmt: skip
    # Table 3.2: σ0 = 475 N·m/rad, σ1 = 10 N·m·s/rad; the model is the simulator's physics
    # integrated independently (semi-implicit, 10 substeps), so a few % remain
    assert pf.sigma0 == pytest.approx(475.0, rel=0.03)
    assert pf.sigma1 == pytest.approx(10.0, rel=0.15)


def test_presliding_refuses_torque_above_breakaway() -> None:
    static = fr.LuGreFit(*(fr.StribeckFit(2.0, 2.3, 0.5, 0.1, 0.0, True),) * 2)
    i = np.full(500, 1.5)
    with pytest.raises(InputDataError, match="breakaway"):
        fr.fit_presliding(i, np.linspace(0, 1e-3, 500), 1e4, inertia_kg_m2=0.01,
                          torque_constant_nm_a=2.0, static=static)  # fmt: skip


def test_presliding_refuses_a_record_that_is_not_a_bristle_spring() -> None:
    """Decision 1603: steps below breakaway whose angle creeps steadily (no spring: slip of
    2 mrad over the record, the kind of record the truth's rotary axes give) are not fitted
    into an absurd σ0; the one-line refusal lets identify friction go on without it."""
    static = fr.LuGreFit(*(fr.StribeckFit(1.2, 1.9, 0.016, 0.8, 0.0, True),) * 2)
    i = np.repeat([1.0, 0.0, -1.0, 0.0], 500) * 0.3
    creep = np.linspace(0.0, 2e-3, i.size)  # rad, monotonic whatever the current's sign
    with pytest.raises(fr.PreslidingNotIdentified, match="does not describe the record"):
        fr.fit_presliding(i, creep, 1e4, inertia_kg_m2=0.005, torque_constant_nm_a=1.5,
                          static=static)  # fmt: skip


def test_spindle_coulomb_and_viscous() -> None:
    p = dataclasses.replace(SpindleDriveParams.aslan_quaser(), coulomb=0.5)
    rec = cm.spindle_friction_test(p, np.array([60.0, 120.0, 240.0]), hold_s=1.0)
    segs = fr.steady_segments(rec["spindle/speed_ref"], min_samples=5000)
    torque = rec["spindle/torque_constant"] * rec["spindle/current"]
    w, t, _ = fr.move_means(rec["spindle/speed"], torque, segs)
    coul, visc = fr.spindle_friction_from_moves(w, t)
    # Aslan Eq. 5.1-5.2 at constant speed (B_eS = 0.009 N·m·s/rad, τ_coul set to 0.5 N·m);
    # the spindle model has no torque noise, so 1 % is ample
    assert coul == pytest.approx(0.5, rel=0.01)
    assert visc == pytest.approx(0.009, rel=0.01)
