"""The virtual machine's flank-wear truth (decision 2001) and the simulated tool life."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.process.coefficients import CuttingCoefficients
from millsense.simulator.tool_life import tool_life_runs
from millsense.simulator.wear import FlankWearModel

SHARP = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)


def test_a_new_tool_keeps_its_coefficients() -> None:
    assert FlankWearModel().coefficients(SHARP, 0.0) is SHARP


def test_land_force_below_the_critical_land_is_sigma_vb() -> None:
    m = FlankWearModel()
    worn = m.coefficients(SHARP, 0.1e-3)
    # closed form (Smithey's land force): ΔK_re = σ VB = 160 N/mm² × 0.1 mm = 16 N/mm,
    # ΔK_te = μ σ VB = 7.2 N/mm; shear × (1 + 0.25/mm × 0.1 mm)
    assert worn.kre - SHARP.kre == pytest.approx(16e3, rel=1e-12)
    assert worn.kte - SHARP.kte == pytest.approx(7.2e3, rel=1e-12)
    assert worn.ktc / SHARP.ktc == pytest.approx(1.025, rel=1e-12)


def test_land_beyond_the_critical_width_carries_less_stress() -> None:
    m = FlankWearModel()
    # VB 0.3 mm: VB_eff = 0.2 + 0.6 × 0.1 = 0.26 mm → ΔK_re = 41.6 N/mm (not 48)
    worn = m.coefficients(SHARP, 0.3e-3)
    assert worn.kre - SHARP.kre == pytest.approx(41.6e3, rel=1e-12)
    assert m.effective_land_m(0.3e-3) == pytest.approx(0.26e-3, rel=1e-12)


def test_growth_has_three_stages_and_taylor_speed_scaling() -> None:
    m = FlankWearModel()
    t = np.array([0.0, 300.0, 5400.0])
    vb = m.vb_at(t)
    assert vb[0] == 0.0
    # closed form at 90 min: 0.05 (1 − e^{−18}) + 0.002 × 90 + 0.005 (e^{3} − 1) mm
    expect = 0.05 * (1 - math.exp(-18)) + 0.18 + 0.005 * (math.exp(3) - 1)
    assert vb[2] * 1e3 == pytest.approx(expect, rel=1e-12)
    assert np.all(np.diff(m.vb_at(np.linspace(0, 9000, 50))) > 0)
    # V T^n = C: twice the speed wears 2^(1/0.3) = 10.08 times faster
    assert m.equivalent_time_s(60.0, 2.0)[()] == pytest.approx(60.0 * 2 ** (1 / 0.3), rel=1e-12)


@pytest.mark.parametrize("vb", [-1e-4, math.nan, 3e-3])
def test_bad_wear_is_refused(vb: float) -> None:
    with pytest.raises(ConfigError, match="VB"):
        FlankWearModel().coefficients(SHARP, vb)


def test_tool_life_schedule_grows_per_tool_and_cycles_programs() -> None:
    runs = tool_life_runs(3, 5, 4, part_cut_s=360.0, cutting_speed_m_s=1.0, seed=1)
    assert len(runs) == 15
    for tool in ("T1", "T2", "T3"):
        vb = [r.vb_m for r in runs if r.tool_id == tool]
        assert vb[0] == 0.0 and np.all(np.diff(vb) > 0)
    # consecutive runs of a tool change program; tools start on different programs
    t1 = [r.program for r in runs if r.tool_id == "T1"]
    assert t1 == [0, 1, 2, 3, 0]
    assert [r.program for r in runs if r.run_index == 0] == [0, 1, 2]
    # the life factors differ between tools (±30 %): the last VBs are not all equal
    last = {r.tool_id: r.vb_m for r in runs if r.run_index == 4}
    assert max(last.values()) / min(last.values()) > 1.05


def test_cli_refuses_an_impossible_wear(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from millsense.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--program", "nothing.nc", "--wear-vb-mm", "5", "-o",
              str(tmp_path / "r.h5")])  # fmt: skip
    assert exc.value.code == 2
    assert "--wear-vb-mm" in capsys.readouterr().err
    assert not (tmp_path / "r.h5").exists()
