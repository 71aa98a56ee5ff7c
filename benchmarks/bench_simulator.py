"""Benchmarks of the closed-loop virtual machine (issue 5 performance acceptance; issue 12 "a
bench fast enough to use").

Every case runs the simulator's default — the truth plant (coupled lumped-mass drives) with
realism on, spindle and cutting — and, side by side in the same run on the same job, the NumPy
block loop of before the speed work (``SimulatorOptions(reference_loop=True)``, decision 1081),
so the speed-up is a ratio of two figures taken under the same load. Real-time factors are
simulated seconds per CPU second of this process (``time.process_time``), the figure the issue
asks for on one core; the wall figures also measure whatever else runs on the host.
"""

from __future__ import annotations

import math
import time

from _harness import Metric, benchmark
from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import EngagementSchedule, ProcessCoupling

#: simulated seconds per measurement (each of the new and the reference loop)
SIM_S = 20.0


def _process() -> ProcessCoupling:
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))  # 2 flutes
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    sched = EngagementSchedule.from_spec("slot", tool.diameter_m, 2e-3, start_m=0.001)
    return ProcessCoupling(tool, coeffs, sched, n_discs=10)


def _setup(kind: str) -> tuple[MachineConfig, Job]:
    m = simulator_machine("quaser-ux600")
    rpm = 6000.0
    om = rpm * 2 * math.pi / 60
    feed = 0.1e-3 * 2 * rpm / 60
    if kind == "5":
        return m, Job.straight([0, 0, 0, 0, 0], [1.3, 0.1, 0, 0.2, 0.5], feed, om)
    if kind == "3":
        m = m.with_axes("xyz", "3-axis")
        return m, Job.straight([0, 0, 0], [1.3, 0.0, 0.0], feed, om)
    # one axis: the UX600's X drive as a stage (its truth plant), with the spindle and cutting
    m = m.with_axes("x", "1-axis-stage")
    return m, Job.straight([0, 0, 0], [1.3, 0.0, 0.0], feed, om)


def _time(machine: MachineConfig, job: Job, reference: bool) -> tuple[float, float]:
    """(wall s, CPU s) of SIM_S simulated seconds read in 10 000-sample chunks."""
    opts = SimulatorOptions(reference_loop=reference)
    # warm-up (numba caches) on a short run
    MachineSimulator(machine, job, _process(), opts, duration_s=0.05).read(500)
    sim = MachineSimulator(machine, job, _process(), opts, duration_s=SIM_S)
    assert sim.truth_axes and sim.metadata["realism"], "the bench measures the default"
    t0 = time.perf_counter()
    c0 = time.process_time()
    while sim.read(10_000) is not None:
        pass
    return time.perf_counter() - t0, time.process_time() - c0


def _metrics(kind: str, target: float | None, what: str) -> list[Metric]:
    machine, job = _setup(kind)
    wall, cpu = _time(machine, job, reference=False)
    _, cpu_ref = _time(machine, job, reference=True)
    return [
        Metric(
            "cpu_x_realtime",
            SIM_S / cpu,
            "x",
            target=target,
            higher_is_better=True,
            note=f"sim s / CPU s of this process, {what}; truth plant, realism on (default)",
        ),
        Metric("x_realtime", SIM_S / wall, "x", note="sim s / wall s (includes the host load)"),
        Metric(
            "cpu_x_realtime_reference",
            SIM_S / cpu_ref,
            "x",
            note="the same job with the NumPy block loop of before the speed work "
            "(reference_loop=True), same run",
        ),
        Metric(
            "speedup_vs_reference",
            cpu_ref / cpu,
            "1",
            baseline="reference_loop=True, same run",
            note="CPU time of the reference loop / CPU time of the default",
        ),
    ]


@benchmark("machine.simulator_5axis")
def _five() -> list[Metric]:
    return _metrics("5", 20.0, "5 truth feed drives, spindle, 2 flutes x 10 discs")


@benchmark("machine.simulator_3axis")
def _three() -> list[Metric]:
    return _metrics("3", None, "X/Y/Z truth drives, spindle, 2 flutes x 10 discs")


@benchmark("machine.simulator_1axis")
def _one() -> list[Metric]:
    return _metrics("1", 50.0, "X truth drive as a stage, spindle, 2 flutes x 10 discs")
