"""The machine file shipped as commissioned (``millsense/data/commissioned/quaser-ux600.toml``,
read by ``run``, ``demo``, ``batch``) and the walkthrough's copy
(``examples/walkthrough/quaser-ux600-commissioned.toml``, read by the README's commands and
the benchmarks) are the same commissioning of the virtual machine: they must not drift apart
(the shipped one had once mixed an older feed commissioning with a newer spindle one)."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from millsense.core.presets import commissioned_machine

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_commissioned_file_equals_the_walkthrough_copy() -> None:
    entry = resources.files("millsense.data").joinpath("commissioned", "quaser-ux600.toml")
    shipped = tomllib.loads(entry.read_text(encoding="utf-8"))
    walkthrough = tomllib.loads(
        (ROOT / "examples/walkthrough/quaser-ux600-commissioned.toml").read_text(encoding="utf-8")
    )
    assert shipped == walkthrough


def test_shipped_commissioned_file_has_every_axis_identified() -> None:
    found = commissioned_machine("quaser-ux600")
    assert found is not None
    cfg, where = found
    assert "quaser-ux600.toml" in where
    for name, axis in cfg.axes.items():
        assert axis.friction is not None, name
