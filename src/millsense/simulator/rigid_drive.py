"""Rigid-body feed drive under cascade position/velocity/current control (simulator).

Plant (Aslan Eq. 3.1): ``J_e·dω/dt = K_t·i − τ_f(ω) − τ_load − τ_dist`` with ω the motor
speed, ``τ_load = (r_g/η)·F_resist`` the load torque of the axis force resisting the motion
(Aslan Eq. 3.11, ``r_g = h_p/2π``), τ_f Coulomb + viscous friction (:mod:`.friction`), and
τ_dist a white torque disturbance standing for the unmodelled fluctuation of an air cut.

Controller at the CNC sample rate (10 kHz): position P (gain K_v, velocity feed-forward),
velocity PI (K_p, K_i) producing the current command ``i_cmd = τ_cmd/K_t``; the current loop
follows as a first-order lag of the given bandwidth. Sensors: the motor encoder is quantised
to its counts per revolution and the CNC's motor speed is its backward difference, so the
current command carries the quantisation noise a real drive's does.

The simulation runs on the general feed-drive kernel (:mod:`.feed_drive`, exact zero-order
hold of the rigid body over ``substeps`` steps per sample); this module keeps the thin
parameter set of the foundation demo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millsense.core.config import FeedAxisConfig
from millsense.models.drive_plant import rigid_plant
from millsense.models.friction import CoulombViscous
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim


@dataclass(frozen=True)
class RigidDriveParams:
    """SI parameters of a rigid-body drive and its cascade controller.

    Attributes
    ----------
    inertia : J_e, kg·m² (motor side).
    torque_constant : K_t, N·m/A.
    transmission : r_g = h_p/2π, m/rad.
    efficiency : η, 0–1.
    friction : Coulomb + viscous friction.
    kp : velocity-loop proportional gain, N·m·s/rad.
    ki : velocity-loop integral gain, N·m/rad.
    kv : position-loop gain, 1/s.
    current_bandwidth_hz : first-order current loop, Hz.
    encoder_counts_rev : motor encoder resolution.
    torque_noise_nm : RMS of the white torque disturbance, N·m.
    """

    inertia: float
    torque_constant: float
    transmission: float
    efficiency: float
    friction: CoulombViscous
    kp: float
    ki: float
    kv: float
    current_bandwidth_hz: float
    encoder_counts_rev: int
    torque_noise_nm: float

    @classmethod
    def from_config(cls, axis: FeedAxisConfig) -> RigidDriveParams:
        """From a machine axis; velocity PI designed from ``velocity_bandwidth_hz`` if absent.

        Notes
        -----
        Aslan gives no feed-drive servo gains. Decision
        (docs/decisions/0001-feed-drive-servo-gains-foundation.md): crossover ω_c = 2π·f_v with
        ``K_p = J_e·ω_c``, integral corner at ω_c/4 (``K_i = K_p·ω_c/4``), position gain
        ``K_v = ω_c/4`` — a conventional cascade tuning that keeps each outer loop about four
        times slower than the inner one.
        """
        wc = 2.0 * math.pi * axis.velocity_bandwidth_hz
        kp = axis.velocity_kp_nm_s_rad or axis.inertia_kg_m2 * wc
        ki = axis.velocity_ki_nm_rad if axis.velocity_ki_nm_rad is not None else kp * wc / 4.0
        return cls(
            inertia=axis.inertia_kg_m2,
            torque_constant=axis.torque_constant_nm_a,
            transmission=axis.transmission_m_rad,
            efficiency=axis.efficiency,
            friction=CoulombViscous.from_config(axis.friction_table()),
            kp=kp,
            ki=ki,
            kv=wc / 4.0,
            current_bandwidth_hz=axis.current_bandwidth_hz,
            encoder_counts_rev=axis.encoder_counts_rev,
            torque_noise_nm=axis.current_noise_a * axis.torque_constant_nm_a,
        )

    def load_torque(self, resisting_force_n: np.ndarray) -> np.ndarray:
        """Motor-side load torque of an axis force resisting the motion (Aslan Eq. 3.11)."""
        return self.transmission / self.efficiency * np.asarray(resisting_force_n)

    def feed_drive_params(self) -> FeedDriveParams:
        """The same drive for the general kernel (:mod:`.feed_drive`): rigid plant whose load
        input is the motor-side load torque, Coulomb + viscous friction, no modes."""
        return FeedDriveParams(
            plant=rigid_plant(self.inertia, self.transmission, self.efficiency, load="torque"),
            torque_constant=self.torque_constant,
            transmission=self.transmission,
            efficiency=self.efficiency,
            friction=self.friction,
            kp=self.kp,
            ki=self.ki,
            kv=self.kv,
            current_bandwidth_hz=self.current_bandwidth_hz,
            encoder_counts_rev=self.encoder_counts_rev,
            torque_noise_nm=self.torque_noise_nm,
        )


class RigidDriveSim:
    """A resumable rigid-body drive: :meth:`advance` continues from where it stopped.

    Inputs per sample are motor-side: position reference (rad), velocity feed-forward (rad/s)
    and load torque (N·m). Results for one long call and many short calls are identical. It
    runs on the one drive kernel, :class:`~millsense.simulator.feed_drive.FeedDriveSim`.
    """

    def __init__(
        self,
        params: RigidDriveParams,
        sample_rate_hz: float,
        *,
        substeps: int = 10,
        seed: int = 0,
        initial_angle_rad: float = 0.0,
    ) -> None:
        self.params = params
        self.dt = 1.0 / sample_rate_hz
        self.substeps = substeps
        self._sim = FeedDriveSim(
            params.feed_drive_params(),
            sample_rate_hz,
            substeps=substeps,
            seed=seed,
            initial_angle_rad=initial_angle_rad,
        )

    def advance(
        self, pos_ref_rad: np.ndarray, vel_ff_rad_s: np.ndarray, load_torque_nm: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Simulate ``len(pos_ref_rad)`` samples.

        Returns
        -------
        dict with ``current_cmd`` (A), ``current`` (A, actual), ``speed`` (rad/s, measured from
        the encoder), ``angle`` (rad, encoder), ``true_speed`` (rad/s), ``true_angle`` (rad).
        """
        res = self._sim.advance(pos_ref_rad, vel_ff_rad_s, load_torque_nm)
        keys = ("current_cmd", "current", "speed", "angle", "true_speed", "true_angle")
        return {k: res[k] for k in keys}


def constant_velocity_move(
    params: RigidDriveParams,
    speed_rad_s: float,
    duration_s: float,
    sample_rate_hz: float,
    *,
    accel_time_s: float = 0.05,
    seed: int = 0,
    table_force_n: float = 0.0,
) -> dict[str, np.ndarray]:
    """Simulate a move at constant motor speed (commissioning test of Aslan C1).

    Ramps to ``speed_rad_s`` in ``accel_time_s`` then holds it; returns the channels of
    :meth:`RigidDriveSim.advance`. ``table_force_n`` is a constant known force on the table in
    the sign convention of a cutting force along the axis (the slot cut's; 0: an air move),
    e.g. a calibrated weight or spring balance for the force-gain calibration of the demo.
    """
    n = round(duration_s * sample_rate_hz)
    t = np.arange(n) / sample_rate_hz
    vel = np.where(t < accel_time_s, speed_rad_s * t / accel_time_s, speed_rad_s)
    pos = np.where(
        t < accel_time_s,
        0.5 * speed_rad_s * t**2 / accel_time_s,
        0.5 * speed_rad_s * accel_time_s + speed_rad_s * (t - accel_time_s),
    )
    sim = RigidDriveSim(params, sample_rate_hz, seed=seed)
    return sim.advance(pos, vel, params.load_torque(np.full(n, -table_force_n)))
