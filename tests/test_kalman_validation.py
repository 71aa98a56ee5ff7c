"""The estimation.kalman_* validation cases are registered and the quick one passes."""

from __future__ import annotations

from millsense.validation import run_case, select_cases


def test_quick_kalman_cases_pass() -> None:
    cases = select_cases("estimation.kalman_*", quick_only=True)
    assert [c.id for c in cases] == ["estimation.kalman_c_axis_flat_to_120hz"]
    for c in cases:
        # C-axis compensated FRF within ±3 dB up to 120 Hz (issue 7 acceptance, Aslan V3)
        r = run_case(c)
        assert r.passed, (r.measured, r.reference)


def test_c_axis_bandwidth_case_registered_against_thesis_figure() -> None:
    (c,) = select_cases("estimation.kalman_c_axis_bandwidth")
    assert c.reference == 120.0 and c.unit == "Hz"
