"""Example stability cases: the default chart's minimum equals a 1 rev/min refinement (issue 14)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.stability.cases import compute_lobes, load_case

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "stability"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.stem for p in EXAMPLES.glob("*.toml")))
def test_example_minimum_matches_1rpm_refinement(name: str) -> None:
    # the default chart (the case file's speeds) reports the same minimum within 0.5 % as the
    # lowest depth of an independent 1 rev/min grid of 31 speeds around the reported speed
    case = load_case(EXAMPLES / f"{name}.toml")
    res = compute_lobes(case)
    n0 = res.min_depth_rpm
    fine = np.arange(round(n0) - 15.0, round(n0) + 15.5, 1.0)
    fine = fine[(fine >= case.rpm.min()) & (fine <= case.rpm.max())]
    ref = compute_lobes(case, rpm=fine, refine_minima=False, bands_up_to=1.0)
    w_fine = float(np.nanmin(ref.critical_depth_m))
    assert res.min_depth_m == pytest.approx(w_fine, rel=0.005), (
        n0,
        fine[np.nanargmin(ref.critical_depth_m)],
    )
    # and no speed of the chart itself is below the refined minimum
    assert res.min_depth_m <= float(np.nanmin(res.critical_depth_m)) + 1e-12
