"""One-off check that splitting the old docs/decisions.md into this folder lost nothing.

Usage (stdlib only), with the old file taken from history::

    git show 1b69cb3:docs/decisions.md > /tmp/decisions-old.md
    python docs/decisions/check_split.py /tmp/decisions-old.md

For every ``## Title`` entry of the old file the decision file whose heading is
``# NNNN. Title`` must exist, and every non-empty line of the entry must occur in that file
with whitespace ignored (the split re-wraps paragraphs, so line breaks and the spaces of
re-joined lines do not count). A line whose sentences went to different sections (Context,
Decision, Consequence, Test) is accepted when each of its sentence pieces (cut at ". ", "; ",
": ") occurs in the file. Prints the counts and every line not found; exit status 1 if any.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
_HEADING = re.compile(r"^# (\d{4})\. (.+)$", re.M)


def _squash(text: str) -> str:
    return re.sub(r"\s+", "", text)


def _entries(old: str) -> list[tuple[str, list[str]]]:
    out: list[tuple[str, list[str]]] = []
    for line in old.splitlines():
        if line.startswith("## "):
            out.append((line[3:].strip(), []))
        elif out and line.strip():
            out[-1][1].append(line)
    return out


def check(old_path: Path, folder: Path = HERE) -> int:
    by_title: dict[str, str] = {}
    for f in sorted(folder.glob("[0-9][0-9][0-9][0-9]-*.md")):
        text = f.read_text(encoding="utf-8")
        m = _HEADING.search(text)
        if m:
            by_title[m.group(2).strip()] = _squash(text)
    entries = _entries(old_path.read_text(encoding="utf-8"))
    n_lines = whole = pieces = 0
    missing: list[str] = []
    for title, lines in entries:
        new = by_title.get(title)
        if new is None:
            missing.append(f"entry without a file: {title!r}")
            continue
        for line in lines:
            n_lines += 1
            if _squash(line) in new:
                whole += 1
                continue
            parts = [p for p in re.split(r"(?<=[.;:])\s+", line) if p.strip()]
            if all(_squash(p) in new for p in parts):
                pieces += 1
            else:
                missing.append(f"{title}: {line.strip()}")
    print(
        f"{len(entries)} entries, {len(by_title)} decision files, {n_lines} non-empty lines: "
        f"{whole} found whole, {pieces} found as sentence pieces, {len(missing)} missing"
    )
    for line in missing:
        print("MISSING", line)
    return 1 if missing else 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python docs/decisions/check_split.py OLD_DECISIONS_MD")
    sys.exit(check(Path(sys.argv[1])))
