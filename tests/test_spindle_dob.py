"""The spindle's disturbance observer for tooth-period averages (seed 001 Eq. 2-15, decision
1726)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.estimation.spindle_dob import DOB_TORQUE, SpindleDobTorque
from millsense.models.friction import CoulombViscous
from millsense.streaming.block import Chunk

FS = 10000.0
J = 0.0322509  # the commissioned quaser-ux600's J_eS, kg·m²
KT = (1.397, 1.634)
COUNTS = 2**20  # the spindle encoder's counts a revolution


def _run(block: SpindleDobTorque, data: dict[str, np.ndarray], chunk: int) -> np.ndarray:
    block.reset(FS)
    n = len(data["spindle/speed"])
    return np.concatenate([
        block.process(Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in data.items()}))
        .channels[DOB_TORQUE]
        for a in range(0, n, chunk)
    ])  # fmt: skip


def _spindle(tau_cut: np.ndarray, w0: float, accel: float, quantise: bool) -> dict[str, np.ndarray]:
    """A rigid spindle (J) accelerating at ``accel`` under the cutting torque ``tau_cut``: the
    current that does it, and its speed as a CNC gives it (one encoder difference a sample,
    quantised to the counts if ``quantise``)."""
    n = tau_cut.size
    t = np.arange(n + 1) / FS
    angle = w0 * t + 0.5 * accel * t**2
    if quantise:
        angle = np.floor(angle * COUNTS / (2 * math.pi)) * 2 * math.pi / COUNTS
    speed = np.diff(angle) * FS
    current = (J * accel + tau_cut) / KT[0]
    return {"spindle/current_cmd": current, "spindle/speed": speed,
            "spindle/speed_cmd": np.full(n, w0)}  # fmt: skip


def test_dob_gives_the_cutting_torque_of_a_rigid_spindle_in_any_chunks() -> None:
    """Closed form: a rigid spindle at 3000 rev/min accelerating at 50 rad/s² under 3 N·m
    whose speed is linear in time: each pair of window means differs by exactly α/f_s, so the
    DOB gives K_tS·I − J·α = 3 N·m (to round-off) once its window holds the stream; the same
    output in 1-, 7- and 1000-sample chunks (its history crosses them)."""
    n = 3000
    data = _spindle(np.full(n, 3.0), 2 * math.pi * 50.0, 50.0, quantise=False)
    block = SpindleDobTorque(KT, math.inf, J)
    assert block.window == 9  # 0.9 ms at 10 kHz
    out = _run(block, data, 1000)
    np.testing.assert_allclose(out[20:], 3.0, atol=1e-9)
    for chunk in (1, 7):
        np.testing.assert_array_equal(_run(block, data, chunk), out)


def test_dob_averages_the_encoder_quantisation_out_of_tooth_periods() -> None:
    """Closed form: the mean of a tooth period's inertial term is J·(Ω̄_end − Ω̄_start)/T, with
    Ω̄ the mean of the window's speeds, (θ_k − θ_{k−m})/(m T_s): the encoder's quantisation of
    the angle is divided by the window m. A steady 3 N·m cut at 6074 rev/min (a speed whose
    counts a sample do not repeat within a period), 2^20 counts a revolution, 25-sample
    periods: with one encoder difference the period mean's error is J·(e₁ − e₂ − e₃ + e₄)·q/T,
    four independent angle quantisations (uniform, σ = 1/√12 count; q = one count a sample in
    rad/s): J·q/T/√3 = 0.45 N·m, ±20 % for 2000 periods' sampling spread and the angles'
    residual correlation; with the 9-sample window 1/9 of it (0.08-0.15)."""
    n = 50_000
    data = _spindle(np.full(n, 3.0), 2 * math.pi * 101.2345, 0.0, quantise=True)
    std = {}
    for m in (1, 9):
        out = _run(SpindleDobTorque(KT, math.inf, J, window=m), data, 1000)
        periods = out[100 : 100 + 25 * 1996].reshape(-1, 25).mean(axis=1)
        assert periods.mean() == pytest.approx(3.0, abs=0.02)
        std[m] = float(periods.std())
    q = 2 * math.pi / COUNTS * FS  # one count of speed, rad/s
    assert std[1] == pytest.approx(J * q * FS / 25 / math.sqrt(3), rel=0.2)
    assert 0.08 <= std[9] / std[1] <= 0.15


def test_dob_switches_the_torque_constant_and_subtracts_the_friction() -> None:
    """Range 2's K_tS at and above the switch speed (the speed command, as the drive and the
    LQE observer), range 1's below; the friction at the window's centre speed subtracted: a
    constant current of 2 A at a constant 3300 rev/min gives 2·K_tS − τ_fric."""
    n = 200
    w = 2 * math.pi * 55.0
    friction = CoulombViscous(0.5, 0.5, 1e-3, 1e-3, 0.5)
    data = {"spindle/current_cmd": np.full(n, 2.0), "spindle/speed": np.full(n, w),
            "spindle/speed_cmd": np.full(n, w)}  # fmt: skip
    expected_friction = float(friction.torque(np.array([w]))[0])
    for switch, kt in ((w, KT[1]), (w * 1.01, KT[0])):
        out = _run(SpindleDobTorque(KT, switch, J, friction=friction), data, 64)
        np.testing.assert_allclose(out, 2.0 * kt - expected_friction, rtol=1e-12)


def test_dob_refuses_bad_parameters() -> None:
    with pytest.raises(ConfigError, match="odd"):
        SpindleDobTorque(KT, math.inf, J, window=4)
    with pytest.raises(ConfigError, match="inertia"):
        SpindleDobTorque(KT, math.inf, 0.0)
    with pytest.raises(ConfigError, match="torque constants"):
        SpindleDobTorque((1.0, -1.0), math.inf, J)


def test_session_breakage_averages_the_dob_torque_by_default() -> None:
    """Decisions 1726, 1727: the session's breakage monitor averages the DOB's cutting torque
    (less its own air reference, a DOB block added) by default and the LQE observer's with
    ``breakage_torque="observer"``; anything else is a one-line error."""
    from pathlib import Path

    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.online.session import (
        CUTTING_TORQUE,
        DOB_CUTTING_TORQUE,
        SessionOptions,
        session_blocks,
    )
    from millsense.validation.cases.control_adaptive import step_plan

    machine = Path(__file__).resolve().parents[1] / (
        "examples/walkthrough/quaser-ux600-commissioned.toml"
    )
    cfg = load_preset(MachineConfig, str(machine))
    assert SessionOptions().breakage_torque == "dob"
    for which, signal in (("dob", DOB_CUTTING_TORQUE), ("observer", CUTTING_TORQUE)):
        built = session_blocks(step_plan(2.0, 3.0), cfg, FS, SessionOptions(breakage_torque=which))
        (brk,) = [c for b in built.blocks for c in getattr(b, "children", ())
                  if c.name == "breakage"]  # fmt: skip
        assert brk.members[0].signal_channels == (signal,)
        dobs = [b for b in built.blocks if isinstance(b, SpindleDobTorque)]
        assert len(dobs) == (which == "dob")
    with pytest.raises(ConfigError, match="--breakage-torque"):
        SessionOptions(breakage_torque="current")

