"""docs/decisions: every decision file has the required layout and README.md is current.

The generator ``docs/decisions/make_index.py`` runs in check mode on the real folder; the other
tests build a small folder to show that the check fails on a stale index, a missing heading or
field, and a test reference that does not exist.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT / "docs" / "decisions"


def _load_generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("make_index", FOLDER / "make_index.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["make_index"] = mod
    spec.loader.exec_module(mod)
    return mod


make_index = _load_generator()

GOOD = """\
# 0001. A decision

- Status: accepted
- Date: 2026-11-25

## Context

The seed is silent.

## Decision

We chose one.

## Consequence

It holds.

## Test

- `tests/test_x.py::test_holds`
"""


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    folder = tmp_path / "docs" / "decisions"
    folder.mkdir(parents=True)
    (folder / "0001-a-decision.md").write_text(GOOD, encoding="utf-8")
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_x.py").write_text("def test_holds():\n    pass\n", "utf-8")
    assert make_index.main([], folder) == 0
    return folder


def test_index_is_current_and_every_file_has_the_layout() -> None:
    # the real folder, as a user runs it: exit status 0, nothing on stderr
    r = subprocess.run(
        [sys.executable, str(FOLDER / "make_index.py"), "--check"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    decisions, problems = make_index.collect(FOLDER)
    assert problems == []
    # one row per decision file, sorted by number, numbers unique
    numbers = [d.number for d in decisions]
    assert numbers == sorted(set(numbers))
    assert len(decisions) == len(list(FOLDER.glob("[0-9][0-9][0-9][0-9]-*.md")))
    rows = [
        ln for ln in (FOLDER / "README.md").read_text("utf-8").splitlines() if ln.startswith("| [")
    ]
    assert len(rows) == len(decisions)


def test_stale_index_fails_the_check(tree: Path) -> None:
    assert make_index.main(["--check"], tree) == 0
    (tree / "0002-another-one.md").write_text(
        GOOD.replace("0001. A decision", "0002. Another one"), encoding="utf-8"
    )
    assert make_index.main(["--check"], tree) == 1  # README.md lacks row 0002
    assert make_index.main([], tree) == 0
    assert make_index.main(["--check"], tree) == 0
    assert "[0002](0002-another-one.md)" in (tree / "README.md").read_text("utf-8")


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("## Consequence\n", "", "sections are"),
        ("- Date: 2026-11-25\n", "", "Date"),
        ("- Status: accepted", "- Status: maybe", "Status"),
        ("- Status: accepted", "- Status: superseded by 0042", "0042, which has no file"),
        ("We chose one.\n", "", "'## Decision' is empty"),
        ("test_x.py::test_holds", "test_x.py::test_gone", "test_x.py::test_gone not found"),
        ("- `tests/test_x.py::test_holds`", "see the tests", "names no `tests/x.py::test_name`"),
        ("# 0001. A decision", "# 0003. A decision", "differs from the file name"),
    ],
)
def test_layout_problem_is_one_line_naming_the_file(
    tree: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, message: str
) -> None:
    f = tree / "0001-a-decision.md"
    f.write_text(GOOD.replace(old, new), encoding="utf-8")
    assert make_index.main(["--check"], tree) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("0001-a-decision.md: ") and message in err[0]


def test_none_yet_is_accepted_and_shown(tree: Path) -> None:
    f = tree / "0001-a-decision.md"
    f.write_text(GOOD.replace("- `tests/test_x.py::test_holds`", "None yet"), encoding="utf-8")
    assert make_index.main([], tree) == 0
    row = [
        ln
        for ln in (tree / "README.md").read_text("utf-8").splitlines()
        if ln.startswith("| [0001]")
    ]
    assert row == [
        "| [0001](0001-a-decision.md) | [A decision](0001-a-decision.md) | accepted | None yet |"
    ]


def test_test_reference_with_a_reason_and_several_per_line(tree: Path) -> None:
    # the form of the common brief: the reference followed by why it holds the decision
    f = tree / "0001-a-decision.md"
    line = (
        "`tests/test_x.py::test_holds` (the test that would fail if the decision were undone), "
        "`tests/test_x.py::test_also[case-1]`"
    )
    (tree.parents[1] / "tests" / "test_x.py").write_text(
        "def test_holds():\n    pass\n\n\ndef test_also():\n    pass\n", "utf-8"
    )
    f.write_text(GOOD.replace("- `tests/test_x.py::test_holds`", line), encoding="utf-8")
    decisions, problems = make_index.collect(tree)
    assert problems == []
    assert decisions[0].tests == ("`tests/test_x.py::test_holds`", "`tests/test_x.py::test_also`")
