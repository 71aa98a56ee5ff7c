"""A quaser-ux600 machine file commissioned on the simulator, as a user must make one.

``millsense commission --identify`` (on the simulator's truth, decision 1041): per axis the
tests, then the printed ``millsense identify`` friction, drive (inertia), the stage-1 merge,
the path moving and at rest, and ``millsense merge`` of every fragment into the nameplate
preset. Only CNC channels and the machine file reach the identification, so the estimators
built from the result know the truth only through identification (issue 12). Built once per
test session: tests/conftest.py registers :func:`commissioned_fixture`, the fixture
`commissioned` (imported into a test module instead, it would be built again for that module).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from millsense.cli.main import main

PRESET = "quaser-ux600"


def _cli(args: list[str]) -> None:
    try:
        main(args)
    except SystemExit as exc:
        assert not exc.code, f"millsense {' '.join(args)}: exit {exc.code}"


def commission_axes(out: Path, axes: str) -> Path:
    """``millsense commission --axis <axes> --no-spindle --identify -o out`` (the printed
    identify and merge commands run verbatim); the merged file's path."""
    _cli(["commission", "--machine", PRESET, "--axis", ",".join(axes), "--no-spindle",
          "--identify", "-o", str(out)])  # fmt: skip
    return out / "machine.toml"


@pytest.fixture(scope="session", name="commissioned")
def commissioned_fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Directory with ``machine.toml`` (quaser-ux600, every feed axis commissioned on the
    truth; ≈ 10 min on one core) and the fragments ``<axis>_{friction,inertia,path,
    path_at_rest}.toml`` (and ``<axis>_stage1.toml``, the friction and inertia merged).
    ``MILLSENSE_TEST_COMMISSIONED=DIR`` reuses (or first fills) DIR
    across sessions while iterating; unset, every session commissions afresh."""
    keep = os.environ.get("MILLSENSE_TEST_COMMISSIONED")
    out = Path(keep) if keep else tmp_path_factory.mktemp("commissioned")
    if not (out / "machine.toml").exists():
        out.mkdir(parents=True, exist_ok=True)
        commission_axes(out, "xyzac")
    return out
