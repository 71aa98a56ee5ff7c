"""Validation cases of the virtual machine (:mod:`millsense.simulator.machine`)."""

from __future__ import annotations

import math

import numpy as np

from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.geometry import EndMill
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import (
    EngagementSchedule,
    ProcessCoupling,
    ToolModes,
    ToothBreak,
)
from millsense.simulator.sensors import SensorOptions
from millsense.stability.time_domain import DirectionModes
from millsense.validation import Measured, case

FS = 10000.0


def _machine3() -> MachineConfig:
    m = simulator_machine("quaser-ux600")
    return m.with_axes("xyz", "3-axis")


def _run(sim: MachineSimulator) -> dict[str, np.ndarray]:
    parts: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(1000)) is not None:
        for k, v in c.data.items():
            parts.setdefault(k, []).append(v)
    return {k: np.concatenate(v) for k, v in parts.items()}


@case(
    "simulator.simulator_breakage_current_step",
    source="issue 5 acceptance; Munasinghe digest V1 (tooth-period averages)",
    reference=0.0,
    unit="tooth periods",
    abs_tol=1.0,
    quick=True,
    description="Slot, Ø20 mm 2-flute, 6000 rev/min, 0.1 mm/tooth, 2 mm: a tooth broken at "
    "0.6 s shows in the tooth-period spread of the spindle current command within one tooth "
    "period of the injected time (measured: offset in tooth periods)",
)
def _breakage() -> Measured:
    rpm = 6000.0
    omega = rpm * 2 * math.pi / 60
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    sched = EngagementSchedule.from_spec("slot", tool.diameter_m, 2e-3, start_m=0.001)
    proc = ProcessCoupling(tool, coeffs, sched, events=[ToothBreak(0.6, 0)])
    job = Job.straight([0, 0, 0], [0.2, 0, 0], 0.1e-3 * 2 * rpm / 60, omega)
    d = _run(MachineSimulator(_machine3(), job, proc, SimulatorOptions(seed=1), duration_s=0.9))
    # per tooth period (by the measured spindle angle): peak-to-peak of the current command
    angle = np.cumsum(d["spindle/speed"]) / FS
    period = np.maximum(np.floor(angle / math.pi), 0).astype(int)
    t = np.arange(len(period)) / FS
    cur = d["spindle/current_cmd"]
    n_p = int(period.max()) + 1
    mean = np.bincount(period, weights=cur, minlength=n_p) / np.maximum(
        np.bincount(period, minlength=n_p), 1
    )
    start = np.array([t[np.argmax(period == p)] for p in range(n_p)])
    # one flute gone: consecutive tooth-period means alternate (one cuts 2c, one nothing)
    alt = np.abs(np.diff(mean))
    ok = (start[1:] > 0.4) & (start[1:] < 0.55)
    base = float(np.max(alt[ok]))
    later = np.nonzero((alt > 3 * base) & (start[1:] > 0.4))[0]
    t_det = float(start[1:][later[0]])
    tooth = math.pi / omega
    off = (t_det - 0.6) / tooth
    return Measured(
        off,
        f"detected at {t_det:.4f} s (injected 0.6 s), tooth period {tooth * 1e3:.1f} ms, "
        f"alternation before {base:.3f} A, after {float(np.median(alt[later])):.3f} A",
    )


def _chatter_run(depth_factor: float) -> tuple[dict[str, np.ndarray], float]:
    # benchmarks.md §1 (Insperger 2003) 1-DOF slotting, 15 870 rev/min, critical 0.3174 mm
    rpm = 15870.0
    omega = rpm * 2 * math.pi / 60
    tool = EndMill(10e-3, 2)
    coeffs = CuttingCoefficients(ktc=6e8, krc=2e8)
    modes = ToolModes(
        DirectionModes.from_arrays([922.0], [0.011], [1.34005e6]), DirectionModes.rigid()
    )
    depth = depth_factor * 0.3174e-3
    sched = EngagementSchedule.constant(Engagement.slot(), depth, start=0.001)
    proc = ProcessCoupling(tool, coeffs, sched, n_discs=1, modes=modes)
    job = Job.straight([0, 0, 0], [0.3, 0, 0], 0.05e-3 * 2 * rpm / 60, omega)
    opts = SimulatorOptions(seed=2, sensors=SensorOptions(accelerometer=True))
    sim = MachineSimulator(_machine3(), job, proc, opts, duration_s=1.6)
    return _run(sim), omega


def _chatter_peak_hz(x: np.ndarray, omega: float) -> float:
    """Largest spectral peak above 100 Hz away from the spindle harmonics (± 3 bins), Hz."""
    x = (x - x.mean()) * np.hanning(len(x))
    spec = np.abs(np.fft.rfft(x))
    f = np.fft.rfftfreq(len(x), 1 / FS)
    f_rev = omega / (2 * math.pi)
    near = np.abs(f / f_rev - np.rint(f / f_rev)) * f_rev <= 3 * f[1]
    spec[near | (f < 100)] = 0.0
    return float(f[int(np.argmax(spec))])


@case(
    "simulator.simulator_chatter_frequency",
    source="benchmarks.md §1 (Insperger 2003); stability.time_domain_insperger_chatter_hz",
    reference=932.0,
    unit="Hz",
    rel_tol=0.02,
    quick=False,
    description="Simulated slot at 1.2 × the SDM critical depth (15 870 rev/min, 1-DOF tool "
    "mode 922 Hz): the chatter frequency of the truth tool vibration over the last 0.5 s, away "
    "from spindle harmonics (the accelerometer and the tool force are reported: the force "
    "carries the chatter at f_c ± k·f_tooth with comparable weights, 404/932/1462 Hz)",
)
def _chatter_hz() -> Measured:
    d, omega = _chatter_run(1.2)
    last = slice(-5000, None)
    f_vib = _chatter_peak_hz(d["truth/tool/vibration_x"][last], omega)
    f_acc = _chatter_peak_hz(d["accel/x"][last], omega)
    f_force = _chatter_peak_hz(d["truth/tool/force_x"][last], omega)
    chat = float(np.mean(d["truth/process/chatter"][last]))
    return Measured(
        f_vib,
        f"tool vibration peak {f_vib:.1f} Hz, accelerometer {f_acc:.1f} Hz, tool force "
        f"{f_force:.1f} Hz (tooth frequency {omega / math.pi:.1f} Hz); chatter flag on "
        f"{chat:.0%} of the last 0.5 s",
    )


@case(
    "simulator.simulator_chatter_flag_below_above",
    source="benchmarks.md §1 (Insperger 2003)",
    reference=2.0,
    unit="agreeing verdicts",
    abs_tol=0.0,
    quick=False,
    description="Chatter flag of the simulator at 0.8× (none) and 1.2× (chatter) the "
    "critical depth, last 0.5 s",
)
def _flags() -> Measured:
    agree = 0
    rows = []
    for fac, want in ((0.8, 0.0), (1.2, 1.0)):
        d, _ = _chatter_run(fac)
        frac = float(np.mean(d["truth/process/chatter"][-5000:]))
        agree += int((frac > 0.5) == (want > 0.5))
        rows.append(f"| {fac} | {frac:.2f} |")
    return Measured(
        float(agree), "| depth factor | chatter fraction |\n|---|---|\n" + "\n".join(rows)
    )


@case(
    "simulator.simulator_sampled_path_feed",
    source="issue 5 (interpolator at the programmed feed); Aslan's 0.4 mm virtual-file spacing",
    reference=20.0,
    unit="mm/s",
    rel_tol=0.001,
    quick=True,
    description="G-code line + R 50 mm arc sampled every 0.4 mm, F1200 on the quaser-ux600 "
    "preset (3-axis program on the 5-axis machine): mean interpolated path speed between the "
    "acceleration ramps (was 19.04 mm/s with a stop-anticipating limit at every vertex)",
)
def _sampled_path_feed() -> Measured:
    from millsense.plan.gcode import interpret
    from millsense.plan.path import sample_path

    prog = "G21 G90 G17\nS6000 M3\nG1 X0 Y0 Z0 F1200\nG1 X20\nG2 X40 Y0 R50\nM30\n"
    job = Job.from_sampled_path(sample_path(interpret(prog)), five_axis=True)
    m = simulator_machine("quaser-ux600")
    opts = SimulatorOptions(seed=6, spindle_accel_rad_s2=20000.0)
    d = _run(MachineSimulator(m, job, None, opts))
    feed = d["cnc/feed"]
    a = opts.path_accel_m_s2
    # cruise: beyond the ramp distances F²/(2a) = 0.1 mm plus the discrete look-ahead's
    # margin (≤ 6 periods at F, 0.36 mm; decision "Interpolator arc length ...")
    moving = np.nonzero(feed > 0)[0]
    length = float(job.arc_length()[-1])
    s = np.cumsum(feed) / FS
    margin = 0.02**2 / (2 * a) + 6 * 0.02 * 3e-3
    cruise = feed[(s > margin) & (s < length - margin)]
    t_move = (moving[-1] - moving[0] + 1) / FS
    return Measured(
        float(np.mean(cruise)) * 1e3,
        f"{len(job.path)} points over {length * 1e3:.2f} mm; cruise min "
        f"{float(np.min(cruise)) * 1e3:.3f} mm/s; move time {t_move:.4f} s against "
        f"L/F + F/a = {length / 0.02 + 0.02 / a:.4f} s; Z and A/C travel "
        f"{float(np.ptp(d['truth/z/position'])) * 1e6:.1f} µm, "
        f"{float(np.max(np.abs(d['truth/a/position']))) * 1e6:.1f} µrad",
    )
