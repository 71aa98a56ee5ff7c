"""The registry behind ``millsense validate`` and ``docs/validation.md``.

Outcome of a case (:attr:`CaseResult.status`, docs/decisions/1021-honest-validation-statuses.md):

``pass``
    within the two-sided tolerance around the reference, not flagged.
``fail``
    outside the tolerance, or the case raised.
``known``
    outside the tolerance with a documented reason and an issue reference
    (``fail (known: <reason>, issue N)``): a failure, counted as one, never excused.
``too_good``
    better than the thesis by more than ``too_good_factor`` — a replica far better than the
    measured original says the simulation is too benign (check realism); a failure.
``calibrated``
    the case is the figure a calibrated parameter was fitted on: agreement there is by
    construction, so within tolerance it is neither a pass nor a failure (outside tolerance it is
    ``too_good`` or ``fail`` like any other case).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import importlib
import math
import pkgutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field

_REGISTRY: dict[str, ValidationCase] = {}

#: Statuses that count as failures (``millsense validate`` exits non-zero on any of them).
FAILED = frozenset({"fail", "known", "too_good"})


@dataclass(frozen=True)
class Measured:
    """What a case function may return instead of a bare float.

    ``details`` is Markdown (e.g. a convergence table) copied into ``docs/validation.md``.
    """

    value: float
    details: str = ""


@dataclass(frozen=True)
class Calibration:
    """A parameter chosen by fitting a validation figure (not taken from the source).

    ``parameter`` names it with its value (e.g. ``"current noise 16 mA RMS"``); ``fitted_on``
    are the ids of the cases whose figure it was fitted to. On those cases the agreement is by
    construction (status ``calibrated`` within tolerance; ``too_good`` or ``fail`` outside it, and
    still "fitted on this figure" in docs/validation.md); every other case declaring the same
    calibration is a held-out check of it.
    """

    parameter: str
    fitted_on: tuple[str, ...]
    how: str = ""


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
        The tolerance is two-sided: a figure a thesis measured is to be reproduced, not beaten.
    quick : True if the case runs in a few seconds (``validate --quick`` runs only these).
    description : one sentence on what is computed.
    func : computes the measured value (float or :class:`Measured`).
    gap : non-empty for a known failure: the written reason the figure is not reproduced
        (e.g. the seed's own printed coefficients cannot give it; docs/decisions/ says why).
        Outside tolerance such a case is a failure shown as ``fail (known: …, issue N)``.
    issue : the issue number that tracks a ``gap`` (required with one).
    too_good_factor : if set, the case fails as ``too_good`` when the measured figure is better
        than the reference by more than this factor (``lower_is_better`` says which way).
    lower_is_better : direction of "better" for ``too_good_factor`` (errors: True; bands: False).
    calibration : the calibrated parameter the case depends on (see :class:`Calibration`).
    self_check : the reference is computed by millsense itself, or the plant is the estimator's
        own model by design (a self-consistency or design check, not an acceptance figure;
        decision 1790); reported as such.
    ci : run by ``.ci/run`` (``validate --ci``): a slow case that guards an acceptance figure.
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
    issue: int | None = None
    too_good_factor: float | None = None
    lower_is_better: bool = True
    calibration: Calibration | None = None
    self_check: bool = False
    ci: bool = False

    def __post_init__(self) -> None:
        if self.rel_tol is None and self.abs_tol is None:
            raise ValueError(f"validation case {self.id}: give rel_tol or abs_tol")
        if "." not in self.id:
            raise ValueError(
                f"validation case {self.id}: ids are dotted, starting with the package"
            )
        if self.gap and self.issue is None:
            raise ValueError(f"validation case {self.id}: a known gap needs an issue number")
        if self.too_good_factor is not None and not (
            self.too_good_factor > 1.0 and self.reference > 0.0
        ):
            raise ValueError(
                f"validation case {self.id}: too_good_factor must exceed 1 and the reference "
                "must be positive"
            )
        if self.ci and self.gap:
            raise ValueError(f"validation case {self.id}: a known failure cannot guard CI")

    @property
    def fitted_here(self) -> bool:
        """True if this case is a figure its calibration was fitted on."""
        return self.calibration is not None and self.id in self.calibration.fitted_on

    def tolerance_text(self) -> str:
        parts = []
        if self.rel_tol is not None:
            parts.append(f"±{self.rel_tol * 100:g} %")
        if self.abs_tol is not None:
            parts.append(f"±{self.abs_tol:g} {self.unit}".rstrip())
        text = " or ".join(parts)
        if self.too_good_factor is not None:
            text += f"; too good beyond {self.too_good_factor:g}× better"
        return text

    def passes(self, measured: float) -> bool:
        """Within the two-sided tolerance around the reference."""
        if not math.isfinite(measured):
            return False
        err = abs(measured - self.reference)
        ok = False
        if self.rel_tol is not None:
            ok |= err <= self.rel_tol * abs(self.reference)
        if self.abs_tol is not None:
            ok |= err <= self.abs_tol
        return ok

    def better_by(self, measured: float) -> float:
        """How many times better than the reference the measured figure is (1 = equal).

        ``reference/measured`` when lower is better (inf at or below zero), else
        ``measured/reference``.
        """
        if self.lower_is_better:
            return math.inf if measured <= 0.0 else self.reference / measured
        return measured / self.reference

    def too_good(self, measured: float) -> bool:
        """True if flagged: better than the reference by more than ``too_good_factor``."""
        if self.too_good_factor is None or not math.isfinite(measured):
            return False
        return self.better_by(measured) > self.too_good_factor


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
    issue: int | None = None
    status: str = ""
    better_by: float = math.nan
    too_good_factor: float | None = None
    calibration: Calibration | None = None
    self_check: bool = False

    @property
    def failed(self) -> bool:
        """Counts as a failure (``fail``, ``known`` or ``too_good``)."""
        return self.status in FAILED

    @property
    def status_text(self) -> str:
        """One line for tables: the status with its reason."""
        if self.status == "known":
            return f"fail (known: {self.gap}, issue {self.issue})"
        if self.status == "too_good":
            return (
                f"fail (too good: {self.better_by:.3g}× better than the reference, more than "
                f"{self.too_good_factor:g}× — check realism)"
            )
        if self.status == "calibrated":
            assert self.calibration is not None
            text = f"calibrated (fitted here: {self.calibration.parameter}; not a pass)"
            if self.too_good_factor is not None and self.better_by > self.too_good_factor:
                text += (
                    f"; also {self.better_by:.3g}× better than the reference, more than "
                    f"{self.too_good_factor:g}× — check realism"
                )
            return text
        if self.status == "fail" and self.error:
            return f"fail ({self.error})"
        if self.status == "pass" and self.self_check:
            return "pass (self-consistency check, not an acceptance figure)"
        return self.status

    @property
    def short_status(self) -> str:
        """The status in a few words (console table; the reason is in :attr:`status_text`)."""
        if self.status == "known":
            return f"fail (known, issue {self.issue})"
        if self.status == "too_good":
            return f"fail (too good: {self.better_by:.3g}× better)"
        if self.status == "pass" and self.self_check:
            return "pass (self-check)"
        return self.status

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
            "status_text": self.status_text,
            "seconds": round(self.seconds, 3),
            **({"error": self.error} if self.error else {}),
            **({"issue": self.issue} if self.issue is not None else {}),
            **({"better_by": self.better_by} if self.too_good_factor is not None else {}),
            **(
                {
                    "calibration": self.calibration.parameter,
                    "fitted_here": self.status == "calibrated",
                }
                if self.calibration is not None
                else {}
            ),
            **({"self_check": True} if self.self_check else {}),
        }


def classify(c: ValidationCase, measured: float, error: str = "") -> str:
    """Status of case ``c`` for a measured value (module docstring; decision 1021)."""
    if error or not math.isfinite(measured):
        return "fail"
    within = c.passes(measured)
    if c.fitted_here and within:
        return "calibrated"  # agreement by construction: never a pass (too good is noted)
    if c.too_good(measured):
        return "too_good"
    if within:
        return "pass"
    return "known" if c.gap else "fail"


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
    issue: int | None = None,
    too_good_factor: float | None = None,
    lower_is_better: bool = True,
    calibration: Calibration | None = None,
    self_check: bool = False,
    ci: bool = False,
) -> Callable[[Callable[[], float | Measured]], Callable[[], float | Measured]]:
    """Register the decorated zero-argument function as validation case ``id``."""

    proto = ValidationCase(  # checks the declaration at import, not at run time
        id=id,
        source=source,
        reference=float(reference),
        unit=unit,
        rel_tol=rel_tol,
        abs_tol=abs_tol,
        quick=quick,
        description=description,
        func=_not_set,
        gap=gap,
        issue=issue,
        too_good_factor=too_good_factor,
        lower_is_better=lower_is_better,
        calibration=calibration,
        self_check=self_check,
        ci=ci,
    )

    def register(func: Callable[[], float | Measured]) -> Callable[[], float | Measured]:
        if id in _REGISTRY:
            raise ValueError(f"validation case {id} registered twice")
        _REGISTRY[id] = dataclasses.replace(
            proto,
            func=func,
            description=description or (func.__doc__ or "").strip().split("\n")[0],
        )
        return func

    return register


def _not_set() -> float:
    raise RuntimeError("validation case function not registered")


def _load_case_modules() -> None:
    import millsense.validation.cases as pkg

    for info in pkgutil.iter_modules(pkg.__path__):
        importlib.import_module(f"{pkg.__name__}.{info.name}")


def all_cases() -> list[ValidationCase]:
    """Every registered case, sorted by id."""
    _load_case_modules()
    cases = [_REGISTRY[k] for k in sorted(_REGISTRY)]
    check_calibrations(cases)
    return cases


def check_calibrations(cases: list[ValidationCase]) -> None:
    """Every calibration names cases that exist and declare that same calibration."""
    by_id = {c.id: c for c in cases}
    for c in cases:
        if c.calibration is None:
            continue
        for fid in c.calibration.fitted_on:
            other = by_id.get(fid)
            if other is None or other.calibration != c.calibration:
                raise ValueError(
                    f"validation case {c.id}: calibration '{c.calibration.parameter}' names "
                    f"{fid} as fitted figure, which does not declare the same calibration"
                )


def select_cases(
    pattern: str = "*", quick_only: bool = False, ci_only: bool = False
) -> list[ValidationCase]:
    """Cases whose id matches the glob ``pattern`` (and that are quick / CI cases, if asked)."""
    return [
        c
        for c in all_cases()
        if fnmatch.fnmatch(c.id, pattern) and (c.quick or not quick_only) and (c.ci or not ci_only)
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
    status = classify(c, measured, error)
    return CaseResult(
        id=c.id,
        source=c.source,
        description=c.description,
        reference=c.reference,
        measured=measured,
        unit=c.unit,
        tolerance=c.tolerance_text(),
        passed=status == "pass",
        seconds=seconds,
        details=details,
        error=error,
        gap=c.gap,
        issue=c.issue,
        status=status,
        better_by=c.better_by(measured) if c.too_good_factor is not None else math.nan,
        too_good_factor=c.too_good_factor,
        calibration=c.calibration,
        self_check=c.self_check,
    )


def summary_line(results: list[CaseResult]) -> str:
    """``N cases: P pass, F fail (K known, T too good), C calibrated (not passes)``."""
    count = {s: sum(r.status == s for r in results) for s in FAILED | {"pass", "calibrated"}}
    n_fail = sum(r.failed for r in results)
    return (
        f"{len(results)} cases: {count['pass']} pass, {n_fail} fail ({count['known']} known, "
        f"{count['too_good']} too good), {count['calibrated']} calibrated (not counted as passes)"
    )


def _status_md(r: CaseResult) -> str:
    return {
        "pass": "yes (self-check)" if r.self_check else "yes",
        "fail": "**NO**",
        "known": f"**NO** (known, issue {r.issue})",
        "too_good": f"**NO** (too good: {r.better_by:.3g}× better)",
        "calibrated": "calibrated",
    }[r.status]


def _calibration_section(results: list[CaseResult]) -> list[str]:
    cals: dict[Calibration, list[str]] = {}
    for r in results:
        if r.calibration is not None:
            cals.setdefault(r.calibration, []).append(r.id)
    if not cals:
        return []
    lines = [
        "## Calibrations",
        "",
        "Parameters chosen by fitting a validation figure. The figure they were fitted on is "
        "status *calibrated* (agreement by construction, never a pass); the other cases that "
        "use them are held-out checks.",
        "",
        "| parameter | fitted on | how | held-out cases |",
        "|---|---|---|---|",
    ]
    for cal, ids in cals.items():
        held = [i for i in ids if i not in cal.fitted_on]
        lines.append(
            f"| {cal.parameter} | {', '.join(f'`{i}`' for i in cal.fitted_on)} | {cal.how} | "
            + (", ".join(f"`{i}`" for i in held) or "none")
            + " |"
        )
    lines.append("")
    return lines


def render_markdown(results: list[CaseResult], header: str) -> str:
    """``docs/validation.md`` from a list of results."""
    lines = [header.rstrip(), "", f"**{summary_line(results)}**", ""]
    lines.append("| case | reference | measured | tolerance | pass | source |")
    lines.append("|---|---|---|---|---|---|")
    for r in results:
        lines.append(
            f"| `{r.id}` | {r.reference:.6g} {r.unit} | {r.measured:.6g} {r.unit} | "
            f"{r.tolerance} | {_status_md(r)} | {r.source} |"
        )
    lines.append("")
    lines.extend(_calibration_section(results))
    for r in results:
        lines.append(f"### `{r.id}`")
        lines.append("")
        lines.append(r.description or "")
        if r.status != "pass" or r.self_check:
            lines.append(f"\nStatus: {r.status_text}")
        if r.error:
            lines.append(f"\nError: `{r.error}`")
        if r.gap and r.status == "known":
            lines.append(f"\nKnown failure (issue {r.issue}): {r.gap}")
        if r.calibration is not None:
            cal = r.calibration
            # by the fitted cases, not the status: a fitted case outside tolerance (too_good,
            # fail) is still fitted on, never a held-out check (issue 12)
            where = "fitted on this figure" if r.id in cal.fitted_on else "held-out check"
            lines.append(
                f"\nCalibration: {cal.parameter} ({where}; fitted on "
                + ", ".join(f"`{i}`" for i in cal.fitted_on)
                + ")"
            )
        if r.details:
            lines.append("")
            lines.append(r.details.rstrip())
        lines.append("")
    return "\n".join(lines)
