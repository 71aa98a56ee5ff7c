"""Validation of the demo chain: simulated drive → current command → estimated force.

The reference is the closed-form slot average force (Altintas, *Manufacturing Automation*
ch. 2; benchmarks.md §3): ``F̄x = −(N·a·K_rc/4)·c − N·a·K_re/π`` on the tool in its feed frame,
which is the force on the table along +X in the demo's frame
(docs/decisions/0007-force-sign-and-frame-of-the-demo.md). Nobody tuned the estimator to it: the
estimate comes from the current command and motor speed alone, with friction identified from
simulated air moves.
"""

from __future__ import annotations

import math
import tempfile
from functools import cache
from typing import TYPE_CHECKING

from millsense.validation import Measured, case

if TYPE_CHECKING:
    from millsense.demo import DemoSummary

N_FLUTES = 2


@cache
def _demo_run() -> DemoSummary:
    from millsense.demo import run_demo

    with tempfile.TemporaryDirectory() as tmp:
        return run_demo(tmp)


def _closed_form_fx(depth_mm: float) -> float:
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.demo import FEED_PER_TOOTH_MM

    mat = load_preset(MaterialConfig, "al7050")
    a, c = depth_mm, FEED_PER_TOOTH_MM
    return -(N_FLUTES * a * mat.krc_n_mm2 / 4.0) * c - N_FLUTES * a * mat.kre_n_mm / math.pi


def _estimated_mean(depth_mm: float) -> Measured:
    for seg in _demo_run().segments:
        if math.isclose(seg.depth_mm, depth_mm):
            return Measured(
                seg.estimate_mean_n,
                f"Window {seg.start_s:.2f}-{seg.end_s:.2f} s (whole revolutions); truth mean "
                f"{seg.truth_mean_n:.2f} N, estimate {seg.estimate_mean_n:.2f} N, closed form "
                f"{_closed_form_fx(depth_mm):.2f} N.",
            )
    raise RuntimeError(f"the demo has no {depth_mm} mm segment")


@case(
    "demo.slot_mean_force_4mm",
    source="closed-form slot average (benchmarks.md §3), Al7050 preset, 0.2 mm/tooth",
    reference=_closed_form_fx(4.0),
    unit="N",
    rel_tol=0.02,
    quick=True,
    description=(
        "Mean X force in the 4 mm slot of `millsense demo`, estimated from the current command "
        "by rigid-body inverse dynamics with friction identified from simulated air moves."
    ),
)
def _mean_4mm() -> Measured:
    return _estimated_mean(4.0)


@case(
    "demo.slot_mean_force_2mm",
    source="closed-form slot average (benchmarks.md §3), Al7050 preset, 0.2 mm/tooth",
    reference=_closed_form_fx(2.0),
    unit="N",
    rel_tol=0.03,
    quick=True,
    description="As demo.slot_mean_force_4mm, in the 2 mm segment (smaller force, same noise).",
)
def _mean_2mm() -> Measured:
    return _estimated_mean(2.0)
