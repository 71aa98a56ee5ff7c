"""The wear monitor at plan-matched engagement (decision 2002), on closed forms and on the
virtual machine, whose flank-wear truth is another model (decision 2001)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.cli.cmd_fleet import write_fleet_plans
from millsense.cli.cmd_simulate import run_simulation
from millsense.core.presets import commissioned_machine
from millsense.io import read_recording
from millsense.monitoring.wear import (
    EDGE_TOLERANCE,
    ToolRun,
    WearBelief,
    WearBlock,
    WearSums,
    assess_tool,
    fresh_fit,
    fresh_scale,
    vb_from_sums,
    wear_trend,
)
from millsense.online.wear_run import recording_wear_sums
from millsense.plan.virtual_plan import VirtualPlan
from millsense.simulator.tool_life import fleet_plant_plan
from millsense.streaming.block import Chunk


def _belief_torque(xs: np.ndarray, xe: np.ndarray, s: float, vb: float, kte: float) -> np.ndarray:
    b = WearBelief()
    return s * xs + xe + vb * (s * b.shear_growth_per_mm * 1e3 * xs
                               + b.flank_friction * b.contact_stress_n_m2 / kte * xe)  # fmt: skip


def test_the_belief_model_is_inverted_exactly() -> None:
    rng = np.random.default_rng(3)
    xs, xe = rng.uniform(0.5, 3.0, 500), rng.uniform(0.2, 1.5, 500)
    fresh, worn = WearSums(), WearSums()
    fresh.add(_belief_torque(xs, xe, 1.07, 0.0, 25e3), xs, xe)
    worn.add(_belief_torque(xs, xe, 1.07, 0.23e-3, 25e3), xs, xe)
    s = fresh_scale(fresh)
    assert s == pytest.approx(1.07, rel=1e-12)
    assert vb_from_sums(worn, s, 25e3, WearBelief()) == pytest.approx(0.23e-3, rel=1e-9)


def _belief_torque_edge(xs: np.ndarray, xe: np.ndarray, s: float, e: float) -> np.ndarray:
    return s * xs + e * xe  # a new tool whose real K_te is e × the plan's


def test_edge_scale_is_identified_only_where_the_engagement_varies() -> None:
    """Decision 1760: with shear and edge torque varying independently (a reference run of
    varying chip thickness) both scales are identified exactly; in a cut of constant width
    (edge a fixed fraction of shear, as in every fleet program) the condition number is far
    beyond what identifies e (EDGE_TOLERANCE) and the plan's K_te is kept (e = 1, s absorbing
    the edge)."""
    rng = np.random.default_rng(6)
    xs, xe = rng.uniform(0.5, 3.0, 500), rng.uniform(0.2, 1.5, 500)
    varied = WearSums()
    varied.add(_belief_torque_edge(xs, xe, 1.06, 1.15), xs, xe)
    fit = fresh_fit(varied)
    # edge over shear c spreads ±61 % about its mean: a 2 % plan mismatch moves e by ≤ 15 %
    assert fit.edge_identified and fit.edge_error < EDGE_TOLERANCE
    assert (fit.scale, fit.edge_scale) == pytest.approx((1.06, 1.15), rel=1e-9)
    # constant width: x_e = 0.256 x_s (the fleet's slot, its ratio measured in decision
    # 1760) within ±0.5 % from the plan's rows
    xe_c = 0.256 * xs * rng.uniform(0.995, 1.005, 500)
    steady = WearSums()
    steady.add(_belief_torque_edge(xs, xe_c, 1.06, 1.15), xs, xe_c)
    fit = fresh_fit(steady)
    assert not fit.edge_identified and fit.edge_scale == 1.0
    # c spreads ±0.29 %: a 2 % plan mismatch could move e by 0.02 × 1.256 / 0.00074 ≈ 34
    assert fit.condition > 1e5 and fit.edge_error > 10.0
    # s takes the edge's 15 % at this ratio: 1.06 + 0.15 × 0.256 (to the rows' ±0.5 %)
    assert fit.scale == pytest.approx(1.06 + 0.15 * 0.256, abs=1e-4)
    assert fit.scale == pytest.approx(fresh_scale(steady), rel=1e-12)


def test_trend_extrapolates_a_line_to_the_limit() -> None:
    t = np.array([0.0, 600.0, 1200.0, 1800.0])
    vb = 0.05e-3 + 1e-7 * t  # 0.1 mm per 1000 s
    tr = wear_trend(t, vb)
    assert tr.rate_m_s == pytest.approx(1e-7, rel=1e-9)
    # at 1800 s VB = 0.23 mm: 0.07 mm left at 1e-7 m/s = 700 s
    assert tr.remaining_s == pytest.approx(700.0, rel=1e-6)
    assert wear_trend([0.0, 10.0], [0.31e-3, 0.32e-3]).remaining_s == 0.0


def test_tool_runs_are_judged_in_order_with_the_first_as_reference() -> None:
    rng = np.random.default_rng(4)
    runs = []
    for order, vb in ((2.0, 0.2e-3), (0.0, 0.0), (1.0, 0.1e-3)):
        xs, xe = rng.uniform(0.5, 3.0, 200), rng.uniform(0.2, 1.5, 200)
        s = WearSums()
        s.add(_belief_torque(xs, xe, 0.95, vb, 25e3), xs, xe)
        runs.append(ToolRun(f"r{order:g}", order * 600, 30.0, s, 25e3))
    out = assess_tool(runs, cutting_time_known=True)
    assert [o.run for o in out] == ["r0", "r1", "r2"]
    assert out[0].reference and out[0].vb_m == 0.0
    assert [o.vb_m * 1e3 for o in out[1:]] == pytest.approx([0.1, 0.2], rel=1e-9)


@pytest.fixture(scope="module")
def fleet_plans(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return write_fleet_plans(tmp_path_factory.mktemp("plans"))


def _simulated(plan: Path, plant: VirtualPlan, vb_mm: float, out: Path) -> Path:
    """The virtual machine cutting its own plan ``plant`` of ``plan``'s program (decisions
    1740, 1760: finer z-map, runout, the lot's true coefficients)."""
    run_simulation(machine="quaser-ux600", program=None, plan=plan, tool=None, material=None,
                   engagement="slot", depth_mm=2.0, out=out, duration_s=None, seed=7,
                   cnc="open", break_at_s=None, break_flute=0, realism=None,
                   accelerometer=False, microphone=False, chunk=2000,
                   wear_vb_mm=vb_mm, plant=plant)  # fmt: skip
    return out


def test_wear_block_is_chunk_invariant(fleet_plans: list[Path]) -> None:
    vp = VirtualPlan.read(fleet_plans[0])
    n = 5000
    rng = np.random.default_rng(5)
    data = {
        "plan/row": np.repeat(np.arange(50, 100), n // 50).astype(np.float64),
        "plan/judged_torque": np.r_[np.zeros(1000), np.ones(n - 1000)],
        "plan/in_cut": np.ones(n),
        "plan/cutting_torque": rng.normal(2.0, 0.3, n),
        "cnc/feed_override": np.full(n, 1.0),
        "spindle/at_speed": np.ones(n),
    }
    sums = []
    for size in (n, 7, 333):
        b = WearBlock(vp)
        b.reset(1e4)
        for k in range(0, n, size):
            b.process(Chunk(k, 1e4, 0.0, {c: v[k : k + size] for c, v in data.items()}))
        sums.append(b.sums.as_dict())
    for other in sums[1:]:
        assert other == pytest.approx(sums[0], rel=1e-12)


def test_vb_on_the_virtual_machine_does_not_depend_on_depth_or_width(
    fleet_plans: list[Path], tmp_path: Path
) -> None:
    machine = commissioned_machine("quaser-ux600")
    assert machine is not None
    est = {}
    for k in (0, 2):  # the 2 mm slot and the 4 mm deep, 5 mm wide side cut
        vp = VirtualPlan.read(fleet_plans[k])
        plant = fleet_plant_plan(fleet_plans[k].with_suffix(".nc"))
        sums = {}
        for vb in (0.0, 0.3):
            out = _simulated(fleet_plans[k], plant, vb, tmp_path / f"p{k}_{vb}.h5")
            rec = read_recording(out)
            # the recording names the monitor's plan, not the machine's own
            assert rec.metadata["plan"] == str(fleet_plans[k])
            sums[vb] = recording_wear_sums(rec, vp, machine[0])
        s = fresh_scale(sums[0.0])
        est[k] = vb_from_sums(sums[0.3], s, 25e3, WearBelief())
        # the worn tool needs more than 10 % more torque in the same cut
        assert sums[0.3].raw_torque_nm > 1.1 * sums[0.0].raw_torque_nm
    # truth VB 0.3 mm; the belief (linear land, other σ, μ, g) reads 0.30–0.36 mm on the
    # truth's relaxed land: within 0.06 mm (20 %, decision 2002)
    for k, v in est.items():
        assert abs(v * 1e3 - 0.3) <= 0.06, (k, v)
    # matched engagement: the two cuts read the same wear within 0.02 mm
    assert abs(est[0] - est[2]) * 1e3 <= 0.02
    assert math.isfinite(est[0])
