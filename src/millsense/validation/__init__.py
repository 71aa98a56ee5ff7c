"""Validation registry: figures computed by millsense against references nobody tuned to.

A case computes one figure with millsense and compares it with a reference from a seed table,
a closed form or a published benchmark, within a stated tolerance. Case modules live in
:mod:`millsense.validation.cases` (one module per package validated); their ids are dotted and
start with that package (``process.…``, ``stability.…``, ``machine.…``, ``demo.…``).
"""

from millsense.validation.registry import (
    CaseResult,
    Measured,
    ValidationCase,
    all_cases,
    case,
    run_case,
    select_cases,
)

__all__ = [
    "CaseResult",
    "Measured",
    "ValidationCase",
    "all_cases",
    "case",
    "run_case",
    "select_cases",
]
