"""Coupled lumped-mass feed drives: the virtual machine's own truth (issue 12).

The estimators model a feed drive as Aslan's rigid body (Eq. 3.1) with the table load reaching
the motor through a disturbance FRF Φ_d (Eq. 3.13, Table 3.4). This module builds the drive the
virtual machine actually runs as mechanics — masses, springs and dampers — so that the modes,
their coupling back into the motor and their dependence on the nut position arise from the
structure and the estimators can only learn them by identification.

Generalised coordinates ``q`` (linear axis; rotary axis in brackets)::

    q = [θ_m, θ_s, x_t, x_b, y_1 … y_m]

- θ_m motor rotor (J_m), joined by the coupling (+ screw torsion) k_c to
- θ_s screw [worm] (J_s);
- x_t table with nut [trunnion/table, rad] (M_t), driven through the screw–nut [worm–wheel]
  spring k(x) on the stretch ``e = r_g·θ_s + δ + x_b − x_t``;
- x_b column/base that carries the screw's thrust bearing (M_b on k_b to the ground);
- y_j structural substructures on the table (saddle, fixture, workpiece: m_j on k_j).

Efficiency: the screw's reaction on the motor side is ``(r_g/η)·k·e`` while the nut pushes the
table with ``k·e``, so a static table load F reaches the motor as ``(r_g/η)·F`` — Aslan
Eq. 3.11 by physics, Φ_d(0) = 1 (decision 0971). This makes K non-symmetric: the element
dissipates ``(1/η − 1)·F·v`` when the motor drives the load (and is not passive when the load
back-drives the motor; a linear model of a direction-dependent loss).

Screw axial stiffness with the nut at distance ℓ from the fixed bearing (decision 0972)::

    fixed–fixed: k_s(ℓ) = E·A·L/(ℓ·(L − ℓ)),   fixed–free: k_s(ℓ) = E·A/ℓ,
    1/k(x) = 1/k_s(ℓ(x)) + 1/k_nut + 1/k_bearing,   ℓ(x) = ℓ_0 + x.

Damping: modal damping of the motor-locked structure, ``C_l = M_l·Φ·diag(2ζω)·Φᵀ·M_l``
(Φ mass-normalised modes of the symmetric locked structure), acting on the displacements
relative to the rigid-body motion: ``C = Tᵀ·C_l·T`` with ``T = [−u | I]`` and u the rigid
motion of the non-motor coordinates per radian of motor. C is symmetric, positive
semi-definite and annihilates the rigid-body mode (no viscous drag of the rigid body from the
structure; friction does that).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import scipy.linalg

from millsense.core.errors import ConfigError
from millsense.models.drive_plant import OUT_THETA, MechanicalPlant
from millsense.simulator.feed_drive import OUT_A, OUT_ALPHA, OUT_OMEGA, OUT_V, OUT_X

# coordinate indices
Q_MOTOR, Q_SCREW, Q_TABLE, Q_BASE = 0, 1, 2, 3
N_CHAIN = 4


@dataclass(frozen=True)
class ScrewGeometry:
    """Axial compliance of a ball screw as a function of the nut position.

    Attributes
    ----------
    ea_n : E·A of the screw shaft (root diameter), N.
    span_m : bearing span L, m (the screw length for ``fixed-free``).
    offset_m : nut distance ℓ_0 from the fixed bearing at table position 0, m.
    support : ``fixed-fixed`` (thrust bearings at both ends) or ``fixed-free``.
    nut_stiffness_n_m, bearing_stiffness_n_m : in series with the shaft, N/m.
    """

    ea_n: float
    span_m: float
    offset_m: float
    support: Literal["fixed-fixed", "fixed-free"]
    nut_stiffness_n_m: float
    bearing_stiffness_n_m: float

    def nut_distance(self, position_m: float | np.ndarray) -> np.ndarray:
        """ℓ(x) = ℓ_0 + x, kept inside 2 %…98 % of the span (beyond the stroke)."""
        ell = self.offset_m + np.asarray(position_m, dtype=float)
        return np.clip(ell, 0.02 * self.span_m, 0.98 * self.span_m)

    def shaft_stiffness(self, position_m: float | np.ndarray) -> np.ndarray:
        """k_s(ℓ) of the shaft alone, N/m (closed form, module docstring)."""
        ell = self.nut_distance(position_m)
        if self.support == "fixed-fixed":
            return self.ea_n * self.span_m / (ell * (self.span_m - ell))
        return self.ea_n / ell

    def stiffness(self, position_m: float | np.ndarray) -> np.ndarray:
        """k(x): shaft, nut and bearing in series, N/m."""
        ks = self.shaft_stiffness(position_m)
        return 1.0 / (1.0 / ks + 1.0 / self.nut_stiffness_n_m + 1.0 / self.bearing_stiffness_n_m)


@dataclass(frozen=True)
class CoupledDrive:
    """A feed drive as coupled lumped masses (module docstring).

    Masses are kg for translations and kg·m² for rotations; stiffnesses N/m or N·m/rad on the
    coordinate they act on (the load side of a rotary axis is in rad).

    Attributes
    ----------
    kind : ``linear`` or ``rotary``.
    transmission : r_g, m/rad (rad/rad rotary).
    efficiency : η.
    motor_inertia : J_m.
    screw_inertia : J_s, screw [worm] with coupling hub, kg·m².
    coupling_stiffness : k_c, motor–screw torsion, N·m/rad.
    table_mass : M_t (nut and table; trunnion/table inertia rotary).
    base_mass, base_stiffness : M_b and k_b of the column/base carrying the thrust bearing.
    attached_mass, attached_stiffness : m_j, k_j of the substructures on the table.
    damping_ratio : ζ of the motor-locked modes in ascending frequency; modes beyond the list
        get ``default_damping``.
    screw : the screw's axial compliance (linear axes); None uses ``drive_stiffness``.
    drive_stiffness : the worm–wheel mesh stiffness at the table (rotary), or a fixed screw
        stiffness, N·m/rad or N/m.
    reference_position : load position at which the damping matrix is designed, m (rad).
    """

    kind: Literal["linear", "rotary"]
    transmission: float
    efficiency: float
    motor_inertia: float
    screw_inertia: float
    coupling_stiffness: float
    table_mass: float
    base_mass: float
    base_stiffness: float
    attached_mass: tuple[float, ...]
    attached_stiffness: tuple[float, ...]
    damping_ratio: tuple[float, ...]
    screw: ScrewGeometry | None = None
    drive_stiffness: float | None = None
    reference_position: float = 0.0
    default_damping: float = 0.05
    name: str = "coupled drive"
    _damping: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.attached_mass) != len(self.attached_stiffness):
            raise ConfigError(f"{self.name}: attached_mass and attached_stiffness differ in length")
        if (self.screw is None) == (self.drive_stiffness is None):
            raise ConfigError(f"{self.name}: give exactly one of screw or drive_stiffness")
        positive = (
            self.transmission,
            self.motor_inertia,
            self.screw_inertia,
            self.coupling_stiffness,
            self.table_mass,
            self.base_mass,
            self.base_stiffness,
            *self.attached_mass,
            *self.attached_stiffness,
        )
        if not all(v > 0 for v in positive):
            raise ConfigError(f"{self.name}: masses, stiffnesses and r_g must be > 0")
        if not 0.0 < self.efficiency <= 1.0:
            raise ConfigError(f"{self.name}: efficiency must be in (0, 1], got {self.efficiency}")

    # ------------------------------------------------------------------ structure
    @property
    def n_dof(self) -> int:
        return N_CHAIN + len(self.attached_mass)

    @property
    def inertia(self) -> float:
        """Total inertia reflected to the motor, J_m + J_s + (M_t + Σm_j)·r_g² (base excluded:
        it does not move with the axis), kg·m²."""
        r = self.transmission
        return (
            self.motor_inertia
            + self.screw_inertia
            + (self.table_mass + sum(self.attached_mass)) * r * r
        )

    def rigid_motion(self) -> np.ndarray:
        """Coordinates of a rigid motion of 1 rad of the motor (no spring stretched)."""
        u = np.zeros(self.n_dof)
        u[Q_MOTOR] = u[Q_SCREW] = 1.0
        u[Q_TABLE] = self.transmission
        u[N_CHAIN:] = self.transmission
        return u

    def transmission_stiffness(self, position: float) -> float:
        """k(x): screw–nut (linear) or mesh (rotary) stiffness at load position x."""
        if self.screw is not None:
            return float(self.screw.stiffness(position))
        assert self.drive_stiffness is not None
        return float(self.drive_stiffness)

    def mass_matrix(self) -> np.ndarray:
        return np.diag(
            [
                self.motor_inertia,
                self.screw_inertia,
                self.table_mass,
                self.base_mass,
                *self.attached_mass,
            ]
        )

    def stiffness_matrix(self, position: float, efficiency: float | None = None) -> np.ndarray:
        """K at load position x (non-symmetric for η < 1: module docstring)."""
        eta = self.efficiency if efficiency is None else efficiency
        n = self.n_dof
        k = np.zeros((n, n))
        g_c = np.zeros(n)
        g_c[Q_MOTOR], g_c[Q_SCREW] = 1.0, -1.0
        k += self.coupling_stiffness * np.outer(g_c, g_c)
        ks = self.transmission_stiffness(position)
        g = self._stretch()
        reaction = g.copy()
        reaction[Q_SCREW] /= eta
        k += ks * np.outer(reaction, g)
        k[Q_BASE, Q_BASE] += self.base_stiffness
        for j, kj in enumerate(self.attached_stiffness):
            gj = np.zeros(n)
            gj[N_CHAIN + j], gj[Q_TABLE] = 1.0, -1.0
            k += kj * np.outer(gj, gj)
        return k

    def stretch(self) -> np.ndarray:
        """∂e/∂q of the screw–nut (worm–wheel) stretch e = r_g·θ_s + x_b − x_t."""
        return self._stretch()

    def _stretch(self) -> np.ndarray:
        """∂e/∂q of the screw–nut stretch e = r_g·θ_s + x_b − x_t."""
        g = np.zeros(self.n_dof)
        g[Q_SCREW] = self.transmission
        g[Q_TABLE] = -1.0
        g[Q_BASE] = 1.0
        return g

    def locked_modes(
        self, position: float | None = None, efficiency: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Undamped modes with the motor held: (ω rad/s ascending, mass-normalised shapes of
        the non-motor coordinates as columns)."""
        x = self.reference_position if position is None else position
        m = self.mass_matrix()[1:, 1:]
        k = self.stiffness_matrix(x, efficiency)[1:, 1:]
        if efficiency is not None and efficiency == 1.0:
            w2, phi = scipy.linalg.eigh(k, m)
        else:
            w2c, phic = scipy.linalg.eig(k, m)
            order = np.argsort(w2c.real)
            w2, phi = w2c.real[order], phic.real[:, order]
            phi = phi / np.sqrt(np.einsum("ij,ij->j", phi, m @ phi))
        return np.sqrt(np.clip(w2, 0.0, None)), phi

    def locked_frequencies_hz(self, position: float | None = None) -> np.ndarray:
        """Natural frequencies of the motor-locked structure, Hz (the modes Table 3.4 is
        compared with; decision 0973)."""
        return self.locked_modes(position)[0] / (2.0 * math.pi)

    def damping_matrix(self) -> np.ndarray:
        """C = Tᵀ·C_l·T (module docstring), designed at ``reference_position``."""
        if self._damping is not None:
            return self._damping
        w, phi = self.locked_modes(self.reference_position, efficiency=1.0)
        zeta = np.full(len(w), self.default_damping)
        nz = min(len(self.damping_ratio), len(w))
        zeta[:nz] = self.damping_ratio[:nz]
        ml = self.mass_matrix()[1:, 1:]
        cl = ml @ phi @ np.diag(2.0 * zeta * w) @ phi.T @ ml
        t = np.zeros((self.n_dof - 1, self.n_dof))
        t[:, 0] = -self.rigid_motion()[1:]
        t[:, 1:] = np.eye(self.n_dof - 1)
        c = t.T @ cl @ t
        c = 0.5 * (c + c.T)
        object.__setattr__(self, "_damping", c)
        return c

    def input_matrix(self, position: float) -> np.ndarray:
        """Generalised forces per input ``[τ_m, F (resisting, on the table), δ]``."""
        f = np.zeros((self.n_dof, 3))
        f[Q_MOTOR, 0] = 1.0
        f[Q_TABLE, 1] = -1.0
        ks = self.transmission_stiffness(position)
        reaction = self._stretch()
        reaction[Q_SCREW] /= self.efficiency
        f[:, 2] = -ks * reaction  # e = r_g·θ_s + δ + x_b − x_t
        return f

    def plant(self, position: float | None = None) -> MechanicalPlant:
        """The linear mechanics at load position x as the feed-drive kernel's plant, states
        ``[q, q̇]``; the load position output is the table x_t."""
        x = self.reference_position if position is None else position
        mass = self.mass_matrix()
        minv = np.diag(1.0 / np.diag(mass))
        nq = self.n_dof
        a = np.zeros((2 * nq, 2 * nq))
        a[:nq, nq:] = np.eye(nq)
        a[nq:, :nq] = -minv @ self.stiffness_matrix(x)
        a[nq:, nq:] = -minv @ self.damping_matrix()
        b = np.zeros((2 * nq, 3))
        b[nq:, :] = minv @ self.input_matrix(x)
        c = np.zeros((6, 2 * nq))
        d = np.zeros((6, 3))
        c[OUT_THETA, Q_MOTOR] = 1.0
        c[OUT_OMEGA, nq + Q_MOTOR] = 1.0
        c[OUT_ALPHA] = a[nq + Q_MOTOR]
        d[OUT_ALPHA] = b[nq + Q_MOTOR]
        c[OUT_X, Q_TABLE] = 1.0
        c[OUT_V, nq + Q_TABLE] = 1.0
        c[OUT_A] = a[nq + Q_TABLE]
        d[OUT_A] = b[nq + Q_TABLE]
        return MechanicalPlant(a, b, c, d, self.inertia, self.name)

    def unstressed_state(self, motor_angle_rad: float) -> np.ndarray:
        """Plant state at rest with the motor at the given angle and no spring stretched."""
        x = np.zeros(2 * self.n_dof)
        x[: self.n_dof] = self.rigid_motion() * motor_angle_rad
        return x

    def with_parameters(self, **changes: object) -> CoupledDrive:
        """A copy with some attributes changed (the damping matrix is rebuilt)."""
        return replace(self, _damping=None, **changes)  # type: ignore[arg-type]


# ---------------------------------------------------------------------- frequency responses
def _resolvent_rows(
    plant: MechanicalPlant, s: np.ndarray, inputs: Sequence[int], output: int
) -> np.ndarray:
    """``c_out·(sI − A)⁻¹·b_in`` for each input column, (len(s), len(inputs))."""
    n = plant.a.shape[0]
    res = np.empty((len(s), len(inputs)), dtype=complex)
    eye = np.eye(n)
    bcols = plant.b[:, list(inputs)]
    for j, sj in enumerate(s):
        x = np.linalg.solve(sj * eye - plant.a, bcols)
        res[j] = plant.c[output] @ x + plant.d[output, list(inputs)]
    return res


@dataclass(frozen=True)
class ServoLoop:
    """The linear part of the cascade controller for frequency responses.

    ``τ_m = −L(s)·ω_m`` with ``L = H_i(s)·e^{−sT}·(K_p + K_i/s)·(1 + K_v/s)``: position P,
    velocity PI, a first-order current loop of ``current_bandwidth_hz`` and the dead time T.
    """

    kp: float
    ki: float
    kv: float
    current_bandwidth_hz: float
    dead_time_s: float = 0.0

    def gain(self, s: np.ndarray) -> np.ndarray:
        wc = 2.0 * math.pi * self.current_bandwidth_hz
        return (
            wc
            / (s + wc)
            * np.exp(-s * self.dead_time_s)
            * (self.kp + self.ki / s)
            * (1.0 + self.kv / s)
        )


def disturbance_frf(
    drive: CoupledDrive,
    frequency_hz: np.ndarray,
    servo: ServoLoop | None,
    position: float | None = None,
    rigid_inertia: float | None = None,
) -> np.ndarray:
    """Φ_d(jω) = τ_c/τ_a of the coupled drive in the units of Aslan Table 3.4 / Eq. 3.13.

    ``τ_a = (r_g/η)·F`` (Eq. 3.11) and τ_c the disturbance torque a rigid-body model sees
    (Eq. 3.10 without friction): ``τ_c = K_t·i − J_e·dω_m/dt``, J_e the total reflected
    inertia. With the servo (Aslan measured at rest under the CNC's control)
    ``Φ_d = −(L + J_e·s)·G_F/((1 + G_τ·L)·r_g/η)``; without it (``servo=None``) the motor is
    held (locked rotor): Φ_d is the coupling torque on the motor over τ_a. Both are 1 at
    s → 0 by the statics of the chain.
    """
    f = np.asarray(frequency_hz, dtype=float)
    s = 2j * math.pi * f
    lg = drive.transmission / drive.efficiency
    if servo is None:
        return _locked_torque(drive, s, position) / lg
    plant = drive.plant(position)
    g = _resolvent_rows(plant, s, (0, 1), OUT_OMEGA)
    g_tau, g_f = g[:, 0], g[:, 1]
    je = drive.inertia if rigid_inertia is None else rigid_inertia
    loop = servo.gain(s)
    return -(loop + je * s) * g_f / ((1.0 + g_tau * loop) * lg)


def _locked_torque(drive: CoupledDrive, s: np.ndarray, position: float | None) -> np.ndarray:
    """Coupling torque on a held motor per unit table load (N·m/N), the locked-rotor FRF."""
    x = drive.reference_position if position is None else position
    m = drive.mass_matrix()[1:, 1:]
    k = drive.stiffness_matrix(x)[1:, 1:]
    c = drive.damping_matrix()[1:, 1:]
    f = drive.input_matrix(x)[1:, 1]
    out = np.empty(len(s), dtype=complex)
    kc = drive.coupling_stiffness
    cm = drive.damping_matrix()[0, 1:]
    for j, sj in enumerate(s):
        q = np.linalg.solve(sj * sj * m + sj * c + k, f)
        # τ_c is minus the torque the drivetrain puts on the motor (Eq. 3.1 sign): the
        # coupling k_c·(θ_m − θ_s) with θ_m = 0, plus the motor row of the damping C·q̇
        out[j] = -kc * q[0] + sj * (cm @ q)
    return out
