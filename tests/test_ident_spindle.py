"""Spindle identification: residual modes and G_dτ from a velocity-loop sweep (issue 6 item 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.ident import spindle as isp
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.simulator import commissioning as cm
from millsense.simulator.spindle import measured_frf


def test_controller_error_unit() -> None:
    a = isp.VelocityController(20.0, 600.0, "rev/s", 0.0).frf(np.array([10.0]))
    b = isp.VelocityController(20.0, 600.0, "rad/s", 0.0).frf(np.array([10.0]))
    # decision 2 of the spindle reading: gains per rev/s are 1/2π of the same gains per rad/s
    assert abs(b[0] / a[0]) == pytest.approx(2 * math.pi, rel=1e-12)
    s = 2j * math.pi * 10.0
    assert b[0] == pytest.approx(20.0 + 600.0 / s, rel=1e-12)


@pytest.fixture(scope="module")
def sweep_fit() -> isp.SpindleFit:
    p = SpindleDriveParams.aslan_quaser()
    rec = cm.spindle_sweep(p, period_s=0.5, n_periods=3, f_lo_hz=2.0, f_hi_hz=2000.0)
    ctl = isp.VelocityController(20.0, 600.0, "rev/s", 2e-4)
    return isp.fit_spindle(
        rec["spindle/speed_ref"], rec["spindle/speed"], rec["spindle/current_cmd"],
        rec["spindle/current"], 1e4, int(rec.metadata["period_samples"]), controller=ctl,
        inertia_kg_m2=0.0316, viscous_nm_s_rad=0.009, torque_constant_nm_a=1.343,
        band_hz=(2.0, 2000.0), max_modes=14,
    )  # fmt: skip


def test_short_sweep_gives_gdtau_within_2_db(sweep_fit: isp.SpindleFit) -> None:
    p = SpindleDriveParams.aslan_quaser()
    f = np.array([20.0, 100.0, 450.0, 1000.0, 1800.0])
    est = sweep_fit.disturbance_frf(f)
    sim = np.array([measured_frf(p, float(x)) for x in f])
    # issue 6 acceptance (2 dB), on a short sweep: truth = the simulator's sine response
    assert np.max(np.abs(20 * np.log10(np.abs(est / sim)))) < 2.0
    # the CNC gains agree with the measured controller (a wrong unit would be 16 dB)
    assert sweep_fit.controller_mismatch_db() < 1.0
    # the fitted residual reproduces the measured one (relative RMS, vector fitting)
    assert sweep_fit.residual.rms_error < 0.05
    table = isp.residual_modes_table(sweep_fit)
    assert len(table["natural_frequency_hz"]) == len(sweep_fit.residual.modes)  # type: ignore[arg-type]


def test_fitted_residual_finds_the_appendix_e_modes(sweep_fit: isp.SpindleFit) -> None:
    found = np.array([m.natural_frequency_hz for m in sweep_fit.residual.modes])
    # Aslan App. E range 1 below 2 kHz: 21.9, 66.8, 258.8, 457.9, 640, 875, 1050, 1350 Hz
    # (1800 Hz has |α|, |β| too small to show); each within 2 %
    for f_true in (21.9, 66.8, 258.8, 457.9, 640.0, 875.0, 1050.0, 1350.0):
        assert np.min(np.abs(found / f_true - 1.0)) < 0.02, f_true


def test_sweep_identifies_the_inertia_and_the_motor_admittance() -> None:
    # decision 1708: the velocity-loop sweep's rigid body (Aslan Eq. 5.1, 5-50 Hz) gives J/K_t
    # and its current loop the Eq. 5.7 admittance (5-500 Hz, the current PI on I_nom held
    # between CNC samples). On the Ch. 5 model without residual modes (J 0.034 against a
    # file's 0.030; the speed from the encoder's difference or at the instant) both come back:
    # measured 2e-6 and 3e-4. On the truth spindle (torsional chain, R-L winding, PI sampled
    # at 20 kHz with a dead time) J is ΣJ·K_t,file/K_t,truth within 0.08 % (nameplate 0.02907
    # is 10 % below it).
    from dataclasses import replace

    from millsense.simulator.truth_spindle import load_truth_spindle

    base = SpindleDriveParams.aslan_quaser()
    ctl = isp.VelocityController(20.0, 600.0, "rev/s", 2e-4)

    def fit(p: object, kt: float) -> isp.SpindleFit:
        rec = cm.spindle_sweep(p, period_s=0.5, n_periods=3)  # type: ignore[arg-type]
        return isp.fit_spindle(
            rec["spindle/speed_ref"], rec["spindle/speed"], rec["spindle/current_cmd"],
            rec["spindle/current"], 1e4, int(rec.metadata["period_samples"]), controller=ctl,
            inertia_kg_m2=0.030, viscous_nm_s_rad=0.009, torque_constant_nm_a=kt,
            identify_inertia=True, current_pi=(3.1, 1010.0, 0.12),
        )  # fmt: skip

    rigid = tuple(replace(r, modes=np.zeros((0, 4))) for r in base.ranges)
    for diff in (False, True):
        p = replace(base, inertia=0.034, ranges=rigid, speed_from_encoder_difference=diff)
        got = fit(p, 1.343)
        assert got.inertia == pytest.approx(0.034, rel=1e-4)
        assert got.admittance == pytest.approx(p.ranges[0].admittance, rel=1e-3)
    truth = load_truth_spindle("quaser-ux600")
    got = fit(truth, 1.397)
    expected = truth.mechanics.total_inertia * 1.397 / truth.ranges[0].torque_constant
    assert got.inertia == pytest.approx(expected, rel=3e-3)
