"""The simulator's own machine files, apart from the nameplate presets (issue 12).

``millsense/data/machines/<name>.toml`` is the *nameplate*: what a user may know of the machine
from catalogues and the CNC, the file estimators start from. The virtual machine runs its own
description, ``millsense/simulator/data/machines/<name>.toml`` (Aslan's and Yamada's tables:
rigid body, friction, disturbance modes, noise, dead times), read only here and by the modules
of :mod:`millsense.simulator` and the acceptance bench (decision
docs/decisions/0991-nameplate-machine-files.md).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from millsense.core.config import MachineConfig, parse_config, read_toml
from millsense.core.errors import ConfigError

if TYPE_CHECKING:
    from millsense.simulator.feed_drive import FeedDriveParams


def simulated_machine_names() -> list[str]:
    """Names of the machines the simulator has its own description of."""
    folder = resources.files("millsense.simulator").joinpath("data", "machines")
    return sorted(
        p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml")
    )


def simulator_machine(name_or_path: str | Path) -> MachineConfig:
    """The machine the simulator runs: its own file for a preset name, else the TOML given.

    A path (``.toml`` or an existing file) is taken as the whole description of a machine to
    simulate (e.g. a file merged from identified fragments).

    Raises
    ------
    ConfigError
        Unknown name or unreadable file (one line).
    """
    text = str(name_or_path)
    if text.endswith(".toml") or Path(text).exists():
        return parse_config(MachineConfig, read_toml(text), text)
    entry = resources.files("millsense.simulator").joinpath("data", "machines", f"{text}.toml")
    if not entry.is_file():
        raise ConfigError(
            f"no machine '{text}' in the simulator (machines: "
            f"{', '.join(simulated_machine_names())}; or give a .toml path)"
        )
    with resources.as_file(entry) as path:
        return parse_config(MachineConfig, read_toml(path), f"simulator machine {text}")


def simulated_feed_drive(machine: str | Path, axis: str) -> FeedDriveParams:
    """The feed drive of ``axis`` the virtual machine runs, as the bench drives it.

    Today the drive of the simulator's machine file (:func:`simulator_machine`); the truth
    plant of issue 12 replaces it here (one place), so that the acceptance bench and its cases
    drive whatever the simulator runs.
    """
    from millsense.simulator.feed_drive import FeedDriveParams

    return FeedDriveParams.from_config(simulator_machine(machine).axis(axis))


def simulator_machine_path(name: str) -> Path:
    """Path of the simulator's own machine file of ``name`` (for tools and tests that need a
    fully specified machine file, e.g. the CLI's own tests)."""
    entry = resources.files("millsense.simulator").joinpath("data", "machines", f"{name}.toml")
    if not entry.is_file():
        raise ConfigError(f"no machine '{name}' in the simulator")
    return Path(str(entry))
