"""The layer rules of docs/architecture.md hold in the code (import-linter contracts in
pyproject.toml), and a deliberate violation is caught — the check can fail."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")

pytestmark = pytest.mark.skipif(not LINT.exists(), reason="import-linter not installed")


def _lint(root: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(root / "src"))
    return subprocess.run(
        [str(LINT), "--no-cache"], cwd=root, env=env, capture_output=True, text=True, timeout=300
    )


def test_contracts_hold_on_the_tree() -> None:
    res = _lint(ROOT)
    assert res.returncode == 0, res.stdout[-3000:]
    assert "2 kept, 0 broken" in res.stdout


@pytest.mark.parametrize(
    ("line", "summary", "edge"),
    [
        # the simulator sits on a lower layer: only the "never import the simulator" rule sees it
        (
            "from millsense.simulator import machine as _violation",
            "1 kept, 1 broken",
            "millsense.estimation.feed.rigid_body -> millsense.simulator.machine",
        ),
        # the bench sits above estimation: both the layers and the forbidden rule see it
        (
            "from millsense.bench import feed_commissioning as _violation",
            "0 kept, 2 broken",
            "millsense.estimation.feed.rigid_body -> millsense.bench.feed_commissioning",
        ),
    ],
)
def test_a_deliberate_violation_fails(tmp_path: Path, line: str, summary: str, edge: str) -> None:
    shutil.copytree(ROOT / "src", tmp_path / "src", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    victim = tmp_path / "src/millsense/estimation/feed/rigid_body.py"
    victim.write_text(victim.read_text() + f"\n{line}  # noqa\n")
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert summary in res.stdout
    assert edge in res.stdout


def test_no_simulator_import_text_in_estimation_monitoring_control() -> None:
    pat = re.compile(r"^\s*(from|import) millsense\.(simulator|bench)\b", re.M)
    for pkg in ("estimation", "monitoring", "control"):
        for f in (ROOT / "src/millsense" / pkg).rglob("*.py"):
            assert not pat.search(f.read_text()), f
