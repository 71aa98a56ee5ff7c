"""Feed-drive kernel: resumability, dead times, current loops, sensors, torque balance."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from millsense.models.lugre import LuGre
from millsense.simulator.feed_drive import ElectricalCurrentLoop, FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine


def axis_params(machine: str, axis: str = "x", **kw: object) -> FeedDriveParams:
    return FeedDriveParams.from_config(simulator_machine(machine).axis(axis), **kw)  # type: ignore[arg-type]


def ramp(n: int, v: float, fs: float, ta: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / fs
    vel = np.where(t < ta, v * t / ta, v)
    pos = np.where(t < ta, 0.5 * v * t**2 / ta, 0.5 * v * ta + v * (t - ta))
    return pos, vel


@pytest.mark.parametrize("machine", ["quaser-ux600", "yamada-a"])
def test_chunked_runs_are_bit_identical(machine: str) -> None:
    # all state (mechanics, modes, LuGre z, current loop, dead-time rings, RNG) carries over
    p = axis_params(machine)
    fs = simulator_machine(machine).sample_rate_hz
    n = 3000
    pos, vel = ramp(n, 40.0, fs)
    load = 100.0 + 50.0 * np.sin(2 * math.pi * 60.0 * np.arange(n) / fs)
    inj = 0.01 * np.sin(2 * math.pi * 300.0 * np.arange(n) / fs)
    whole = FeedDriveSim(p, fs, seed=5).advance(pos, vel, load, inj)
    sim = FeedDriveSim(p, fs, seed=5)
    parts: dict[str, list[np.ndarray]] = {}
    for a, b in [(0, 1), (1, 7), (7, 1000), (1000, 2333), (2333, n)]:
        for k, v in sim.advance(pos[a:b], vel[a:b], load[a:b], inj[a:b]).items():
            parts.setdefault(k, []).append(v)
    for k, v in whole.items():
        np.testing.assert_array_equal(np.concatenate(parts[k]), v)


def test_amplifier_dead_time_and_first_order_current_loop() -> None:
    # open loop, current step at t = 0: nothing for T_s = 0.35 ms (Yamada A), then
    # i = 1 − exp(−ω_cc (t − T_s)) with ω_cc = 3000 rad/s (Table 3-2, 3-3)
    p = replace(axis_params("yamada-a", friction="none", periodic=False), closed_loop=False)
    fs = 20000.0
    n = 100
    res = FeedDriveSim(p, fs).advance(np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n))
    t = (np.arange(n) + 1) / fs  # actual current at the end of each sample
    expected = np.where(t > 0.35e-3, 1.0 - np.exp(-3000.0 * (t - 0.35e-3)), 0.0)
    np.testing.assert_allclose(res["current"], expected, atol=2e-3)  # ω_cc·h/2 discretisation


def test_electrical_pi_current_loop_bandwidth() -> None:
    # PI designed by pole–zero cancellation: closed loop ω_cc/(s + ω_cc) apart from the back-EMF;
    # motor at rest for the first ms, so the 63 % rise time is 1/ω_cc (1 kHz → 159 µs)
    base = axis_params("quaser-ux600", friction="none", modes=False)
    cl = ElectricalCurrentLoop.designed(0.5, 5e-3, 1.2, 1000.0)
    p = replace(base, current_loop=cl, closed_loop=False, torque_noise_nm=0.0)
    fs = 100000.0
    n = 100
    res = FeedDriveSim(p, fs).advance(np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n))
    t63 = (np.argmax(res["current"] >= 1 - math.exp(-1)) + 1) / fs
    assert t63 == pytest.approx(1 / (2 * math.pi * 1000.0), rel=0.07)  # 10 µs sample grid


def test_sensors_are_quantised() -> None:
    # Yamada A: 17-bit motor encoder, 20 nm linear scale (Table 3-2)
    p = axis_params("yamada-a")
    fs = 20000.0
    n = 400
    pos, vel = ramp(n, 10.0, fs, 0.01)
    res = FeedDriveSim(p, fs).advance(pos, vel, np.zeros(n))
    counts = res["scale"] / 20e-9
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    q = 2 * math.pi / 2**17
    np.testing.assert_allclose(res["angle"] / q, np.round(res["angle"] / q), atol=1e-6)
    assert q * 5e-3 / (2 * math.pi) == pytest.approx(38e-9, rel=0.01)  # "38 nm equiv."


def test_constant_speed_torque_balance_with_modes() -> None:
    # Aslan Eq. 3.1 + 3.13 at steady speed: K_t·i = g(v) + σ2·v + Φ_d(0)·(r_g/η)·F; the printed
    # X modes give Φ_d(0) = 0.558, not 1 (digest P5) — the drive feels 56 % of a static load
    p = replace(axis_params("quaser-ux600"), torque_noise_nm=0.0)
    assert isinstance(p.friction, LuGre) and p.modes is not None
    fs = 10000.0
    n = 20000
    omega, force = 20.0, 400.0
    pos, vel = ramp(n, omega, fs)
    res = FeedDriveSim(p, fs).advance(pos, vel, np.full(n, force))
    tau = p.torque_constant * np.mean(res["current"][n // 2 :])
    expected = float(p.friction.steady_torque(np.array([omega]))[0])
    expected += p.modes.static_gain() * p.transmission / p.efficiency * force
    assert tau == pytest.approx(expected, rel=2e-3)


def test_drive_validation_cases_registered_and_quick_ones_pass() -> None:
    from millsense.validation import run_case, select_cases

    ids = {c.id for c in select_cases("simulator.*")}
    want = {f"simulator.quaser_disturbance_frf_peak_{a}" for a in "xyzac"}
    want |= {"simulator.yamada_a_resonance", "simulator.yamada_b_resonance"}
    want |= {"simulator.lugre_stribeck_sweep"}
    assert want <= ids
    # the Yamada resonances (335/408 Hz ± 2 %, Table 3-3) are quick
    for c in select_cases("simulator.yamada_*", quick_only=True):
        r = run_case(c)
        assert r.passed, (c.id, r.measured, r.error)
