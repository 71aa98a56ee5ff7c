"""The quick stability validation cases pass (reference values in the registry)."""

from __future__ import annotations

import pytest

from millsense.validation import run_case, select_cases


@pytest.mark.parametrize("c", select_cases("stability.*", quick_only=True), ids=lambda c: c.id)
def test_quick_stability_case(c) -> None:  # type: ignore[no-untyped-def]
    r = run_case(c)
    assert r.passed, f"{c.id}: measured {r.measured} vs {c.reference} ({r.error})"
