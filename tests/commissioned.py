"""A quaser-ux600 machine file commissioned on the simulator, as a user must make one.

``millsense commission`` (on the simulator's truth, decision 1041) → ``millsense identify``
friction, drive (inertia), path moving and at rest, per axis → ``millsense merge`` into the
preset. Only CNC channels and the machine file reach the identification, so the estimators
built from the result know the truth only through identification (issue 12). Built once per
test session (import :func:`commissioned_fixture`, the fixture `commissioned`, to use it).
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
    """Commission, identify and merge ``axes`` (e.g. ``"xyzac"``); the merged file's path."""
    frags: list[str] = []
    for ax in axes:
        d = out / f"com_{ax}"
        _cli(["commission", "--machine", PRESET, "--axis", ax, "-o", str(d), "--no-spindle"])
        f = d / f"{PRESET}-{ax}"
        m = ["--machine", PRESET, "--axis", ax]
        pres = [str(f) + "-presliding.h5"] if Path(str(f) + "-presliding.h5").exists() else []
        steps = (
            ("friction", ["friction", str(f) + "-friction.h5", *pres]),
            ("inertia", ["drive", str(f) + "-acceleration.h5"]),
            ("path", ["path", str(f) + "-table_load_sweep.h5", "--input-channel", f"{ax}/load"]),
            (
                "path_at_rest",
                ["path", str(f) + "-table_load_sweep_at_rest.h5", "--input-channel", f"{ax}/load"],
            ),
        )
        for name, args in steps:
            frag = out / f"{ax}_{name}.toml"
            _cli(["identify", *args, *m, "-o", str(frag)])
            frags.append(str(frag))
    merged = out / "machine.toml"
    _cli(["merge", PRESET, *frags, "-o", str(merged)])
    return merged


@pytest.fixture(scope="session", name="commissioned")
def commissioned_fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Directory with ``machine.toml`` (quaser-ux600, every feed axis commissioned on the
    truth; ≈ 10 min on one core) and the fragments ``<axis>_{friction,inertia,path,
    path_at_rest}.toml``. ``MILLSENSE_TEST_COMMISSIONED=DIR`` reuses (or first fills) DIR
    across sessions while iterating; unset, every session commissions afresh."""
    keep = os.environ.get("MILLSENSE_TEST_COMMISSIONED")
    out = Path(keep) if keep else tmp_path_factory.mktemp("commissioned")
    if not (out / "machine.toml").exists():
        out.mkdir(parents=True, exist_ok=True)
        commission_axes(out, "xyzac")
    return out
