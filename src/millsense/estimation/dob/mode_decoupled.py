"""Mode-decoupled cutting-force estimation on the dual-inertia drive (Yamada C6, Ch. 5).

Under proportional damping (Yamada Eq. 2-29/2-30, ``C = α_c M + β_c K``) the dual-inertia model
diagonalises with the modes ``Φ_rigid = {1, 1}`` and ``Φ_vib = {1, −1/α}`` (Eq. 2-36…2-38):

    x_rigid = (x_m + α x_t)/(α + 1),   x_vib = α(x_m − x_t)/(α + 1)                  (2-39)
    M_rigid = M_r + M_t,  M_vib = (1 + 1/α)M_r,  K_vib = (1 + 1/α)²K_r,
    C_rigid = α_c M_rigid,  C_vib = α_c M_vib + β_c K_vib                              (2-41)

- Rigid-body mode (Eq. 2-43) ≡ MEDOB (Appendix A): :func:`rigid_mode_observer` returns the
  exact discrete MEDOB of :mod:`.dob`.
- Vibration mode (Eq. 2-44): ``F = α{M_vib a_vib + C_vib v_vib + K_vib x_vib − K_tI/R +
  T_fric/R} − F_fric``. Expanded without assuming proportional damping (identical to Eq. 2-44
  when it holds, re-derived from Eq. 2-1/2-2)::

      F = (1+α)K_rΔx + (1+α)C_kΔẋ + M_t(ẍ_m − ẍ_t) + αC_r ẋ_m − C_t ẋ_t − αK_tI/R

  with ``Δx = x_m − x_t``. The thrust enters weighted by α (≈ 0.08), so friction on the motor
  side (T_fric) and rotary-encoder noise matter little; the elastic term dominates and needs an
  accurate K_r. This is why the estimate works on a **stationary axis** (cross-feed, Yamada
  §5.4): static friction holds the motor, the table force still stretches the screw–nut spring.
  Guideway friction F_fric is not modelled (it is removed by the idling table when the axis
  moves; Yamada §2.9).

Discretisation: central differences at sample k − 1 (``a = Δ²x/T²``, ``v = (x_k −
x_{k−2})/2T``, ``Ī = (I_{k−1} + I_{k−2})/2``), the same one-sample latency as the MEDOB (a = 0
weights), then the output Butterworth; phase-lag delays (T_1, T_2, T_3) as in the MEDOB.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.estimation.dob.observers import (
    DisturbanceTable,
    DriveParameters,
    RigidSumObserver,
    StreamingSOS,
    butterworth_sos,
    medob_observer,
)
from millsense.estimation.dob.phase_lag import StreamingDelay

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ModalParameters:
    """Modal masses, dampings and stiffness of Yamada Eq. 2-41 (SI)."""

    alpha: float
    m_rigid: float
    c_rigid: float
    m_vib: float
    c_vib: float
    k_vib: float


def modal_parameters(p: DriveParameters) -> ModalParameters:
    """Eq. 2-41 with α_c = (C_r + C_t)/(M_r + M_t) and β_c = C_k/K_r (Eq. 2-30)."""
    mr, mt = p.rotor_mass_kg, p.table_mass_kg
    alpha = mt / mr
    ac = (p.rotor_damping_n_s_m + p.table_damping_n_s_m) / (mr + mt)
    bc = p.axial_damping_n_s_m / p.axial_stiffness_n_m if p.axial_stiffness_n_m > 0 else 0.0
    m_vib = (1.0 + 1.0 / alpha) * mr
    k_vib = (1.0 + 1.0 / alpha) ** 2 * p.axial_stiffness_n_m
    return ModalParameters(
        alpha=alpha,
        m_rigid=mr + mt,
        c_rigid=ac * (mr + mt),
        m_vib=m_vib,
        c_vib=ac * m_vib + bc * k_vib,
        k_vib=k_vib,
    )


def modal_coordinates(
    x_motor_m: ArrayLike, x_table_m: ArrayLike, alpha: float
) -> tuple[FloatArray, FloatArray]:
    """(x_rigid, x_vib) of Yamada Eq. 2-39, m."""
    xm = np.asarray(x_motor_m, dtype=float)
    xt = np.asarray(x_table_m, dtype=float)
    return (xm + alpha * xt) / (alpha + 1.0), alpha * (xm - xt) / (alpha + 1.0)


def rigid_mode_observer(
    p: DriveParameters,
    sample_rate_hz: float,
    *,
    cutoff_hz: float,
    order: int = 4,
    delays_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    disturbance_table: DisturbanceTable | None = None,
    current_loop_hz: float | None = None,
) -> RigidSumObserver:
    """Rigid-body-mode estimator (Eq. 2-43) — identical to the MEDOB (Yamada Appendix A)."""
    return medob_observer(
        p,
        sample_rate_hz,
        cutoff_hz=cutoff_hz,
        order=order,
        delays_s=delays_s,
        disturbance_table=disturbance_table,
        current_loop_hz=current_loop_hz,
    )


class VibrationModeObserver:
    """Streaming vibration-mode force estimator (Yamada Eq. 2-44), chunk-size invariant.

    Parameters
    ----------
    p : nominal drive parameters (K_r and C_k are required).
    sample_rate_hz : Hz.
    cutoff_hz, order : output Butterworth.
    delays_s : (T_1, T_2, T_3) on (current, motor position, table position), s.
    disturbance_table : idling table (table position → force, N) subtracted after the filter.
    """

    def __init__(
        self,
        p: DriveParameters,
        sample_rate_hz: float,
        *,
        cutoff_hz: float,
        order: int = 4,
        delays_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
        disturbance_table: DisturbanceTable | None = None,
    ) -> None:
        if not p.axial_stiffness_n_m > 0.0:
            raise ValueError("the vibration-mode estimator needs the axial stiffness K_r")
        self.p = p
        self.fs = float(sample_rate_hz)
        self.dt = 1.0 / self.fs
        self.sos = butterworth_sos(order, cutoff_hz, self.fs)
        self.delays_s = delays_s
        self.disturbance_table = disturbance_table
        self.reset()

    def reset(self) -> None:
        """Forget all state."""
        self._d = [StreamingDelay(d * self.fs) for d in self.delays_s]
        self._tail: FloatArray | None = None  # (3, 2): I, x_m, x_t
        self._out = StreamingSOS(self.sos)

    def raw(self, current_a: ArrayLike, x_motor_m: ArrayLike, x_table_m: ArrayLike) -> FloatArray:
        """Unfiltered estimate at sample k − 1, N (updates the state)."""
        cur = self._d[0].process(current_a)
        xm = self._d[1].process(x_motor_m)
        xt = self._d[2].process(x_table_m)
        n = len(cur)
        if n == 0:
            return np.zeros(0)
        if self._tail is None:
            self._tail = np.array([[cur[0]] * 2, [xm[0]] * 2, [xt[0]] * 2])
        ie = np.concatenate([self._tail[0], cur])
        me = np.concatenate([self._tail[1], xm])
        te = np.concatenate([self._tail[2], xt])
        self._tail = np.array([ie[-2:], me[-2:], te[-2:]])
        dt = self.dt
        p = self.p
        alpha = p.inertia_ratio
        dx = me - te
        elastic = (1.0 + alpha) * p.axial_stiffness_n_m * dx[1:-1]
        dv = (dx[2:] - dx[:-2]) / (2.0 * dt)
        vm = (me[2:] - me[:-2]) / (2.0 * dt)
        vt = (te[2:] - te[:-2]) / (2.0 * dt)
        da = (dx[2:] - 2.0 * dx[1:-1] + dx[:-2]) / (dt * dt)
        thrust = p.force_constant_n_a * 0.5 * (ie[1:-1] + ie[:-2])
        est = (
            elastic
            + (1.0 + alpha) * p.axial_damping_n_s_m * dv
            + p.table_mass_kg * da
            + alpha * p.rotor_damping_n_s_m * vm
            - p.table_damping_n_s_m * vt
            - alpha * thrust
        )
        return np.asarray(est, dtype=float)

    def process(
        self, current_a: ArrayLike, x_motor_m: ArrayLike, x_table_m: ArrayLike
    ) -> FloatArray:
        """Filtered vibration-mode estimate F̂_cut(vib), N (resisting +motion)."""
        xt = np.asarray(x_table_m, dtype=float)
        r = self.raw(current_a, x_motor_m, xt)
        if r.size == 0:
            return r
        out = self._out.process(r)
        if self.disturbance_table is not None:
            out = out - np.asarray(self.disturbance_table(xt), dtype=float)
        return out
