"""Embedded presets: machines, tools and materials shipped with millsense.

A preset is addressed by name (``quaser-ux600``) or by a path to a TOML file.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel

from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig, parse_config, read_toml
from millsense.core.errors import ConfigError

M = TypeVar("M", bound=BaseModel)

_KINDS: dict[type[BaseModel], str] = {
    MachineConfig: "machines",
    ToolConfig: "tools",
    MaterialConfig: "materials",
}


def preset_names(model: type[BaseModel]) -> list[str]:
    """Names of the embedded presets of one kind."""
    folder = resources.files("millsense.data").joinpath(_KINDS[model])
    return sorted(
        p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml")
    )


def preset_data(model: type[BaseModel], name_or_path: str | Path) -> tuple[dict[str, Any], str]:
    """The raw TOML mapping of a preset (by name) or file (by path), and its name for messages.

    Raises
    ------
    ConfigError
        Unknown preset, missing or unreadable file (one line).
    """
    text = str(name_or_path)
    if text.endswith(".toml") or Path(text).exists():
        return read_toml(text), text
    folder = resources.files("millsense.data").joinpath(_KINDS[model])
    entry = folder.joinpath(f"{text}.toml")
    if not entry.is_file() and model is not MachineConfig:
        # a tool or material named as a stock file or a data sheet spells it (Al7050 for the
        # preset al7050): one preset equal but for case is that one. Not machines: their name
        # also finds the commissioned file and the cached tunings, which spell it exactly.
        same = [n for n in preset_names(model) if n.lower() == text.lower()]
        if len(same) == 1:
            text = same[0]
            entry = folder.joinpath(f"{text}.toml")
    if not entry.is_file():
        raise ConfigError(
            f"no {_KINDS[model][:-1]} preset '{text}' "
            f"(presets: {', '.join(preset_names(model))}; or give a .toml path)"
        )
    with resources.as_file(entry) as path:
        return read_toml(path), f"preset {text}"


def load_preset(model: type[M], name_or_path: str | Path) -> M:
    """Load an embedded preset by name, or a TOML file by path."""
    data, source = preset_data(model, name_or_path)
    return parse_config(model, data, source)


def commissioned_machine(name: str) -> tuple[MachineConfig, str] | None:
    """The machine file shipped as commissioned for the preset ``name``, and where it is from.

    ``millsense/data/commissioned/<name>.toml`` is what ``millsense commission --machine NAME
    --axis x,y,z,a,c --identify`` wrote on the virtual machine (the nameplate plus friction,
    inertia, noise, disturbance paths and spindle identified on the simulator's truth): the
    machine as a user would have commissioned it, so that ``millsense run`` and ``demo`` work
    out of the box. None when no such file is shipped.
    """
    entry = resources.files("millsense.data").joinpath("commissioned", f"{name}.toml")
    if not entry.is_file():
        return None
    with resources.as_file(entry) as path:
        where = f"commissioned {name} (millsense/data/commissioned/{name}.toml)"
        return parse_config(MachineConfig, read_toml(path), where), where
