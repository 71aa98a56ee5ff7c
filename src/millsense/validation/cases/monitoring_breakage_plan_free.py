"""Tool breakage without a plan: `millsense monitor` on the virtual machine's V7 recording.

A shop's CNC trace often comes without a virtual plan. `monitor --methods
breakage-dual,breakage-constant` then runs seed 002's dual-residual detector and the constant
reference on the spindle observer's torque, gated by the torque alone (decision 1706) and,
for the dual one, on a broken flute's drop and the next flute's rise (decision 1707).

The recording is V7's (:func:`~millsense.validation.cases.monitoring_breakage.v7_plant`): the
demo part's three slots, the virtual machine cutting its own plan (its z-map, runout and true
coefficients), flute 0 broken in SLOT3, the CNC running the program as written from the
spindle's start. The monitor reads what a CNC records and the commissioned machine file; it
sees no plan. The slots hold a depth step, two crossings, a cavity and two exits: every change
of the cut a shop's part has. Issue 15: "both residuals exceed their thresholds at the
breakage and only there"; breakage effect to event ≤ 3 tooth periods.
"""

from __future__ import annotations

import functools
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millsense.streaming.block import Event
from millsense.streaming.event_log import read_event_log
from millsense.validation import Measured, case
from millsense.validation.cases.monitoring_breakage import MACHINE_FILE, TOOTH_S_V7

METHODS = ("breakage-dual", "breakage-constant")


@dataclass
class PlanFreeRun:
    break_s: float
    events: dict[str, list[Event]]

    def false_alarms(self) -> int:
        return sum(e.time_s < self.break_s for ev in self.events.values() for e in ev)

    def latency_periods(self, method: str) -> float:
        after = [e.time_s for e in self.events[method] if e.time_s >= self.break_s]
        return (min(after) - self.break_s) / TOOTH_S_V7 if after else math.inf

    def table(self) -> str:
        rows = ["| detector | alarms before the break | first alarm after it (tooth periods) |",
                "|---|---|---|"]  # fmt: skip
        for m in METHODS:
            before = [f"{e.time_s:.2f} s" for e in self.events[m] if e.time_s < self.break_s]
            lat = self.latency_periods(m)
            rows.append(f"| {m} | {', '.join(before) or 'none'} | "
                        f"{'none' if math.isinf(lat) else f'{lat:.2f}'} |")  # fmt: skip
        return "\n".join(rows) + f"\n\nFlute 0 breaks at {self.break_s:.3f} s (SLOT3)."


@functools.lru_cache(maxsize=1)
def plan_free_run() -> PlanFreeRun:
    """V7's plant run to its end (seed 7, as the V7 case), recorded as a CNC records it, then
    `millsense monitor` without a plan, in its own process (≈ 30 s)."""
    import subprocess
    import sys

    from millsense.core.recording import Recording
    from millsense.io.recording_file import write_recording
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.validation.cases.monitoring_breakage import v7_plant
    from millsense.validation.cases.simulator_plan import machine_3axis

    m = machine_3axis()
    job, proc, break_s, _ = v7_plant()
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=7))
    keep = [c for c in sim.channel_info if not c.name.startswith("truth/")]
    parts: dict[str, list[np.ndarray]] = {c.name: [] for c in keep}
    while (chunk := sim.read(10000)) is not None:
        for c in keep:
            parts[c.name].append(np.asarray(chunk.data[c.name], dtype=np.float64))
    rec = Recording(m.sample_rate_hz, 0.0, {"flutes": 2, "program": "demo_part_slots.nc"})
    for c in keep:
        rec.add_channel(c.name, np.concatenate(parts[c.name]), c.unit)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "v7.h5"
        write_recording(path, rec)
        # the command as a shop runs it (validation sits below the CLI: run, not imported)
        log = Path(tmp) / "events.parquet"
        cmd = [sys.executable, "-m", "millsense", "monitor", str(path), "--machine",
               str(MACHINE_FILE), "--methods", ",".join(METHODS), "-o", str(log)]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"millsense monitor failed: {done.stderr.strip()[-500:]}")
        logged = read_event_log(log)
    events = {mth: [e for e in logged if e.source == mth and e.name == "breakage"]
              for mth in METHODS}  # fmt: skip
    return PlanFreeRun(break_s, events)


@case(
    "monitoring.breakage.plan_free_false_alarms",
    source="issue 15 (seed 002 breakage pattern): both residuals beyond their thresholds at "
    "the breakage and only there, on a recording without a plan (V7's slots: a depth step, "
    "crossings, a cavity, exits)",
    reference=0.0,
    abs_tol=0.0,
    unit="alarms",
    quick=False,
    description="breakage alarms of `monitor`'s dual and constant detectors before the break, "
    "without a plan (decisions 1706, 1707)",
    issue=15,
)
def _false() -> Measured:
    run = plan_free_run()
    return Measured(float(run.false_alarms()), run.table())


@case(
    "monitoring.breakage.plan_free_dual_latency_periods",
    source="issue 15 acceptance: breakage effect to event ≤ 3 tooth periods (seed 002's "
    "dual-residual detector, no plan)",
    reference=1.5,
    abs_tol=1.5,
    unit="tooth periods",
    quick=False,
    description="first dual-residual alarm after the break, in tooth periods (inf: missed), "
    "`monitor` without a plan",
    issue=15,
)
def _latency() -> Measured:
    run = plan_free_run()
    return Measured(run.latency_periods("breakage-dual"), run.table())
