"""Disturbance observers of a ball-screw drive: conventional DOB and multi-encoder DOB (MEDOB).

Yamada (2017) C2–C4, C7. Every observer here is one *rigid-body sum*: adding the equations of
motion of all the bodies of the drive cancels the internal spring and damper forces
(Yamada Eq. 2-20, 2-49), leaving, in translational coordinates ``x_i`` (motor ``x_m = Rθ_m``,
nut, table; ``R = ℓ/2π``)::

    Σ_i (M_i ẍ_i + C_i ẋ_i) = K_t·I/R − F_cut                                  (2-20)

- MEDOB (Eq. 2-21): ``x = (x_m, x_t)``, ``M = (J_r/R², M_t)``, ``C = (D_r/R², C_t)``; needs no
  stiffness and, with exact parameters, F̂/F equals the output filter exactly.
- Conventional DOB (Eq. 2-15): the motor coordinate alone with ``M_a = M_r + M_t``,
  ``C_a = C_r + C_t`` (rigid assumption, Eq. 2-7); F̂/F is Eq. 2-19 (exact form in
  :func:`dob_frf_closed_form`).
- Triple inertia (Eq. 2-49): ``(x_m, x_n, x_t)`` with ``(M_r, M_n, M_t)``; reduced comparators
  (Eq. 2-64, 2-65) lump the nut into the motor coordinate.

Discretisation (decision docs/decisions/0067-exact-discrete-medob-seed-001-observers.md): the thesis
pseudo-differentiates each signal (``s·g/(s + g)``) and low-passes the sum. Here the sum is
differentiated exactly instead. With ``y = Σ M_i x_i`` and ``w = Σ C_i x_i = a·y + e`` (``a =
ΣC_i/ΣM_i``; e = 0 under proportional damping, Yamada Eq. 2-29/2-30), Eq. 2-20 reads
``ÿ + a·ẏ = u − ė`` with ``u = K_t I/R − F``. For ``u`` held over each sample (the CNC's
zero-order hold) the ZOH map of ``1/(s(s + a))`` gives exactly::

    b₁u_k + b₀u_{k−1} = y_{k+1} − (1 + E)y_k + E·y_{k−1}
                        + (b₁/T)(e_{k+1} − e_k) + (b₀/T)(e_k − e_{k−1})

``E = e^{−aT}``, ``b₁ = (aT − 1 + E)/a²``, ``b₀ = (1 − E − aT·E)/a²`` (→ T²/2 as a → 0); the
e-terms (mean of ė over each interval) are the only approximation and vanish under proportional
damping. The raw estimate is therefore the force filtered by the 2-tap low-pass
``P(z) = (b₁ + b₀z⁻¹)/(b₁ + b₀)`` (zero near Nyquist) one sample late, and the output
Butterworth ``Q(z)`` follows, applied to every term alike. The observer's output filter is
``L(z) = Q(z)·z⁻¹·P(z)`` (:meth:`RigidSumObserver.output_filter_frf`); with exact parameters and
proportional damping F̂ = L·F to round-off. The thesis' pseudo-differentiation cutoff g_LPF is
folded into Q (an extra pole would only lower the band).

Delays: each input passes a :class:`~millsense.estimation.dob.phase_lag.StreamingDelay` (T_1 for
the current, T_2/T_3 for the encoders, Yamada §2.4) before the sum.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.estimation.dob.phase_lag import StreamingDelay
from millsense.models.drive_plant import MechanicalPlant
from millsense.streaming.block import Block, BlockOutput, Chunk

FloatArray = NDArray[np.float64]
DisturbanceTable = Callable[[FloatArray], FloatArray]
"""Position-indexed disturbance (Yamada §2.9): table position (m) → force (N), vectorised."""


@dataclass(frozen=True)
class DriveParameters:
    """Nominal (identified) parameters of a dual-inertia ball-screw drive, SI (Table 3-3).

    Attributes
    ----------
    torque_constant_nm_a : K_tn, N·m/A.
    lead_m : ball-screw lead ℓ, m (R = ℓ/2π).
    rotor_inertia_kg_m2 : J_rn (motor + coupling + screw), kg·m².
    table_mass_kg : M_tn, kg.
    rotary_damping_nm_s_rad : D_rn, N·m·s/rad.
    table_damping_n_s_m : C_tn, N·s/m.
    axial_stiffness_n_m : K_rn, N/m (vibration-mode estimator only).
    axial_damping_n_s_m : C_kn, N·s/m (vibration-mode estimator only).
    """

    torque_constant_nm_a: float
    lead_m: float
    rotor_inertia_kg_m2: float
    table_mass_kg: float
    rotary_damping_nm_s_rad: float = 0.0
    table_damping_n_s_m: float = 0.0
    axial_stiffness_n_m: float = 0.0
    axial_damping_n_s_m: float = 0.0

    @property
    def transmission_m_rad(self) -> float:
        """R = ℓ/2π, m/rad."""
        return self.lead_m / (2.0 * math.pi)

    @property
    def rotor_mass_kg(self) -> float:
        """M_r = J_r/R², kg."""
        return self.rotor_inertia_kg_m2 / self.transmission_m_rad**2

    @property
    def rotor_damping_n_s_m(self) -> float:
        """C_r = D_r/R², N·s/m."""
        return self.rotary_damping_nm_s_rad / self.transmission_m_rad**2

    @property
    def inertia_ratio(self) -> float:
        """α = M_t/M_r (Yamada Eq. 2-6)."""
        return self.table_mass_kg / self.rotor_mass_kg

    @property
    def force_constant_n_a(self) -> float:
        """K_t/R, N/A (thrust per ampere)."""
        return self.torque_constant_nm_a / self.transmission_m_rad

    @classmethod
    def from_axis_config(cls, axis: object) -> DriveParameters:
        """The preset's true values (for exact-parameter checks only; acceptance runs use
        :func:`identify_drive_parameters`)."""
        from millsense.core.config import FeedAxisConfig

        if not isinstance(axis, FeedAxisConfig) or axis.ball_screw is None:
            raise ConfigError("axis: a ball_screw table is required for a MEDOB")
        if axis.lead_mm_rev is None:
            raise ConfigError("axis: lead_mm_rev is required for a MEDOB")
        bs = axis.ball_screw
        return cls(
            torque_constant_nm_a=axis.torque_constant_nm_a,
            lead_m=axis.lead_mm_rev * 1e-3,
            rotor_inertia_kg_m2=axis.inertia_kg_m2,
            table_mass_kg=bs.table_mass_kg,
            rotary_damping_nm_s_rad=bs.rotary_damping_nm_s_rad,
            table_damping_n_s_m=bs.table_damping_n_s_m,
            axial_stiffness_n_m=bs.axial_stiffness_n_um * 1e6,
            axial_damping_n_s_m=bs.axial_damping_n_s_m,
        )


@dataclass(frozen=True)
class RigidSum:
    """``Σ (M_i s² + C_i s) x_i = k_f·I − F`` over the observed coordinates.

    Attributes
    ----------
    masses_kg : M_i, kg, one per coordinate (translational).
    dampings_n_s_m : C_i, N·s/m.
    force_constant_n_a : k_f = K_t/R, N/A.
    name : what the sum is (``MEDOB``, ``DOB``...).
    """

    masses_kg: tuple[float, ...]
    dampings_n_s_m: tuple[float, ...]
    force_constant_n_a: float
    name: str = "rigid sum"

    def __post_init__(self) -> None:
        if len(self.masses_kg) != len(self.dampings_n_s_m) or not self.masses_kg:
            raise ValueError("masses and dampings must be non-empty and of equal length")
        if sum(self.masses_kg) <= 0.0:
            raise ValueError(f"total mass must be positive, got {sum(self.masses_kg)}")

    @property
    def n_coordinates(self) -> int:
        return len(self.masses_kg)

    @property
    def damping_rate(self) -> float:
        """a = ΣC_i/ΣM_i, 1/s (the proportional part of the damping)."""
        return sum(self.dampings_n_s_m) / sum(self.masses_kg)


def medob_model(p: DriveParameters, *, table_mass_factor: float = 1.0) -> RigidSum:
    """MEDOB of Yamada Eq. 2-21 on ``(x_m = Rθ_m, x_t)``.

    ``table_mass_factor`` = Q scales M_tn (Yamada Appendix B mass-error study, Eq. B-4).
    """
    return RigidSum(
        (p.rotor_mass_kg, table_mass_factor * p.table_mass_kg),
        (p.rotor_damping_n_s_m, p.table_damping_n_s_m),
        p.force_constant_n_a,
        "MEDOB",
    )


def dob_model(p: DriveParameters) -> RigidSum:
    """Conventional DOB of Yamada Eq. 2-15 on ``x_m`` with M_a = M_r + M_t, C_a = C_r + C_t."""
    return RigidSum(
        (p.rotor_mass_kg + p.table_mass_kg,),
        (p.rotor_damping_n_s_m + p.table_damping_n_s_m,),
        p.force_constant_n_a,
        "DOB",
    )


def triple_medob_model(
    rotor_mass_kg: float,
    nut_mass_kg: float,
    table_mass_kg: float,
    force_constant_n_a: float,
    dampings_n_s_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    *,
    reduced: str = "none",
) -> RigidSum:
    """Triple-inertia observers (Yamada Eq. 2-49, 2-64, 2-65).

    Parameters
    ----------
    rotor_mass_kg, nut_mass_kg, table_mass_kg : M_r, M_n, M_t, kg.
    force_constant_n_a : K_t/R, N/A.
    dampings_n_s_m : C_r, C_n, C_t, N·s/m.
    reduced : ``none`` — full MEDOB on ``(x_m, x_n, x_t)`` (Eq. 2-49); ``medob`` — nut lumped
        on the motor, coordinates ``(x_m, x_t)`` (Eq. 2-65); ``dob`` — all lumped on ``x_m``
        (Eq. 2-64).
    """
    cr, cn, ct = dampings_n_s_m
    if reduced == "none":
        return RigidSum(
            (rotor_mass_kg, nut_mass_kg, table_mass_kg),
            (cr, cn, ct),
            force_constant_n_a,
            "triple MEDOB",
        )
    if reduced == "medob":
        return RigidSum(
            (rotor_mass_kg + nut_mass_kg, table_mass_kg),
            (cr + cn, ct),
            force_constant_n_a,
            "reduced MEDOB",
        )
    if reduced == "dob":
        return RigidSum(
            (rotor_mass_kg + nut_mass_kg + table_mass_kg,),
            (cr + cn + ct,),
            force_constant_n_a,
            "reduced DOB",
        )
    raise ValueError(f"reduced must be none, medob or dob, got {reduced!r}")


def zoh_weights(rate_1_s: float, dt: float) -> tuple[float, float, float]:
    """(b₁, b₀, E) of the ZOH map of ``1/(s(s + a))``: ``(b₁z + b₀)/((z − 1)(z − E))``."""
    x = rate_1_s * dt
    e = math.exp(-x)
    if abs(x) < 1e-3:
        # series (cancellation in the closed form)
        b1 = dt * dt * (0.5 - x / 6.0 + x * x / 24.0 - x**3 / 120.0)
        b0 = dt * dt * (0.5 - x / 3.0 + x * x / 8.0 - x**3 / 30.0)
    else:
        a2 = rate_1_s * rate_1_s
        b1 = (x - 1.0 + e) / a2
        b0 = (1.0 - e - x * e) / a2
    return b1, b0, e


def butterworth_sos(order: int, cutoff_hz: float, sample_rate_hz: float) -> FloatArray:
    """Digital Butterworth low-pass (bilinear), second-order sections."""
    if not 0.0 < cutoff_hz < 0.5 * sample_rate_hz:
        raise ConfigError(
            f"observer: cutoff_hz must be in (0, {0.5 * sample_rate_hz:g}) Hz, got {cutoff_hz}"
        )
    if order < 1:
        raise ConfigError(f"observer: filter order must be ≥ 1, got {order}")
    return np.asarray(signal.butter(order, cutoff_hz, fs=sample_rate_hz, output="sos"))


class CurrentLoopModel:
    """Mean torque current over each sample behind a first-order current loop, streaming.

    For a command I held over a sample and the loop ``ω/(s + ω)``: ``I_a[k+1] = I[k] +
    (I_a[k] − I[k])·E`` and the mean over the sample ``Ī[k] = I[k] + (I_a[k] − I[k])(1 − E)/x``
    with ``x = ωT``, ``E = e^{−x}`` — the held input the ZOH-exact rigid sum expects.

    Parameters
    ----------
    bandwidth_hz : loop bandwidth ω/2π, Hz (Yamada Table 3-2: 5000 rad/s on Machine B).
    sample_rate_hz : Hz.
    """

    def __init__(self, bandwidth_hz: float, sample_rate_hz: float) -> None:
        self.bandwidth_hz = bandwidth_hz
        if not bandwidth_hz > 0.0:
            raise ConfigError(f"current loop: bandwidth_hz must be > 0, got {bandwidth_hz}")
        self.x = 2.0 * math.pi * bandwidth_hz / sample_rate_hz
        self.e = math.exp(-self.x)
        self._sos = np.array([[0.0, 1.0 - self.e, 0.0, 1.0, -self.e, 0.0]])
        self._state: float | None = None

    def reset(self) -> None:
        self._state = None

    def process(self, command_a: ArrayLike) -> FloatArray:
        i = np.asarray(command_a, dtype=float)
        if i.size == 0:
            return np.zeros(0)
        if self._state is None:
            self._state = float(i[0])
        # I_a[k] = E·I_a[k−1] + (1 − E)·I[k−1] as one first-order section whose state is I_a
        # at the chunk start
        zi = np.array([[self._state, 0.0]])
        ia = _sos_kernel(self._sos, np.ascontiguousarray(i), zi)
        self._state = float(zi[0, 0])
        return np.asarray(i + (ia - i) * (1.0 - self.e) / self.x, dtype=float)


@numba.njit(cache=True)
def _sos_kernel(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Second-order sections in transposed direct form II (as scipy's sosfilt), zi in place."""
    y = np.empty_like(x)
    for k in range(x.shape[0]):
        v = x[k]
        for j in range(sos.shape[0]):
            o = sos[j, 0] * v + zi[j, 0]
            zi[j, 0] = sos[j, 1] * v - sos[j, 4] * o + zi[j, 1]
            zi[j, 1] = sos[j, 2] * v - sos[j, 5] * o
            v = o
        y[k] = v
    return y


class StreamingSOS:
    """A second-order-section filter run chunk by chunk in numba (scipy's sosfilt costs
    ~0.1 ms per call, too much for 10 ms chunks); starts in steady state on its first input.

    Parameters
    ----------
    sos : (n, 6) sections with a0 = 1.
    """

    def __init__(self, sos: FloatArray) -> None:
        self.sos = np.ascontiguousarray(sos, dtype=np.float64)
        self._zi_unit = np.asarray(signal.sosfilt_zi(self.sos), dtype=np.float64)
        self._zi: FloatArray | None = None

    def reset(self) -> None:
        self._zi = None

    def process(self, x: ArrayLike) -> FloatArray:
        xa = np.ascontiguousarray(x, dtype=np.float64)
        if xa.size == 0:
            return np.zeros(0)
        if self._zi is None:
            self._zi = np.ascontiguousarray(self._zi_unit * xa[0])
        return np.asarray(_sos_kernel(self.sos, xa, self._zi))


@dataclass
class _Tail:
    """Last two samples of the sum's signals (carried between chunks)."""

    y: FloatArray = field(default_factory=lambda: np.zeros(0))
    e: FloatArray = field(default_factory=lambda: np.zeros(0))
    i: FloatArray = field(default_factory=lambda: np.zeros(0))


class RigidSumObserver:
    """Streaming rigid-body-sum observer (MEDOB, DOB, triple MEDOB), chunk-size invariant.

    Parameters
    ----------
    model : masses, dampings and K_t/R of the observed coordinates.
    sample_rate_hz : CNC sample rate, Hz.
    cutoff_hz : output Butterworth cutoff g_cut, Hz (Yamada: 500 Hz Machine B, 1 kHz sim).
    order : Butterworth order (4, Yamada §2.3).
    current_delay_s : T_1, s (phase-lag compensation of the current command).
    coordinate_delays_s : T_2, T_3 … per coordinate, s (default 0).
    disturbance_table : optional position-indexed disturbance (idling table, Yamada §2.9),
        subtracted from the filtered estimate at the table position given to :meth:`process`.
    current_loop_hz : bandwidth of a first-order current loop between command and torque, Hz
        (None: ideal, as the thesis assumes, §4.2.2). When given, the current command passes
        :class:`CurrentLoopModel` (the torque's mean over each sample) before the sum.

    Notes
    -----
    See the module docstring for the discrete form. Before the first sample, every input is
    taken to have held its first value and the output filter starts in steady state on the
    first raw estimate.
    """

    def __init__(
        self,
        model: RigidSum,
        sample_rate_hz: float,
        *,
        cutoff_hz: float,
        order: int = 4,
        current_delay_s: float = 0.0,
        coordinate_delays_s: Sequence[float] | None = None,
        disturbance_table: DisturbanceTable | None = None,
        current_loop_hz: float | None = None,
    ) -> None:
        self.model = model
        self.current_loop_hz = current_loop_hz
        self.sample_rate_hz = float(sample_rate_hz)
        self.dt = 1.0 / self.sample_rate_hz
        self.cutoff_hz = float(cutoff_hz)
        self.order = int(order)
        self.sos = butterworth_sos(self.order, self.cutoff_hz, self.sample_rate_hz)
        delays = (
            [0.0] * model.n_coordinates
            if coordinate_delays_s is None
            else [float(d) for d in coordinate_delays_s]
        )
        if len(delays) != model.n_coordinates:
            raise ConfigError(
                f"observer: {len(delays)} coordinate delays for {model.n_coordinates} coordinates"
            )
        self.current_delay_s = float(current_delay_s)
        self.coordinate_delays_s = tuple(delays)
        self.disturbance_table = disturbance_table
        self.a = model.damping_rate
        self.b1, self.b0, self.e_pole = zoh_weights(self.a, self.dt)
        self._m = np.asarray(model.masses_kg, dtype=float)
        self._ce = np.asarray(model.dampings_n_s_m, dtype=float) - self.a * self._m
        self.reset()

    def reset(self) -> None:
        """Forget all state."""
        self._d_i = StreamingDelay(self.current_delay_s * self.sample_rate_hz)
        self._loop = (
            None
            if self.current_loop_hz is None
            else CurrentLoopModel(self.current_loop_hz, self.sample_rate_hz)
        )
        self._d_x = [StreamingDelay(d * self.sample_rate_hz) for d in self.coordinate_delays_s]
        self._tail: _Tail | None = None
        self._out = StreamingSOS(self.sos)

    @property
    def latency_samples(self) -> int:
        """Samples between a force at the plant and its raw estimate (excluding sensor dead
        times and T_2/T_3): 1."""
        return 1

    def output_filter_frf(self, f_hz: ArrayLike) -> NDArray[np.complex128]:
        """``L(e^{jωT}) = Q·z⁻¹·P``: F̂/F with exact parameters (module docstring)."""
        f = np.asarray(f_hz, dtype=float)
        _, q = signal.sosfreqz(self.sos, worN=f, fs=self.sample_rate_hz)
        zi = np.exp(-2j * np.pi * f * self.dt)
        p = (self.b1 + self.b0 * zi) / (self.b1 + self.b0)
        return np.asarray(q * zi * p, dtype=complex)

    def output_filter(self, force: ArrayLike) -> FloatArray:
        """Apply ``L(z)`` to a force record from rest (reference for error figures)."""
        x = np.asarray(force, dtype=float)
        s = self.b1 + self.b0
        p = signal.lfilter([0.0, self.b1 / s, self.b0 / s], [1.0], x)
        return np.asarray(signal.sosfilt(self.sos, p), dtype=float)

    def raw(self, current_a: ArrayLike, coordinates_m: Sequence[ArrayLike]) -> FloatArray:
        """Unfiltered estimate of ``P(z)·F`` one sample late, N (updates the state)."""
        cur = self._d_i.process(current_a)
        if self._loop is not None:
            cur = self._loop.process(cur)
        n = len(cur)
        if len(coordinates_m) != self.model.n_coordinates:
            raise ValueError(
                f"{len(coordinates_m)} coordinate signals for {self.model.n_coordinates}"
            )
        if n == 0:
            return np.zeros(0)
        xs = [d.process(x) for d, x in zip(self._d_x, coordinates_m, strict=True)]
        y = np.zeros(n)
        e = np.zeros(n)
        for mi, ci, x in zip(self._m, self._ce, xs, strict=True):
            if len(x) != n:
                raise ValueError("all input signals of a chunk must have the same length")
            y += mi * x
            if ci != 0.0:
                e += ci * x
        if self._tail is None:
            self._tail = _Tail(np.full(2, y[0]), np.full(2, e[0]), np.full(2, cur[0]))
        ye = np.concatenate([self._tail.y, y])
        ee = np.concatenate([self._tail.e, e])
        ie = np.concatenate([self._tail.i, cur])
        self._tail = _Tail(ye[-2:].copy(), ee[-2:].copy(), ie[-2:].copy())
        b1, b0, ep, dt = self.b1, self.b0, self.e_pole, self.dt
        # sample k of the chunk is index k + 2 of the extended arrays
        d2 = ye[2:] - (1.0 + ep) * ye[1:-1] + ep * ye[:-2]
        de = (b1 / dt) * (ee[2:] - ee[1:-1]) + (b0 / dt) * (ee[1:-1] - ee[:-2])
        thrust = self.model.force_constant_n_a * (b1 * ie[1:-1] + b0 * ie[:-2])
        return np.asarray((thrust - d2 - de) / (b1 + b0), dtype=float)

    def process(
        self,
        current_a: ArrayLike,
        coordinates_m: Sequence[ArrayLike],
        table_position_m: ArrayLike | None = None,
    ) -> FloatArray:
        """Filtered estimate F̂_cut, N (resisting the +motion, Yamada Eq. 2-2 sign).

        Parameters
        ----------
        current_a : current command I^ref, A.
        coordinates_m : one signal per coordinate, m (motor angle already multiplied by R).
        table_position_m : scale position, m; required with a disturbance table.
        """
        r = self.raw(current_a, coordinates_m)
        if r.size == 0:
            return r
        out = self._out.process(r)
        if self.disturbance_table is not None:
            if table_position_m is None:
                raise ValueError("a disturbance table needs the table position")
            out = out - np.asarray(
                self.disturbance_table(np.asarray(table_position_m, dtype=float)), dtype=float
            )
        return out


def medob_observer(
    p: DriveParameters,
    sample_rate_hz: float,
    *,
    cutoff_hz: float,
    order: int = 4,
    delays_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    table_mass_factor: float = 1.0,
    disturbance_table: DisturbanceTable | None = None,
    current_loop_hz: float | None = None,
) -> RigidSumObserver:
    """MEDOB (Yamada Eq. 2-21) with delays ``(T_1, T_2, T_3)`` on (current, angle, scale)."""
    return RigidSumObserver(
        medob_model(p, table_mass_factor=table_mass_factor),
        sample_rate_hz,
        cutoff_hz=cutoff_hz,
        order=order,
        current_delay_s=delays_s[0],
        coordinate_delays_s=(delays_s[1], delays_s[2]),
        disturbance_table=disturbance_table,
        current_loop_hz=current_loop_hz,
    )


def dob_observer(
    p: DriveParameters,
    sample_rate_hz: float,
    *,
    cutoff_hz: float,
    order: int = 4,
    delays_s: tuple[float, float] = (0.0, 0.0),
    disturbance_table: DisturbanceTable | None = None,
    current_loop_hz: float | None = None,
) -> RigidSumObserver:
    """Conventional DOB (Yamada Eq. 2-15) with delays ``(T_1, T_2)`` on (current, angle)."""
    return RigidSumObserver(
        dob_model(p),
        sample_rate_hz,
        cutoff_hz=cutoff_hz,
        order=order,
        current_delay_s=delays_s[0],
        coordinate_delays_s=(delays_s[1],),
        disturbance_table=disturbance_table,
        current_loop_hz=current_loop_hz,
    )


class MEDOBBlock(Block):
    """Streaming block: MEDOB (or DOB) cutting force of one ball-screw axis.

    Parameters
    ----------
    axis : axis name; reads ``{axis}/current_cmd`` (A), ``{axis}/motor_angle`` (rad) and, for
        the MEDOB, ``{axis}/scale`` (m); writes ``{axis}/force_{kind}`` (N, resisting +motion).
    params : nominal drive parameters.
    kind : ``medob`` or ``dob``.
    cutoff_hz, order : output Butterworth.
    delays_s : phase-lag compensation (T_1, T_2, T_3), s (T_3 unused by the DOB).
    disturbance_table : idling table position → force (N), subtracted (MEDOB: at the scale
        position; DOB: at ``R·θ_m``).
    current_loop_hz : first-order current-loop bandwidth, Hz (None: ideal current loop).
    """

    def __init__(
        self,
        axis: str,
        params: DriveParameters,
        *,
        kind: str = "medob",
        cutoff_hz: float = 500.0,
        order: int = 4,
        delays_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
        disturbance_table: DisturbanceTable | None = None,
        current_loop_hz: float | None = None,
    ) -> None:
        if kind not in ("medob", "dob"):
            raise ConfigError(f"observer kind must be medob or dob, got {kind!r}")
        self.axis = axis
        self.params = params
        self.kind = kind
        self.cutoff_hz = cutoff_hz
        self.order = order
        self.delays_s = delays_s
        self.disturbance_table = disturbance_table
        self.current_loop_hz = current_loop_hz
        self.name = f"{kind}_{axis}"
        base = (f"{axis}/current_cmd", f"{axis}/motor_angle")
        self.inputs = base + ((f"{axis}/scale",) if kind == "medob" else ())
        self._out = f"{axis}/force_{kind}"
        self._obs: RigidSumObserver | None = None

    def output_channels(self) -> list[ChannelInfo]:
        eq = "Eq. 2-21" if self.kind == "medob" else "Eq. 2-15"
        return [
            ChannelInfo(
                self._out,
                "N",
                f"{self.axis} cutting force by the {self.kind.upper()} (Yamada {eq}), "
                f"{self.order}th-order Butterworth {self.cutoff_hz:g} Hz",
            )
        ]

    def reset(self, sample_rate_hz: float) -> None:
        if self.kind == "medob":
            self._obs = medob_observer(
                self.params,
                sample_rate_hz,
                cutoff_hz=self.cutoff_hz,
                order=self.order,
                delays_s=self.delays_s,
                disturbance_table=self.disturbance_table,
                current_loop_hz=self.current_loop_hz,
            )
        else:
            self._obs = dob_observer(
                self.params,
                sample_rate_hz,
                cutoff_hz=self.cutoff_hz,
                order=self.order,
                delays_s=(self.delays_s[0], self.delays_s[1]),
                disturbance_table=self.disturbance_table,
                current_loop_hz=self.current_loop_hz,
            )

    def process(self, chunk: Chunk) -> BlockOutput:
        if self._obs is None:
            raise RuntimeError(f"block {self.name}: reset() was not called")
        cur = np.asarray(chunk.data[self.inputs[0]], dtype=float)
        xm = self.params.transmission_m_rad * np.asarray(chunk.data[self.inputs[1]], dtype=float)
        if self.kind == "medob":
            xt = np.asarray(chunk.data[self.inputs[2]], dtype=float)
            est = self._obs.process(cur, [xm, xt], xt)
        else:
            est = self._obs.process(cur, [xm], xm)
        return BlockOutput({self._out: est})


# ---------------------------------------------------------------- frequency responses


def coordinate_frf(
    plant: MechanicalPlant, f_hz: ArrayLike, transmission_m_rad: float
) -> NDArray[np.complex128]:
    """Continuous FRF of every generalised coordinate to (motor torque, load force).

    Returns
    -------
    (nf, nq, 2) complex: translational coordinates (the motor angle times R), m per N·m and
    m per N (load resisting, as the plant's input 1).
    """
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    n = plant.a.shape[0]
    nq = n // 2
    out = np.empty((len(f), nq, 2), dtype=complex)
    eye = np.eye(n)
    scale = np.ones(nq)
    scale[0] = transmission_m_rad
    for k, fk in enumerate(f):
        x = np.linalg.solve(2j * np.pi * fk * eye - plant.a, plant.b[:, :2])
        out[k] = x[:nq] * scale[:, None]
    return out


def rigid_sum_frf(
    plant: MechanicalPlant,
    model: RigidSum,
    coordinates: Sequence[int],
    f_hz: ArrayLike,
    *,
    torque_constant_nm_a: float,
    transmission_m_rad: float,
    lowpass: Callable[[NDArray[np.complex128]], NDArray[np.complex128]] | None = None,
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Analytic (continuous, ideal differentiation) FRFs F̂/F and F̂/I of a rigid-sum observer.

    Parameters
    ----------
    plant : the true plant (Yamada Eq. 2-1/2-2 or 2-45…2-47).
    model : the observer's sum.
    coordinates : plant coordinate index observed by each model coordinate (0 = motor).
    f_hz : frequencies, Hz.
    torque_constant_nm_a : true K_t of the plant, N·m/A.
    transmission_m_rad : R, m/rad.
    lowpass : Q(s) as a function of s (None: 1).

    Returns
    -------
    (F̂/F, F̂/I) complex arrays; with exact parameters F̂/F = Q and F̂/I = 0 (Yamada §2.3).
    """
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    s = 2j * np.pi * f
    g = coordinate_frf(plant, f, transmission_m_rad)
    acc_f = np.zeros(len(f), dtype=complex)
    acc_t = np.zeros(len(f), dtype=complex)
    for mi, ci, q in zip(model.masses_kg, model.dampings_n_s_m, coordinates, strict=True):
        op = mi * s * s + ci * s
        acc_t += op * g[:, q, 0]
        acc_f += op * g[:, q, 1]
    h_f = -acc_f
    h_i = model.force_constant_n_a - torque_constant_nm_a * acc_t
    qs = np.ones(len(f), dtype=complex) if lowpass is None else lowpass(s)
    return np.asarray(qs * h_f), np.asarray(qs * h_i)


def butterworth_analog(
    order: int, cutoff_hz: float
) -> Callable[[NDArray[np.complex128]], NDArray[np.complex128]]:
    """Q(s) of an analog Butterworth low-pass (Yamada: 4th order)."""
    b, a = signal.butter(order, 2.0 * np.pi * cutoff_hz, analog=True)

    def q(s: NDArray[np.complex128]) -> NDArray[np.complex128]:
        return np.asarray(np.polyval(b, s) / np.polyval(a, s), dtype=complex)

    return q


def dual_inertia_ratios(p: DriveParameters) -> dict[str, float]:
    """ω_t, ω_s, α, ζ_r, ζ_k, ζ_t of Yamada Eq. 2-5/2-6 (SI)."""
    mt, kr = p.table_mass_kg, p.axial_stiffness_n_m
    wt = math.sqrt(kr / mt)
    alpha = p.inertia_ratio
    return {
        "omega_t": wt,
        "omega_s": math.sqrt(alpha + 1.0) * wt,
        "alpha": alpha,
        "zeta_r": p.rotor_damping_n_s_m / (2.0 * wt * mt),
        "zeta_k": p.axial_damping_n_s_m / (2.0 * wt * mt),
        "zeta_t": p.table_damping_n_s_m / (2.0 * wt * mt),
    }


def _d_poly(r: dict[str, float]) -> NDArray[np.float64]:
    wt, ws, al = r["omega_t"], r["omega_s"], r["alpha"]
    zr, zk, zt = r["zeta_r"], r["zeta_k"], r["zeta_t"]
    return np.array(
        [
            1.0,
            2.0 * wt * (al * zr + (al + 1.0) * zk + zt),
            ws**2 + 4.0 * al * (zr * zt + zr * zk + zt * zk) * wt**2,
            2.0 * al * (zr + zt) * wt**3,
        ]
    )


def dob_frf_closed_form(p: DriveParameters, f_hz: ArrayLike) -> NDArray[np.complex128]:
    """Conventional-DOB F̂/F without its low-pass, Yamada Eq. 2-19 with the s³ erratum.

    ``N(s) = [2(1+α)ζ_kω_t s³ + {4αζ_k(ζ_r+ζ_t)ω_t² + ω_s²}s² + 2α(ζ_r+ζ_t)ω_t³ s]/(s·D(s))``
    (digest §2.2: the thesis prints 2ζ_kω_s for the s³ coefficient).
    """
    r = dual_inertia_ratios(p)
    wt, ws, al = r["omega_t"], r["omega_s"], r["alpha"]
    zr, zk, zt = r["zeta_r"], r["zeta_k"], r["zeta_t"]
    num = np.array(
        [
            2.0 * (1.0 + al) * zk * wt,
            4.0 * al * zk * (zr + zt) * wt**2 + ws**2,
            2.0 * al * (zr + zt) * wt**3,
        ]
    )
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    return np.asarray(np.polyval(num, s) / np.polyval(_d_poly(r), s), dtype=complex)


def medob_mass_error_frf(
    p: DriveParameters, table_mass_factor: float, f_hz: ArrayLike
) -> NDArray[np.complex128]:
    """MEDOB F̂/F without its low-pass for M_tn = Q·M_t, Yamada Eq. B-4/B-5 (a₂ erratum).

    ``(a₃s³ + a₂s² + a₁s + a₀)/D(s)`` with a₃ = Q, a₂ = 2ω_t{Qαζ_r + (Qα+1)ζ_k + ζ_t},
    a₁ = ω_t²{4α(ζ_tζ_r + ζ_kζ_t + ζ_rζ_k) + Qα + 1}, a₀ = 2αω_t³(ζ_r + ζ_t).
    """
    r = dual_inertia_ratios(p)
    wt, al = r["omega_t"], r["alpha"]
    zr, zk, zt = r["zeta_r"], r["zeta_k"], r["zeta_t"]
    q = table_mass_factor
    num = np.array(
        [
            q,
            2.0 * wt * (q * al * zr + (q * al + 1.0) * zk + zt),
            wt**2 * (4.0 * al * (zt * zr + zk * zt + zr * zk) + q * al + 1.0),
            2.0 * al * wt**3 * (zr + zt),
        ]
    )
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    return np.asarray(np.polyval(num, s) / np.polyval(_d_poly(r), s), dtype=complex)


# ---------------------------------------------------------------- identification


def identify_drive_parameters(
    current_a: ArrayLike,
    angle_rad: ArrayLike,
    scale_m: ArrayLike,
    sample_rate_hz: float,
    *,
    torque_constant_nm_a: float,
    lead_m: float,
    delays_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    band_hz: tuple[float, float] = (5.0, 1000.0),
    current_loop_hz: float | None = None,
    stiffness_band_hz: tuple[float, float] | None = None,
) -> DriveParameters:
    """Identify J_r, M_t, D_r, C_t, K_r, C_k from an air sweep by linear least squares.

    Parameters
    ----------
    current_a, angle_rad, scale_m : CNC signals of a current-injection sweep at constant feed
        (no cutting), A, rad, m.
    sample_rate_hz : Hz.
    torque_constant_nm_a : K_t (catalogue; not identifiable from motion, Yamada §3.2).
    lead_m : ℓ, m.
    delays_s : phase-lag compensation (T_1, T_2, T_3), s.
    band_hz : every regressor and the regressand are band-passed (4th-order Butterworth each
        side) to this band — linear filters keep the equations, and remove friction offset,
        lead ripple and quantisation noise.
    current_loop_hz : first-order current-loop bandwidth, Hz (:class:`CurrentLoopModel`).
    stiffness_band_hz : band of a second K_r fit (C_k kept from ``band_hz``); a band well below
        the first unmodelled mode gives the quasi-static stiffness the vibration-mode
        estimator needs on a stationary axis.

    Returns
    -------
    DriveParameters.

    Notes
    -----
    Time-domain form of Yamada C11 (the thesis fits FRFs), second differences at sample k − 1
    as in the observers: the table equation (Eq. 2-2, no load)
    ``a_t = (K_r Δx + C_k Δẋ − C_t v_t)/M_t`` gives K_r, C_k, C_t per unit table mass; the
    rigid sum (Eq. 2-20) ``K_t·Ī/R = M_r a_m + C_r v_m + M_t(a_t + (C_t/M_t) v_t)`` then gives
    M_r, C_r and M_t. K_r and C_k are then refitted so that the vibration-mode equation
    (:mod:`.mode_decoupled`, Eq. 2-44) holds in the air sweep: on a drive with more modes than
    the dual-inertia model this is the stiffness that makes that estimator right in the band.
    """
    fs = float(sample_rate_hz)
    dt = 1.0 / fs
    r = lead_m / (2.0 * math.pi)
    cur = StreamingDelay(delays_s[0] * fs).process(current_a)
    if current_loop_hz is not None:
        cur = CurrentLoopModel(current_loop_hz, fs).process(cur)
    xm = StreamingDelay(delays_s[1] * fs).process(r * np.asarray(angle_rad, dtype=float))
    xt = StreamingDelay(delays_s[2] * fs).process(scale_m)
    sos = signal.butter(4, band_hz, btype="bandpass", fs=fs, output="sos")

    # sample k refers to time k − 1: a = Δ²x/T², v = (x_k − x_{k−2})/2T, Ī = (I_{k−1}+I_{k−2})/2
    def acc(x: FloatArray) -> FloatArray:
        return (x[2:] - 2.0 * x[1:-1] + x[:-2]) / (dt * dt)

    def vel(x: FloatArray) -> FloatArray:
        return (x[2:] - x[:-2]) / (2.0 * dt)

    thrust = (torque_constant_nm_a / r) * 0.5 * (cur[1:-1] + cur[:-2])
    am, at, vm, vt = acc(xm), acc(xt), vel(xm), vel(xt)
    dx = (xm - xt)[1:-1]
    dv = vm - vt
    trim = slice(int(0.05 * fs), len(am) - int(0.05 * fs))

    sos_k = (
        sos
        if stiffness_band_hz is None
        else signal.butter(4, stiffness_band_hz, btype="bandpass", fs=fs, output="sos")
    )

    def lsq(cols: tuple[FloatArray, ...], rhs: FloatArray, sos_: FloatArray = sos) -> FloatArray:
        def f(x: FloatArray) -> FloatArray:
            return np.asarray(signal.sosfiltfilt(sos_, x), dtype=float)[trim]

        a = np.column_stack([f(c) for c in cols])
        sc = np.max(np.abs(a), axis=0)
        return np.asarray(np.linalg.lstsq(a / sc, f(rhs), rcond=None)[0] / sc)

    # table equation per unit table mass: a_t = (K_r Δx + C_k Δv − C_t v_t)/M_t
    kr_m, ck_m, ct_m = (float(v) for v in lsq((dx, dv, -vt), at))
    # rigid sum with the table's damping ratio known: K_t Ī/R = M_r a_m + C_r v_m + M_t(a_t + c v_t)
    mr, cr, mt = (float(v) for v in lsq((am, vm, at + ct_m * vt), thrust))
    ct = ct_m * mt
    # K_r, C_k so that the vibration-mode equation (Eq. 2-44 expanded, no load) holds:
    # (1+α)(K_r Δx + C_k Δẋ) = α K_t Ī/R − M_t(a_m − a_t) − α C_r v_m + C_t v_t
    alpha = mt / mr
    rhs_v = alpha * thrust - mt * (am - at) - alpha * cr * vm + ct * vt
    kr, ck = (float(v) for v in lsq(((1.0 + alpha) * dx, (1.0 + alpha) * dv), rhs_v))
    if stiffness_band_hz is not None:
        # C_k from the full band; K_r alone from the quasi-static band
        kr = float(lsq(((1.0 + alpha) * dx,), rhs_v - (1.0 + alpha) * ck * dv, sos_k)[0])
    del kr_m, ck_m
    return DriveParameters(
        torque_constant_nm_a=torque_constant_nm_a,
        lead_m=lead_m,
        rotor_inertia_kg_m2=mr * r * r,
        table_mass_kg=mt,
        rotary_damping_nm_s_rad=cr * r * r,
        table_damping_n_s_m=ct,
        axial_stiffness_n_m=kr,
        axial_damping_n_s_m=ck,
    )


def with_table_mass(p: DriveParameters, factor: float) -> DriveParameters:
    """Copy of ``p`` with M_tn scaled by ``factor`` (Table 4-7 0.5/1.5 M_tn rows)."""
    return replace(p, table_mass_kg=p.table_mass_kg * factor)
