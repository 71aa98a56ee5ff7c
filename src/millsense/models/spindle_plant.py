"""The spindle drive's linear model (Aslan Ch. 5, App. E): parameters, plant matrices, the
closed velocity loop and its disturbance FRF G_dτ, loop bandwidths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import scipy.linalg

from millsense.core import units
from millsense.core.config import SpindleConfig
from millsense.core.errors import InputDataError
from millsense.models import spindle_modes as sm

# plant state layout
_TH, _OM, _I, _ID, _Q = 0, 1, 2, 3, 4
_N_BASE = 5


_F_GRID = np.logspace(-1, math.log10(5000.0), 4000)


@dataclass(frozen=True)
class SpindleRange:
    """One speed range of the spindle motor.

    Attributes
    ----------
    torque_constant : K_tS, N·m/A (Table 5.1).
    admittance : (a, b, c) of ``I/V = 1/(a s² + b s + c)``, s/Ω-ish SI (Eq. 5.7).
    modes : (k, 4) array ``[f_n Hz, ζ fraction, α, β]`` of the residual R (App. E).
    """

    torque_constant: float
    admittance: tuple[float, float, float]
    modes: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class SpindleDriveParams:
    """SI parameters of the spindle drive (Aslan Ch. 5).

    Attributes
    ----------
    inertia : J_eS, kg·m².
    viscous : B_eS, N·m·s/rad.
    coulomb : τ_coul,S, N·m.
    back_emf : K_b, V·s/rad.
    velocity_kp, velocity_ki : G_Ω = kp + ki/s as printed (A per unit of speed error).
    current_kp, current_ki : G_I = kp + ki/s, V/A and V/(A·s).
    ranges : (range 1, range 2).
    switch_rad_s : speed reference at which range 2 is used, rad/s (inf: range 1 only).
    velocity_period_s : velocity-loop sampling, s (0.2 ms, Aslan P7).
    velocity_error_unit : "rev/s" (default, decision 2) or "rad/s" (as printed).
    friction_smoothing_rad_s : sgn(Ω) is tanh(Ω/this), rad/s.
    speed_from_encoder_difference : the velocity loop acts on the motor encoder's angle
        difference over its period, ``(θ_k − θ_{k−1})/T_v`` (the mean speed over the last
        period: a lag of T_v/2), not on the speed at its instant (decision 1708); read by the
        sampled loop of :mod:`millsense.estimation.spindle_observer` and by
        :class:`~millsense.simulator.spindle.SpindleDriveSim`, not by the continuous closed
        loop's bandwidths here.
    """

    inertia: float
    viscous: float
    coulomb: float
    back_emf: float
    velocity_kp: float
    velocity_ki: float
    current_kp: float
    current_ki: float
    ranges: tuple[SpindleRange, SpindleRange]
    switch_rad_s: float
    velocity_period_s: float = 2e-4
    velocity_error_unit: Literal["rev/s", "rad/s"] = "rev/s"
    friction_smoothing_rad_s: float = 0.5
    speed_from_encoder_difference: bool = False

    @classmethod
    def aslan_quaser(cls) -> SpindleDriveParams:
        """The Quaser UX600 spindle as given by Aslan (Eq. 5.3, 5.7, Table 5.1, App. E)."""
        return cls(
            inertia=0.0316,
            viscous=0.009,
            coulomb=0.0,
            back_emf=0.12,
            velocity_kp=20.0,
            velocity_ki=600.0,
            current_kp=3.1,
            current_ki=1010.0,
            ranges=(
                SpindleRange(1.343, sm.ADMITTANCE_RANGE1, sm.MODES_RANGE1),
                SpindleRange(1.571, sm.ADMITTANCE_RANGE2, sm.MODES_RANGE2),
            ),
            switch_rad_s=3300.0 * units.RPM,
        )

    @classmethod
    def from_config(cls, cfg: SpindleConfig) -> SpindleDriveParams:
        """Quaser defaults overridden by the configured values.

        Inertia, K_tS, friction, switch and the speed's measurement always; back EMF, the
        velocity PI (per rev/s of speed error, decision 2), its period, the current PI and the
        Eq. 5.7 admittance per range when their keys are present (absent keys keep Aslan's
        Quaser values). The residual modes stay App. E's (``residual_modes`` is read by the
        estimator only).
        """
        base = cls.aslan_quaser()
        kt2 = cfg.torque_constant_range2_nm_a or cfg.torque_constant_nm_a
        r1, r2 = base.ranges

        def pick(value: float | None, default: float) -> float:
            return default if value is None else float(value)

        adm1 = (
            pick(cfg.motor_a_v_s2_a, r1.admittance[0]),
            pick(cfg.motor_b_v_s_a, r1.admittance[1]),
            pick(cfg.motor_c_ohm, r1.admittance[2]),
        )
        given2 = (cfg.motor_a_range2_v_s2_a, cfg.motor_b_range2_v_s_a, cfg.motor_c_range2_ohm)
        adm1_given = (cfg.motor_a_v_s2_a, cfg.motor_b_v_s_a, cfg.motor_c_ohm)
        # range 2 falls back to the configured range 1 if only range 1 is given
        fallback2 = adm1 if any(v is not None for v in adm1_given) else r2.admittance
        adm2 = (
            pick(given2[0], fallback2[0]),
            pick(given2[1], fallback2[1]),
            pick(given2[2], fallback2[2]),
        )
        ms = 1e-3
        return replace(
            base,
            inertia=cfg.inertia_kg_m2,
            viscous=cfg.viscous_nm_s_rad,
            coulomb=cfg.coulomb_nm,
            back_emf=pick(cfg.back_emf_v_s_rad, base.back_emf),
            velocity_kp=pick(cfg.velocity_kp_a_s_rev, base.velocity_kp),
            velocity_ki=pick(cfg.velocity_ki_a_rev, base.velocity_ki),
            current_kp=pick(cfg.current_kp_v_a, base.current_kp),
            current_ki=pick(cfg.current_ki_v_a_s, base.current_ki),
            velocity_period_s=(
                base.velocity_period_s
                if cfg.velocity_loop_period_ms is None
                else cfg.velocity_loop_period_ms * ms
            ),
            velocity_error_unit="rev/s",
            ranges=(
                replace(r1, torque_constant=cfg.torque_constant_nm_a, admittance=adm1),
                replace(r2, torque_constant=kt2, admittance=adm2),
            ),
            switch_rad_s=(cfg.range_switch_rpm * units.RPM if cfg.range_switch_rpm else math.inf),
            speed_from_encoder_difference=cfg.speed_from_encoder_difference,
        )

    @property
    def velocity_gains(self) -> tuple[float, float]:
        """(kp, ki) per rad/s of speed error, after the unit decision (A·s/rad, A/rad)."""
        k = 1.0 / (2.0 * math.pi) if self.velocity_error_unit == "rev/s" else 1.0
        return self.velocity_kp * k, self.velocity_ki * k

    def range_index(self, speed_ref_rad_s: float) -> int:
        """0 for range 1, 1 for range 2 (by |speed reference|)."""
        return 1 if abs(speed_ref_rad_s) >= self.switch_rad_s else 0


def plant_matrices(p: SpindleDriveParams, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous plant ``ẋ = A x + B u`` of range ``r`` (0/1) and the residual output row.

    Inputs ``u = [I_nom (A), e (rad/s, velocity error), τ_load (N·m)]``; states
    ``[θ, Ω, I_act, dI_act/dt, q_I, (ω_k x_k, ẋ_k)…]``. Returns (A, B, c_r) with
    ``Ω_meas = Ω + c_r·x``.
    """
    rng = p.ranges[r]
    a, b, c = rng.admittance
    modes = rng.modes
    n = _N_BASE + 2 * len(modes)
    A = np.zeros((n, n))
    B = np.zeros((n, 3))
    cr = np.zeros(n)
    A[_TH, _OM] = 1.0
    A[_OM, _OM] = -p.viscous / p.inertia
    A[_OM, _I] = rng.torque_constant / p.inertia
    B[_OM, 2] = -1.0 / p.inertia
    A[_I, _ID] = 1.0
    # a·Ï + b·İ + c·I = V,  V = kpI·(I_nom − I) + kiI·q − K_b·Ω
    A[_ID, _I] = (-c - p.current_kp) / a
    A[_ID, _ID] = -b / a
    A[_ID, _Q] = p.current_ki / a
    A[_ID, _OM] = -p.back_emf / a
    B[_ID, 0] = p.current_kp / a
    A[_Q, _I] = -1.0
    B[_Q, 0] = 1.0
    for k, (f_n, zeta, alpha, beta) in enumerate(modes):
        w = 2.0 * math.pi * f_n
        i1, i2 = _N_BASE + 2 * k, _N_BASE + 2 * k + 1
        A[i1, i2] = w
        A[i2, i1] = -w
        A[i2, i2] = -2.0 * zeta * w
        B[i2, 1] = 1.0
        cr[i1] = alpha / w
        cr[i2] = beta
    return A, B, cr


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation (A_d, B_d) of ẋ = A x + B u over a step h (one matrix
    exponential of the augmented [[A, B], [0, 0]]·h)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * h
    M[:n, n:] = B * h
    E = scipy.linalg.expm(M)
    return E[:n, :n].copy(), E[:n, n:].copy()


def _closed_loop(p: SpindleDriveParams, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous closed loop (velocity PI continuous): A, B (inputs Ω_ref, τ_d), C rows.

    C rows: I_nom, Ω_meas, I_act.
    """
    A, B, cr = plant_matrices(p, r)
    n = A.shape[0]
    kp, ki = p.velocity_gains
    meas = cr.copy()
    meas[_OM] += 1.0  # Ω_meas = Ω + c_r x
    # e = Ω_ref − meas·x;  I_nom = kp·e + z;  ż = ki·e
    Acl = np.zeros((n + 1, n + 1))
    Bcl = np.zeros((n + 1, 2))
    Acl[:n, :n] = A - np.outer(B[:, 0] * kp + B[:, 1], meas)
    Acl[:n, n] = B[:, 0]
    Bcl[:n, 0] = B[:, 0] * kp + B[:, 1]
    Bcl[:n, 1] = B[:, 2]
    Acl[n, :n] = -ki * meas
    Bcl[n, 0] = ki
    C = np.zeros((3, n + 1))
    D = np.zeros((3, 2))
    C[0, :n] = -kp * meas
    C[0, n] = 1.0
    D[0, 0] = kp
    C[1, :n] = meas
    C[2, _I] = 1.0
    return Acl, Bcl, np.hstack([C, D])


def state_space_frf(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, s: np.ndarray
) -> np.ndarray:
    """C (sI − A)⁻¹ B + D at each complex frequency of ``s``: (len(s), outputs, inputs)."""
    n = A.shape[0]
    out = np.empty((len(s), C.shape[0], B.shape[1]), dtype=complex)
    eye = np.eye(n)
    for k, sk in enumerate(s):
        out[k] = C @ np.linalg.solve(sk * eye - A, B) + D
    return out


def disturbance_frf(p: SpindleDriveParams, freq_hz: np.ndarray, range_index: int = 0) -> np.ndarray:
    """Analytic G_dτ = I_nom/τ_d (A/(N·m)) of the continuous model at ``freq_hz``.

    Notes
    -----
    Aslan Eq. 5.12 with decision 1 of the module: ``G_Ω·G_r/(1 + G_oΩ)``; computed from the
    closed-loop state space (velocity PI continuous, current loop PI + Eq. 5.7 admittance
    with back EMF).
    """
    Acl, Bcl, CD = _closed_loop(p, range_index)
    n = Acl.shape[0]
    s = 2j * math.pi * np.atleast_1d(np.asarray(freq_hz, dtype=float))
    return state_space_frf(Acl, Bcl[:, 1:2], CD[0:1, :n], CD[0:1, n + 1 : n + 2], s)[:, 0, 0]


def disturbance_frf_printed(
    p: SpindleDriveParams, freq_hz: np.ndarray, range_index: int = 0
) -> np.ndarray:
    """G_dτ with the printed closed current loop G_m of Eq. 5.8 (transfer-function form).

    ``G_Ω·G_r/(1 + G_Ω·G_m·K_t·G_r + R)`` with ``G_r = 1/(J s + B)`` (decision 1); no back EMF.
    """
    s = 2j * math.pi * np.atleast_1d(np.asarray(freq_hz, dtype=float))
    kp, ki = p.velocity_gains
    rng = p.ranges[range_index]
    g_v = kp + ki / s
    g_r = 1.0 / (p.inertia * s + p.viscous)
    g_m = sm.printed_current_loop_frf(range_index + 1, s)
    res = sm.modal_sum_frf(rng.modes, s)
    return np.asarray(g_v * g_r / (1.0 + g_v * g_m * rng.torque_constant * g_r + res))


def velocity_decimation(period_s: float, sample_rate_hz: float, where: str) -> int:
    """Samples per velocity-loop period (Aslan P7: 0.2 ms) at the CNC rate.

    Raises
    ------
    InputDataError
        The period is not a whole number (≥ 1) of samples; ``where`` names the drive.
    """
    nv = period_s * sample_rate_hz
    if nv < 0.999 or abs(nv - round(nv)) > 1e-9:
        raise InputDataError(
            f"{where}: velocity period {period_s} s is not a whole number of samples at "
            f"{sample_rate_hz:g} Hz"
        )
    return round(nv)


def first_crossing(f: np.ndarray, mag: np.ndarray, level: float) -> float:
    """The first frequency of ``f`` where ``mag`` falls below ``level`` (log-log
    interpolation between the bracketing points; NaN if it never does): a −3 dB bandwidth
    with ``level = mag[0]/√2``."""
    idx = np.nonzero(mag < level)[0]
    if len(idx) == 0:
        return math.nan
    k = int(idx[0])
    if k == 0:
        return float(f[0])
    # log-log interpolation between the bracketing points
    x0, x1 = math.log(f[k - 1]), math.log(f[k])
    y0, y1 = math.log(mag[k - 1]), math.log(mag[k])
    return float(math.exp(x0 + (math.log(level) - y0) * (x1 - x0) / (y1 - y0)))


def current_loop_bandwidth_hz(
    p: SpindleDriveParams, range_index: int = 0, printed: bool = False
) -> float:
    """−3 dB bandwidth of I_act/I_nom (speed held), Hz; ``printed`` uses Eq. 5.8 as printed."""
    s = 2j * math.pi * _F_GRID
    if printed:
        mag = np.abs(sm.printed_current_loop_frf(range_index + 1, s))
    else:
        a, b, c = p.ranges[range_index].admittance
        gi = p.current_kp + p.current_ki / s
        y = 1.0 / (a * s * s + b * s + c)
        mag = np.abs(gi * y / (1.0 + gi * y))
    return first_crossing(_F_GRID, mag, mag[0] / math.sqrt(2.0))


def velocity_loop_bandwidth_hz(p: SpindleDriveParams, range_index: int = 0) -> float:
    """−3 dB bandwidth of the closed velocity loop Ω_meas/Ω_ref (continuous model), Hz."""
    Acl, Bcl, CD = _closed_loop(p, range_index)
    n = Acl.shape[0]
    s = 2j * math.pi * _F_GRID
    h = state_space_frf(Acl, Bcl[:, 0:1], CD[1:2, :n], CD[1:2, n : n + 1], s)[:, 0, 0]
    mag = np.abs(h)
    return first_crossing(_F_GRID, mag, mag[0] / math.sqrt(2.0))


def closed_loop_poles(p: SpindleDriveParams, range_index: int = 0) -> np.ndarray:
    """Eigenvalues of the continuous closed loop without the spindle angle state, rad/s."""
    a = _closed_loop(p, range_index)[0]
    return np.linalg.eigvals(a[1:, 1:])
