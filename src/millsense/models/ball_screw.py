"""Dual- and triple-inertia ball-screw drives (Yamada 2017) and position-periodic disturbances.

Generalised coordinates: motor angle θ_m (rad) first, then the nut (triple only) and the
table positions (m). ``R = ℓ/2π`` maps rotation to travel.

Dual inertia (Yamada Eq. 2-1/2-2)::

    J_r·θ̈_m = τ − K_r(Rθ_m − x_t)R − C_k(Rω_m − v_t)R − D_r·ω_m
    M_t·ẍ_t = K_r(Rθ_m − x_t) + C_k(Rω_m − v_t) − C_t·v_t − F

Triple inertia (Yamada Eq. 2-45…2-47, written with the motor in rotation, ``C_r = D_r/R²``)::

    J_r·θ̈_m = τ + R·[K_ω(x_n − Rθ_m) + C_ω(v_n − Rω_m)] − D_r·ω_m
    M_n·ẍ_n = K_r(x_t − x_n) − K_ω(x_n − Rθ_m) + C_k(v_t − v_n) − C_ω(v_n − Rω_m) − C_n·v_n
    M_t·ẍ_t = −K_r(x_t − x_n) − C_k(v_t − v_n) − C_t·v_t − F

The screw error δ (lead error, Yamada §3.6) is a kinematic offset inside the screw–nut spring:
the dual model's spring stretches by ``Rθ_m + δ − x_t``, the triple model's motor–nut spring by
``x_n − Rθ_m − δ``. Only its stiffness force is applied (its rate term C·δ̇ is neglected: δ
varies over millimetres of travel, so δ̇ is small beside the relative velocities).

Decision (docs/decisions/0040-yamada-presets.md): Table 3-3 does not give K_t, the friction or
the amplitudes of the §3.6 disturbances; the presets choose them and say so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from millsense.core.config import BallScrewConfig, FeedAxisConfig, PeriodicDisturbanceConfig
from millsense.models.drive_plant import (
    KIND_MOTOR_ENCODER,
    KIND_SCALE,
    KIND_SCREW,
    KIND_TORQUE,
    OUT_A,
    OUT_ALPHA,
    OUT_OMEGA,
    OUT_THETA,
    OUT_V,
    OUT_X,
    MechanicalPlant,
    PeriodicTerm,
)


def _assemble(
    mass: np.ndarray,
    stiff: np.ndarray,
    damp: np.ndarray,
    force_in: np.ndarray,
    name: str,
    inertia: float,
) -> MechanicalPlant:
    """``M q̈ + C q̇ + K q = F_in u`` → first-order plant with states ``[q, q̇]``."""
    nq = mass.shape[0]
    minv = np.linalg.inv(mass)
    a = np.zeros((2 * nq, 2 * nq))
    a[:nq, nq:] = np.eye(nq)
    a[nq:, :nq] = -minv @ stiff
    a[nq:, nq:] = -minv @ damp
    b = np.zeros((2 * nq, 3))
    b[nq:, :] = minv @ force_in
    c = np.zeros((6, 2 * nq))
    d = np.zeros((6, 3))
    c[OUT_THETA, 0] = 1.0
    c[OUT_OMEGA, nq] = 1.0
    c[OUT_ALPHA] = a[nq]
    d[OUT_ALPHA] = b[nq]
    c[OUT_X, nq - 1] = 1.0
    c[OUT_V, 2 * nq - 1] = 1.0
    c[OUT_A] = a[2 * nq - 1]
    d[OUT_A] = b[2 * nq - 1]
    return MechanicalPlant(a, b, c, d, inertia, name)


def dual_inertia_plant(
    screw_inertia_kg_m2: float,
    lead_m: float,
    table_mass_kg: float,
    axial_stiffness_n_m: float,
    axial_damping_n_s_m: float = 0.0,
    table_damping_n_s_m: float = 0.0,
    rotary_damping_nm_s_rad: float = 0.0,
) -> MechanicalPlant:
    """Yamada's dual-inertia plant (Eq. 2-1/2-2), states ``[θ_m, x_t, ω_m, v_t]``.

    Parameters
    ----------
    screw_inertia_kg_m2 : J_r, motor + coupling + screw, kg·m².
    lead_m : ball-screw lead ℓ, m (R = ℓ/2π).
    table_mass_kg : M_t, kg.
    axial_stiffness_n_m : K_r, N/m.
    axial_damping_n_s_m : C_k, N·s/m.
    table_damping_n_s_m : C_t, N·s/m.
    rotary_damping_nm_s_rad : D_r, N·m·s/rad.

    Notes
    -----
    Resonance ``ω_s = √((α + 1)K_r/M_t)`` with ``α = M_t R²/J_r`` (Yamada Eq. 2-5/2-6; the
    thesis' Appendix A prints α = M_t/(J_r R²), a typo).
    """
    r = lead_m / (2.0 * math.pi)
    g = np.array([r, -1.0])  # spring stretch Rθ − x_t
    mass = np.diag([screw_inertia_kg_m2, table_mass_kg])
    stiff = axial_stiffness_n_m * np.outer(g, g)
    damp = axial_damping_n_s_m * np.outer(g, g) + np.diag(
        [rotary_damping_nm_s_rad, table_damping_n_s_m]
    )
    force_in = np.zeros((2, 3))
    force_in[0, 0] = 1.0  # motor torque
    force_in[1, 1] = -1.0  # load resists
    force_in[:, 2] = -axial_stiffness_n_m * g  # stretch Rθ + δ − x_t
    inertia = screw_inertia_kg_m2 + table_mass_kg * r * r
    return _assemble(mass, stiff, damp, force_in, "dual-inertia ball screw", inertia)


def triple_inertia_plant(
    screw_inertia_kg_m2: float,
    lead_m: float,
    nut_mass_kg: float,
    table_mass_kg: float,
    screw_stiffness_n_m: float,
    axial_stiffness_n_m: float,
    screw_damping_n_s_m: float = 0.0,
    axial_damping_n_s_m: float = 0.0,
    nut_damping_n_s_m: float = 0.0,
    table_damping_n_s_m: float = 0.0,
    rotary_damping_nm_s_rad: float = 0.0,
) -> MechanicalPlant:
    """Yamada's triple-inertia plant (Eq. 2-45…2-47), states ``[θ_m, x_n, x_t, ω_m, v_n, v_t]``.

    Parameters
    ----------
    screw_inertia_kg_m2 : J_r, kg·m² (M_r = J_r/R²).
    lead_m : ℓ, m.
    nut_mass_kg : M_n, kg.
    table_mass_kg : M_t, kg.
    screw_stiffness_n_m : K_ω (motor–nut), N/m.
    axial_stiffness_n_m : K_r (nut–table), N/m.
    screw_damping_n_s_m, axial_damping_n_s_m : C_ω, C_k, N·s/m.
    nut_damping_n_s_m, table_damping_n_s_m : C_n, C_t, N·s/m.
    rotary_damping_nm_s_rad : D_r, N·m·s/rad.
    """
    r = lead_m / (2.0 * math.pi)
    g1 = np.array([-r, 1.0, 0.0])  # x_n − Rθ
    g2 = np.array([0.0, -1.0, 1.0])  # x_t − x_n
    mass = np.diag([screw_inertia_kg_m2, nut_mass_kg, table_mass_kg])
    stiff = screw_stiffness_n_m * np.outer(g1, g1) + axial_stiffness_n_m * np.outer(g2, g2)
    damp = (
        screw_damping_n_s_m * np.outer(g1, g1)
        + axial_damping_n_s_m * np.outer(g2, g2)
        + np.diag([rotary_damping_nm_s_rad, nut_damping_n_s_m, table_damping_n_s_m])
    )
    force_in = np.zeros((3, 3))
    force_in[0, 0] = 1.0
    force_in[2, 1] = -1.0
    force_in[:, 2] = screw_stiffness_n_m * g1  # stretch x_n − Rθ − δ
    inertia = screw_inertia_kg_m2 + (nut_mass_kg + table_mass_kg) * r * r
    return _assemble(mass, stiff, damp, force_in, "triple-inertia ball screw", inertia)


def plant_from_config(axis: FeedAxisConfig) -> MechanicalPlant:
    """The ball-screw plant of a machine axis (``axis.ball_screw`` must be set)."""
    bs: BallScrewConfig | None = axis.ball_screw
    if bs is None:
        raise ValueError("axis has no ball_screw table")
    if axis.lead_mm_rev is None:
        raise ValueError("a ball-screw axis needs lead_mm_rev")
    lead = axis.lead_mm_rev * 1e-3
    if bs.model == "dual":
        return dual_inertia_plant(
            axis.inertia_kg_m2,
            lead,
            bs.table_mass_kg,
            bs.axial_stiffness_n_um * 1e6,
            bs.axial_damping_n_s_m,
            bs.table_damping_n_s_m,
            bs.rotary_damping_nm_s_rad,
        )
    assert bs.nut_mass_kg is not None and bs.screw_stiffness_n_um is not None
    return triple_inertia_plant(
        axis.inertia_kg_m2,
        lead,
        bs.nut_mass_kg,
        bs.table_mass_kg,
        bs.screw_stiffness_n_um * 1e6,
        bs.axial_stiffness_n_um * 1e6,
        bs.screw_damping_n_s_m,
        bs.axial_damping_n_s_m,
        bs.nut_damping_n_s_m,
        bs.table_damping_n_s_m,
        bs.rotary_damping_nm_s_rad,
    )


def periodic_terms(
    cfgs: Sequence[PeriodicDisturbanceConfig], transmission_m_rad: float
) -> tuple[PeriodicTerm, ...]:
    """Convert machine-file disturbances to SI kernel terms (Yamada §3.6).

    ``thrust`` N → motor torque ``F·R``; ``screw_error`` µm → m; ``motor_encoder`` µm of
    travel → motor rad ``/R``; ``scale`` µm → m as a function of table position. Periods in
    ``wavelength_mm`` of travel become ``2πR/λ`` per motor radian (``2π/λ`` per metre for the
    scale); ``per_motor_rev`` n becomes n per motor radian (``n/R`` per metre).
    """
    r = transmission_m_rad
    terms = []
    for c in cfgs:
        if c.wavelength_mm is not None:
            lam = c.wavelength_mm * 1e-3
            k_rad, k_m = 2.0 * math.pi * r / lam, 2.0 * math.pi / lam
        else:
            assert c.per_motor_rev is not None
            k_rad, k_m = c.per_motor_rev, c.per_motor_rev / r
        if c.kind == "thrust":
            assert c.amplitude_n is not None
            terms.append(PeriodicTerm(KIND_TORQUE, k_rad, c.amplitude_n * r, c.phase_rad))
        else:
            assert c.amplitude_um is not None
            amp = c.amplitude_um * 1e-6
            if c.kind == "screw_error":
                terms.append(PeriodicTerm(KIND_SCREW, k_rad, amp, c.phase_rad))
            elif c.kind == "motor_encoder":
                terms.append(PeriodicTerm(KIND_MOTOR_ENCODER, k_rad, amp / r, c.phase_rad))
            else:
                terms.append(PeriodicTerm(KIND_SCALE, k_m, amp, c.phase_rad))
    return tuple(terms)


def resonance_hz(plant: MechanicalPlant) -> np.ndarray:
    """Undamped natural frequencies of the plant's elastic modes, Hz (ascending)."""
    nq = plant.a.shape[0] // 2
    k_over_m = -plant.a[nq:, :nq]
    w2 = np.sort(np.real(np.linalg.eigvals(k_over_m)))
    return np.sqrt(np.clip(w2[w2 > 1e-6 * max(w2.max(), 1.0)], 0.0, None)) / (2.0 * math.pi)
