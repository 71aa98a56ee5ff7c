"""The registry behind ``millsense validate`` and ``docs/validation.md``."""

from __future__ import annotations

import fnmatch
import importlib
import math
import pkgutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field

_REGISTRY: dict[str, ValidationCase] = {}


@dataclass(frozen=True)
class Measured:
    """What a case function may return instead of a bare float.

    ``details`` is Markdown (e.g. a convergence table) copied into ``docs/validation.md``.
    """

    value: float
    details: str = ""


@dataclass(frozen=True)
class ValidationCase:
    """One registered figure.

    Attributes
    ----------
    id : dotted identifier starting with the package validated.
    source : where the reference comes from (seed table, closed form, benchmark).
    reference : the reference value, in ``unit``.
    unit : unit of ``reference`` and of the measured value.
    rel_tol, abs_tol : tolerance; the case passes if either is met (at least one is given).
    quick : True if the case runs in a few seconds (``validate --quick`` runs only these).
    description : one sentence on what is computed.
    func : computes the measured value (float or :class:`Measured`).
    gap : non-empty for a documented gap: the seed states ``reference`` but its own printed
        coefficients cannot reproduce it (docs/decisions/ says why). Outside tolerance such a
        case has status ``gap``, not ``fail``; a pytest pins the measured gap so that a change
        of the model is still caught.
    """

    id: str
    source: str
    reference: float
    unit: str
    rel_tol: float | None
    abs_tol: float | None
    quick: bool
    description: str
    func: Callable[[], float | Measured] = field(repr=False, compare=False)
    gap: str = ""

    def tolerance_text(self) -> str:
        parts = []
        if self.rel_tol is not None:
            parts.append(f"±{self.rel_tol * 100:g} %")
        if self.abs_tol is not None:
            parts.append(f"±{self.abs_tol:g} {self.unit}".rstrip())
        return " or ".join(parts)

    def passes(self, measured: float) -> bool:
        if not math.isfinite(measured):
            return False
        err = abs(measured - self.reference)
        ok = False
        if self.rel_tol is not None:
            ok |= err <= self.rel_tol * abs(self.reference)
        if self.abs_tol is not None:
            ok |= err <= self.abs_tol
        return ok


@dataclass(frozen=True)
class CaseResult:
    """The outcome of running one case."""

    id: str
    source: str
    description: str
    reference: float
    measured: float
    unit: str
    tolerance: str
    passed: bool
    seconds: float
    details: str = ""
    error: str = ""
    gap: str = ""

    @property
    def status(self) -> str:
        """``pass``, ``fail``, or ``gap`` (documented seed gap, outside tolerance)."""
        if self.passed:
            return "pass"
        return "gap" if self.gap and not self.error else "fail"

    def as_dict(self) -> dict[str, object]:
        return {
            "id": self.id,
            "source": self.source,
            "reference": self.reference,
            "measured": self.measured,
            "unit": self.unit,
            "tolerance": self.tolerance,
            "passed": self.passed,
            "status": self.status,
            "seconds": round(self.seconds, 3),
            **({"error": self.error} if self.error else {}),
        }


def case(
    id: str,
    *,
    source: str,
    reference: float,
    unit: str,
    rel_tol: float | None = None,
    abs_tol: float | None = None,
    quick: bool = True,
    description: str = "",
    gap: str = "",
) -> Callable[[Callable[[], float | Measured]], Callable[[], float | Measured]]:
    """Register the decorated zero-argument function as validation case ``id``."""
    if rel_tol is None and abs_tol is None:
        raise ValueError(f"validation case {id}: give rel_tol or abs_tol")
    if "." not in id:
        raise ValueError(f"validation case {id}: ids are dotted, starting with the package")

    def register(func: Callable[[], float | Measured]) -> Callable[[], float | Measured]:
        if id in _REGISTRY:
            raise ValueError(f"validation case {id} registered twice")
        _REGISTRY[id] = ValidationCase(
            id=id,
            source=source,
            reference=float(reference),
            unit=unit,
            rel_tol=rel_tol,
            abs_tol=abs_tol,
            quick=quick,
            description=description or (func.__doc__ or "").strip().split("\n")[0],
            func=func,
            gap=gap,
        )
        return func

    return register


def _load_case_modules() -> None:
    import millsense.validation.cases as pkg

    for info in pkgutil.iter_modules(pkg.__path__):
        importlib.import_module(f"{pkg.__name__}.{info.name}")


def all_cases() -> list[ValidationCase]:
    """Every registered case, sorted by id."""
    _load_case_modules()
    return [_REGISTRY[k] for k in sorted(_REGISTRY)]


def select_cases(pattern: str = "*", quick_only: bool = False) -> list[ValidationCase]:
    """Cases whose id matches the glob ``pattern`` (and that are quick, if asked)."""
    return [
        c for c in all_cases() if fnmatch.fnmatch(c.id, pattern) and (c.quick or not quick_only)
    ]


def run_case(c: ValidationCase) -> CaseResult:
    """Run one case; an exception inside it is a failure with the error recorded."""
    t0 = time.perf_counter()
    details = ""
    error = ""
    try:
        out = c.func()
        if isinstance(out, Measured):
            measured, details = float(out.value), out.details
        else:
            measured = float(out)
    except Exception as exc:  # a crashing case is a failed case, reported, not raised
        measured = math.nan
        error = f"{type(exc).__name__}: {exc}"
    seconds = time.perf_counter() - t0
    return CaseResult(
        id=c.id,
        source=c.source,
        description=c.description,
        reference=c.reference,
        measured=measured,
        unit=c.unit,
        tolerance=c.tolerance_text(),
        passed=c.passes(measured) and not error,
        seconds=seconds,
        details=details,
        error=error,
        gap=c.gap,
    )


_STATUS_MD = {"pass": "yes", "fail": "**NO**", "gap": "gap (documented)"}


def render_markdown(results: list[CaseResult], header: str) -> str:
    """``docs/validation.md`` from a list of results."""
    lines = [header.rstrip(), ""]
    lines.append("| case | reference | measured | tolerance | pass | source |")
    lines.append("|---|---|---|---|---|---|")
    for r in results:
        lines.append(
            f"| `{r.id}` | {r.reference:.6g} {r.unit} | {r.measured:.6g} {r.unit} | "
            f"{r.tolerance} | {_STATUS_MD[r.status]} | {r.source} |"
        )
    lines.append("")
    for r in results:
        lines.append(f"### `{r.id}`")
        lines.append("")
        lines.append(r.description or "")
        if r.error:
            lines.append(f"\nError: `{r.error}`")
        if r.gap and not r.passed:
            lines.append(f"\nDocumented gap: {r.gap}")
        if r.details:
            lines.append("")
            lines.append(r.details.rstrip())
        lines.append("")
    return "\n".join(lines)
