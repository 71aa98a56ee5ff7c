"""The estimation.kalman_* validation cases are registered and the quick one passes."""

from __future__ import annotations

import pytest

from millsense.validation import run_case, select_cases


def test_quick_kalman_cases_pass() -> None:
    cases = select_cases("estimation.kalman_*", quick_only=True)
    ids = [c.id for c in cases]
    assert ids == [
        "estimation.kalman_a_axis_flat_to_120hz",
        "estimation.kalman_c_axis_flat_to_120hz",
    ]
    # C-axis compensated FRF within ±3 dB up to 120 Hz (issue 7 acceptance, Aslan V3)
    r = run_case(cases[1])
    assert r.passed, (r.measured, r.reference)
    # A axis, same rule: a known failure (issue 12); the printed modes give 5.98 dB at ≤ 120 Hz
    # (docs/validation.md table), pinned so that a model change is seen
    a = run_case(cases[0])
    assert a.status == "known" and a.issue == 12
    assert a.measured == pytest.approx(5.98, abs=0.05)


def test_c_axis_bandwidth_case_registered_against_thesis_figure() -> None:
    (c,) = select_cases("estimation.kalman_c_axis_bandwidth")
    assert c.reference == 120.0 and c.unit == "Hz"


def test_kalman_cases_are_labelled_design_checks_with_a_truth_acceptance() -> None:
    # Decision 1712: the printed estimator on its own printed model shares every parameter
    # with its plant, so each case says so and names the acceptance measured on the truth
    # (estimation_feed_drive), which must exist and cover every rotary axis.
    import re

    cases = select_cases("estimation.kalman_*")
    assert len(cases) == 3
    known = {c.id for c in select_cases("estimation.feed_*")}
    for c in cases:
        assert c.description.startswith("Design check, plant = estimator model by design"), c.id
        refs = set(re.findall(r"estimation\.feed_[a-z0-9_]+", c.description))
        assert refs and refs <= known, (c.id, refs - known)
    for axis in ("a", "c"):
        assert f"estimation.feed_compensated_band_{axis}" in known
        assert f"estimation.feed_raw_current_band_{axis}" in known
    assert "estimation.feed_rotary_flat_to_120hz" in known


def test_kalman_cases_do_not_call_themselves_an_acceptance() -> None:
    # decision 1213 (audit of issue 12): a design check on the printed model is never presented
    # as the acceptance, neither in its source line (the summary table's column) nor its gap
    for c in select_cases("estimation.kalman_*"):
        assert "acceptance" not in c.source.split(";")[0].replace("design check", ""), c.id
        assert "estimation.kalman_" not in (c.gap or ""), c.id
