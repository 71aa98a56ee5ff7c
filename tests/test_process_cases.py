"""The quick validation cases of millsense.process pass."""

from __future__ import annotations

import pytest

from millsense.validation import run_case, select_cases

_CASES = select_cases("process.*", quick_only=True)


@pytest.mark.parametrize("c", _CASES, ids=[c.id for c in _CASES])
def test_process_case(c) -> None:  # type: ignore[no-untyped-def]
    # Each case compares with its own reference (seed table, closed form) and tolerance.
    r = run_case(c)
    assert r.passed, (r.measured, r.reference, r.error)


def test_process_cases_registered() -> None:
    # The acceptance figures of issue 3 items 1–3 are all registered.
    ids = {c.id for c in select_cases("process.*")}
    assert {"process.ilme_peak_fy", "process.ilme_rms_fy", "process.ilme_harmonic_vs_sliced"} <= ids
