"""Cutting force from a feed drive's current command by rigid-body inverse dynamics.

Aslan Eq. 3.10: ``τ_c = K_t·I_nom − τ_f(ω) − J_e·dω/dt``, then Eq. 3.11 to the axis:
``F = η·τ_c / r_g`` with ``r_g = h_p/2π``. This is capability C3 of seed 000, whose bandwidth
is limited (10–15 Hz on the Quaser with its structural modes); the Kalman compensation of the
drive's disturbance dynamics (C5–C6) builds on it in issue 7.

Derivative filter (the thesis specifies none; decision
docs/decisions/0005-derivative-filter-of-the-rigid-body-force-estimator-aslan.md): dω/dt is the
backward difference of the CNC's motor speed, and the whole torque estimate is low-passed by a
2nd-order Butterworth filter at ``cutoff_hz`` (the difference of an encoder-derived speed is
otherwise dominated by quantisation noise: one count of a 2²⁰-count encoder at 10 kHz is 0.06 rad/s,
i.e. 600 rad/s² in the difference). Both are exact streaming operations (stored previous sample,
``sosfilt`` state), so the output does not depend on the chunking.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import signal

from millsense.core.config import FeedAxisConfig
from millsense.core.recording import ChannelInfo
from millsense.models.friction import CoulombViscous
from millsense.streaming.block import Block, BlockOutput, Chunk


@dataclass(frozen=True)
class DriveModel:
    """What the estimator knows of a drive (identified or nominal), SI.

    inertia J_e [kg·m²], torque_constant K_t [N·m/A], transmission r_g [m/rad],
    efficiency η, friction (motor side).
    """

    inertia: float
    torque_constant: float
    transmission: float
    efficiency: float
    friction: CoulombViscous

    @classmethod
    def from_config(
        cls,
        cfg: FeedAxisConfig,
        friction_smoothing_rad_s: float,
        *,
        where: str = "machine",
        axis: str = "",
    ) -> DriveModel:
        """The rigid-body drive of an axis table: nameplate K_t, r_g, η; J_e and the viscous
        friction of :func:`rigid_limit` (a ball-screw axis's table inertia and damping
        included); Coulomb + viscous friction with sgn(ω) smoothed over
        ``friction_smoothing_rad_s``. A table without identified friction (a nameplate file)
        raises a one-line ConfigError naming ``axes.<axis>.friction``."""
        inertia, damping = rigid_limit(cfg)
        fric = CoulombViscous.from_config(cfg.friction_table(where, axis), friction_smoothing_rad_s)
        fric = replace(
            fric, viscous_pos=fric.viscous_pos + damping, viscous_neg=fric.viscous_neg + damping
        )
        return cls(inertia, cfg.torque_constant_nm_a, cfg.transmission_m_rad, cfg.efficiency, fric)


def rigid_limit(cfg: FeedAxisConfig) -> tuple[float, float]:
    """Inertia and viscous damping of an axis seen rigidly at the motor (Aslan Eq. 3.10 terms).

    Parameters
    ----------
    cfg : the axis table.

    Returns
    -------
    (J_e kg·m², D_e N·m·s/rad) : J_e = ``inertia_kg_m2`` and D_e = 0 for an axis without
    ``[axes.<a>.ball_screw]`` (its viscous friction is the friction table's); with a ball
    screw the rigid-body limit of Yamada's plant.

    Notes
    -----
    Dual inertia (Yamada Eq. 2-1/2-2) with the screw rigid (x_t = R·θ_m): the two equations
    summed give ``(J_r + M_t·R²)·θ̈ + (D_r + C_t·R²)·θ̇ = τ_m − F·R`` (the axial spring and its
    damping C_k act on R·θ − x_t = 0 only). Triple inertia (Eq. 2-45…2-47) likewise:
    ``J_r + (M_n + M_t)·R²`` and ``D_r + (C_n + C_t)·R²``. ``inertia_kg_m2`` of a ball-screw
    axis is J_r alone (the table is in ``ball_screw``), so the C3 estimate that used it missed
    the table's inertia and, at constant feed, the damping thrust ``D_r·ω/R + C_t·v`` (decision
    docs/decisions/0103-raw-estimate-of-a-ball-screw-axis-issue-7-item-b.md).
    """
    bs = cfg.ball_screw
    if bs is None:
        return cfg.inertia_kg_m2, 0.0
    r = cfg.transmission_m_rad
    triple = bs.model == "triple"
    mass = bs.table_mass_kg + ((bs.nut_mass_kg or 0.0) if triple else 0.0)
    damp = bs.table_damping_n_s_m + (bs.nut_damping_n_s_m if triple else 0.0)
    return cfg.inertia_kg_m2 + mass * r * r, bs.rotary_damping_nm_s_rad + damp * r * r


class RigidBodyForceEstimator(Block):
    """Streaming block: axis force (N, acting on the table along +axis) from current and speed.

    Parameters
    ----------
    axis : axis name; reads ``{axis}/current_cmd`` (A) and ``{axis}/motor_speed`` (rad/s),
        writes ``{axis}/force_est`` (N).
    model : the drive model the estimator believes.
    cutoff_hz : corner of the 2nd-order Butterworth low-pass applied to the torque estimate.
    """

    def __init__(self, axis: str, model: DriveModel, cutoff_hz: float = 300.0) -> None:
        self.axis = axis
        self.model = model
        self.cutoff_hz = cutoff_hz
        self.name = f"rigid_body_force_{axis}"
        self.inputs = (f"{axis}/current_cmd", f"{axis}/motor_speed")
        self._out = f"{axis}/force_est"
        self._sos = np.zeros((1, 6))
        self._zi = np.zeros((1, 2))
        self._prev_speed: float | None = None
        self._started = False
        self._fs = 0.0

    def output_channels(self) -> list[ChannelInfo]:
        return [
            ChannelInfo(
                self._out,
                "N",
                f"{self.axis} axis force on the table from current command by rigid-body "
                f"inverse dynamics (Aslan Eq. 3.10-3.11), low-passed at {self.cutoff_hz:g} Hz",
            )
        ]

    def reset(self, sample_rate_hz: float) -> None:
        if not 0 < self.cutoff_hz < sample_rate_hz / 2:
            raise ValueError(
                f"cutoff_hz must be in (0, {sample_rate_hz / 2:g}) Hz, got {self.cutoff_hz}"
            )
        self._fs = sample_rate_hz
        self._sos = signal.butter(2, self.cutoff_hz, fs=sample_rate_hz, output="sos")
        self._zi = np.zeros((self._sos.shape[0], 2))
        self._prev_speed = None
        self._started = False

    def process(self, chunk: Chunk) -> BlockOutput:
        current = np.asarray(chunk.data[self.inputs[0]], dtype=float)
        speed = np.asarray(chunk.data[self.inputs[1]], dtype=float)
        if len(speed) == 0:
            return BlockOutput({self._out: np.zeros(0)})
        prev = speed[0] if self._prev_speed is None else self._prev_speed
        accel = np.diff(speed, prepend=prev) * self._fs
        self._prev_speed = float(speed[-1])
        m = self.model
        tau_c = m.torque_constant * current - m.friction.torque(speed) - m.inertia * accel
        if not self._started:
            # start the filter in steady state on the first sample (no start-up transient)
            self._zi = signal.sosfilt_zi(self._sos) * tau_c[0]
            self._started = True
        tau_f, self._zi = signal.sosfilt(self._sos, tau_c, zi=self._zi)
        # τ_c is the torque of the force resisting +motion: F_table(+axis) = −η·τ_c/r_g
        force = -m.efficiency * tau_f / m.transmission
        return BlockOutput({self._out: force})
