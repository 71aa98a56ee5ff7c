"""The virtual machine runs its own truth by default; ``ideal`` is today's one-way model
(decision 0976)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.models.lugre import LuGre
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.truth_machine import load_truth

FEED = 0.02  # m/s


def _run(opts: SimulatorOptions) -> tuple[MachineSimulator, dict[str, np.ndarray]]:
    m = simulator_machine("quaser-ux600")
    m = m.with_axes("xyz", "3-axis")
    job = Job.straight([0, 0, 0], [0.2, 0, 0], FEED, 0.0)
    sim = MachineSimulator(m, job, None, opts, duration_s=0.8)
    parts: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(2000)) is not None:
        for k, v in c.data.items():
            parts.setdefault(k, []).append(v)
    return sim, {k: np.concatenate(v) for k, v in parts.items()}


def test_default_is_the_truth_and_ideal_is_the_machine_file() -> None:
    """Steady air move at 20 mm/s on X: the mean motor torque K_t·i equals the steady friction
    of the model that runs (closed form sgn(v)·g(v) + σ2·v, Aslan Eq. 3.2–3.4): the truth's
    K_t and friction by default, the machine file's with ``ideal=True``; the two differ by
    more than 3 %."""
    m = simulator_machine("quaser-ux600")
    truth = load_truth("quaser-ux600")["x"]
    preset_fric = LuGre.from_config(m.axes["x"].friction)
    means = {}
    for ideal in (False, True):
        sim, data = _run(SimulatorOptions(seed=2, ideal=ideal))
        meta = sim.metadata
        assert meta["truth_plant"] == ("ideal" if ideal else "coupled")
        assert meta["realism"] is (not ideal)
        kt = truth.torque_constant if not ideal else m.axes["x"].torque_constant_nm_a
        fric = truth.friction if not ideal else preset_fric
        speed = FEED / m.axes["x"].transmission_m_rad
        steady = data["truth/x/motor_speed"] > 0.98 * speed
        assert steady.sum() > 3000
        tau = kt * float(np.mean(data["x/current"][steady]))
        expect = float(fric.steady_torque(np.array([speed]))[0])
        # realism's friction drift is a few per cent at most over 0.8 s (ripple of ±1–3 %)
        assert tau == pytest.approx(expect, rel=0.04), (ideal, tau, expect)
        means[ideal] = tau
    assert abs(means[False] / means[True] - 1) > 0.03
