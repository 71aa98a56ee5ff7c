"""The compiled block loop gives the recordings of the NumPy block loop (decision 1081).

Golden comparison: the same job run with ``reference_loop=True`` (the block loop of before the
speed work, kept verbatim) and with the default, on the simulator's default plant (truth, realism
on, spindle, cutting). Tolerance 1e-9 of each channel's range (of the force family's range for
the loads and forces, whose z components are round-off themselves): the two loops evaluate the
same formulas with a different summation order of 3- and 5-term products (≤ 1e-15 relative per
block); the closed loops (drives, tooth-period chip, tool modes) carry that round-off forward,
which stays below 1e-10 of the range over these runs (measured 3e-12 at 0.5 s).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.models.kinematics import TrunnionACMachine
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.fast_block import trunnion_block, trunnion_loads, trunnion_tip_error
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import EngagementSchedule, ProcessCoupling, ToolModes
from millsense.simulator.realism import RealismOptions
from millsense.stability.time_domain import DirectionModes

RTOL = 1e-9
RPM = 6000.0
OMEGA = RPM * 2 * math.pi / 60
FEED = 0.1e-3 * 2 * RPM / 60


def _process(tool_modes: bool) -> ProcessCoupling:
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    sched = EngagementSchedule.from_spec("slot", tool.diameter_m, 2e-3, start_m=0.0005)
    modes = (
        ToolModes(
            DirectionModes.from_arrays([922.0], [0.03], [2e7]),
            DirectionModes.from_arrays([1100.0], [0.03], [2e7]),
        )
        if tool_modes
        else None
    )
    return ProcessCoupling(tool, coeffs, sched, n_discs=4, modes=modes)


def _machine(kind: str) -> tuple[MachineConfig, Job]:
    m = simulator_machine("quaser-ux600")
    if kind in ("5", "5-ideal"):
        return m, Job.straight([0, 0, 0, 0, 0], [0.3, 0.02, 0, 0.2, 0.5], FEED, OMEGA)
    if kind == "3":
        m = m.with_axes("xyz", "3-axis")
        return m, Job.straight([0, 0, 0], [0.3, 0.02, 0.0], FEED, OMEGA)
    m = m.with_axes("x", "1-axis-stage")
    return m, Job.straight([0, 0, 0], [0.3, 0.0, 0.0], FEED, OMEGA)


def _record(
    kind: str, reference: bool, tool_modes: bool, seconds: float
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], int]:
    m, job = _machine(kind)
    # a fast spindle run-up puts the cut inside a short run; "5-ideal": the machine file's
    # one-way drives with the realism layer's position-dependent mode tables (the per-axis
    # fallback of the batched drive call)
    ideal = kind == "5-ideal"
    opts = SimulatorOptions(
        seed=7,
        spindle_accel_rad_s2=20000.0,
        reference_loop=reference,
        ideal=ideal,
        realism=RealismOptions() if ideal else None,
    )
    sim = MachineSimulator(m, job, _process(tool_modes), opts, duration_s=seconds)
    assert sim.metadata["realism"] and bool(sim.truth_axes) != ideal
    assert (sim._fb_states is None) == ideal  # which drive path the compiled loop takes
    parts: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(997)) is not None:  # reads not aligned with the 30-sample blocks
        for k, v in c.data.items():
            parts.setdefault(k, []).append(v)
    rows = sim.take_stream_rows()
    return {k: np.concatenate(v) for k, v in parts.items()}, rows, len(sim.take_events())


def _worst(ref: dict[str, np.ndarray], new: dict[str, np.ndarray]) -> tuple[str, float]:
    assert ref.keys() == new.keys()
    fam = [k for k in ref if k.startswith("truth/tool/force") or k.endswith("/load")]
    f_scale = max(float(np.max(np.abs(ref[k]))) for k in fam)
    worst, name = 0.0, ""
    for k, x in ref.items():
        y = new[k]
        assert x.shape == y.shape, k
        scale = f_scale if k in fam else float(np.max(np.abs(x)))
        d = float(np.max(np.abs(x - y))) / max(scale, 1e-300)
        if d > worst:
            worst, name = d, k
    return name, worst


@pytest.mark.parametrize(
    ("kind", "tool_modes"),
    [("5", False), ("5", True), ("1", False), ("3", True), ("5-ideal", False)],
    ids=["5axis", "5axis-modes", "1axis", "3axis-modes", "5axis-ideal-realism"],
)
def test_fast_loop_matches_reference(kind: str, tool_modes: bool) -> None:
    ref, rows_ref, ev_ref = _record(kind, True, tool_modes, 0.4)
    new, rows_new, ev_new = _record(kind, False, tool_modes, 0.4)
    # the run cuts: forces of the order of 100 N (slot, 0.1 mm/tooth, 2 mm deep in Al 7050)
    assert float(np.max(np.abs(ref["truth/tool/force_x"]))) > 50.0
    name, worst = _worst(ref, new)
    assert worst < RTOL, f"{name}: {worst:.3g} of its range"
    for k, v in rows_ref.items():
        np.testing.assert_allclose(rows_new[k], v, rtol=0, atol=RTOL * max(np.max(np.abs(v)), 1e-3))
    assert ev_new == ev_ref


def test_trunnion_kernels_match_kinematics() -> None:
    """The compiled trunnion formulas against :class:`TrunnionACMachine` on random poses
    (independent NumPy implementation of Aslan Eq. 3.38/3.39/3.49), to 1e-13."""
    kin = TrunnionACMachine()
    rng = np.random.default_rng(4)
    n = 50
    q = np.column_stack([rng.uniform(-0.3, 0.3, (n, 3)), rng.uniform(-3.0, 3.0, (n, 2))])
    v = rng.normal(size=(n, 5))
    f = rng.normal(scale=300.0, size=(n, 3))
    v_w, axis, rot, lm = (
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty((n, 3, 3)),
        np.empty((n, 5, 3)),
    )
    trunnion_block(q, v, kin.a2_m, kin.d4_m, v_w, axis, rot, lm)
    np.testing.assert_allclose(v_w, np.einsum("nij,nj->ni", kin.jacobian(q), v), atol=1e-13)
    np.testing.assert_allclose(axis, kin.orientation(q[:, 3], q[:, 4]), atol=1e-13)
    np.testing.assert_allclose(rot, kin.rotation(q[:, 3], q[:, 4]), atol=1e-13)
    np.testing.assert_allclose(lm, kin.load_matrix(q), atol=1e-13)
    f_m, loads = np.empty((n, 3)), np.empty((n, 5))
    trunnion_loads(rot, lm, f, f_m, loads)
    f_ref = np.einsum("nji,nj->ni", kin.rotation(q[:, 3], q[:, 4]), f)
    np.testing.assert_allclose(f_m, f_ref, atol=1e-10)
    np.testing.assert_allclose(loads, -kin.drive_loads(q, f_ref), atol=1e-10)
    err = rng.normal(scale=1e-4, size=5)
    out = np.empty(3)
    trunnion_tip_error(q[0], err, kin.a2_m, kin.d4_m, out)
    np.testing.assert_allclose(out, kin.forward(q[0]) - kin.forward(q[0] - err), atol=1e-15)
