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

The continuous plant is integrated with ``substeps`` semi-implicit Euler steps per sample.

This is the thin drive of the foundation demo; issue 5 adds LuGre dynamics, structural modes,
dual/triple-inertia ball screws and the interpolator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from millsense.core.config import FeedAxisConfig
from millsense.machine.friction import CoulombViscous, coulomb_viscous_torque


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
        Aslan gives no feed-drive servo gains. Decision (docs/decisions.md, "feed-drive servo
        gains"): crossover ω_c = 2π·f_v with ``K_p = J_e·ω_c``, integral corner at ω_c/4
        (``K_i = K_p·ω_c/4``), position gain ``K_v = ω_c/4`` — a conventional cascade tuning
        that keeps each outer loop about four times slower than the inner one.
        """
        wc = 2.0 * math.pi * axis.velocity_bandwidth_hz
        kp = axis.velocity_kp_nm_s_rad or axis.inertia_kg_m2 * wc
        ki = axis.velocity_ki_nm_rad if axis.velocity_ki_nm_rad is not None else kp * wc / 4.0
        return cls(
            inertia=axis.inertia_kg_m2,
            torque_constant=axis.torque_constant_nm_a,
            transmission=axis.transmission_m_rad,
            efficiency=axis.efficiency,
            friction=CoulombViscous.from_config(axis.friction),
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


# state vector layout of the kernel
_THETA, _OMEGA, _I_ACT, _INTEG, _ENC_PREV = 0, 1, 2, 3, 4


@numba.njit(cache=True)
def _drive_kernel(
    state: np.ndarray,
    pos_ref: np.ndarray,
    vel_ff: np.ndarray,
    load_torque: np.ndarray,
    dist_torque: np.ndarray,
    p: np.ndarray,
    fric: np.ndarray,
    dt: float,
    substeps: int,
    out: np.ndarray,
) -> None:
    """Advance the drive by len(pos_ref) samples; ``out`` columns described in the caller."""
    J, kt, kp, ki, kv, wcur, q = p[0], p[1], p[2], p[3], p[4], p[5], p[6]
    h = dt / substeps
    acur = 1.0 - math.exp(-wcur * h)
    for k in range(pos_ref.shape[0]):
        # sensors at the sample instant
        theta_enc = math.floor(state[_THETA] / q) * q
        omega_meas = (theta_enc - state[_ENC_PREV]) / dt
        state[_ENC_PREV] = theta_enc
        # position P + velocity feed-forward, velocity PI
        omega_ref = vel_ff[k] + kv * (pos_ref[k] - theta_enc)
        err = omega_ref - omega_meas
        state[_INTEG] += ki * err * dt
        i_cmd = (kp * err + state[_INTEG]) / kt
        # plant over one sample
        for _ in range(substeps):
            state[_I_ACT] += acur * (i_cmd - state[_I_ACT])
            tau_f = coulomb_viscous_torque(state[_OMEGA], fric)
            acc = (kt * state[_I_ACT] - tau_f - load_torque[k] - dist_torque[k]) / J
            state[_OMEGA] += h * acc
            state[_THETA] += h * state[_OMEGA]
        out[k, 0] = i_cmd
        out[k, 1] = state[_I_ACT]
        out[k, 2] = omega_meas
        out[k, 3] = theta_enc
        out[k, 4] = state[_OMEGA]
        out[k, 5] = state[_THETA]


class RigidDriveSim:
    """A resumable rigid-body drive: :meth:`advance` continues from where it stopped.

    Inputs per sample are motor-side: position reference (rad), velocity feed-forward (rad/s)
    and load torque (N·m). Results for one long call and many short calls are identical.
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
        self._rng = np.random.default_rng(seed)
        q = 2.0 * math.pi / params.encoder_counts_rev
        self._state = np.zeros(5)
        self._state[_THETA] = initial_angle_rad
        self._state[_ENC_PREV] = math.floor(initial_angle_rad / q) * q
        self._p = np.array(
            [
                params.inertia,
                params.torque_constant,
                params.kp,
                params.ki,
                params.kv,
                2.0 * math.pi * params.current_bandwidth_hz,
                q,
            ]
        )
        self._fric = params.friction.as_array()

    def advance(
        self, pos_ref_rad: np.ndarray, vel_ff_rad_s: np.ndarray, load_torque_nm: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Simulate ``len(pos_ref_rad)`` samples.

        Returns
        -------
        dict with ``current_cmd`` (A), ``current`` (A, actual), ``speed`` (rad/s, measured from
        the encoder), ``angle`` (rad, encoder), ``true_speed`` (rad/s), ``true_angle`` (rad).
        """
        n = len(pos_ref_rad)
        out = np.empty((n, 6))
        dist = self._rng.standard_normal(n) * self.params.torque_noise_nm
        _drive_kernel(
            self._state,
            np.ascontiguousarray(pos_ref_rad, dtype=np.float64),
            np.ascontiguousarray(vel_ff_rad_s, dtype=np.float64),
            np.ascontiguousarray(load_torque_nm, dtype=np.float64),
            dist,
            self._p,
            self._fric,
            self.dt,
            self.substeps,
            out,
        )
        return {
            "current_cmd": out[:, 0],
            "current": out[:, 1],
            "speed": out[:, 2],
            "angle": out[:, 3],
            "true_speed": out[:, 4],
            "true_angle": out[:, 5],
        }


def constant_velocity_move(
    params: RigidDriveParams,
    speed_rad_s: float,
    duration_s: float,
    sample_rate_hz: float,
    *,
    accel_time_s: float = 0.05,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Simulate an air move at constant motor speed (commissioning test of Aslan C1).

    Ramps to ``speed_rad_s`` in ``accel_time_s`` then holds it; returns the channels of
    :meth:`RigidDriveSim.advance` (no load).
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
    return sim.advance(pos, vel, np.zeros(n))
