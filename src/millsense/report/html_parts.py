"""The pieces every millsense HTML page shares: the style sheet and the table writer (the run
report, :mod:`millsense.report.run_report`, and the fleet view,
:mod:`millsense.report.fleet_report`)."""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any

__all__ = ["CSS", "html_table"]

CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222;max-width:1400px}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.85em}
td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}
th{background:#f2f2f2} h2{border-bottom:1px solid #ddd;margin-top:1.6em}
.note{color:#666;font-size:0.85em} .fail{color:#b00} .pass{color:#070}
tr.this-run td{background:#fff4cc;font-weight:600}
"""


def _fmt(v: Any) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.6g}"
    return html.escape(str(v))


def html_table(
    head: Sequence[str],
    rows: Sequence[Sequence[Any]],
    cls: str = "",
    marked: Sequence[int] = (),
) -> str:
    """An HTML table of the rows (values formatted, text escaped); the rows whose index is in
    ``marked`` carry the class ``this-run`` (highlighted)."""
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    mark = set(marked)
    body = "".join(
        ('<tr class="this-run">' if i in mark else "<tr>")
        + "".join(f"<td>{_fmt(v)}</td>" for v in r)
        + "</tr>"
        for i, r in enumerate(rows)
    )
    return f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>'
