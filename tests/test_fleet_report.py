"""The fleet view of a batch (issue 20 item 3): the page's tables are the summary's, and the page
opens in headless Chromium with its plot drawn and no console error."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from tests.browser import chromium, console_errors, screenshot

from millsense.report.fleet_plots import tool_table
from millsense.report.fleet_report import fleet_html


def _rows() -> list[dict[str, Any]]:
    rows = []
    for tool, rate in (("T1", 0.004), ("T2", 0.006)):
        for i in range(4):
            t = 360.0 * i
            rows.append({"run": f"{tool}_r{i}", "status": "ok", "machine": "m1", "tool_id": tool,
                         "tool_cutting_time_s": t, "wear_vb_mm": rate * t / 60,
                         "truth_wear_vb_mm": 0.9 * rate * t / 60, "raw_torque_nm": 2.0 + i,
                         "alarms": i % 2, "wear_rate_mm_min": rate,
                         "wear_remaining_min": (0.3 - rate * t / 60) / rate})  # fmt: skip
    rows.append({"run": "bad", "status": "error", "error": "bad.h5: not a recording",
                 "machine": "m1", "tool_id": "T2"})  # fmt: skip
    return rows


def test_tool_table_takes_each_tools_latest_run() -> None:
    tools = {t["tool"]: t for t in tool_table(_rows())}
    assert tools["T1"]["runs"] == 4 and tools["T2"]["runs"] == 5 and tools["T2"]["failed"] == 1
    # the last run (18 min of cutting): VB = rate × 18 min, remaining = (0.3 − VB)/rate
    assert tools["T2"]["vb_mm"] == pytest.approx(0.006 * 18, rel=1e-12)
    assert tools["T2"]["remaining_min"] == pytest.approx((0.3 - 0.108) / 0.006, rel=1e-12)
    assert tools["T1"]["alarms"] == 2


def test_page_carries_the_summary_numbers() -> None:
    page = fleet_html(_rows(), limit_mm=0.3)
    blob = re.search(r"id='millsense-fleet-data'>(.*?)</script>", page, re.S)
    assert blob is not None
    data = json.loads(blob.group(1).replace("<\\/", "</"))
    assert data["tools"] == json.loads(json.dumps(tool_table(_rows()), default=float))
    assert "bad.h5: not a recording" in page
    assert "plot-fleet" in page and math.isfinite(data["tools"][0]["vb_mm"])


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    yield from chromium()


def test_fleet_page_opens_in_chromium(browser: Any, tmp_path: Path) -> None:
    path = tmp_path / "fleet.html"
    path.write_text(fleet_html(_rows(), limit_mm=0.3), encoding="utf-8")
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    errors = console_errors(page)
    page.route("http*://**", lambda route: route.abort())
    page.goto(path.as_uri())
    page.wait_for_function("document.querySelectorAll('#plot-fleet .main-svg').length > 0")
    traces = page.evaluate("document.getElementById('plot-fleet').data.length")
    screenshot(page, "fleet.png")
    assert errors == []
    # per tool: VB, true VB, raw torque
    assert traces == 6
    assert page.locator("table.tools tbody tr").count() == 2
    assert page.locator("table.runs tbody tr").count() == 9


def test_run_report_shows_the_fleet_with_this_run_marked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``millsense report RUN.h5 --fleet summary.parquet`` (issue 20 item 3): the run report
    carries the fleet view; the run's own summary row is shown first and highlighted, its tool's
    line of the tool table is the one marked, and the tool table's figures are those of
    :func:`tool_table` (the same rows as the batch's page)."""
    import sys

    import pyarrow as pa
    import pyarrow.parquet as pq
    from tests.cli_run import run_cli

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_report

    rec = tmp_path / "T2_r2.h5"
    bench_report.synthesise(rec, 2.0)
    summary = tmp_path / "summary.parquet"
    pq.write_table(pa.Table.from_pylist(_rows()), summary)
    out = tmp_path / "r.html"
    code, _, err = run_cli(["report", str(rec), "--fleet", str(summary), "-o", str(out)],
                           capsys)  # fmt: skip
    assert code == 0, err
    page = out.read_text(encoding="utf-8")
    assert "Fleet: tools and wear" in page and "this run is marked" in page
    marked = re.findall(r'<tr class="this-run">(.*?)</tr>', page, re.S)
    cells = [re.findall(r"<td>(.*?)</td>", m) for m in marked]
    # this run's row (twice: shown first, and marked in the runs table) and its tool's line
    assert [c[0] for c in cells] == ["T2_r2", "m1", "T2_r2"]
    assert cells[0][9] == f"{0.006 * 12:.6g}"  # VB [mm] of the row (12 min of cutting)
    t2 = {t["tool"]: t for t in tool_table(_rows())}["T2"]
    assert cells[1][:4] == ["m1", "T2", str(t2["runs"]), str(t2["failed"])]
    assert cells[1][4] == f"{t2['vb_mm']:.6g}"

    # a run that is not in the table: the view without a mark, and said so
    other = tmp_path / "elsewhere.h5"
    bench_report.synthesise(other, 1.0)
    code, _, err = run_cli(["report", str(other), "--fleet", str(summary), "-o",
                            str(tmp_path / "o.html")], capsys)  # fmt: skip
    o = (tmp_path / "o.html").read_text(encoding="utf-8")
    assert code == 0 and "is not in it" in o and '<tr class="this-run">' not in o


def test_report_fleet_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A summary that is not a Parquet file, or a Parquet table that is not a batch's: one line
    naming the file, exit 2, no report written."""
    import sys

    import pyarrow as pa
    import pyarrow.parquet as pq
    from tests.cli_run import run_cli

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_report

    rec = tmp_path / "run.h5"
    bench_report.synthesise(rec, 1.0)
    bad = tmp_path / "bad.parquet"
    bad.write_text("not parquet", encoding="utf-8")
    other = tmp_path / "other.parquet"
    pq.write_table(pa.Table.from_pylist([{"x": 1.0}]), other)
    for path, words in ((bad, "not a readable summary table"), (other, "no column run")):
        out = tmp_path / "r.html"
        code, _, err = run_cli(["report", str(rec), "--fleet", str(path), "-o", str(out)],
                               capsys)  # fmt: skip
        assert code == 2 and str(path) in err and words in err, err
        assert len(err.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("limit", ["-1", "0", "nan"])
def test_report_wear_limit_must_be_positive(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], limit: str
) -> None:
    """``report --wear-limit-mm -1`` (or 0, nan) drew the fleet view against that limit with
    exit 0, where ``batch --vb-limit-mm`` refuses it: the same one line, exit 2, checked
    before anything is read."""
    from tests.cli_run import run_cli

    out = tmp_path / "r.html"
    code, _, err = run_cli(["report", str(tmp_path / "run.h5"), "--wear-limit-mm", limit,
                            "-o", str(out)], capsys)  # fmt: skip
    assert code == 2 and f"--wear-limit-mm: must be > 0, got {limit}" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
