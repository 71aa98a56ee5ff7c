"""The recorded validation status of the estimators, monitors and controllers a run used, for
its report (decision 1903).

Running the cases takes minutes to an hour; the status a report shows is the one last recorded
in ``docs/validation.md`` (written by :func:`~millsense.validation.registry.render_markdown`,
``make validate-full``), read back here with the commit and date of its header. Outside a
source checkout the file is absent and the report says the status is not known.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

#: Case prefixes of what every on-line session runs: the spindle torque observer, the chatter
#: and breakage monitors, the chatter avoidance and adaptive feed control, the session itself.
SESSION_PREFIXES = (
    "estimation.spindle",
    "monitoring.chatter",
    "monitoring.breakage",
    "control.chatter_avoidance",
    "control.v",
    "online.",
)
#: Added when the run used the feed-drive estimators (``est/feed/...`` channels).
FEED_PREFIXES = ("estimation.feed", "estimation.kalman")

_ROW = re.compile(r"^\| `([^`]+)` \| ([^|]*) \| ([^|]*) \| ([^|]*) \| ([^|]*) \|")
_HEADER = re.compile(r"^Generated (.+) from commit `([0-9a-f]+)`")


def validation_md() -> Path:
    """``docs/validation.md`` of the source checkout millsense runs from."""
    return Path(__file__).resolve().parents[3] / "docs" / "validation.md"


def prefixes_for(channels: Iterable[str]) -> tuple[str, ...]:
    """Case prefixes of a run with these recorded channels."""
    feed = any(c.startswith("est/feed/") or c.startswith("est/tool/") for c in channels)
    return SESSION_PREFIXES + (FEED_PREFIXES if feed else ())


def read_status(
    prefixes: Iterable[str], path: Path | None = None
) -> tuple[list[dict[str, str]], str] | None:
    """The rows of the cases whose id starts with one of ``prefixes`` (``case``,
    ``reference``, ``measured``, ``tolerance``, ``status``) and the header's date and commit;
    None when the file is absent."""
    md = path or validation_md()
    if not md.is_file():
        return None
    pre = tuple(prefixes)
    rows: list[dict[str, str]] = []
    when = ""
    for line in md.read_text(encoding="utf-8").splitlines():
        h = _HEADER.match(line)
        if h:
            when = f"{md.name}: generated {h.group(1)} from commit {h.group(2)}"
        m = _ROW.match(line)
        if m and m.group(1).startswith(pre):
            case, ref, meas, tol, status = (g.strip() for g in m.groups())
            rows.append({"case": case, "reference": ref, "measured": meas, "tolerance": tol,
                         "status": status.replace("*", "")})  # fmt: skip
    return rows, when or md.name
