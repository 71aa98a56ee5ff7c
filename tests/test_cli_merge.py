"""``millsense merge``: machine file = base machine + identify fragments, validated."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from cli_run import run_cli
from millsense.core.config import MachineConfig
from millsense.core.presets import load_preset
from millsense.ident.fragment import kept_keys
from millsense.simulator.machine_file import simulator_machine_path

FRICTION = """[axes.x.friction]
coulomb_nm = [1.8, 1.9]
viscous_nm_s_rad = [0.2, 0.16]
source = "identified"
"""
INERTIA = """[axes.x]
inertia_kg_m2 = 0.0137
"""


def test_merge_writes_the_base_with_the_fragments_over_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "f.toml").write_text(FRICTION)
    (tmp_path / "i.toml").write_text(INERTIA)
    out = tmp_path / "m.toml"
    # a base with a friction table (the simulator's own file; the nameplate preset has none)
    sim = str(simulator_machine_path("quaser-ux600"))
    code, stdout, err = run_cli(
        ["merge", sim, str(tmp_path / "f.toml"), str(tmp_path / "i.toml"), "-o",
         str(out)], capsys)  # fmt: skip
    assert code == 0, err
    got = load_preset(MachineConfig, str(out))
    base = load_preset(MachineConfig, sim)
    x, bx = got.axis("x"), base.axis("x")
    # the fragments' keys, to the writer's 7 significant digits
    assert x.friction.coulomb_nm == (1.8, 1.9) and x.inertia_kg_m2 == 0.0137
    # everything else is the base: the other axes whole, X's other keys
    assert got.axis("y") == base.axis("y") and got.spindle == base.spindle
    assert x.friction.sigma0_nm_rad == bx.friction.sigma0_nm_rad and x.lead_mm_rev == 12.0
    # the partial friction table keeps the base's LuGre keys, and says so
    assert "keeps from the base axes.x.friction: static_nm" in err
    assert "2 fragment(s) merged" in stdout


def test_kept_keys_only_for_leaf_tables() -> None:
    base = tomllib.loads("[a]\nk = 1\n[a.t]\nu = 1\nv = 2\n[a.s]\nw = 3\n")
    frag = tomllib.loads("[a]\nk = 2\n[a.t]\nu = 5\n")
    assert kept_keys(base, frag) == ["a.t: v"]


def test_merge_errors_name_the_fragment_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[axes.x.friction]\ncoulomb_nm = [-1.0, 1.0]\n")
    out = tmp_path / "m.toml"
    code, _, err = run_cli(["merge", "quaser-ux600", str(bad), "-o", str(out)], capsys)
    assert code == 2 and "bad.toml" in err and "coulomb_nm" in err and not out.exists()
    assert len(err.strip().splitlines()) == 1
    code, _, err = run_cli(["merge", "quaser-ux600", str(bad), "-o", str(bad)], capsys)
    assert code == 2 and "is one of the fragments" in err
    assert bad.read_text().startswith("[axes.x.friction]")
    code, _, err = run_cli(["merge", "no-such", str(bad), "-o", str(out)], capsys)
    assert code == 2 and "no machine preset 'no-such'" in err
    # an output in a folder that does not exist: one line naming it (any command, cli.main)
    good = tmp_path / "good.toml"
    good.write_text("[axes.x]\ninertia_kg_m2 = 0.0137\n")
    missing = tmp_path / "no" / "m.toml"
    code, _, err = run_cli(["merge", "quaser-ux600", str(good), "-o", str(missing)], capsys)
    assert code == 2 and str(missing) in err and len(err.strip().splitlines()) == 1
