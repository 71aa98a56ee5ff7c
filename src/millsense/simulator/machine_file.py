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


def simulated_feed_drive(machine: str | Path, axis: str, *, ideal: bool = False) -> FeedDriveParams:
    """The feed drive of ``axis`` the virtual machine runs, as the bench drives it.

    For a preset with a truth of its own (:data:`~.truth_machine.TRUTH_PRESETS`) the truth's
    coupled drive (:func:`~.truth_machine.truth_feed_params`, as
    :class:`~.machine.MachineSimulator` runs it, decision 1062); otherwise, or with ``ideal``,
    the drive of the simulator's machine file (Aslan Eq. 3.1 + Eq. 3.13: the estimators' own
    model class, for debugging only). The acceptance bench and its cases drive whatever this
    returns (one place).
    """
    from millsense.simulator.feed_drive import FeedDriveParams
    from millsense.simulator.truth_machine import TRUTH_PRESETS, load_truth, truth_feed_params

    cfg = simulator_machine(machine)
    if not ideal and cfg.name in TRUTH_PRESETS:
        truth = load_truth(cfg.name)
        if axis in truth:
            return truth_feed_params(cfg.axis(axis), truth[axis])
    return FeedDriveParams.from_config(cfg.axis(axis))


def simulated_feed_substeps(machine: str | Path, axis: str, *, ideal: bool = False) -> int:
    """Plant integration substeps per sample of the drive :func:`simulated_feed_drive` returns,
    as :class:`~.machine.MachineSimulator` runs it: the truth's own ``substeps`` (its dead times
    are rounded to whole substeps), else the simulator's default of 10."""
    from millsense.simulator.truth_machine import TRUTH_PRESETS, load_truth

    cfg = simulator_machine(machine)
    if not ideal and cfg.name in TRUTH_PRESETS:
        truth = load_truth(cfg.name)
        if axis in truth:
            return truth[axis].substeps
    return 10


def simulator_machine_path(name: str) -> Path:
    """Path of the simulator's own machine file of ``name`` (for tools and tests that need a
    fully specified machine file, e.g. the CLI's own tests)."""
    entry = resources.files("millsense.simulator").joinpath("data", "machines", f"{name}.toml")
    if not entry.is_file():
        raise ConfigError(f"no machine '{name}' in the simulator")
    return Path(str(entry))
