"""The acceptance machine at commissioning, and the feed estimator of a ball-screw axis."""

from __future__ import annotations

import numpy as np

from millsense.estimation.feed.estimator import DEFAULT_FRICTION_SMOOTHING_RAD_S, FeedAxisModel
from millsense.estimation.feed.rigid_body import rigid_limit
from millsense.models.friction import CoulombViscous
from millsense.simulator.drive_mismatch import UNMODELLED_MODE, commissioning_drive, perturbed_drive
from millsense.simulator.feed_drive import FeedDriveParams
from millsense.simulator.machine_file import simulator_machine


def test_commissioning_machine_has_the_unmodelled_mode_without_drift() -> None:
    # decision "Unmodelled higher mode present at commissioning": the sweep machine carries the
    # 420 Hz mode exactly as the cutting machine does; friction and the other modes are the
    # preset's (drift and shift belong to the cutting machine only)
    ax = simulator_machine("quaser-ux600").axis("y")
    params = FeedDriveParams.from_config(ax)
    comm = commissioning_drive(params)
    cut = perturbed_drive(params, frequency_scale=1.0)
    assert comm.modes is not None and cut.modes is not None and params.modes is not None
    n0 = len(params.modes.frequency_hz)
    assert len(comm.modes.frequency_hz) == n0 + 1
    assert comm.modes.frequency_hz[-1] == UNMODELLED_MODE[0]
    np.testing.assert_allclose(comm.modes.frequency_hz, cut.modes.frequency_hz, rtol=1e-12)
    np.testing.assert_allclose(comm.modes.alpha, cut.modes.alpha, rtol=1e-12)
    assert comm.friction == params.friction
    assert cut.friction != params.friction


def test_feed_model_of_a_ball_screw_axis_uses_the_rigid_limit() -> None:
    # yamada-b is a ball-screw stage: the feed estimator's J_e is J_r + M_t·R² and its viscous
    # friction includes D_r + C_t·R² (Yamada Eq. 2-1/2-2 summed with the screw rigid), the same
    # drive the raw estimate uses (decision "Feed estimator of a ball-screw axis")
    machine = simulator_machine("yamada-b")
    ax = machine.axis("x")
    bs = ax.ball_screw
    assert bs is not None
    # give the axis the disturbance modes of the Quaser X so that the feed model can be built
    quaser = simulator_machine("quaser-ux600").axis("x")
    cfg = ax.model_copy(
        update={"disturbance_modes": quaser.disturbance_modes, "current_noise_a": 0.016}
    )
    model = FeedAxisModel.from_config("x", cfg, sample_rate_hz=1e4)
    r = ax.transmission_m_rad
    j_e, d_e = rigid_limit(ax)
    assert j_e > ax.inertia_kg_m2
    np.testing.assert_allclose(model.drive.inertia, j_e, rtol=1e-12)
    np.testing.assert_allclose(j_e, ax.inertia_kg_m2 + bs.table_mass_kg * r * r, rtol=1e-12)
    table = CoulombViscous.from_config(ax.friction, DEFAULT_FRICTION_SMOOTHING_RAD_S)
    assert d_e > 0
    np.testing.assert_allclose(model.drive.friction.viscous_pos, table.viscous_pos + d_e)
    np.testing.assert_allclose(model.drive.friction.viscous_neg, table.viscous_neg + d_e)
