"""Spindle drive: stated figures vs the printed coefficients, time domain vs analytic FRF."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from millsense.models import spindle_plant as SP
from millsense.models.spindle_modes import ATTENUATION_RANGE1
from millsense.simulator import spindle as S
from millsense.simulator.machine_file import simulator_machine

P = SP.SpindleDriveParams.aslan_quaser()


def test_closed_loop_is_stable_in_both_ranges() -> None:
    for r in (0, 1):
        # decision 1 (residual in the open velocity loop) must give a stable loop
        assert SP.closed_loop_poles(P, r).real.max() < -10.0


def test_additive_gsp_reading_would_be_unstable() -> None:
    # The rejected reading: modes added to the mechanical G_sp = 1/(Js+B) + Σ modes, with the
    # printed Eq. 5.8 G_m. Characteristic polynomial den_L + num_L (polynomial algebra, an
    # independent construction): a right-half-plane root, for either G_Ω unit reading.
    from millsense.models.spindle_modes import GM_DEN_RANGE1, GM_NUM, MODES_RANGE1

    num_m, den_m = np.array([0.0]), np.array([1.0])
    for f_n, zeta, alpha, beta in MODES_RANGE1:
        w = 2 * math.pi * f_n
        d = np.array([1.0, 2 * zeta * w, w * w])
        num_m = np.polyadd(np.polymul(num_m, d), np.polymul([beta, alpha], den_m))
        den_m = np.polymul(den_m, d)
    rig = np.array([P.inertia, P.viscous])
    num_sp = np.polyadd(den_m, np.polymul(num_m, rig))
    den_sp = np.polymul(rig, den_m)
    for scale in (1.0, 2 * math.pi):
        num_l = np.polymul(np.polymul([20 / scale, 600 / scale], GM_NUM), num_sp) * 1.343
        den_l = np.polymul(np.polymul([1.0, 0.0], GM_DEN_RANGE1), den_sp)
        assert np.roots(np.polyadd(den_l, num_l)).real.max() > 50.0  # +124 and +1674 rad/s


def test_current_loop_bandwidth_gap_is_documented() -> None:
    # printed Eq. 5.8: the digest computes ≈ 286 Hz / 1590 Hz; PI + Eq. 5.7 gives the same
    assert SP.current_loop_bandwidth_hz(P, 0, printed=True) == pytest.approx(286.0, rel=0.02)
    assert SP.current_loop_bandwidth_hz(P, 1, printed=True) == pytest.approx(1590.0, rel=0.02)
    bw1 = SP.current_loop_bandwidth_hz(P, 0)
    bw2 = SP.current_loop_bandwidth_hz(P, 1)
    assert bw1 == pytest.approx(SP.current_loop_bandwidth_hz(P, 0, printed=True), rel=0.02)
    # documented gap (docs/decisions/0032-spindle-drive-reading-of-aslan-ch-5.md): stated simulated
    # 360 Hz and 1240 Hz
    assert 360.0 - bw1 == pytest.approx(80.0, abs=5.0)
    assert bw2 - 1240.0 == pytest.approx(344.0, abs=10.0)


def test_velocity_loop_bandwidth_gap_is_documented() -> None:
    # stated (range 1): 34 Hz simulated, 38 Hz measured; this model gives ≈ 91 Hz (the
    # printed residual modes raise the loop gain between 30 and 300 Hz); rigid body alone
    # with G_Ω per rev/s gives ≈ 27 Hz (digest P7 caveat: 27–29 Hz)
    assert SP.velocity_loop_bandwidth_hz(P, 0) == pytest.approx(91.2, rel=0.03)
    rigid = replace(P, ranges=tuple(replace(r, modes=r.modes[:0]) for r in P.ranges))  # type: ignore[arg-type]
    assert SP.velocity_loop_bandwidth_hz(rigid, 0) == pytest.approx(28.0, rel=0.06)


def test_attenuation_table_gaps() -> None:
    f = np.array([hz for hz, _ in ATTENUATION_RANGE1])
    stated = np.array([db for _, db in ATTENUATION_RANGE1])
    model = 20 * np.log10(np.abs(SP.disturbance_frf(P, f)))
    # The printed coefficients cannot reproduce the table; gaps (model − stated, dB) recorded
    # in docs/decisions/0032-spindle-drive-reading-of-aslan-ch-5.md: +3.2, +3.7, −7.7, −6.0, −14.2
    np.testing.assert_allclose(model - stated, [3.2, 3.7, -7.7, -6.0, -14.2], atol=0.3)
    # the state-space FRF and the transfer-function form with printed Eq. 5.8 agree (0.1 dB):
    # two independent constructions of G_dτ
    printed = 20 * np.log10(np.abs(SP.disturbance_frf_printed(P, f)))
    np.testing.assert_allclose(model, printed, atol=0.1)


def test_low_frequency_gain_is_inverse_torque_constant() -> None:
    # within the velocity bandwidth the controller balances τ_d: I_nom/τ_d → 1/K_tS
    assert abs(SP.disturbance_frf(P, [0.01])[0]) == pytest.approx(1 / 1.343, rel=1e-3)


@pytest.mark.parametrize("f_hz", [20.0, 457.0, 2320.0])
def test_time_domain_matches_exact_discrete_frf(f_hz: float) -> None:
    p1 = replace(P, velocity_period_s=1e-4)
    sim = S.SpindleDriveSim(p1)
    h_sim = S.measured_frf(p1, f_hz)
    h_exact = S.discrete_disturbance_frf(sim, [f_hz])[0]
    # same linear system stepped vs solved in z: residual transient after 0.6 s < e^{-16·0.6}
    assert abs(h_sim / h_exact - 1.0) < 1e-6


def test_sampled_loop_magnitude_close_to_continuous() -> None:
    # 0.2 ms velocity loop vs continuous analytic G_dτ: the hold adds phase lag, magnitude
    # within 0.5 dB up to 945 Hz (measured 0.08/0.24/0.45 dB)
    for f_hz in (100.0, 457.0, 945.0):
        db_sim = 20 * math.log10(abs(S.measured_frf(P, f_hz)))
        db_cont = 20 * math.log10(abs(SP.disturbance_frf(P, [f_hz])[0]))
        assert abs(db_sim - db_cont) < 0.5


def test_resumable_chunks_and_range_switch() -> None:
    n = 6000
    t = np.arange(n) * 1e-4
    ref = np.minimum(t / 0.3, 1.0) * 4000.0 * 2 * math.pi / 60  # ramp through 3300 rev/min
    tau = 2.0 * (t > 0.4)
    one = S.SpindleDriveSim(P).advance(ref, tau)
    sim = S.SpindleDriveSim(P)
    parts = [sim.advance(ref[a:b], tau[a:b]) for a, b in [(0, 17), (17, 2503), (2503, n)]]
    for k in one:
        np.testing.assert_array_equal(np.concatenate([p[k] for p in parts]), one[k])
    # range 2 once the reference passes 3300 rev/min (t = 0.2475 s)
    assert one["speed_range"][2470] == 0 and one["speed_range"][2490] == 1
    # steady state: speed follows, current balances viscous + cutting torque through K_t2
    w = ref[-1]
    assert one["speed"][-1] == pytest.approx(w, rel=1e-3)
    assert one["current_cmd"][-1] == pytest.approx((2.0 + 0.009 * w) / 1.571, rel=1e-2)


def test_from_preset() -> None:
    m = simulator_machine("quaser-ux600")
    assert m.spindle is not None
    p = SP.SpindleDriveParams.from_config(m.spindle)
    assert p.ranges[1].torque_constant == 1.571
    assert p.switch_rad_s == pytest.approx(3300 * 2 * math.pi / 60)
