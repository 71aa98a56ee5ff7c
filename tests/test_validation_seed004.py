"""Seed 004 acceptance cases on a realistic plant (decision 1780, issue 12): references are the
thesis' printed figures, tolerances two-sided with a too-good flag, the runout is judged with
edge forces in the plant, and the edge-free figure is only a self-check."""

from __future__ import annotations

import math

import pytest

from millsense.validation.cases import monitoring_engagement as me
from millsense.validation.registry import Measured, ValidationCase, select_cases


def _case(case_id: str) -> ValidationCase:
    (c,) = select_cases(case_id)
    return c


def test_references_are_the_thesis_printed_figures() -> None:
    # digest §4.1: worst d_a errors 9.4 % (rows 2 of Table 2.3, 4 of 2.4), 13.4 % (row 5 of 2.5)
    assert me.thesis_max_da_error(1) == pytest.approx(9.4, abs=0.01)
    assert me.thesis_max_da_error(2) == pytest.approx(9.4, abs=0.01)
    assert me.thesis_max_da_error(4) == pytest.approx(13.4, abs=0.01)
    # 1.04 µm monitored against the dial gauge's 1.5 µm
    assert me.THESIS_MAX_RUNOUT_ERROR_UM == pytest.approx(0.46, abs=1e-9)
    for table_id, n in (("23", 1), ("24", 2), ("25", 4)):
        c = _case(f"monitoring.engagement.table{table_id}_axial_depth")
        assert c.reference == pytest.approx(me.thesis_max_da_error(n))
        assert (c.rel_tol, c.abs_tol, c.too_good_factor) == (0.5, None, 2.0)
    th = _case("monitoring.engagement.table25_runout_thesis")
    assert th.reference == pytest.approx(0.46) and th.too_good_factor == 2.0
    issue = _case("monitoring.engagement.table25_runout")
    # issue 15's bound, met since decision 1806: no gap or issue marker left
    assert (issue.reference, issue.abs_tol, issue.issue, issue.gap) == (0.0, 0.3, None, "")
    assert _case("monitoring.engagement.table25_runout_shear_only").self_check
    bound = _case("monitoring.contact.repeatability_30")
    assert (bound.reference, bound.abs_tol) == (0.0, 2.0)  # issue 15, as the issue states it
    sig = _case("monitoring.contact.repeatability_30_thesis")
    assert (sig.reference, sig.rel_tol, sig.too_good_factor) == (1.18, 0.5, 2.0)


def test_only_the_self_check_runs_on_the_edge_free_plant(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[int, bool]] = []

    def fake_table(n_flutes: int, edge: bool = True) -> tuple[me.RowResult, ...]:
        calls.append((n_flutes, edge))
        return tuple(
            me.RowResult(n_flutes, dr, da, 1.5, dr, da * 1.05, 1.6, sig, sig, tda, math.nan)
            for dr, da, tda, sig in me.TABLES[n_flutes]
        )

    monkeypatch.setattr(me, "table", fake_table)
    for c in select_cases("monitoring.engagement.*"):
        calls.clear()
        out = c.func()
        assert calls and all(edge == (not c.self_check) for _, edge in calls), c.id
        if "axial_depth" in c.id:
            assert isinstance(out, Measured) and out.value == pytest.approx(5.0)
