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
