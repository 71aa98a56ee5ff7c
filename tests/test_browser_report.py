"""The run report in headless Chromium (issue 19): it opens from a file with no network, no
console error, and every plot is drawn."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from tests.browser import chromium, console_errors, screenshot

from millsense.streaming.block import Event, EventKind, Severity

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_report  # noqa: E402


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    yield from chromium()


def test_report_opens_offline_with_its_plots(browser: Any, tmp_path: Path) -> None:
    """The six plots of a run with truth (estimates, harmonics, path, breakage, control,
    spindle) are drawn (plotly's SVG in each), requests leaving the file are blocked and none
    is made, and the console stays clean."""
    from millsense.report.run_report import write_report

    rec = tmp_path / "run.h5"
    bench_report.synthesise(rec, 20.0)
    events = [Event(8.0, EventKind.ALARM, "breakage", "tool breakage", name="breakage",
                    sample=80000, severity=Severity.CRITICAL)]  # fmt: skip
    rep = write_report(tmp_path / "run.html", rec, events=events)
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    errors = console_errors(page)
    outside: list[str] = []

    def block(route: Any) -> None:
        outside.append(route.request.url)
        route.abort()

    page.route("http*://**", block)
    page.goto((tmp_path / "run.html").as_uri())
    page.wait_for_function("document.querySelectorAll('.js-plotly-plot .main-svg').length > 0")
    page.wait_for_timeout(500)
    drawn = page.evaluate(
        "Array.from(document.querySelectorAll('.js-plotly-plot')).map(d => "
        "[d.id, d.querySelectorAll('.main-svg').length, (d.data || []).length])"
    )
    screenshot(page, "report.png")
    assert errors == []
    assert outside == []  # plotly.js is embedded: nothing fetched
    assert sorted(d[0] for d in drawn) == sorted(f"plot-{k}" for k in rep.figures)
    assert len(drawn) == 6
    for plot_id, svgs, traces in drawn:
        assert svgs >= 1 and traces >= 1, plot_id
    # the breakage marker on the path (its position from the recorded tool-centre point)
    names = page.evaluate("document.getElementById('plot-path').data.map(t => t.name)")
    assert "breakage" in names
    page.close()
