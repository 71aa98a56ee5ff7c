"""Cutting force from a feed drive's current command by rigid-body inverse dynamics.

Aslan Eq. 3.10: ``τ_c = K_t·I_nom − τ_f(ω) − J_e·dω/dt``, then Eq. 3.11 to the axis:
``F = η·τ_c / r_g`` with ``r_g = h_p/2π``. This is capability C3 of seed 000, whose bandwidth
is limited (10–15 Hz on the Quaser with its structural modes); the Kalman compensation of the
drive's disturbance dynamics (C5–C6) builds on it in issue 7.

Derivative filter (the thesis specifies none; decision in docs/decisions.md, "derivative filter
of the rigid-body estimator"): dω/dt is the backward difference of the CNC's motor speed, and
the whole torque estimate is low-passed by a 2nd-order Butterworth filter at ``cutoff_hz``
(the difference of an encoder-derived speed is otherwise dominated by quantisation noise: one
count of a 2²⁰-count encoder at 10 kHz is 0.06 rad/s, i.e. 600 rad/s² in the difference).
Both are exact streaming operations (stored previous sample, ``sosfilt`` state), so the output
does not depend on the chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from millsense.core.recording import ChannelInfo
from millsense.machine.friction import CoulombViscous
from millsense.online.block import Block, BlockOutput, Chunk


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
