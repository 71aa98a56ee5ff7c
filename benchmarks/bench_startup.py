"""What a session pays before its first sample: the feed-drive estimators' design and the
virtual machine's construction, each against the code it replaced, run side by side.

- ``startup.feed_estimators``: the five feed axes' estimators of the commissioned quaser-ux600
  built from the machine file (Q tuning: the design model's FRF on 2001 frequencies for every
  candidate Q). Baseline: the same build with ``StateSpaceModel.frf`` as a Python loop of one
  solve per frequency and the model's FRF recomputed for every candidate, as before the
  change (same numbers; the tuned filters are bit-identical).
- ``startup.simulator``: a ``MachineSimulator`` of the V8 slot on the 5-axis truth plant,
  constructed in a fresh process (numba's disk cache warm). Baseline: the same with the drives'
  states also put in a numba typed List, which the simulator used to pass (its methods are
  compiled in every process, not cached).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _harness import Metric, alternated, benchmark

ROOT = Path(__file__).resolve().parents[1]
MACHINE_FILE = ROOT / "examples/walkthrough/quaser-ux600-commissioned.toml"


def _loop_frf(self, f_hz):  # type: ignore[no-untyped-def]
    """``StateSpaceModel.frf`` as it was: one solve per frequency in a Python loop."""
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    s = 2j * np.pi * f if self.dt is None else np.exp(2j * np.pi * f * self.dt)
    eye = np.eye(self.n_states)
    out = np.empty((len(f), self.c.shape[0], self.b.shape[1]), dtype=complex)
    for i, si in enumerate(s):
        out[i] = self.c @ np.linalg.solve(si * eye - self.a, self.b) + self.d
    return out


def _build_estimators(old: bool) -> float:
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.feed import tuning
    from millsense.estimation.from_config import build_estimators
    from millsense.estimation.kalman import design

    cfg = load_preset(MachineConfig, str(MACHINE_FILE))
    saved = (design.StateSpaceModel.frf, design.compensated_frf)
    if old:
        plain = design.compensated_frf

        def every_time(model, gains, f_hz, *, output=0, measurement=0, plant_frf=None):  # type: ignore[no-untyped-def]
            return plain(model, gains, f_hz, output=output, measurement=measurement)

        design.StateSpaceModel.frf = _loop_frf  # type: ignore[method-assign]
        tuning.compensated_frf = every_time  # type: ignore[assignment]
    try:
        t0 = time.perf_counter()
        build_estimators(cfg, ["feed"], list(cfg.axes), 10000.0, where="bench")
        return time.perf_counter() - t0
    finally:
        design.StateSpaceModel.frf = saved[0]  # type: ignore[method-assign]
        tuning.compensated_frf = saved[1]


_SIM = """
import time
from millsense.simulator.machine import MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.plan_job import plan_job
from millsense.validation.cases.control_adaptive import DEPTH_HIGH_MM, DEPTH_LOW_MM, step_plan
m = simulator_machine("quaser-ux600")
job, proc, _, _ = plan_job(step_plan(DEPTH_LOW_MM, DEPTH_HIGH_MM), m, "v8")
t0 = time.perf_counter()
sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=0), duration_s=1.0)
if {old}:
    from numba.typed import List
    states = List()
    for st in sim._fb_states:
        states.append(st)
print(time.perf_counter() - t0)
"""


def _construct_simulator(old: bool) -> float:
    out = subprocess.run([sys.executable, "-c", _SIM.format(old=old)], capture_output=True,
                         text=True, check=True, cwd=ROOT)  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


@benchmark("startup.feed_estimators")
def _feed_estimators() -> list[Metric]:
    _build_estimators(False)  # imports, numba cache
    new, old = alternated(lambda: _build_estimators(False), lambda: _build_estimators(True), 2)
    note = "the commissioned quaser-ux600's five feed axes (ten filters), best of 2, one core"
    return [
        Metric("build_s", new, "s", higher_is_better=False, note=note),
        Metric("build_s_before", old, "s", higher_is_better=False, note=note),
        Metric("speedup", old / new, "x", baseline="per-frequency loop, FRF per Q", note=note),
    ]


@benchmark("startup.simulator")
def _simulator() -> list[Metric]:
    _construct_simulator(False)  # numba's disk cache filled
    new, old = alternated(lambda: _construct_simulator(False),
                          lambda: _construct_simulator(True), 3)  # fmt: skip
    note = "MachineSimulator of the V8 slot on the 5-axis truth, a fresh process, best of 3"
    return [
        Metric("construct_s", new, "s", higher_is_better=False, note=note),
        Metric("construct_s_before", old, "s", higher_is_better=False, note=note),
        Metric("speedup", old / new, "x", baseline="states in a numba typed List", note=note),
    ]
