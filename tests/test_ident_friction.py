"""Friction identification from simulated constant-velocity moves (Aslan C1)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.config import MachineConfig
from millsense.core.errors import InputDataError
from millsense.core.presets import load_preset
from millsense.ident.friction import coulomb_viscous_from_moves, fit_line
from millsense.machine.rigid_drive import RigidDriveParams, constant_velocity_move


def test_line_fit_exact_on_a_line() -> None:
    w = np.array([2.0, 4.0, 8.0])
    fit = fit_line(w, 1.5 + 0.2 * w)  # closed form: intercept 1.5, slope 0.2
    assert fit.intercept == pytest.approx(1.5, abs=1e-12)
    assert fit.slope == pytest.approx(0.2, abs=1e-12)


def test_one_speed_is_refused() -> None:
    with pytest.raises(InputDataError, match="two speeds"):
        fit_line(np.array([3.0, 3.0]), np.array([1.0, 1.0]))


def test_recovers_table_3_2_friction_from_simulated_moves() -> None:
    axis = load_preset(MachineConfig, "quaser-ux600").axis("x")
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
