"""The spindle drive the virtual machine runs: a torsional structure, not Aslan's Ch. 5 model.

The spindle torque observer (:mod:`millsense.estimation.spindle_observer`) models the drive as
Aslan's rigid body (Eq. 5.1, 5.2) under the velocity PI and current PI of Eq. 5.3 with the
Eq. 5.7 admittance, the structure entering as a fitted residual R(s) of the open velocity loop
(Eq. 5.10, App. E; decision 0032). This module is the truth it is identified on, built from
mechanics and electrics so that the residual arises from the structure (decision 1210):

- a torsional chain of ``n`` inertias ``θ = [θ_0 (motor rotor), θ_1 …, θ_{n−1} (holder+tool)]``
  on ``n − 1`` springs (rotor–shaft fit, shaft, HSK interface): ``M θ̈ + C θ̇ + K θ = τ``.
  Damping is modal on the free–free structure, ``C = M Φ diag(2ζ_k ω_k) Φᵀ M`` over the
  elastic modes (Φ mass-normalised), so C annihilates the rigid-body mode;
- the motor (Eq. 5.1 by physics): ``τ_m = K_t·i`` on θ_0, with electrics
  ``L di/dt = v − R i − K_b ω_0`` per speed range (wye/delta winding: K_t, R, L, K_b differ);
- bearing drag on the bearing node ``j_b``: viscous ``B ω``, Coulomb ``τ_c tanh(ω/ω_s)`` and a
  speed-dependent part ``τ_drag·sgn ω·(|ω|/ω_ref)^{2/3}`` (Palmgren's load-independent
  moment ∝ (ν n)^{2/3}); Aslan Eq. 5.2 is its linear belief;
- torque ripple on the rotor: ``Σ A_k sin(n_k θ_0 + φ_k)`` (slot/cogging and current
  harmonics per motor revolution), applied as its exact mean over each current-loop step
  (constant speed over the step), so no harmonic aliases;
- the drive's current PI ``v = k_p e + k_i ∫e`` sampled at ``current_substeps`` × the CNC rate,
  the voltage applied after ``current_dead_substeps`` current-loop periods (computation and
  PWM dead time);
- the drive's velocity PI (Eq. 5.3 gains, per rev/s of speed error, decision 0032) sampled
  every ``velocity_period_s`` on the motor encoder's speed (``encoder_counts`` per rev; the
  angle difference over the velocity period), its output I_nom held; the CNC's speed channel
  is the difference over one CNC sample;
- the cutting torque acts on the last inertia (the tool).

The linear part is discretised exactly (zero-order hold, one matrix exponential per range) on
the current-loop step; the nonlinear torques are held over a step. Coordinates are the rotor
angle and the twists ``θ_j − θ_0``, so the state stays accurate over hours at 24 000 rev/min.

What the CNC reads: I_nom, the actual current and the encoder speed; the process sees the
tool's angle and speed (``angle``, ``true_speed`` of :meth:`TruthSpindleSim.advance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numba
import numpy as np
import scipy.linalg

from millsense.core import units
from millsense.core.errors import ConfigError, InputDataError
from millsense.models.spindle_plant import first_crossing, velocity_decimation, zoh
from millsense.simulator.spindle import spindle_inputs, steady_sine_point
from millsense.simulator.truth_machine import read_truth_file

#: inputs of the continuous plant: applied voltage, rotor torque, bearing torque, tool torque
_N_IN = 4
#: output columns of the kernel (the same as :class:`~millsense.simulator.spindle.SpindleDriveSim`)
OUT_INOM, OUT_IACT, OUT_SPEED, OUT_TOOL_SPEED, OUT_TOOL_ANGLE, OUT_RANGE = range(6)


@dataclass(frozen=True)
class SpindleMechanics:
    """Torsional chain (SI): inertias from the motor rotor to the holder + tool.

    Attributes
    ----------
    inertias : J_0 … J_{n−1}, kg·m² (J_0 the motor rotor, J_{n−1} holder + tool).
    stiffnesses : k_1 … k_{n−1} between consecutive inertias, N·m/rad.
    damping_ratios : modal ζ of the n − 1 elastic free–free modes, ascending frequency.
    bearing_node : index of the inertia carrying the bearings (drag acts there).
    """

    inertias: tuple[float, ...]
    stiffnesses: tuple[float, ...]
    damping_ratios: tuple[float, ...]
    bearing_node: int = 1

    def __post_init__(self) -> None:
        n = len(self.inertias)
        if n < 3:
            raise ConfigError("truth spindle: at least three inertias (two torsional modes)")
        if len(self.stiffnesses) != n - 1 or len(self.damping_ratios) != n - 1:
            raise ConfigError(
                f"truth spindle: {n} inertias need {n - 1} stiffnesses and damping ratios"
            )
        if min(self.inertias) <= 0 or min(self.stiffnesses) <= 0:
            raise ConfigError("truth spindle: inertias and stiffnesses must be > 0")
        if not 0 <= self.bearing_node < n:
            raise ConfigError(f"truth spindle: bearing_node must be in 0…{n - 1}")

    @property
    def total_inertia(self) -> float:
        """Σ J, kg·m² (the rigid body Aslan's J_eS describes)."""
        return float(sum(self.inertias))

    def mass_stiffness(self) -> tuple[np.ndarray, np.ndarray]:
        """(M, K) of the chain in absolute angles."""
        m = np.diag(np.asarray(self.inertias, dtype=float))
        n = len(self.inertias)
        k = np.zeros((n, n))
        for j, kj in enumerate(self.stiffnesses):
            k[j, j] += kj
            k[j + 1, j + 1] += kj
            k[j, j + 1] -= kj
            k[j + 1, j] -= kj
        return m, k

    def modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Elastic free–free modes: (frequencies Hz ascending, mass-normalised shapes n×(n−1))."""
        m, k = self.mass_stiffness()
        lam, phi = scipy.linalg.eigh(k, m)
        order = np.argsort(lam)[1:]  # drop the rigid-body mode (λ = 0)
        return np.sqrt(np.maximum(lam[order], 0.0)) / (2 * math.pi), phi[:, order]

    def damping(self) -> np.ndarray:
        """Modal damping ``C = M Φ diag(2ζω) Φᵀ M`` over the elastic modes."""
        m, _ = self.mass_stiffness()
        f, phi = self.modes()
        w = 2 * math.pi * f
        d = np.diag(2.0 * np.asarray(self.damping_ratios) * w)
        return m @ phi @ d @ phi.T @ m


@dataclass(frozen=True)
class SpindleMotorRange:
    """The motor's true electrics in one speed range (SI)."""

    torque_constant: float
    resistance: float
    inductance: float
    back_emf: float


@dataclass(frozen=True)
class TruthSpindle:
    """The spindle drive of the truth (SI; see the module)."""

    mechanics: SpindleMechanics
    ranges: tuple[SpindleMotorRange, SpindleMotorRange]
    switch_rad_s: float
    current_kp: float
    current_ki: float
    current_substeps: int
    current_dead_substeps: int
    velocity_kp: float
    velocity_ki: float
    velocity_period_s: float
    encoder_counts: int
    viscous: float
    coulomb: float
    coulomb_smoothing_rad_s: float
    drag: float
    drag_ref_rad_s: float
    ripple_orders: tuple[float, ...] = ()
    ripple_amplitudes: tuple[float, ...] = ()
    ripple_phases: tuple[float, ...] = ()

    def linear(self) -> TruthSpindle:
        """The same drive without Coulomb, speed-dependent drag, ripple and encoder
        quantisation (the linear part, for FRFs)."""
        return replace(
            self,
            coulomb=0.0,
            drag=0.0,
            ripple_amplitudes=tuple(0.0 for _ in self.ripple_amplitudes),
            encoder_counts=0,
        )

    def range_index(self, speed_ref_rad_s: float) -> int:
        """0 for range 1, 1 for range 2 (by |speed reference|, as the drive switches)."""
        return 1 if abs(speed_ref_rad_s) >= self.switch_rad_s else 0


def plant_matrices(t: TruthSpindle, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous ``ẋ = A x + B u`` of range ``r``.

    States ``[i, θ_0, θ_1 − θ_0, …, θ_{n−1} − θ_0, ω_0, …, ω_{n−1}]``; inputs
    ``[v (V), τ_rotor (N·m), τ_bearing (N·m), τ_tool (N·m, opposing rotation)]``.
    """
    mech = t.mechanics
    rng = t.ranges[r]
    n = len(mech.inertias)
    _, k = mech.mass_stiffness()
    c = mech.damping()
    c[mech.bearing_node, mech.bearing_node] += t.viscous
    minv = np.diag(1.0 / np.asarray(mech.inertias))
    # absolute coordinates y = [i, θ (n), ω (n)]
    ny = 1 + 2 * n
    a = np.zeros((ny, ny))
    b = np.zeros((ny, _N_IN))
    a[0, 0] = -rng.resistance / rng.inductance
    a[0, 1 + n] = -rng.back_emf / rng.inductance
    b[0, 0] = 1.0 / rng.inductance
    a[1 : 1 + n, 1 + n :] = np.eye(n)
    a[1 + n :, 1 : 1 + n] = -minv @ k
    a[1 + n :, 1 + n :] = -minv @ c
    a[1 + n, 0] = rng.torque_constant / mech.inertias[0]
    b[1 + n, 1] = 1.0 / mech.inertias[0]
    b[1 + n + mech.bearing_node, 2] = 1.0 / mech.inertias[mech.bearing_node]
    b[1 + n + n - 1, 3] = -1.0 / mech.inertias[n - 1]
    # twist coordinates x = T⁻¹ y:  θ_j = θ_0 + d_j
    tm = np.eye(ny)
    tm[2 : 1 + n, 1] = 1.0
    ti = np.linalg.inv(tm)
    return ti @ a @ tm, ti @ b


def _discrete(t: TruthSpindle, h: float) -> tuple[np.ndarray, np.ndarray]:
    ads, bds = [], []
    for r in (0, 1):
        a, b = plant_matrices(t, r)
        ad, bd = zoh(a, b, h)
        ads.append(ad)
        bds.append(bd)
    return np.ascontiguousarray(np.stack(ads)), np.ascontiguousarray(np.stack(bds))


#: Harmonic orders up to this, all integers, take the ripple's binary powers of e^{iθ}.
_RIPPLE_POWERS_MAX = 64


def ripple_rows(
    orders: tuple[float, ...], amps: tuple[float, ...], phases: tuple[float, ...]
) -> tuple[np.ndarray, int]:
    """Ripple rows ``(order n_k, amplitude A_k, phase φ_k, cos φ_k, sin φ_k)``, and the highest
    order when every order is an integer ≤ ``_RIPPLE_POWERS_MAX`` (0 otherwise:
    :func:`_ripple_mean` then takes two sines per harmonic)."""
    rip = np.column_stack([orders, amps, phases]).reshape(-1, 3).astype(np.float64)
    tab = np.ascontiguousarray(np.column_stack([rip, np.cos(rip[:, 2]), np.sin(rip[:, 2])]))
    o = rip[:, 0]
    integer = bool(np.all((o == np.round(o)) & (o >= 1) & (o <= _RIPPLE_POWERS_MAX)))
    return tab, (int(o.max()) if integer and len(o) else 0)


@numba.njit(cache=True)
def _cis_power(c: float, s: float, m: int) -> tuple[float, float]:
    """``(cos mφ, sin mφ)`` from ``(cos φ, sin φ)`` by binary powers of ``e^{iφ}`` (m ≥ 0)."""
    rc, rs = 1.0, 0.0
    while m > 0:
        if m & 1:
            rc, rs = rc * c - rs * s, rs * c + rc * s
        m >>= 1
        if m:
            c, s = c * c - s * s, 2.0 * c * s
    return rc, rs


@numba.njit(cache=True)
def _ripple_mean(rip: np.ndarray, n_max: int, th: float, dth: float) -> float:
    """``Σ A_k·mean(sin(n_k θ + φ_k))`` over the step ``θ … θ + dθ`` (speed held), N·m.

    The mean ``(cos(n θ + φ) − cos(n(θ + dθ) + φ))/(n dθ)`` is summed as the equal product
    ``sin(n θ_c + φ)·sin(n dθ/2)/(n dθ/2)``, ``θ_c = θ + dθ/2`` (no cancellation of two close
    cosines); ``sin(n θ + φ)`` when ``|n dθ| ≤ 1e-9``. With ``n_max`` > 0 (integer orders)
    the multiples ``n θ_c`` and ``n dθ/2`` come from binary powers of ``e^{iθ_c}`` and
    ``e^{i dθ/2}`` (one sine–cosine pair each per step, short independent products).
    """
    tr = 0.0
    if n_max > 0:
        th_c = th + 0.5 * dth
        c1, s1 = math.cos(th_c), math.sin(th_c)
        ch, sh = math.cos(0.5 * dth), math.sin(0.5 * dth)
        for j in range(rip.shape[0]):
            o = int(rip[j, 0])
            od = o * dth
            if abs(od) > 1e-9:
                cm, sm = _cis_power(c1, s1, o)
                shm = _cis_power(ch, sh, o)[1]
                # sin(o θ_c + φ) = sin(o θ_c) cos φ + cos(o θ_c) sin φ
                tr += rip[j, 1] * (sm * rip[j, 3] + cm * rip[j, 4]) * shm / (0.5 * od)
            else:
                tr += rip[j, 1] * math.sin(o * th + rip[j, 2])
        return tr
    for j in range(rip.shape[0]):
        o, a_r, ph = rip[j, 0], rip[j, 1], rip[j, 2]
        od = o * dth
        if abs(od) > 1e-9:
            tr += a_r * math.sin(o * (th + 0.5 * dth) + ph) * math.sin(0.5 * od) / (0.5 * od)
        else:
            tr += a_r * math.sin(o * th + ph)
    return tr


@numba.njit(cache=True)
def _truth_spindle_kernel(
    x: np.ndarray,
    ctl: np.ndarray,
    vbuf: np.ndarray,
    speed_ref: np.ndarray,
    torque_dist: np.ndarray,
    ad: np.ndarray,
    bd: np.ndarray,
    prm: np.ndarray,
    rip: np.ndarray,
    out: np.ndarray,
) -> None:
    """One call steps ``len(speed_ref)`` CNC samples.

    ctl = [sample counter, velocity integrator, I_nom held, range, current integrator,
    encoder angle of the previous sample, measured speed (CNC), started, encoder angle at the
    previous velocity sample]; vbuf the voltages in
    flight (dead time); prm described in :class:`TruthSpindleSim`; rip the rows of
    :func:`ripple_rows`.
    """
    kpv, kiv, tv, nv, w_sw = prm[0], prm[1], prm[2], prm[3], prm[4]
    kpc, kic, hc, ns, nd = prm[5], prm[6], prm[7], int(prm[8]), int(prm[9])
    q_enc, h = prm[10], prm[11]
    coul, w_s, drag, w_ref = prm[12], prm[13], prm[14], prm[15]
    n_j = int(prm[16])
    jb = int(prm[17])
    ib = 1 + n_j + jb  # bearing speed state
    it = n_j  # twist of the tool (state index 1 + n_j − 1)
    nx = x.shape[0]
    xn = np.empty(nx)
    n_rip_max = int(prm[18])
    for k in range(speed_ref.shape[0]):
        # motor encoder: quantised rotor angle, speed by backward difference over one sample
        th0 = x[1]
        if q_enc > 0.0:
            enc = math.floor(th0 / q_enc) * q_enc
        else:
            enc = th0
        if ctl[7] == 0.0:
            ctl[5] = enc
            ctl[8] = enc
            ctl[7] = 1.0
        ctl[6] = (enc - ctl[5]) / h
        ctl[5] = enc
        r = int(ctl[3])
        if int(ctl[0]) % int(nv) == 0:
            r = 1 if abs(speed_ref[k]) >= w_sw else 0
            ctl[3] = r
            # the drive's speed: encoder difference over its own period
            e = speed_ref[k] - (enc - ctl[8]) / tv
            ctl[8] = enc
            ctl[1] += kiv * e * tv
            ctl[2] = kpv * e + ctl[1]
        ctl[0] += 1.0
        out[k, 0] = ctl[2]
        out[k, 1] = x[0]
        out[k, 2] = ctl[6]
        out[k, 3] = x[1 + n_j + n_j - 1]
        out[k, 4] = x[1] + x[it]
        out[k, 5] = r
        for _ in range(ns):
            # current PI (sampled), voltage applied after nd current-loop periods
            ei = ctl[2] - x[0]
            v_new = kpc * ei + ctl[4]
            ctl[4] += kic * ei * hc
            if nd > 0:
                u0 = vbuf[0]
                for j in range(nd - 1):
                    vbuf[j] = vbuf[j + 1]
                vbuf[nd - 1] = v_new
            else:
                u0 = v_new
            # ripple: exact mean over the step at the held rotor speed
            u1 = _ripple_mean(rip, n_rip_max, x[1], x[1 + n_j] * hc)
            wb = x[ib]
            tb = coul * math.tanh(wb / w_s)
            if drag != 0.0:
                c = np.cbrt(abs(wb) / w_ref)  # (|ω|/ω_ref)^{2/3} = cbrt², to round-off
                tb += drag * math.copysign(1.0, wb) * (c * c)
            u2 = -tb
            u3 = torque_dist[k]
            adr = ad[r]
            bdr = bd[r]
            for i in range(nx):
                acc = 0.0
                for j in range(nx):
                    acc += adr[i, j] * x[j]
                acc += bdr[i, 0] * u0
                acc += bdr[i, 1] * u1
                acc += bdr[i, 2] * u2
                acc += bdr[i, 3] * u3
                xn[i] = acc
            for i in range(nx):
                x[i] = xn[i]


class TruthSpindleSim:
    """A resumable truth spindle with the interface of
    :class:`~millsense.simulator.spindle.SpindleDriveSim` (:meth:`advance`, :meth:`advance_into`).

    Inputs per sample: speed reference (rad/s) and the cutting torque at the tool (N·m,
    opposing positive rotation). Outputs: ``current_cmd`` (I_nom, A), ``current`` (actual
    current, A), ``speed`` (motor encoder speed, rad/s), ``true_speed`` and ``angle`` (the
    tool's, rad/s and rad), ``speed_range``.
    """

    def __init__(self, truth: TruthSpindle, sample_rate_hz: float = 10000.0) -> None:
        self.truth = truth
        self.dt = 1.0 / sample_rate_hz
        nv = velocity_decimation(truth.velocity_period_s, sample_rate_hz, "truth spindle")
        ns = int(truth.current_substeps)
        if ns < 1 or truth.current_dead_substeps < 0:
            raise ConfigError("truth spindle: current_substeps ≥ 1, dead substeps ≥ 0")
        hc = self.dt / ns
        self._ad, self._bd = _discrete(truth, hc)
        n_j = len(truth.mechanics.inertias)
        q = 2 * math.pi / truth.encoder_counts if truth.encoder_counts > 0 else 0.0
        self._prm = np.array(
            [
                truth.velocity_kp,
                truth.velocity_ki,
                truth.velocity_period_s,
                float(nv),
                truth.switch_rad_s if math.isfinite(truth.switch_rad_s) else 1e300,
                truth.current_kp,
                truth.current_ki,
                hc,
                float(ns),
                float(truth.current_dead_substeps),
                q,
                self.dt,
                truth.coulomb,
                truth.coulomb_smoothing_rad_s,
                truth.drag,
                truth.drag_ref_rad_s,
                float(n_j),
                float(truth.mechanics.bearing_node),
                0.0,  # the ripple's highest order for binary powers, 0: sines (below)
            ]
        )
        self._rip, n_rip_max = ripple_rows(
            truth.ripple_orders, truth.ripple_amplitudes, truth.ripple_phases
        )
        self._prm[18] = n_rip_max
        self._x = np.zeros(1 + 2 * n_j)
        self._ctl = np.zeros(9)
        self._vbuf = np.zeros(max(truth.current_dead_substeps, 1))

    def advance(
        self, speed_ref_rad_s: np.ndarray, torque_dist_nm: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Simulate ``len(speed_ref_rad_s)`` samples (see the class for the outputs)."""
        ref, dist = spindle_inputs(speed_ref_rad_s, torque_dist_nm)
        out = np.empty((len(ref), 6))
        self.advance_into(ref, dist, out)
        return {
            "current_cmd": out[:, OUT_INOM],
            "current": out[:, OUT_IACT],
            "speed": out[:, OUT_SPEED],
            "true_speed": out[:, OUT_TOOL_SPEED],
            "angle": out[:, OUT_TOOL_ANGLE],
            "speed_range": out[:, OUT_RANGE].astype(np.int8),
        }

    def advance_into(
        self, speed_ref_rad_s: np.ndarray, torque_dist_nm: np.ndarray, out: np.ndarray
    ) -> None:
        """:meth:`advance` into ``out`` ((n, 6) C-contiguous) without the checks."""
        _truth_spindle_kernel(
            self._x,
            self._ctl,
            self._vbuf,
            speed_ref_rad_s,
            torque_dist_nm,
            self._ad,
            self._bd,
            self._prm,
            self._rip,
            out,
        )

    @property
    def state(self) -> np.ndarray:
        """A copy of the plant state ``[i, θ_0, twists…, ω…]`` (tests)."""
        return self._x.copy()


# ---------------------------------------------------------------- measurements of the truth


def sine_response(
    truth: TruthSpindle,
    freq_hz: float,
    *,
    output: str = "disturbance",
    sample_rate_hz: float = 10000.0,
    amplitude: float = 1.0,
    settle_s: float = 0.5,
    fit_periods: int = 20,
) -> complex:
    """One FRF point of the truth from a steady sine (least squares over whole periods).

    ``output="disturbance"``: I_nom/τ_tool (A/(N·m)) at zero speed reference, the torque a
    sine at the tool (Aslan's G_dτ, Eq. 5.12, measured by a tangential tap at 0 rev/min);
    ``"velocity"``: measured motor speed / speed reference (the closed velocity loop, Fig. 5.4).
    """
    sim = TruthSpindleSim(truth, sample_rate_hz)
    if output == "disturbance":

        def respond(s: np.ndarray) -> np.ndarray:
            return sim.advance(np.zeros(len(s)), s)["current_cmd"]
    elif output == "velocity":

        def respond(s: np.ndarray) -> np.ndarray:
            return sim.advance(s, np.zeros(len(s)))["speed"]
    else:
        raise InputDataError(f"truth spindle: unknown output {output!r}")
    return steady_sine_point(respond, freq_hz, sample_rate_hz, amplitude, settle_s, fit_periods)


def sampled_disturbance_frf(
    truth: TruthSpindle,
    *,
    sample_rate_hz: float = 10000.0,
    period_s: float = 1.0,
    n_periods: int = 3,
    amplitude_nm: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """G_dτ = I_nom/τ_d of the linear truth (range 1, 0 rev/min) at the velocity-loop rate.

    The tool torque is a multisine (Schroeder phases, every line k/period_s below the
    velocity-loop Nyquist frequency) that changes every CNC sample, as a cut's torque does; it
    is read at the velocity-loop instants, where I_nom is new. The loop is periodic with the
    velocity period, so a line in the torque gives the same line in the I_nom samples (the
    velocity-loop's samples of the sample-rate response): the ratio of the DFTs of I_nom and the
    torque at those instants over whole periods (after one settling period) is its FRF at the
    lines. A torque held over the velocity period (what the loop's own ZOH model assumes) is
    not what a cut applies: that held-torque FRF is 3.3 dB above this one at 1.94 kHz, 4.3 dB at
    2.28 kHz
    (decision 1696). Returns (frequencies Hz, complex FRF).
    """
    m = round(truth.velocity_period_s * sample_rate_hz)
    fv = sample_rate_hz / m
    per = round(period_s * fv)
    k = np.arange(1, per // 2)
    phase = -math.pi * k * (k - 1) / len(k)
    t_fast = np.arange(per * m) / sample_rate_hz
    u_fast = np.cos(2 * math.pi * np.outer(t_fast, k / period_s) + phase).sum(axis=1)
    u_fast *= amplitude_nm / np.sqrt(np.mean(u_fast**2))
    u_all = np.tile(u_fast, n_periods + 1)
    sim = TruthSpindleSim(truth.linear(), sample_rate_hz)
    out = sim.advance(np.zeros(len(u_all)), u_all)
    y = out["current_cmd"][::m][per:]
    # the torque at the instants I_nom is computed (before that sample's torque acts)
    uu = u_all[::m][per:]
    ys = np.fft.rfft(y.reshape(n_periods, per).mean(axis=0))
    us = np.fft.rfft(uu.reshape(n_periods, per).mean(axis=0))
    return k / period_s, ys[k] / us[k]


def current_loop_frf(
    truth: TruthSpindle, r: int, freq_hz: np.ndarray, sample_rate_hz: float = 10000.0
) -> np.ndarray:
    """I_act/I_nom of the sampled current loop with the rotor held (exact z-domain: ZOH of
    ``1/(L s + R)``, forward-Euler PI, ``current_dead_substeps`` delay), range ``r``."""
    rng = truth.ranges[r]
    hc = 1.0 / (sample_rate_hz * truth.current_substeps)
    a = math.exp(-rng.resistance * hc / rng.inductance)
    z = np.exp(2j * math.pi * np.asarray(freq_hz, dtype=float) * hc)
    g = (1.0 - a) / rng.resistance / (z - a)
    c = truth.current_kp + truth.current_ki * hc / (z - 1.0)
    loop = c * g * z ** (-float(truth.current_dead_substeps))
    return np.asarray(loop / (1.0 + loop))


def current_loop_bandwidth_hz(truth: TruthSpindle, r: int = 0) -> float:
    """−3 dB bandwidth of the truth's current loop (rotor held), Hz (Aslan Fig. 5.2)."""
    f = np.logspace(0, math.log10(4900.0), 3000)
    mag = np.abs(current_loop_frf(truth, r, f))
    return first_crossing(f, mag, mag[0] / math.sqrt(2.0))


def velocity_loop_bandwidth_hz(truth: TruthSpindle, f_max_hz: float = 400.0) -> float:
    """−3 dB bandwidth of the closed velocity loop (encoder speed / reference), range 1, Hz,
    from sine responses of the linear part (Aslan Fig. 5.4)."""
    lin = truth.linear()
    f = np.geomspace(2.0, f_max_hz, 36)
    mag = np.array([abs(sine_response(lin, fk, output="velocity", settle_s=0.4)) for fk in f])
    return first_crossing(f, mag, mag[0] / math.sqrt(2.0))


# ---------------------------------------------------------------- the truth file


def truth_spindle_from_tables(motor: dict[str, Any], mech: dict[str, Any]) -> TruthSpindle:
    """A :class:`TruthSpindle` from the ``[spindle]`` tables of ``<name>-truth.toml``
    (``motor``) and ``<name>-truth-mechanics.toml`` (``mech``), units in the keys."""
    try:
        mechanics = SpindleMechanics(
            inertias=tuple(float(v) for v in mech["inertias_kg_m2"]),
            stiffnesses=tuple(float(v) for v in mech["stiffnesses_nm_rad"]),
            damping_ratios=tuple(float(v) for v in mech["damping_ratios"]),
            bearing_node=int(mech.get("bearing_node", 1)),
        )
        ranges = tuple(
            SpindleMotorRange(
                torque_constant=float(motor["torque_constant_nm_a"][r]),
                resistance=float(motor["resistance_ohm"][r]),
                inductance=float(motor["inductance_mh"][r]) * 1e-3,
                back_emf=float(motor["back_emf_v_s_rad"][r]),
            )
            for r in (0, 1)
        )
        rip = motor.get("ripple", {})
        two_pi = 2 * math.pi
        return TruthSpindle(
            mechanics=mechanics,
            ranges=(ranges[0], ranges[1]),
            switch_rad_s=float(motor["range_switch_rpm"]) * units.RPM,
            current_kp=float(motor["current_kp_v_a"]),
            current_ki=float(motor["current_ki_v_a_s"]),
            current_substeps=int(motor["current_substeps"]),
            current_dead_substeps=int(motor["current_dead_substeps"]),
            velocity_kp=float(motor["velocity_kp_a_s_rev"]) / two_pi,
            velocity_ki=float(motor["velocity_ki_a_rev"]) / two_pi,
            velocity_period_s=float(motor["velocity_loop_period_ms"]) * 1e-3,
            encoder_counts=int(motor["encoder_counts"]),
            viscous=float(motor["viscous_nm_s_rad"]),
            coulomb=float(motor["coulomb_nm"]),
            coulomb_smoothing_rad_s=float(motor["coulomb_smoothing_rad_s"]),
            drag=float(motor["drag_nm"]),
            drag_ref_rad_s=float(motor["drag_ref_rpm"]) * units.RPM,
            ripple_orders=tuple(float(v) for v in rip.get("per_motor_rev", [])),
            ripple_amplitudes=tuple(float(v) for v in rip.get("amplitude_nm", [])),
            ripple_phases=tuple(float(v) for v in rip.get("phase_rad", [])),
        )
    except KeyError as exc:
        raise ConfigError(f"truth spindle: missing key {exc.args[0]!r} in [spindle]") from exc


def load_truth_spindle(machine_name: str) -> TruthSpindle:
    """The truth spindle of a preset (``<name>-truth.toml`` + ``-truth-mechanics.toml``)."""
    motor = read_truth_file(f"{machine_name}-truth.toml").get("spindle")
    mech = (
        read_truth_file(f"{machine_name}-truth-mechanics.toml").get("spindle", {}).get("mechanics")
    )
    if motor is None or mech is None:
        raise ConfigError(f"machine truth {machine_name}: no [spindle] truth")
    return truth_spindle_from_tables(motor, mech)


def has_truth_spindle(machine_name: str) -> bool:
    """True when the preset's truth files carry a spindle."""
    try:
        load_truth_spindle(machine_name)
    except ConfigError:
        return False
    return True
