"""The thesis's printed estimator designs (Aslan Table 3.4, Eq. 3.30), for design checks only.

Moved out of :mod:`millsense.bench` (decision 1790): these designs read the SIMULATOR's machine
file (its Table 3.4 modes and exact ``current_noise_a``), so they may serve only the disclosed
design checks (``estimation.kalman_*``, reported as self-checks), tests of the Kalman toolkit and
benchmarks, never the commissioning path a user's estimator is built on.

:class:`millsense.models.modal_ss.ModalStateSpace` realises Aslan Eq. 3.13 (α/β residue modes)
as balanced 2×2 blocks; :func:`state_space_from_modal` turns it into the
:class:`~millsense.estimation.kalman.design.StateSpaceModel` the Kalman toolkit designs on. The
Quaser
data come from the ``quaser-ux600`` preset (Table 3.4 modes, Eq. 3.30 R as ``current_noise_a``),
so no table is copied here; only the thesis's hand-tuned Q (Eq. 3.30), which is estimator
tuning rather than a machine property, is kept in this module.
"""

from __future__ import annotations

import numpy as np

from millsense.core.errors import ConfigError
from millsense.estimation.kalman.design import StateSpaceModel
from millsense.models.modal_ss import ModalStateSpace
from millsense.simulator.machine_file import simulator_machine

#: Aslan Eq. 3.30: process-noise intensity Q of the disturbance Kalman filter per axis.
ASLAN_EQ_3_30_Q: dict[str, float] = {"x": 200.0, "y": 700.0, "z": 2000.0, "a": 800.0, "c": 10000.0}


def state_space_from_modal(modes: ModalStateSpace) -> StateSpaceModel:
    """Continuous SISO state space (A, B, C, D) of a modal realisation."""
    a, b, c, d = modes.dense()
    return StateSpaceModel.from_arrays(a, b.reshape(-1, 1), c.reshape(1, -1), d)


def aslan_disturbance_modes(axis: str, modes: slice | None = None) -> ModalStateSpace:
    """Table 3.4 disturbance modes Φ_d = τ_c/τ_a of a Quaser axis (optionally a subset)."""
    cfg = simulator_machine("quaser-ux600").axis(axis).disturbance_modes
    if cfg is None:
        raise ConfigError(f"preset quaser-ux600: axis '{axis}' has no disturbance_modes")
    sel = slice(None) if modes is None else modes
    return ModalStateSpace.from_modes(
        np.asarray(cfg.natural_frequency_hz)[sel],
        np.asarray(cfg.damping_ratio)[sel],
        np.asarray(cfg.alpha)[sel],
        np.asarray(cfg.beta)[sel],
    )


def aslan_disturbance_model(axis: str, modes: slice | None = None) -> StateSpaceModel:
    """:func:`aslan_disturbance_modes` as a :class:`StateSpaceModel`."""
    return state_space_from_modal(aslan_disturbance_modes(axis, modes))


def aslan_r_q(axis: str) -> tuple[float, float]:
    """(R, Q) of Aslan Eq. 3.30 for an axis: R = (current_noise_a·K_t)² from the preset."""
    a = simulator_machine("quaser-ux600").axis(axis)
    return (a.current_noise_a * a.torque_constant_nm_a) ** 2, ASLAN_EQ_3_30_Q[axis]
