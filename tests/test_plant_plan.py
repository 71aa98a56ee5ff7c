"""The virtual machine cuts its own plan of a program (decision 1740): the helper, and the
acceptance cases the issue 12 audit named (V8/V6 closed loop, the on-line session's slot, chatter
pass and demo part, the tool-life fleet), whose plant engagement must never be the controller's
or monitor's plan object."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from millsense.plan.plan_engagement import PlanEngagement
from millsense.simulator import plan_job as plan_job_module
from millsense.simulator.plant_plan import (
    PLANT_CELL_M,
    PLANT_LOT_FACTORS,
    PLANT_RUNOUT_ANGLE_RAD,
    PLANT_RUNOUT_M,
    plant_plan,
)

SLOT = "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\nG1 Z-2 F400\nX72\nG0 Z5\nM30\n"


class _Stop(Exception):
    """Raised by a patched consumer once the case's plans are captured (no simulation)."""


def _capture_plan_job(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Any, Any]]:
    """Wrap plan_job: record (plan given, process built) of every call."""
    real = plan_job_module.plan_job
    seen: list[tuple[Any, Any]] = []

    def wrapped(vp: Any, *a: Any, **k: Any) -> Any:
        out = real(vp, *a, **k)
        seen.append((vp, out[1]))
        return out

    monkeypatch.setattr(plan_job_module, "plan_job", wrapped)
    return seen


def _stop_at(monkeypatch: pytest.MonkeyPatch, module: Any, name: str, arg: int = 0) -> list[Any]:
    """Replace ``module.name`` by a recorder of its positional argument ``arg`` (the plan it
    is given) that stops the case."""
    got: list[Any] = []

    def stop(*a: Any, **k: Any) -> Any:
        got.append(a[arg])
        raise _Stop

    monkeypatch.setattr(module, name, stop)
    return got


def _assert_own_plan(proc: Any, plant: Any, expectation: Any) -> None:
    """The process cuts ``plant`` (its own plan, runout), never the expectation's plan."""
    eng = proc.engagement
    assert isinstance(eng, PlanEngagement)
    assert eng.plan is plant
    assert eng.plan is not expectation
    # the plant's tool has the runout the expectation's plan does not know (decision 1730)
    assert proc.tool.runout_offset_m == pytest.approx(PLANT_RUNOUT_M, rel=1e-12)
    assert float(expectation.metadata["tool"].get("runout_um", 0.0)) == 0.0
    # the same program: the same rows and path
    assert len(plant) == len(expectation)
    np.testing.assert_allclose(plant.xyz_m, expectation.xyz_m, atol=1e-12)
    _assert_lot_coefficients(proc, expectation)


def test_plant_plan_is_a_finer_cut_with_runout() -> None:
    """Same program and stock, its own z-map and runout; earlier programs shape the stock."""
    from millsense.plan.gcode import interpret
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import plan_program
    from millsense.validation.cases.simulator_plan import _tool_coeffs

    tool, coeffs = _tool_coeffs()
    cells: list[float] = []

    def stock(cell_m: float) -> ZMapStock:
        cells.append(cell_m)
        return ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], cell_m)

    prog = interpret(SLOT, source="slot.nc")
    nameplate = plan_program(prog, stock(1e-4), tool, coeffs)
    plant = plant_plan([prog], stock, tool, coeffs)
    assert cells == [1e-4, PLANT_CELL_M]
    assert plant.metadata["tool"]["runout_um"] == pytest.approx(PLANT_RUNOUT_M * 1e6)
    assert tool.runout_offset_m == 0.0  # the caller's tool is not changed
    ap_plan, ap_plant = np.asarray(nameplate["axial_depth_mm"]), np.asarray(plant["axial_depth_mm"])
    # the same slot, 2 mm deep in both (the cell does not change the depth in full cut) ...
    assert np.median(ap_plant[ap_plant > 0]) == pytest.approx(2.0, abs=0.05)
    assert np.median(ap_plan[ap_plan > 0]) == pytest.approx(2.0, abs=0.05)
    # ... run twice, the second pass cuts the air the first one left (the stock is shared)
    twice = plant_plan([prog, prog], stock, tool, coeffs, runout_angle_rad=1.0)
    assert float(np.max(np.asarray(twice["axial_depth_mm"]))) == pytest.approx(0.0, abs=0.01)
    assert twice.metadata["tool"]["runout_angle_deg"] == pytest.approx(np.degrees(1.0))
    assert PLANT_RUNOUT_ANGLE_RAD == 0.4
    with pytest.raises(ValueError, match="at least one program"):
        plant_plan([], stock, tool, coeffs)


def test_v8_v6_closed_loop_plant_is_not_the_controller_plan(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import millsense.control.adaptive_feed as af
    from millsense.validation.cases import control_adaptive as ca

    for args in ((ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM, False), (7.62, 10.5, True)):
        seen = _capture_plan_job(monkeypatch)
        ctrl = _stop_at(monkeypatch, af, "AdaptiveFeedBlock", arg=1)  # (options, plan)
        with pytest.raises(_Stop):
            ca.closed_loop_run.__wrapped__(False, "open", *args)
        assert len(seen) == 1 and len(ctrl) == 1
        assert ctrl[0] is ca.step_plan(*args)
        _assert_own_plan(seen[0][1], ca.plant_step_plan(*args), ctrl[0])


def test_online_session_slot_and_chatter_plant_is_not_the_session_plan(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import millsense.online.session as session
    from millsense.validation.cases import control_adaptive as ca
    from millsense.validation.cases import online_session as os_

    seen = _capture_plan_job(monkeypatch)
    plans = _stop_at(monkeypatch, session, "session_blocks")
    with pytest.raises(_Stop):
        os_.session_run.__wrapped__()
    assert plans[0] is ca.step_plan(ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM)
    _assert_own_plan(seen[0][1], ca.plant_step_plan(ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM), plans[0])

    with pytest.raises(_Stop):
        os_.chatter_run.__wrapped__()
    _assert_own_plan(seen[1][1], seen[1][0], plans[1])


def test_demo_part_plant_is_not_the_session_plan(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    import millsense.online.session as session
    from millsense import demo_online

    seen = _capture_plan_job(monkeypatch)
    plans = _stop_at(monkeypatch, session, "session_blocks")
    plan, plant = demo_online._plan(tmp_path), demo_online._plant_plan()
    with pytest.raises(_Stop):
        demo_online._run(plan, plant, False, tmp_path / "r.h5", tmp_path / "e.parquet", None)
    assert plans[0] is plan
    _assert_own_plan(seen[0][1], plant, plan)
    # the finer cut of the cavity and the step gives engagements of its own
    assert not np.array_equal(
        np.asarray(plant["axial_depth_mm"]), np.asarray(plan["axial_depth_mm"])
    )


def test_demo_chatter_plant_is_not_the_session_plan(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    import millsense.online.session as session
    from millsense import demo_chatter

    seen = _capture_plan_job(monkeypatch)
    plans = _stop_at(monkeypatch, session, "session_blocks")
    plan, plant = demo_chatter._plan(tmp_path), demo_chatter._plant_plan()
    with pytest.raises(_Stop):
        demo_chatter._run(plan, plant, False, tmp_path / "r.h5", tmp_path / "e.parquet", None)
    assert plans[0] is plan
    _assert_own_plan(seen[0][1], plant, plan)


def test_tool_life_plant_is_not_the_wear_monitor_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    import millsense.online.wear_run as wear_run
    from millsense.validation.cases import monitoring_wear as mw

    seen = _capture_plan_job(monkeypatch)
    monitored = _stop_at(monkeypatch, wear_run, "source_wear_sums", arg=1)  # (source, plan)
    with pytest.raises(_Stop):
        mw.tool_life.__wrapped__()
    _assert_own_plan(seen[0][1], seen[0][0], monitored[0])
    assert seen[0][0].metadata["program"] == monitored[0].metadata["program"]


def _assert_lot_coefficients(proc: Any, expectation: Any) -> None:
    """The plant cuts with the lot's true coefficients (the preset's × PLANT_LOT_FACTORS,
    decisions 1760, 1798), the controller's or monitor's plan carries the preset's (a new
    tool: VB = 0)."""
    from millsense.plan.virtual_plan import coefficients_from_metadata

    preset = coefficients_from_metadata(expectation.metadata, "monitor plan")
    for name, factor in PLANT_LOT_FACTORS.items():
        assert getattr(proc.coeffs, name) == pytest.approx(getattr(preset, name) * factor,
                                                           rel=1e-12), name  # fmt: skip
    assert preset.kte == pytest.approx(25e3, rel=1e-12)  # the al7050 preset, 25 N/mm


def test_tool_life_plant_cuts_the_lots_coefficients(monkeypatch: pytest.MonkeyPatch) -> None:
    import millsense.online.wear_run as wear_run
    import millsense.simulator.tool_life as tl
    from millsense.validation.cases import monitoring_wear as mw

    seen = _capture_plan_job(monkeypatch)
    monitored = _stop_at(monkeypatch, wear_run, "source_wear_sums", arg=1)
    # the first run is a new tool's: VB = 0, the plant's coefficients are the lot's as they are
    monkeypatch.setattr(mw, "RUNS", 1)
    with pytest.raises(_Stop):
        mw.tool_life.__wrapped__()
    assert tl.tool_life_runs(1, 1, 4, part_cut_s=1.0, cutting_speed_m_s=1.0)[0].vb_m == 0.0
    _assert_lot_coefficients(seen[0][1], monitored[0])


def test_simulate_fleet_cuts_the_plant_plan_and_names_the_monitor_plan(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    """``simulate-fleet`` (issue 12): the machine cuts its own plan of the run's program while
    the recording names the monitor's plan in ``plans/`` (what ``batch`` reads)."""
    import millsense.simulator.machine as machine
    from millsense.cli.cmd_fleet import simulate_fleet
    from millsense.plan.virtual_plan import VirtualPlan

    real = plan_job_module.plan_job
    names: list[str] = []

    def named(vp: Any, mcfg: Any, plan_name: str, **k: Any) -> Any:
        names.append(plan_name)
        return real(vp, mcfg, plan_name, **k)

    monkeypatch.setattr(plan_job_module, "plan_job", named)
    seen = _capture_plan_job(monkeypatch)
    _stop_at(monkeypatch, machine, "MachineSimulator")
    with pytest.raises(_Stop):
        simulate_fleet(tmp_path, tools=1, runs=1, part_cut_min=6.0, seed=0)
    monitor_plan = tmp_path / "plans" / "slot2.parquet"
    expectation = VirtualPlan.read(monitor_plan)
    plant, proc = seen[0]
    _assert_own_plan(proc, plant, expectation)
    _assert_lot_coefficients(proc, expectation)
    assert names == [str(monitor_plan)]  # the recording's metadata 'plan'
    assert not list(tmp_path.glob("*.h5"))  # stopped before the machine ran
