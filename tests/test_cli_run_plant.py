"""``millsense run`` / ``serve-machine``: the virtual machine cuts its own plan of the program
(decision 1798), never the session's plan object; with ``--plan`` only it cuts that plan and
says so."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from millsense.plan.plan_engagement import PlanEngagement
from millsense.simulator.plant_plan import PLANT_LOT_FACTORS, PLANT_RUNOUT_M
from test_plant_plan import _capture_plan_job

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "examples/demo_part"
SLOT = "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\nG1 Z-2 F400\nX30\nG0 Z5\nM30\n"


def test_run_cuts_the_machines_own_plan(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from millsense.cli.cmd_run import virtual_machine
    from millsense.plan.virtual_plan import coefficients_from_metadata

    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT)
    seen = _capture_plan_job(monkeypatch)
    vm = virtual_machine(program=prog, stock=DEMO / "stock.toml", tool="aslan-d20-2flute",
                         material="al7050", plan=None, plan_out=tmp_path / "plan.parquet",
                         machine="quaser-ux600", duration_s=0.5)  # fmt: skip
    (plant, proc), = seen
    assert plant is not vm.plan
    eng = proc.engagement
    assert isinstance(eng, PlanEngagement) and eng.plan is plant
    # its own cut: the plant's runout and the lot's coefficients, the same path
    assert proc.tool.runout_offset_m == pytest.approx(PLANT_RUNOUT_M, rel=1e-12)
    nominal = coefficients_from_metadata(vm.plan.metadata, "session plan")
    for name, factor in PLANT_LOT_FACTORS.items():
        assert getattr(proc.coeffs, name) == pytest.approx(getattr(nominal, name) * factor,
                                                           rel=1e-12), name  # fmt: skip
    assert len(plant) == len(vm.plan)
    assert not any("cuts the given --plan" in n for n in vm.notes)

    # --plan only: nothing to plan the machine's cut from; it cuts that plan and says so
    seen.clear()
    vm2 = virtual_machine(program=None, stock=None, tool=None, material=None,
                          plan=tmp_path / "plan.parquet", plan_out=None, machine="quaser-ux600",
                          duration_s=0.5)  # fmt: skip
    (plant2, _), = seen
    assert plant2 is vm2.plan
    assert any("cuts the given --plan" in n for n in vm2.notes)


def test_run_tool_modes_lobes_come_from_a_tap_test(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``run --tool-modes CASE``: the virtual tool runs the file's modes, the chatter avoidance
    checks the lobes of a simulated tap test of that tool (decision 1750), not the file's
    table itself."""
    from importlib import resources

    import millsense.online.session as session
    from millsense.cli.cmd_run import run_online
    from millsense.online.session import SessionOptions
    from millsense.stability.cases import load_case

    class _Stop(Exception):
        pass

    got: list[Any] = []

    def stop(*a: Any, **k: Any) -> Any:
        got.append(a[3])  # the session options
        raise _Stop

    monkeypatch.setattr(session, "session_blocks", stop)
    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT)
    entry = resources.files("millsense.data").joinpath("tool_modes", "aslan-v5-t1.toml")
    with resources.as_file(entry) as modes:
        with pytest.raises(_Stop):
            run_online(program=prog, stock=DEMO / "stock.toml", tool="aslan-d20-2flute",
                       material="al7050", plan=None, machine="quaser-ux600", machine_file=None,
                       out=tmp_path / "run.h5", events_out=None, plan_out=None, plot=None,
                       options=SessionOptions(), tool_modes=modes, duration_s=0.5)  # fmt: skip
        table = load_case(modes).structure
    case = got[0].stability_case
    assert case is not None
    fitted = [m.omega for m in case.structure.x]
    exact = [m.omega for m in table.x]
    assert fitted != exact  # identified, not copied
    # the tap test finds the table's modes within its stated frequency error (decision 1750)
    for w in exact:
        assert min(abs(f / w - 1.0) for f in fitted) < 0.005


def test_plant_cell_is_finer_than_the_session_and_bounded_for_large_stock() -> None:
    """The plant's z-map in ``run``: 4 × finer than the session's 0.2 mm (0.05 mm) on the demo
    part's 100 × 80 mm block; on a 1 × 1 m block 0.05 mm would be 400 million cells, so it is
    sqrt(1 m² / 16e6) = 0.25 mm, capped at half the session's cell: 0.1 mm."""
    from millsense.cli.cmd_run import PLANT_MAX_CELLS, plant_cell_m
    from millsense.core.config import StockConfig, load_config

    demo = load_config(StockConfig, DEMO / "stock.toml")
    assert plant_cell_m(demo, None, 0.2e-3) == pytest.approx(0.05e-3, rel=1e-12)
    big = demo.model_copy(update={"min_mm": [0.0, 0.0, -30.0], "max_mm": [1000.0, 1000.0, 0.0]})
    assert PLANT_MAX_CELLS == 16_000_000
    assert plant_cell_m(big, None, 0.2e-3) == pytest.approx(0.1e-3, rel=1e-12)
    # a 300 x 300 mm block: sqrt(0.09 / 16e6) = 0.075 mm, between the two bounds
    mid = demo.model_copy(update={"min_mm": [0.0, 0.0, -30.0], "max_mm": [300.0, 300.0, 0.0]})
    assert plant_cell_m(mid, None, 0.2e-3) == pytest.approx(0.075e-3, rel=1e-9)


def test_run_takes_the_g28_reference_for_both_plans(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A program that starts with Fanuc's ``G28 G91 Z0.`` (CAM posts write it): without a
    reference the one-line error names ``--home-mm``; with ``home_mm`` the session's plan and
    the machine's own plan both start at the reference (Z 50 mm) and then follow the program."""
    from millsense.cli.cmd_run import virtual_machine
    from millsense.core.errors import ProgramError

    prog = tmp_path / "g28.nc"
    prog.write_text("G21 G90 G17\nT1 M6\nG28 G91 Z0.\nG90\nS1000 M3\n"
                    "G0 X-12 Y40 Z5\nG1 Z-2 F400\nX30\nG0 Z5\nM30\n")  # fmt: skip
    args = dict(program=prog, stock=DEMO / "stock.toml", tool="aslan-d20-2flute",
                material="al7050", plan=None, plan_out=None, machine="quaser-ux600",
                duration_s=0.5)  # fmt: skip
    with pytest.raises(ProgramError, match=r"g28\.nc:3: G28 .*--home-mm"):
        virtual_machine(**args)  # type: ignore[arg-type]
    seen = _capture_plan_job(monkeypatch)
    vm = virtual_machine(**args, home_mm="0,0,50")  # type: ignore[arg-type]
    (plant, _), = seen
    for p in (vm.plan, plant):
        z = p["z_mm"]
        assert max(z) == pytest.approx(50.0, abs=1e-9)
        assert min(z) == pytest.approx(-2.0, abs=1e-9)


def test_run_starts_both_plans_above_a_stock_standing_above_z0(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Decision 1709: with the block's top at Z+10 mm the session's plan and the machine's own
    plan both begin at X0 Y0 Z10, so neither runs the first rapid through the material."""
    from millsense.cli.cmd_run import virtual_machine

    stock = tmp_path / "stock.toml"
    stock.write_text('kind = "box"\nmin_mm = [0, 0, -20]\nmax_mm = [100, 80, 10]\n')
    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT.replace("Z5", "Z15").replace("Z-2", "Z8"))
    seen = _capture_plan_job(monkeypatch)
    vm = virtual_machine(program=prog, stock=stock, tool="aslan-d20-2flute",  # type: ignore[arg-type]
                         material="al7050", plan=None, plan_out=None, machine="quaser-ux600",
                         duration_s=0.5)  # fmt: skip
    (plant, _), = seen
    for p in (vm.plan, plant):
        assert (p["x_mm"][0], p["y_mm"][0], p["z_mm"][0]) == (0.0, 0.0, 10.0)
        assert not (p["in_cut"] & p["rapid"]).any()


def test_run_recording_names_the_tool_material_and_program_digest(tmp_path: Path) -> None:
    """The metadata of a ``run --program`` recording name the tool and material the session
    planned with and carry the program's SHA-256, as its plan does (found by the qa4 helper:
    they said tool 'plan', material 'plan', the plant's own plan carrying no names, and two
    programs of one file name could not be told apart by ``replay``/``monitor``)."""
    import hashlib

    from millsense.cli.cmd_run import virtual_machine
    from millsense.plan.virtual_plan import VirtualPlan

    prog = tmp_path / "program.nc"
    prog.write_text(SLOT)
    vm = virtual_machine(program=prog, stock=DEMO / "stock.toml", tool="aslan-d20-2flute",
                         material="al7050", plan=None, plan_out=tmp_path / "plan.parquet",
                         machine="quaser-ux600", duration_s=0.5)  # fmt: skip
    digest = hashlib.sha256(SLOT.encode()).hexdigest()
    assert vm.metadata["program_sha256"] == digest
    assert vm.metadata["tool"] == "D20 2-flute 30 deg helix (Aslan V1)"
    assert vm.metadata["material"] == "Al7050"
    assert VirtualPlan.read(tmp_path / "plan.parquet").metadata["program_sha256"] == digest
