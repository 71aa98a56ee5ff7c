"""An axis reversal in air on the virtual machine, estimated with the shipped commissioned file
(decision 1695: a presliding fit without a resolved Stribeck curve still makes the LuGre C3
stage, Aslan Eq. 3.2-3.4, so the estimator's friction turns over the bristles' deflection as the
machine's does instead of stepping by 2·T_c when the measured speed changes sign).

One job on the quaser-ux600 truth: rapids with a Y reversal at a junction (X keeps moving), in
air; the Y feed estimator of ``commissioned_machine("quaser-ux600")`` (Aslan ch. 3) on its
signals, as ``millsense estimate`` runs it.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

FS_HZ = 10_000.0
RAPID_M_S = 20.0 / 60.0


@cache
def _run() -> tuple[np.ndarray, np.ndarray, float]:
    """Estimated Y load (lag removed), commanded Y position and the drive's force rating."""
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import commissioned_machine, load_preset
    from millsense.estimation.from_config import build_estimators
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.process_coupling import EngagementSchedule, ProcessCoupling
    from millsense.streaming.block import Chunk, Event
    from millsense.streaming.engine import Pipeline, run

    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    sched = EngagementSchedule.from_spec("slot", tool.diameter_m, 2e-3, start_m=10.0)  # air
    proc = ProcessCoupling(tool, coeffs, sched, n_discs=4)
    w = 1000 * 2 * math.pi / 60
    job = Job(
        np.array([[0, 0, 0, 0, 0], [-0.05, 0.025, 0, 0, 0], [-0.10, -0.025, 0, 0, 0]]),
        np.array([RAPID_M_S, RAPID_M_S]),
        np.array([w, w]),
        np.array([10, 20]),
        np.array([True, True]),
    )
    sim = MachineSimulator(simulator_machine("quaser-ux600"), job, proc, SimulatorOptions(),
                           duration_s=1.2)  # fmt: skip
    shipped = commissioned_machine("quaser-ux600")
    assert shipped is not None
    built = build_estimators(shipped[0], ["feed"], ["y"], FS_HZ)
    kept: list[np.ndarray] = []

    def keep(chunk: Chunk, _out: dict[str, np.ndarray], _ev: list[Event]) -> None:
        kept.append(np.asarray(chunk.data["y/position_cmd"]))

    res = run(sim, Pipeline(list(built.blocks)), 1000, sink=keep)
    ((_, _, channel, lag),) = built.estimates
    est = np.asarray(res.channels[channel], dtype=np.float64)
    est = np.concatenate([est[lag:], np.full(lag, np.nan)])
    limits = shipped[0].limits
    assert limits is not None and limits.axis_force_n is not None
    return est, np.concatenate(kept), limits.axis_force_n


def test_reversal_in_air_stays_within_the_drives_rating() -> None:
    # In air the true Y load is friction-free zero; the estimate's largest excursion is at the
    # reversal (the measured speed changes sign). With the Coulomb C3 stage of the file before
    # decision 1695 it read 17.8 kN here (the -15.5 kN of decision 1682's program), beyond the
    # 9600 N the Y drive can push at all ([limits] axis_force_n, which `estimate` warns about);
    # with the LuGre stage 7.0 kN (2026-11-30).
    est, pos, rating = _run()
    turn = int(np.argmax(pos))  # Y turns from + to - at the junction
    peak = int(np.nanargmax(np.abs(est)))
    assert abs(peak - turn) < 0.02 * FS_HZ  # the excursion is the reversal's
    assert np.nanmax(np.abs(est)) < rating
