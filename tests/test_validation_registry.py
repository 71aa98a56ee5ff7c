"""Registry semantics with synthetic cases: a known gap is a failure, a figure far better than
the thesis is flagged, a calibration cannot pass the figure it was fitted on (decision 1021)."""

from __future__ import annotations

import datetime as dt
import math
import subprocess
from pathlib import Path

import pytest

from cli_run import run_cli
from millsense.validation import Calibration, ValidationCase, run_case
from millsense.validation.provenance import provenance_line
from millsense.validation.registry import check_calibrations, render_markdown, summary_line


def _case(value: float, **kw: object) -> ValidationCase:
    base: dict[str, object] = {
        "id": "demo.synthetic",
        "source": "synthetic",
        "reference": 10.0,
        "unit": "%",
        "rel_tol": 0.5,
        "abs_tol": None,
        "quick": True,
        "description": "d",
        "func": lambda: value,
    }
    base.update(kw)
    return ValidationCase(**base)  # type: ignore[arg-type]


def test_gap_outside_tolerance_is_a_failure_with_reason_and_issue() -> None:
    # 280 Hz against 360 Hz ±10 %: outside; the written reason does not excuse it
    c = _case(280.0, reference=360.0, rel_tol=0.1, gap="printed coefficients give 280 Hz", issue=12)
    r = run_case(c)
    assert r.status == "known" and r.failed and not r.passed
    assert r.status_text == "fail (known: printed coefficients give 280 Hz, issue 12)"
    md = render_markdown([r], "# V")
    assert "**NO** (known, issue 12)" in md and "printed coefficients give 280 Hz" in md
    assert summary_line([r]) == (
        "1 cases: 0 pass, 1 fail (1 known, 0 too good), 0 calibrated (not counted as passes)"
    )
    # inside the tolerance a case with a gap text passes like any other (352 Hz: 2.2 % off)
    assert run_case(_case(352.0, reference=360.0, rel_tol=0.1, gap="x", issue=12)).passed


def test_gap_needs_an_issue_and_cannot_guard_ci() -> None:
    with pytest.raises(ValueError, match="issue number"):
        _case(1.0, gap="reason")
    with pytest.raises(ValueError, match="cannot guard CI"):
        _case(1.0, gap="reason", issue=12, ci=True)


def test_error_is_a_plain_failure_even_with_a_gap() -> None:
    def boom() -> float:
        raise RuntimeError("broken")

    r = run_case(_case(0.0, func=boom, gap="why", issue=12))
    assert r.status == "fail" and "RuntimeError: broken" in r.status_text
    assert math.isnan(r.measured)


@pytest.mark.parametrize(
    ("value", "status", "better"),
    [
        (10.0, "pass", 1.0),  # the thesis's 10 %
        (6.0, "pass", 10.0 / 6.0),  # 1.67× better: within the factor 2 and ±50 %
        (4.0, "too_good", 2.5),  # 2.5× better than the thesis: check realism
        (0.0, "too_good", math.inf),  # zero error: infinitely better
        (16.0, "fail", 10.0 / 16.0),  # worse than the thesis beyond +50 %
    ],
)
def test_too_good_flag_for_an_error_figure(value: float, status: str, better: float) -> None:
    r = run_case(_case(value, too_good_factor=2.0))
    assert r.status == status
    assert r.better_by == pytest.approx(better)
    assert r.failed == (status != "pass")


def test_too_good_flag_for_a_bandwidth_and_its_text() -> None:
    # 300 Hz against a 180 Hz thesis band (higher is better): 1.67× better > 1.5
    c = _case(300.0, reference=180.0, rel_tol=1.0, too_good_factor=1.5, lower_is_better=False)
    r = run_case(c)
    assert r.status == "too_good" and r.better_by == pytest.approx(300.0 / 180.0)
    assert "1.67× better than the reference, more than 1.5× — check realism" in r.status_text
    assert "**NO** (too good: 1.67× better)" in render_markdown([r], "# V")
    assert run_case(
        _case(200.0, reference=180.0, rel_tol=1.0, too_good_factor=1.5, lower_is_better=False)
    ).passed  # 1.11× better


def test_too_good_factor_needs_a_positive_reference_and_factor_above_one() -> None:
    with pytest.raises(ValueError, match="too_good_factor"):
        _case(1.0, reference=0.0, abs_tol=1.0, too_good_factor=2.0)
    with pytest.raises(ValueError, match="too_good_factor"):
        _case(1.0, too_good_factor=0.5)


def test_calibration_cannot_pass_its_own_figure() -> None:
    cal = Calibration("noise 16 mA", ("demo.fitted",))
    fitted = _case(10.1, id="demo.fitted", calibration=cal)  # 1 % off, by construction
    held = _case(12.0, id="demo.held", calibration=cal)  # 20 % off, within ±50 %
    rf, rh = run_case(fitted), run_case(held)
    assert rf.status == "calibrated" and not rf.passed and not rf.failed
    assert rh.status == "pass"
    # a calibrated figure that misses even after the fit is a failure like any other
    assert run_case(_case(20.0, id="demo.fitted", calibration=cal)).status == "fail"
    too = _case(4.0, id="demo.fitted", calibration=cal, too_good_factor=2.0)  # 2.5× better
    assert run_case(too).status == "too_good"
    # and a fitted figure far better than the thesis is still only 'calibrated'
    assert (
        run_case(
            _case(1.0, id="demo.fitted", calibration=cal, too_good_factor=2.0, abs_tol=10.0)
        ).status
        == "calibrated"
    )
    md = render_markdown([rf, rh], "# V")
    assert "## Calibrations" in md
    assert "| noise 16 mA | `demo.fitted` |  | `demo.held` |" in md
    assert summary_line([rf, rh]).endswith(
        "1 pass, 0 fail (0 known, 0 too good), 1 calibrated (not counted as passes)"
    )


def test_fitted_case_is_labelled_fitted_whatever_its_status() -> None:
    """Issue 12: a case a calibration was fitted on but whose status is not 'calibrated' (too
    good, fail) is 'fitted on this figure', never a 'held-out check'; held-out cases stay so."""
    cal = Calibration("eps 0.2", ("demo.fitted", "demo.fitted2"))
    too = run_case(_case(4.0, id="demo.fitted", calibration=cal, too_good_factor=2.0))
    bad = run_case(_case(20.0, id="demo.fitted2", calibration=cal))
    held = run_case(_case(30.0, id="demo.held", calibration=cal))  # fails, held out
    assert (too.status, bad.status, held.status) == ("too_good", "fail", "fail")
    md = render_markdown([too, bad, held], "# V")
    sections = {s.split("`")[0]: s for s in md.split("### `")[1:]}
    assert "(fitted on this figure;" in sections["demo.fitted"]
    assert "(fitted on this figure;" in sections["demo.fitted2"]
    assert "held-out check" not in sections["demo.fitted"] + sections["demo.fitted2"]
    assert "(held-out check;" in sections["demo.held"]


def test_calibration_must_name_cases_that_declare_it() -> None:
    cal = Calibration("eps 0.2", ("demo.missing",))
    with pytest.raises(ValueError, match=r"demo\.missing"):
        check_calibrations([_case(1.0, id="demo.a", calibration=cal)])
    ok = Calibration("eps 0.2", ("demo.a",))
    check_calibrations([_case(1.0, id="demo.a", calibration=ok)])


def test_self_check_is_labelled() -> None:
    r = run_case(_case(10.0, self_check=True))
    assert r.passed and r.status_text.startswith("pass (self-consistency check")


def test_provenance_line_names_date_and_commit() -> None:
    when = dt.datetime(2026, 11, 25, 14, 2, tzinfo=dt.UTC)
    here = Path(__file__).resolve().parent
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, check=True
    ).stdout.strip()
    line = provenance_line(when, here)
    assert line.startswith(f"Generated 2026-11-25 14:02 UTC from commit `{head[:12]}`")


def test_provenance_outside_git_is_unknown(tmp_path: Path) -> None:
    when = dt.datetime(2026, 11, 25, 14, 2, tzinfo=dt.UTC)
    assert provenance_line(when, tmp_path) == (
        "Generated 2026-11-25 14:02 UTC; git commit unknown (not run from a git checkout)."
    )


def test_validate_exit_status_is_one_on_a_failing_case(capsys: pytest.CaptureFixture[str]) -> None:
    # simulator.spindle_current_bw_printed_eq58 is quick and passes: exit 0; a known failure
    # (estimation.kalman_a_axis_flat_to_120hz, 5.98 dB > 3 dB) makes the run exit 1
    code, out, _ = run_cli(
        ["validate", "--case", "simulator.spindle_current_bw_printed_eq58"], capsys
    )
    assert code == 0 and "1 cases: 1 pass, 0 fail" in out
    code, out, _ = run_cli(["validate", "--case", "estimation.kalman_a_axis_flat_to_120hz"], capsys)
    assert code == 1 and "1 fail (1 known" in out


def test_validate_list_names_the_cases_without_running_them(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``validate --list``: the ids a --case glob matches, with reference, tolerance and tags,
    one case a line and nothing run (there was no way to learn the ids but to run them: the
    full set takes over an hour). The stability cases are listed whole; with --quick only
    the quick ones; with --json it is refused (nothing to write), one line, exit 2."""
    import time

    from millsense.validation.registry import select_cases

    t0 = time.perf_counter()
    code, out, err = run_cli(["validate", "--list", "--case", "stability.*"], capsys)
    assert code == 0, err
    assert time.perf_counter() - t0 < 20.0  # listing, not running (a case takes seconds)
    ids = [c.id for c in select_cases("stability.*")]
    assert len(ids) >= 3
    lines = out.strip().splitlines()
    assert [ln.split()[0] for ln in lines[:-1]] == ids
    assert lines[-1] == f"{len(ids)} cases"
    quick = [c.id for c in select_cases("stability.*", quick_only=True)]
    code, out, _ = run_cli(["validate", "--list", "--quick", "--case", "stability.*"], capsys)
    assert code == 0 and [ln.split()[0] for ln in out.strip().splitlines()[:-1]] == quick
    code, _, err = run_cli(["validate", "--list", "--json", "-"], capsys)
    assert code == 2 and "--list" in err and len(err.strip().splitlines()) == 1
