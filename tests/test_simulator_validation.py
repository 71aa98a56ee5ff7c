"""The quick ``machine.simulator*`` validation cases are collected by test_validation_cases."""

from __future__ import annotations

from millsense.validation import select_cases


def test_quick_simulator_cases_are_collected() -> None:
    # tests/test_validation_cases.py runs every quick case (run_case(c).passed); the
    # simulator's quick cases must be among them
    ids = {c.id for c in select_cases("simulator.simulator*", quick_only=True)}
    assert ids == {
        "simulator.simulator_breakage_current_step",
        "simulator.simulator_sampled_path_feed",
    }
