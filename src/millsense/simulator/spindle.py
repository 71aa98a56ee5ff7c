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
from collections.abc import Callable

import numba
import numpy as np

from millsense.core.errors import InputDataError
from millsense.models.spindle_plant import (
    SpindleDriveParams,
    plant_matrices,
    state_space_frf,
    velocity_decimation,
    zoh,
)


def spindle_inputs(
    speed_ref_rad_s: np.ndarray, torque_dist_nm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A spindle simulator's inputs as contiguous float arrays (speed reference, rad/s; torque
    at the tool, N·m), checked to be equal 1-D (one-line error otherwise)."""
    ref = np.ascontiguousarray(speed_ref_rad_s, dtype=np.float64)
    dist = np.ascontiguousarray(torque_dist_nm, dtype=np.float64)
    if ref.shape != dist.shape or ref.ndim != 1:
        raise InputDataError(
            f"spindle: speed reference {ref.shape} and torque {dist.shape} must be equal 1-D"
        )
    return ref, dist


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
    """ctl = [sample counter, integrator, I_nom held, e held, range, angle at the previous
    velocity sample]; prm described in caller (prm[7] = 1: the loop's speed is the angle's
    difference over its period)."""
    kp, ki, tv, nv, w_sw, coul, w_s = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6]
    diff = prm[7] != 0.0
    n = x.shape[0]
    xn = np.empty(n)
    for k in range(speed_ref.shape[0]):
        r = int(ctl[4])
        res = 0.0
        for j in range(n):
            res += cr[r, j] * x[j]
        om_meas = x[1] + res
        if int(ctl[0]) % int(nv) == 0:
            r = 1 if abs(speed_ref[k]) >= w_sw else 0
            ctl[4] = r
            om_loop = om_meas
            if diff:
                # the angle's difference over the period (none before the first period)
                om_loop = (x[0] - ctl[5]) / tv + res if ctl[0] > 0.0 else res
                ctl[5] = x[0]
            e = speed_ref[k] - om_loop
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
        nv = velocity_decimation(params.velocity_period_s, sample_rate_hz, "spindle")
        mats = [plant_matrices(params, r) for r in (0, 1)]
        sizes = {m[0].shape[0] for m in mats}
        if len(sizes) != 1:
            raise InputDataError("spindle: both speed ranges need the same number of modes")
        disc = [zoh(A, B, self.dt) for A, B, _ in mats]
        self._ad = np.ascontiguousarray(np.stack([d[0] for d in disc]))
        self._bd = np.ascontiguousarray(np.stack([d[1] for d in disc]))
        self._cr = np.ascontiguousarray(np.stack([m[2] for m in mats]))
        kp, ki = params.velocity_gains
        self._prm = np.array(
            [
                kp,
                ki,
                params.velocity_period_s,
                float(nv),
                params.switch_rad_s if math.isfinite(params.switch_rad_s) else 1e300,
                params.coulomb,
                params.friction_smoothing_rad_s,
                1.0 if params.speed_from_encoder_difference else 0.0,
            ]
        )
        self._x = np.zeros(sizes.pop())
        self._ctl = np.zeros(6)

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
        ref, dist = spindle_inputs(speed_ref_rad_s, torque_dist_nm)
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

    def advance_into(
        self, speed_ref_rad_s: np.ndarray, torque_dist_nm: np.ndarray, out: np.ndarray
    ) -> None:
        """:meth:`advance` into ``out`` ((n, 6) C-contiguous: current_cmd, current, speed,
        true_speed, angle, speed_range) without the checks (the simulator's block loop;
        both inputs C-contiguous float64 of length n)."""
        _spindle_kernel(
            self._x,
            self._ctl,
            speed_ref_rad_s,
            torque_dist_nm,
            self._ad,
            self._bd,
            self._cr,
            self._prm,
            out,
        )


def discrete_disturbance_frf(
    sim: SpindleDriveSim, freq_hz: np.ndarray, range_index: int = 0
) -> np.ndarray:
    """Exact FRF I_nom/τ_d of the sampled loop when the velocity PI runs every sample.

    Independent of the kernel: built from the ZOH matrices and the controller algebra,
    ``H(z) = C (zI − A_cl)⁻¹ B_cl + D`` at ``z = e^{jωh}``.
    """
    if round(sim._prm[3]) != 1 or sim._prm[7] != 0.0:
        raise InputDataError(
            "spindle: discrete FRF needs velocity_period_s equal to the sample time and the "
            "speed at the instant"
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
    return state_space_frf(A, B, C, np.zeros((1, 1)), z)[:, 0, 0]


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
    return steady_sine_point(
        lambda s: sim.advance(np.zeros(len(s)), s)["current_cmd"],
        freq_hz, sample_rate_hz, amplitude_nm, settle_s, fit_periods,
    )  # fmt: skip


def steady_sine_point(
    respond: Callable[[np.ndarray], np.ndarray],
    freq_hz: float,
    sample_rate_hz: float,
    amplitude: float,
    settle_s: float,
    fit_periods: int,
) -> complex:
    """One FRF point from a steady sine: ``respond`` maps the input ``A·sin(ωt)`` (a fresh
    simulator's whole run) to the output; ``settle_s`` is discarded and sin/cos/offset are fitted
    by least squares over ``fit_periods`` whole periods (at least 0.05 s)."""
    fit_s = max(fit_periods / freq_hz, 0.05)
    n_fit = round(round(fit_s * freq_hz) / freq_hz * sample_rate_hz)
    n = round(settle_s * sample_rate_hz) + n_fit
    t = np.arange(n) / sample_rate_hz
    w = 2.0 * math.pi * freq_hz
    y = respond(amplitude * np.sin(w * t))[-n_fit:]
    tt = t[-n_fit:]
    basis = np.column_stack([np.sin(w * tt), np.cos(w * tt), np.ones_like(tt)])
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    # y = Re(H·A·e^{jωt})·… : sin coefficient = A·Re H, cos coefficient = A·Im H
    return complex(coef[0], coef[1]) / amplitude
