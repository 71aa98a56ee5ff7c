"""Spindle drive under velocity PI / current PI control with structural modes (Aslan Ch. 5.2).

Blocks (Aslan Fig. 5.1, Eq. 5.1–5.13):

- velocity PI ``G_Ω = (20s + 600)/s`` sampled every 0.2 ms (Eq. 5.3), output I_nom;
- current PI ``G_I = (3.1s + 1010)/s`` acting on the voltage of the motor admittance
  ``I/V = 1/(a·s² + b·s + c)`` of Eq. 5.7 per speed range, with back EMF ``K_b·Ω``;
- rigid body ``J_eS·dΩ/dt = K_tS·I_act − B_eS·Ω − τ_coul·sgn Ω − τ_d`` (Eq. 5.1, 5.2), τ_d
  the cutting (disturbance) torque at the tool;
- structural residual ``R(s) = Σ (α_k + β_k·s)/(s² + 2ζ_k ω_k s + ω_k²)`` (Eq. 5.10, App. E),
  realised in modal blocks with scaled states ``[ω_k·x_k, ẋ_k]``.

Two speed ranges (wye-delta switch at 3300 rev/min) change K_tS, the admittance and the modes;
the range follows the speed reference.

Decisions (docs/decisions/0032-spindle-drive-reading-of-aslan-ch-5.md):

1. R is the residual between the measured and rigid-body *open velocity loop* FRFs (the text:
   "subtracted from the measured one … the remaining FRF is identified"), so
   ``G_oΩ = G_Ω·G_m·K_t/(J s + B) + R``. Read instead as an additive term of the mechanical
   G_sp, the printed modes make the closed velocity loop unstable (pole at Re s = +124 rad/s
   with G_Ω per rev/s, +1674 rad/s with G_Ω per rad/s), so that reading is impossible. R is
   realised in the speed-measurement path driven by the velocity error:
   ``Ω_meas = Ω + R·e``; hence ``G_dτ = I_nom/τ_d = G_Ω·G_r/(1 + G_oΩ)`` (Eq. 5.12 with this
   G_oΩ).
2. G_Ω acts on the speed error in rev/s (``velocity_error_unit="rev/s"``): the printed gains
   per rad/s give a 202 Hz rigid velocity loop against the stated 34–38 Hz; per rev/s, 27 Hz.
3. The current loop is G_I with the Eq. 5.7 admittance (−3 dB at 280/1584 Hz), the same as
   the printed Eq. 5.8 (282/1585 Hz); both miss the stated 360/385 and 1240/1190 Hz — the
   gap is reported by :func:`current_loop_bandwidth_hz` and the validation cases, not tuned.

The simulation is a ZOH-exact discretisation of the continuous plant at the CNC sample rate
(10 kHz) stepped by a numba kernel; the velocity PI runs every ``velocity_period_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numba
import numpy as np
import scipy.linalg

from millsense.core import units
from millsense.core.config import SpindleConfig
from millsense.core.errors import InputDataError
from millsense.machine import spindle_modes as sm

# plant state layout
_TH, _OM, _I, _ID, _Q = 0, 1, 2, 3, 4
_N_BASE = 5


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

        Inertia, K_tS, friction and switch always; back EMF, the velocity PI (per rev/s of
        speed error, decision 2), its period, the current PI and the Eq. 5.7 admittance per
        range when their keys are present (absent keys keep Aslan's Quaser values). The
        residual modes stay App. E's (``residual_modes`` is read by the estimator only).
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


def _zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
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


def _frf(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, s: np.ndarray) -> np.ndarray:
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
    return _frf(Acl, Bcl[:, 1:2], CD[0:1, :n], CD[0:1, n + 1 : n + 2], s)[:, 0, 0]


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


def _first_crossing(f: np.ndarray, mag: np.ndarray, level: float) -> float:
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


_F_GRID = np.logspace(-1, math.log10(5000.0), 4000)


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
    return _first_crossing(_F_GRID, mag, mag[0] / math.sqrt(2.0))


def velocity_loop_bandwidth_hz(p: SpindleDriveParams, range_index: int = 0) -> float:
    """−3 dB bandwidth of the closed velocity loop Ω_meas/Ω_ref (continuous model), Hz."""
    Acl, Bcl, CD = _closed_loop(p, range_index)
    n = Acl.shape[0]
    s = 2j * math.pi * _F_GRID
    h = _frf(Acl, Bcl[:, 0:1], CD[1:2, :n], CD[1:2, n : n + 1], s)[:, 0, 0]
    mag = np.abs(h)
    return _first_crossing(_F_GRID, mag, mag[0] / math.sqrt(2.0))


def closed_loop_poles(p: SpindleDriveParams, range_index: int = 0) -> np.ndarray:
    """Eigenvalues of the continuous closed loop without the spindle angle state, rad/s."""
    a = _closed_loop(p, range_index)[0]
    return np.linalg.eigvals(a[1:, 1:])


@numba.njit(cache=True)
def _spindle_kernel(
    x: np.ndarray,
    ctl: np.ndarray,
    speed_ref: np.ndarray,
    torque_dist: np.ndarray,
    ad: np.ndarray,
    bd: np.ndarray,
    cr: np.ndarray,
    prm: np.ndarray,
    out: np.ndarray,
) -> None:
    """ctl = [sample counter, integrator, I_nom held, e held, range]; prm described in caller."""
    kp, ki, tv, nv, w_sw, coul, w_s = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6]
    n = x.shape[0]
    xn = np.empty(n)
    for k in range(speed_ref.shape[0]):
        r = int(ctl[4])
        om_meas = x[1]
        for j in range(n):
            om_meas += cr[r, j] * x[j]
        if int(ctl[0]) % int(nv) == 0:
            r = 1 if abs(speed_ref[k]) >= w_sw else 0
            ctl[4] = r
            e = speed_ref[k] - om_meas
            ctl[1] += ki * e * tv
            ctl[2] = kp * e + ctl[1]
            ctl[3] = e
        ctl[0] += 1.0
        tau = torque_dist[k] + coul * math.tanh(x[1] / w_s)
        out[k, 0] = ctl[2]
        out[k, 1] = x[2]
        out[k, 2] = om_meas
        out[k, 3] = x[1]
        out[k, 4] = x[0]
        out[k, 5] = r
        for i in range(n):
            acc = bd[r, i, 0] * ctl[2] + bd[r, i, 1] * ctl[3] + bd[r, i, 2] * tau
            for j in range(n):
                acc += ad[r, i, j] * x[j]
            xn[i] = acc
        for i in range(n):
            x[i] = xn[i]


class SpindleDriveSim:
    """A resumable spindle drive: :meth:`advance` continues from where it stopped.

    Inputs per sample: speed reference (rad/s) and disturbance torque at the tool (N·m,
    opposing positive rotation: a cutting torque is positive while cutting forward). One long
    call and many short calls give identical results.
    """

    def __init__(self, params: SpindleDriveParams, sample_rate_hz: float = 10000.0) -> None:
        self.params = params
        self.dt = 1.0 / sample_rate_hz
        nv = params.velocity_period_s / self.dt
        if nv < 0.999 or abs(nv - round(nv)) > 1e-9:
            raise InputDataError(
                f"spindle: velocity period {params.velocity_period_s} s is not a whole number of "
                f"samples at {sample_rate_hz} Hz"
            )
        mats = [plant_matrices(params, r) for r in (0, 1)]
        sizes = {m[0].shape[0] for m in mats}
        if len(sizes) != 1:
            raise InputDataError("spindle: both speed ranges need the same number of modes")
        disc = [_zoh(A, B, self.dt) for A, B, _ in mats]
        self._ad = np.ascontiguousarray(np.stack([d[0] for d in disc]))
        self._bd = np.ascontiguousarray(np.stack([d[1] for d in disc]))
        self._cr = np.ascontiguousarray(np.stack([m[2] for m in mats]))
        kp, ki = params.velocity_gains
        self._prm = np.array(
            [
                kp,
                ki,
                params.velocity_period_s,
                float(round(nv)),
                params.switch_rad_s if math.isfinite(params.switch_rad_s) else 1e300,
                params.coulomb,
                params.friction_smoothing_rad_s,
            ]
        )
        self._x = np.zeros(sizes.pop())
        self._ctl = np.zeros(5)

    def advance(
        self, speed_ref_rad_s: np.ndarray, torque_dist_nm: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Simulate ``len(speed_ref_rad_s)`` samples.

        Returns
        -------
        dict with ``current_cmd`` (A, I_nom), ``current`` (A, I_act), ``speed`` (rad/s,
        measured Ω_meas incl. the structural residual), ``true_speed`` (rad/s, rigid body),
        ``angle`` (rad, rigid body), ``speed_range`` (0 or 1).
        """
        ref = np.ascontiguousarray(speed_ref_rad_s, dtype=np.float64)
        dist = np.ascontiguousarray(torque_dist_nm, dtype=np.float64)
        if ref.shape != dist.shape or ref.ndim != 1:
            raise InputDataError(
                f"spindle: speed reference {ref.shape} and torque {dist.shape} must be equal 1-D"
            )
        out = np.empty((len(ref), 6))
        _spindle_kernel(self._x, self._ctl, ref, dist, self._ad, self._bd, self._cr, self._prm, out)
        return {
            "current_cmd": out[:, 0],
            "current": out[:, 1],
            "speed": out[:, 2],
            "true_speed": out[:, 3],
            "angle": out[:, 4],
            "speed_range": out[:, 5].astype(np.int8),
        }


def discrete_disturbance_frf(
    sim: SpindleDriveSim, freq_hz: np.ndarray, range_index: int = 0
) -> np.ndarray:
    """Exact FRF I_nom/τ_d of the sampled loop when the velocity PI runs every sample.

    Independent of the kernel: built from the ZOH matrices and the controller algebra,
    ``H(z) = C (zI − A_cl)⁻¹ B_cl + D`` at ``z = e^{jωh}``.
    """
    if round(sim._prm[3]) != 1:
        raise InputDataError(
            "spindle: discrete FRF needs velocity_period_s equal to the sample time"
        )
    ad, bd, cr = sim._ad[range_index], sim._bd[range_index], sim._cr[range_index]
    n = ad.shape[0]
    kp, ki, tv = sim._prm[0], sim._prm[1], sim._prm[2]
    meas = cr.copy()
    meas[1] += 1.0
    g = kp + ki * tv  # I_nom = −g·meas·x + z_old ; e = −meas·x ; z_new = z_old − ki·tv·meas·x
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = ad - np.outer(bd[:, 0] * g + bd[:, 1], meas)
    A[:n, n] = bd[:, 0]
    A[n, :n] = -ki * tv * meas
    A[n, n] = 1.0
    B = np.zeros((n + 1, 1))
    B[:n, 0] = bd[:, 2]
    C = np.zeros((1, n + 1))
    C[0, :n] = -g * meas
    C[0, n] = 1.0
    z = np.exp(2j * math.pi * np.atleast_1d(np.asarray(freq_hz, dtype=float)) * sim.dt)
    return _frf(A, B, C, np.zeros((1, 1)), z)[:, 0, 0]


def measured_frf(
    params: SpindleDriveParams,
    freq_hz: float,
    *,
    sample_rate_hz: float = 10000.0,
    amplitude_nm: float = 1.0,
    settle_s: float = 0.6,
    fit_periods: int = 20,
) -> complex:
    """I_nom/τ_d of the simulated drive at one frequency from a steady sine disturbance.

    Runs :class:`SpindleDriveSim` at zero speed reference with ``τ_d = A·sin(ωt)``, discards
    ``settle_s`` and fits sin/cos by least squares over ``fit_periods`` whole periods (at
    least 0.05 s).
    """
    sim = SpindleDriveSim(params, sample_rate_hz)
    fit_s = max(fit_periods / freq_hz, 0.05)
    n_fit = round(round(fit_s * freq_hz) / freq_hz * sample_rate_hz)
    n = round(settle_s * sample_rate_hz) + n_fit
    t = np.arange(n) / sample_rate_hz
    w = 2.0 * math.pi * freq_hz
    out = sim.advance(np.zeros(n), amplitude_nm * np.sin(w * t))
    tt, y = t[-n_fit:], out["current_cmd"][-n_fit:]
    basis = np.column_stack([np.sin(w * tt), np.cos(w * tt), np.ones_like(tt)])
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    # y = Re(H·A·e^{jωt})·… : sin coefficient = A·Re H, cos coefficient = A·Im H
    return complex(coef[0], coef[1]) / amplitude_nm
