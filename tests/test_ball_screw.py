"""Dual/triple-inertia ball screws (Yamada) and position-periodic disturbances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.config import PeriodicDisturbanceConfig
from millsense.models.ball_screw import (
    dual_inertia_plant,
    periodic_terms,
    plant_from_config,
    resonance_hz,
    triple_inertia_plant,
)
from millsense.models.drive_plant import KIND_SCALE, KIND_TORQUE, OUT_ALPHA
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine

R = 5e-3 / (2 * math.pi)


@pytest.mark.parametrize(("machine", "fs_hz"), [("yamada-a", 340.4), ("yamada-b", 409.8)])
def test_dual_inertia_undamped_resonance(machine: str, fs_hz: float) -> None:
    # Yamada Eq. 2-5/2-6: ω_s = √((α+1)K_r/M_t), α = M_t R²/J_r; the digest computes
    # 340 Hz (A) and 410 Hz (B) from Table 3-3 (the FRF peak 335/408 Hz is a validation case)
    plant = plant_from_config(simulator_machine(machine).axis("x"))
    assert resonance_hz(plant)[0] == pytest.approx(fs_hz, rel=2e-3)


def test_dual_inertia_rigid_body_limit() -> None:
    # far below the resonance the stage is one body (Eq. 2-7/2-8):
    # α_m/τ = s/(J_a s + D_r + C_t R²), J_a = J_r + M_t R² (Table 3-3 A)
    plant = dual_inertia_plant(3.8e-5, 5e-3, 6.2, 25.7e6, 2500.0, 370.0, 2.3e-3)
    f = np.array([5.0, 20.0])
    s = 2j * math.pi * f
    expected = s / ((3.8e-5 + 6.2 * R**2) * s + 2.3e-3 + 370.0 * R**2)
    np.testing.assert_allclose(plant.frf(f, 0, OUT_ALPHA), expected, rtol=2e-3)


def test_triple_inertia_resonances() -> None:
    # digest §2.6: M_r 30 kg, M_n 30 kg, M_t 6.2 kg, K_r 3.06e7, K_ω 3.41e8 N/m reproduce the
    # 366 Hz and 770 Hz resonances of Yamada Fig. 2-9 (roots of Eq. 2-56)
    plant = triple_inertia_plant(30.0 * R**2, 5e-3, 30.0, 6.2, 3.41e8, 3.06e7)
    np.testing.assert_allclose(resonance_hz(plant), [366.0, 770.0], rtol=0.02)


def test_periodic_term_conversion() -> None:
    cfgs = [
        PeriodicDisturbanceConfig(kind="thrust", wavelength_mm=5.0, amplitude_n=5.0),
        PeriodicDisturbanceConfig(kind="scale", per_motor_rev=512.0, amplitude_um=0.01),
    ]
    t0, t1 = periodic_terms(cfgs, R)
    # a 5 mm wavelength on a 5 mm lead is once per motor revolution; 5 N of thrust is 5·R N·m
    assert (t0.kind, t0.wavenumber, t0.amplitude) == (
        KIND_TORQUE,
        pytest.approx(1.0),
        pytest.approx(5 * R),
    )
    # 512 per revolution is a 9.77 µm wavelength of table travel (Yamada §2.8)
    assert t1.kind == KIND_SCALE
    assert 2 * math.pi / t1.wavenumber == pytest.approx(9.766e-6, rel=1e-3)


def test_torque_ripple_appears_at_its_frequency() -> None:
    # Yamada B at 5 mm/s: the motor turns once per second, so the 30-per-revolution torque
    # ripple (§3.6) is a 30 Hz line in the current command; the ball circulation
    # (0.610 mm) is at 5/0.61 = 8.2 Hz
    m = simulator_machine("yamada-b")
    p = FeedDriveParams.from_config(m.axis("x"), friction="none")
    fs = m.sample_rate_hz
    n = 40000
    t = np.arange(n) / fs
    w = 2 * math.pi  # rad/s of motor = 5 mm/s
    res = FeedDriveSim(p, fs).advance(w * t, np.full(n, w), np.zeros(n))
    i = res["current_cmd"][n // 2 :]
    spec = np.abs(np.fft.rfft(i - i.mean()))
    f = np.fft.rfftfreq(len(i), 1 / fs)
    band = (f > 20) & (f < 45)
    assert f[band][np.argmax(spec[band])] == pytest.approx(30.0, abs=0.1)
    band = (f > 5) & (f < 12)
    assert f[band][np.argmax(spec[band])] == pytest.approx(5 / 0.61, abs=0.2)
