"""Validation registry: figures computed by millsense against references nobody tuned to.

A case computes one figure with millsense and compares it with a reference from a seed table,
a closed form or a published benchmark, within a stated tolerance. Case modules live in
:mod:`millsense.validation.cases` (one module per package validated); their ids are dotted and
start with that package (``process.…``, ``stability.…``, ``simulator.…``, ``demo.…``).
A case that misses its reference is a failure, also when the reason is known (status
``known``, with the issue that tracks it); a figure far better than the thesis it replicates is
flagged ``too_good``; a figure a parameter was fitted on is ``calibrated``, never a pass
(:mod:`millsense.validation.registry`).
"""

from millsense.validation.registry import (
    Calibration,
    CaseResult,
    Measured,
    ValidationCase,
    all_cases,
    case,
    run_case,
    select_cases,
)

__all__ = [
    "Calibration",
    "CaseResult",
    "Measured",
    "ValidationCase",
    "all_cases",
    "case",
    "run_case",
    "select_cases",
]
