"""The machine file shipped as commissioned (``millsense/data/commissioned/quaser-ux600.toml``,
read by ``run``, ``demo``, ``batch``) and the walkthrough's
(``examples/walkthrough/quaser-ux600-commissioned.toml``, read by the README's commands and
the benchmarks) are one file: the walkthrough's is a link to the shipped one, so they cannot
drift apart (a copy written over the link would)."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from millsense.core.presets import commissioned_machine

ROOT = Path(__file__).resolve().parents[1]


def test_walkthrough_commissioned_file_is_the_shipped_one() -> None:
    walkthrough = ROOT / "examples/walkthrough/quaser-ux600-commissioned.toml"
    shipped = ROOT / "src/millsense/data/commissioned/quaser-ux600.toml"
    assert walkthrough.is_symlink()
    assert walkthrough.resolve() == shipped.resolve()
    entry = resources.files("millsense.data").joinpath("commissioned", "quaser-ux600.toml")
    assert tomllib.loads(entry.read_text(encoding="utf-8")) == tomllib.loads(
        walkthrough.read_text(encoding="utf-8")
    )


def test_shipped_commissioned_file_has_every_axis_identified() -> None:
    found = commissioned_machine("quaser-ux600")
    assert found is not None
    cfg, where = found
    assert "quaser-ux600.toml" in where
    for name, axis in cfg.axes.items():
        assert axis.friction is not None, name
