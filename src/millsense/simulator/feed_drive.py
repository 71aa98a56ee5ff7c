"""Feed-drive simulator: one kernel for rigid, structural-mode and ball-screw drives.

Plant. A linear mechanical part ``ẋ = A x + B u`` with inputs ``u = [τ_m, F, δ]`` — net motor
torque (N·m), load at the table (N for linear axes, N·m for rotary; positive resists +motion)
and kinematic screw error (m) — built by :func:`rigid_plant` (Aslan Eq. 3.1) or by
:mod:`.ball_screw` (Yamada Eq. 2-1/2-2 dual inertia, Eq. 2-45…2-47 triple inertia). Nonlinear
and position-dependent parts act on the motor: friction (Coulomb + viscous, or LuGre Aslan
Eq. 3.2–3.9), position-periodic torques (Yamada §3.6), white torque noise (Aslan Eq. 3.30).
Optionally the load reaches the motor through structural disturbance modes
``τ_c = Φ_d(s)·τ_a`` with ``τ_a = (r_g/η)·F`` (Aslan Eq. 3.11, 3.13, Table 3.4), realised in
balanced 2×2 modal blocks (:mod:`.modal_ss`): then the motor equation is
``J_e·dω/dt = K_t·i − τ_f − τ_c`` (Eq. 3.1) and the load does not act on the plant directly.

Controller at the sample rate: position P (gain K_v; motor encoder or linear scale feedback),
velocity PI (K_p, K_i) on the backward difference of the motor encoder, velocity
feed-forward; ``i_cmd = τ_cmd/K_t`` plus an optional injected current (for sine sweeps).
Actuation: dead time T_s, then a current loop — first order of the given bandwidth, or a PI on
the motor electrics ``L di/dt = u − R i − K_e ω``. Sensors: motor encoder quantised to its
counts, linear scale to its resolution, each after its interpolation error and dead time
(T_m, T_t; Yamada Table 3-3).

Position-dependent modes (optional, decision "Position-dependent disturbance modes"): every
mode frequency follows the true load position x, ``f_k(x) = f_k0·λ(x)``, ``λ = 1 + κ·(x − x_ref)``,
with the mode shape kept (``Φ_k(s; λ) = Φ_k0(s/λ)``: α × λ², β × λ, ζ and the static gain
unchanged). In the balanced block of :mod:`.modal_ss` with B held at its reference value this is
``A = λ·A_0``, ``C = λ·C_0``; the blocks are re-discretised in closed form (rotation × decay)
from the position at the start of every ``mode_update_s`` (1 ms: < 0.1 mm of travel at cutting
feeds), counted in absolute samples so that chunking does not matter.

Integration: ``substeps`` steps per sample; the linear mechanics and each modal block are
advanced by their exact zero-order-hold maps, friction and position-periodic terms held over a
substep (LuGre's bristle state integrated exactly for the held speed, :mod:`.lugre`). Dead
times are rounded to whole substeps. All state lives in arrays, so :meth:`FeedDriveSim.advance`
called chunk by chunk is bit-identical to one call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numba
import numpy as np
import scipy.linalg

from millsense.core import units
from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError, InputDataError
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
    rigid_plant,
)
from millsense.models.friction import CoulombViscous, coulomb_viscous_torque
from millsense.models.lugre import LuGre, lugre_step
from millsense.models.modal_ss import ModalStateSpace


@dataclass(frozen=True)
class ElectricalCurrentLoop:
    """PI current loop on the motor electrics ``L di/dt = u − R·i − K_e·ω``.

    Attributes: resistance Ω, inductance H, back_emf V·s/rad, kp V/A, ki V/(A·s).
    ``designed`` sets ``kp = L·ω_cc``, ``ki = R·ω_cc`` (pole–zero cancellation, closed loop
    ω_cc/(s + ω_cc) apart from the back-EMF).
    """

    resistance: float
    inductance: float
    back_emf: float
    kp: float
    ki: float

    @classmethod
    def designed(
        cls, resistance: float, inductance: float, back_emf: float, bandwidth_hz: float
    ) -> ElectricalCurrentLoop:
        wc = 2.0 * math.pi * bandwidth_hz
        return cls(resistance, inductance, back_emf, inductance * wc, resistance * wc)


@dataclass(frozen=True)
class PlantSchedule:
    """Position-dependent mechanics: the plant at load positions on a uniform grid.

    The kernel interpolates the discretised plants (Ad, Bd and the output maps) linearly
    between neighbouring grid positions at the true load position, re-evaluated every
    ``mode_update_s`` like the disturbance modes (decision 0974); ``plant`` of the drive is the
    plant at the initial position. Every plant has the same states and the same position-
    independent rows for θ_m, ω_m and the load position.
    """

    positions: np.ndarray
    plants: tuple[MechanicalPlant, ...]

    def __post_init__(self) -> None:
        x = np.asarray(self.positions, dtype=float)
        if x.ndim != 1 or len(x) != len(self.plants) or len(x) < 2:
            raise ConfigError("plant schedule: need ≥ 2 positions, one plant each")
        step = np.diff(x)
        if not (np.all(step > 0) and np.allclose(step, step[0], rtol=1e-9, atol=0.0)):
            raise ConfigError("plant schedule: positions must be uniform and ascending")


@dataclass(frozen=True)
class LostMotion:
    """Backlash and preload lift-off of the element whose stretch is ``e = stretch·x + δ``
    (the screw–nut or worm–wheel spring of a coupled plant, decision 0978).

    The element's force is ``k·φ(e)`` instead of ``k·e``: no force inside the gap |e| ≤ b, then
    ``e' = e − b·sgn(e)``, and beyond the preload lift-off |e'| > e_L the stiffness drops to
    ``ratio·k``: ``φ = sgn(e')·(e_L + ratio·(|e'| − e_L))``. The kernel applies it through the
    kinematic-offset input, ``δ_eff = δ + φ(e) − e``, held over a substep.

    Attributes: stretch (n,) row on the plant state; half_gap b; lift e_L (stretch units: m,
    rad); ratio (0, 1].
    """

    stretch: np.ndarray
    half_gap: float
    lift: float
    ratio: float


@dataclass(frozen=True)
class FeedDriveParams:
    """SI parameters of a feed drive, its friction, sensors and cascade controller.

    Attributes
    ----------
    plant : linear mechanics.
    torque_constant : K_t, N·m/A.
    transmission : r_g, m/rad (rad/rad rotary).
    efficiency : η.
    friction : Coulomb + viscous, LuGre, or None.
    kp : velocity-loop proportional gain, N·m·s/rad.
    ki : velocity-loop integral gain, N·m/rad.
    kv : position-loop gain, 1/s.
    current_bandwidth_hz : first-order current loop, Hz (ignored when ``current_loop`` set).
    encoder_counts_rev : motor encoder counts per revolution.
    torque_noise_nm : RMS white torque disturbance per sample, N·m.
    current_loop : PI loop on motor electrics, or None for the first-order loop.
    scale_resolution_m : linear-scale count, m (None: no scale, the channel is the true one).
    position_feedback : ``motor`` (semi-closed) or ``scale`` (full-closed).
    dead_time_amplifier_s, dead_time_motor_encoder_s, dead_time_scale_s : T_s, T_m, T_t, s.
    modes : structural disturbance modes Φ_d (rigid plants), or None.
    periodic : position-periodic terms.
    closed_loop : False runs the drive on the injected current alone (controller off).
    mode_shift_per_m : κ, relative change of every disturbance-mode frequency per unit of load
        position, 1/m (1/rad rotary); 0 = modes independent of position.
    mode_reference_position : x_ref, load position at which ``modes`` hold, m (rad rotary).
    mode_update_s : interval at which the modes follow the position, s (rounded to samples).
    plant_schedule : position-dependent mechanics (:class:`PlantSchedule`), or None.
    lost_motion : backlash / preload lift-off of the transmission (:class:`LostMotion`), or
        None.
    """

    plant: MechanicalPlant
    torque_constant: float
    transmission: float
    efficiency: float
    friction: CoulombViscous | LuGre | None
    kp: float
    ki: float
    kv: float
    current_bandwidth_hz: float
    encoder_counts_rev: int
    torque_noise_nm: float = 0.0
    current_loop: ElectricalCurrentLoop | None = None
    scale_resolution_m: float | None = None
    position_feedback: Literal["motor", "scale"] = "motor"
    dead_time_amplifier_s: float = 0.0
    dead_time_motor_encoder_s: float = 0.0
    dead_time_scale_s: float = 0.0
    modes: ModalStateSpace | None = None
    periodic: tuple[PeriodicTerm, ...] = field(default_factory=tuple)
    closed_loop: bool = True
    mode_shift_per_m: float = 0.0
    mode_reference_position: float = 0.0
    mode_update_s: float = 1e-3
    plant_schedule: PlantSchedule | None = None
    lost_motion: LostMotion | None = None

    def mode_scale(self, position: float | np.ndarray) -> float | np.ndarray:
        """λ(x) = 1 + κ·(x − x_ref): the factor on every mode frequency at load position x (m,
        rad rotary)."""
        return 1.0 + self.mode_shift_per_m * (np.asarray(position) - self.mode_reference_position)

    def modes_at(self, position: float) -> ModalStateSpace | None:
        """The disturbance modes at a fixed load position x (m; rad rotary), Eq. 3.13 form.

        Frequencies × λ(x), α × λ², β × λ (the same mode shape on a scaled frequency axis,
        ``Φ(s/λ)``), damping ratios and feed-through unchanged; None without modes.
        """
        if self.modes is None:
            return None
        lam = float(self.mode_scale(position))
        if not lam > 0:
            raise InputDataError(
                f"feed drive: mode frequency factor {lam:g} at position {position:g} (need > 0)"
            )
        return self.modes.frequency_scaled(lam)

    @classmethod
    def from_config(
        cls,
        axis: FeedAxisConfig,
        *,
        friction: Literal["auto", "lugre", "coulomb_viscous", "none"] = "auto",
        modes: bool = True,
        periodic: bool = True,
    ) -> FeedDriveParams:
        """From a machine axis (rigid or ball screw, with its modes and disturbances).

        Parameters
        ----------
        axis : the axis table of a machine file.
        friction : ``auto`` uses LuGre when the friction table has all LuGre keys, else
            Coulomb + viscous.
        modes : include ``disturbance_modes`` if the axis has them.
        periodic : include ``periodic_disturbances``.

        Notes
        -----
        Servo gains as in :class:`~millsense.simulator.rigid_drive.RigidDriveParams` (decision
        "feed-drive servo gains"), with the total reflected inertia of the plant:
        ``K_p = J·ω_c``, ``K_i = K_p·ω_c/4``, ``K_v = ω_c/4`` unless given.
        """
        from millsense.models import ball_screw

        if axis.ball_screw is not None:
            plant = ball_screw.plant_from_config(axis)
        else:
            plant = rigid_plant(axis.inertia_kg_m2, axis.transmission_m_rad, axis.efficiency)
        fric: CoulombViscous | LuGre | None
        if friction == "none":
            fric = None
        else:
            ft = axis.friction_table("simulated machine")
            if friction == "lugre" or (friction == "auto" and LuGre.configured(ft)):
                fric = LuGre.from_config(ft, "axis friction")
            else:
                fric = CoulombViscous.from_config(ft)
        wc = 2.0 * math.pi * axis.velocity_bandwidth_hz
        kp = axis.velocity_kp_nm_s_rad or plant.inertia * wc
        ki = axis.velocity_ki_nm_rad if axis.velocity_ki_nm_rad is not None else kp * wc / 4.0
        mss = None
        if modes and axis.disturbance_modes is not None:
            mss = ModalStateSpace.from_config(axis.disturbance_modes)
        terms = (
            ball_screw.periodic_terms(axis.periodic_disturbances, axis.transmission_m_rad)
            if periodic
            else ()
        )
        return cls(
            plant=plant,
            torque_constant=axis.torque_constant_nm_a,
            transmission=axis.transmission_m_rad,
            efficiency=axis.efficiency,
            friction=fric,
            kp=kp,
            ki=ki,
            kv=axis.position_gain(),
            current_bandwidth_hz=axis.current_bandwidth_hz,
            encoder_counts_rev=axis.encoder_counts_rev,
            torque_noise_nm=axis.current_noise_a * axis.torque_constant_nm_a,
            scale_resolution_m=(
                axis.scale_resolution_nm * 1e-9 if axis.scale_resolution_nm is not None else None
            ),
            position_feedback=axis.position_feedback,
            dead_time_amplifier_s=axis.dead_time_amplifier_ms * 1e-3,
            dead_time_motor_encoder_s=axis.dead_time_motor_encoder_ms * 1e-3,
            dead_time_scale_s=axis.dead_time_scale_ms * 1e-3,
            modes=mss,
            periodic=terms,
            mode_shift_per_m=axis.mode_shift_pct_per_100mm / 100.0 / (100.0 * units.MM),
            mode_reference_position=axis.mode_reference_mm * units.MM,
        )


# scalar state layout
_Z, _I_ACT, _I_INT, _V_INT, _ENC_PREV, _TAU_F, _TAU_C = 0, 1, 2, 3, 4, 5, 6
_N_SCALARS = 7
# integer parameters
_IP_SUB, _IP_DS, _IP_DM, _IP_DT, _IP_FRIC, _IP_CUR, _IP_FB, _IP_CLOSED = range(8)
# float parameters
(_P_KT, _P_KP, _P_KI, _P_KV, _P_ACUR, _P_QENC, _P_QLIN, _P_RG, _P_LG) = range(9)
(_P_L, _P_R, _P_KE, _P_KPI, _P_KII) = range(9, 14)
(_P_GAP, _P_LIFT, _P_SOFT) = range(14, 17)
_N_P = 17
N_OUT = 13


@numba.njit(cache=True)
def _dot(row: np.ndarray, x: np.ndarray) -> float:
    acc = 0.0
    for i in range(x.shape[0]):
        acc += row[i] * x[i]
    return acc


@numba.njit(cache=True)
def _few(row: np.ndarray) -> tuple[bool, int, int, int, float, float, float]:
    """A row of at most three nonzeros as ``(True, i0, i1, i2, c0, c1, c2)`` — indices ascending,
    an unused term index 0 with coefficient 0 — for :func:`_few_dot`; ``(False, …)`` for a
    denser row."""
    i0 = i1 = i2 = 0
    c0 = c1 = c2 = 0.0
    m = 0
    for i in range(row.shape[0]):
        if row[i] != 0.0:
            if m == 0:
                i0, c0 = i, row[i]
            elif m == 1:
                i1, c1 = i, row[i]
            elif m == 2:
                i2, c2 = i, row[i]
            else:
                return False, 0, 0, 0, 0.0, 0.0, 0.0
            m += 1
    return True, i0, i1, i2, c0, c1, c2


@numba.njit(cache=True, inline="always")
def _few_dot(
    t: tuple[bool, int, int, int, float, float, float], row: np.ndarray, x: np.ndarray
) -> float:
    """``row·x``: from its nonzeros ``t`` (:func:`_few`) when it has at most three — the
    products :func:`_dot` sums, in its order, less exact zeros: the same value bit for bit (up
    to the sign of a zero) — else :func:`_dot`."""
    if t[0]:
        return (t[4] * x[t[1]] + t[5] * x[t[2]]) + t[6] * x[t[3]]
    return _dot(row, x)


@numba.njit(cache=True)
def _periodic(terms: np.ndarray, kind: int, q: float) -> float:
    acc = 0.0
    for j in range(terms.shape[0]):
        if int(terms[j, 0]) == kind:
            acc += terms[j, 2] * math.sin(terms[j, 1] * q + terms[j, 3])
    return acc


@numba.njit(cache=True)
def _rescale_modes(
    lam: float,
    ma0: np.ndarray,
    mb0: np.ndarray,
    mc0: np.ndarray,
    h: float,
    mad: np.ndarray,
    mbd: np.ndarray,
    mc: np.ndarray,
) -> None:
    """Exact ZOH of the blocks ``A = λ·A_0 = [[σ, ω_d], [−ω_d, σ]]``, ``B = B_0``, ``C = λ·C_0``.

    ``e^{Ah} = e^{σh}·[[cos ω_d h, sin ω_d h], [−sin ω_d h, cos ω_d h]]`` and
    ``B_d = A⁻¹(e^{Ah} − I)·B_0`` with ``A⁻¹ = [[σ, −ω_d], [ω_d, σ]]/(σ² + ω_d²)``.
    """
    for j in range(ma0.shape[0]):
        sig = lam * ma0[j, 0, 0]
        wd = lam * ma0[j, 0, 1]
        e = math.exp(sig * h)
        c = e * math.cos(wd * h)
        s = e * math.sin(wd * h)
        mad[j, 0, 0] = c
        mad[j, 0, 1] = s
        mad[j, 1, 0] = -s
        mad[j, 1, 1] = c
        m00, m01, m10, m11 = c - 1.0, s, -s, c - 1.0
        v0 = m00 * mb0[j, 0] + m01 * mb0[j, 1]
        v1 = m10 * mb0[j, 0] + m11 * mb0[j, 1]
        den = sig * sig + wd * wd
        mbd[j, 0] = (sig * v0 - wd * v1) / den
        mbd[j, 1] = (wd * v0 + sig * v1) / den
        mc[j, 0] = lam * mc0[j, 0]
        mc[j, 1] = lam * mc0[j, 1]


#: Plants with this many states or more (the coupled truth drives) take the reassociating
#: matrix–vector product; smaller ones keep the sequential sums (their results unchanged).
_N_FAST = 8


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _zoh_step(
    ad: np.ndarray,
    bd: np.ndarray,
    xm: np.ndarray,
    u0: float,
    u1: float,
    u2: float,
    xnew: np.ndarray,
) -> None:
    """``xnew = Ad·x + Bd·u`` with the sums reassociated (vectorised by LLVM).

    Four rows per pass over ``x`` (one load of ``x[j]`` for four products; the truth plants'
    16–28 states are too few for LLVM's 32-wide vectorised reduction of a single row, which
    then runs scalar): ~1.6–1.8× faster, each row's sum the same as row by row (LLVM orders a
    row's reduction the same way; equal bit for bit in the tests).
    """
    n = xm.shape[0]
    i = 0
    while i + 3 < n:
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        for j in range(n):
            xj = xm[j]
            a0 += ad[i, j] * xj
            a1 += ad[i + 1, j] * xj
            a2 += ad[i + 2, j] * xj
            a3 += ad[i + 3, j] * xj
        xnew[i] = a0 + bd[i, 0] * u0 + bd[i, 1] * u1 + bd[i, 2] * u2
        xnew[i + 1] = a1 + bd[i + 1, 0] * u0 + bd[i + 1, 1] * u1 + bd[i + 1, 2] * u2
        xnew[i + 2] = a2 + bd[i + 2, 0] * u0 + bd[i + 2, 1] * u1 + bd[i + 2, 2] * u2
        xnew[i + 3] = a3 + bd[i + 3, 0] * u0 + bd[i + 3, 1] * u1 + bd[i + 3, 2] * u2
        i += 4
    while i < n:
        acc = 0.0
        for j in range(n):
            acc += ad[i, j] * xm[j]
        xnew[i] = acc + bd[i, 0] * u0 + bd[i, 1] * u1 + bd[i, 2] * u2
        i += 1


#: Points per motor revolution of the tabulated torque ripple.
_RIPPLE_POINTS = 4096


def ripple_table(terms: tuple[PeriodicTerm, ...]) -> np.ndarray:
    """The torque terms (all of integer wavenumber: one motor revolution is their period)
    tabulated over one revolution, ``_RIPPLE_POINTS + 1`` values (the last = the first)."""
    q = np.linspace(0.0, 2.0 * math.pi, _RIPPLE_POINTS + 1)
    tab = np.zeros_like(q)
    for t in terms:
        if t.kind == KIND_TORQUE:
            tab += t.amplitude * np.sin(t.wavenumber * q + t.phase)
    return tab


@numba.njit(cache=True)
def _ripple_lookup(tab: np.ndarray, theta: float) -> float:
    """Linear interpolation in the one-revolution table of :func:`ripple_table`."""
    m = tab.shape[0] - 1
    r = theta / (2.0 * math.pi)
    # r − ⌊r⌋ is r % 1.0 bit for bit (but for the sign of a zero) without libm's slow fmod
    u = (r - math.floor(r)) * m
    i = int(u)
    if i >= m:
        i = m - 1
    w = u - i
    return (1.0 - w) * tab[i] + w * tab[i + 1]


@numba.njit(cache=True)
def _lost_motion(e: float, half_gap: float, lift: float, ratio: float) -> float:
    """φ(e) of :class:`LostMotion`: the stretch the element's spring actually carries."""
    a = abs(e) - half_gap
    if a <= 0.0:
        return 0.0
    if a > lift:
        a = lift + ratio * (a - lift)
    return a if e > 0.0 else -a


@numba.njit(cache=True)
def _interpolate_plant(
    x: float,
    pgrid: np.ndarray,
    pad: np.ndarray,
    pbd: np.ndarray,
    pcy: np.ndarray,
    pdy: np.ndarray,
    ad: np.ndarray,
    bd: np.ndarray,
    cy: np.ndarray,
    dy: np.ndarray,
) -> None:
    """The discretised plant at load position x: linear between the grid's neighbours
    (clamped at the ends of the grid), written in place into (ad, bd, cy, dy)."""
    g = pad.shape[0]
    u = (x - pgrid[0]) / pgrid[1]
    if u <= 0.0:
        i, w = 0, 0.0
    elif u >= g - 1:
        i, w = g - 2, 1.0
    else:
        i = int(u)  # u > 0 here: truncation is the floor
        if i > g - 2:
            i = g - 2
        w = u - i
    v = 1.0 - w
    n = ad.shape[0]
    for r in range(n):
        for c in range(n):
            ad[r, c] = v * pad[i, r, c] + w * pad[i + 1, r, c]
        for c in range(3):
            bd[r, c] = v * pbd[i, r, c] + w * pbd[i + 1, r, c]
    for r in range(cy.shape[0]):
        for c in range(n):
            cy[r, c] = v * pcy[i, r, c] + w * pcy[i + 1, r, c]
        for c in range(3):
            dy[r, c] = v * pdy[i, r, c] + w * pdy[i + 1, r, c]


@numba.njit(cache=True)
def feed_drive_kernel(
    xm: np.ndarray,
    xd: np.ndarray,
    sc: np.ndarray,
    ring: np.ndarray,
    ring_idx: np.ndarray,
    pos_ref: np.ndarray,
    vel_ff: np.ndarray,
    load: np.ndarray,
    inject: np.ndarray,
    dist: np.ndarray,
    ad: np.ndarray,
    bd: np.ndarray,
    cy: np.ndarray,
    dy: np.ndarray,
    mad: np.ndarray,
    mbd: np.ndarray,
    mc: np.ndarray,
    md: float,
    fric: np.ndarray,
    terms: np.ndarray,
    p: np.ndarray,
    ip: np.ndarray,
    dt: float,
    out: np.ndarray,
    ma0: np.ndarray,
    mb0: np.ndarray,
    mc0: np.ndarray,
    sched: np.ndarray,
    sched_block: int,
    n_done: int,
    pad: np.ndarray,
    pbd: np.ndarray,
    pcy: np.ndarray,
    pdy: np.ndarray,
    pgrid: np.ndarray,
    c_e: np.ndarray,
    ripple: np.ndarray,
) -> None:
    """Advance the drive by ``len(pos_ref)`` samples (state arrays updated in place).

    ``ring`` is (3, L): current command, motor angle and load position at substep resolution,
    for the dead times; ``out`` columns are described in :meth:`FeedDriveSim.advance`.
    Position-dependent modes: when ``sched[0]`` (κ) is not 0 the blocks (``mad``, ``mbd``,
    ``mc``) are recomputed from the reference blocks (``ma0``, ``mb0``, ``mc0``) at
    ``λ = 1 + κ·(x − sched[1])`` at every absolute sample ``n_done + k`` that is a multiple
    of ``sched_block``, x the true load position at that instant.
    """
    n = xm.shape[0]
    nm = xd.shape[0]
    substeps = ip[_IP_SUB]
    h = dt / substeps
    length = ring.shape[1]
    # parameters and scalar states as locals (kept in registers over the loop)
    kt = p[_P_KT]
    qenc = p[_P_QENC]
    qlin = p[_P_QLIN]
    kv, kp, ki, rg, lg = p[_P_KV], p[_P_KP], p[_P_KI], p[_P_RG], p[_P_LG]
    acur, ind, res, ke, kpi, kii = p[_P_ACUR], p[_P_L], p[_P_R], p[_P_KE], p[_P_KPI], p[_P_KII]
    gap, lift, soft = p[_P_GAP], p[_P_LIFT], p[_P_SOFT]
    closed = ip[_IP_CLOSED] == 1
    scale_fb = ip[_IP_FB] != 0
    cur_mode = ip[_IP_CUR]
    fric_mode = ip[_IP_FRIC]
    d_m = ip[_IP_DM]
    d_t = ip[_IP_DT]
    z_f = sc[_Z]
    i_act = sc[_I_ACT]
    i_int = sc[_I_INT]
    v_int = sc[_V_INT]
    enc_prev = sc[_ENC_PREV]
    tau_f = sc[_TAU_F]
    tau_c = sc[_TAU_C]
    xnew = np.empty(n)
    u0 = u1 = u2 = 0.0  # plant input [τ_m, F, δ]
    c_th = cy[OUT_THETA].copy()
    c_om = cy[OUT_OMEGA].copy()
    c_x = cy[OUT_X].copy()
    # the rows evaluated at every substep on the critical path by their few nonzeros (a truth
    # chain's θ_m and ω_m are single states, its stretch three)
    f_th = _few(c_th)
    f_om = _few(c_om)
    f_e = _few(c_e)
    # the load velocity and motor acceleration outputs (per sample; re-read after a schedule
    # update, like the rows they come from)
    f_v = _few(cy[OUT_V])
    f_al = _few(cy[OUT_ALPHA])
    d_x = dy[OUT_X, 2]
    n_terms = terms.shape[0]
    has_screw = False
    for j in range(n_terms):
        if int(terms[j, 0]) == KIND_SCREW:
            has_screw = True
    ds = ip[_IP_DS]
    kappa = sched[0]
    n_grid = pad.shape[0]
    lost = c_e.shape[0] > 0
    n_ripple = ripple.shape[0]
    for k in range(pos_ref.shape[0]):
        idx = ring_idx[0]
        if n_grid > 1 and (n_done + k) % sched_block == 0:
            _interpolate_plant(ring[2, idx], pgrid, pad, pbd, pcy, pdy, ad, bd, cy, dy)
            f_v = _few(cy[OUT_V])
            f_al = _few(cy[OUT_ALPHA])
        if kappa != 0.0 and nm > 0 and (n_done + k) % sched_block == 0:
            lam = 1.0 + kappa * (ring[2, idx] - sched[1])
            if lam < 0.05:
                lam = 0.05  # beyond any stroke: keep the blocks stable (checked in Python)
            _rescale_modes(lam, ma0, mb0, mc0, h, mad, mbd, mc)
        # ---- sensors at the sample instant, after their dead times
        j_m = idx - d_m  # the dead times are shorter than the ring
        th_d = ring[1, j_m + length if j_m < 0 else j_m]
        th_m = th_d + _periodic(terms, KIND_MOTOR_ENCODER, th_d)
        theta_enc = math.floor(th_m / qenc) * qenc
        j_t = idx - d_t
        x_d = ring[2, j_t + length if j_t < 0 else j_t]
        x_m = x_d + _periodic(terms, KIND_SCALE, x_d)
        x_scale = math.floor(x_m / qlin) * qlin if qlin > 0.0 else x_m
        omega_meas = (theta_enc - enc_prev) / dt
        enc_prev = theta_enc
        # ---- cascade controller
        i_cmd = inject[k]
        if closed:
            pos_fb = x_scale / rg if scale_fb else theta_enc
            omega_ref = vel_ff[k] + kv * (pos_ref[k] - pos_fb)
            err = omega_ref - omega_meas
            v_int += ki * err * dt
            i_cmd += (kp * err + v_int) / kt
        tau_a = lg * load[k]
        dist_k = dist[k]
        # ---- plant over one sample
        for _ in range(substeps):
            idx += 1
            if idx == length:
                idx = 0
            ring[0, idx] = i_cmd
            j_s = idx - ds
            if j_s < 0:
                j_s += length
            i_ref = ring[0, j_s]
            omega = _few_dot(f_om, c_om, xm)
            if cur_mode == 0:
                i_act += acur * (i_ref - i_act)
            else:
                e_i = i_ref - i_act
                i_int += kii * e_i * h
                volt = kpi * e_i + i_int
                i_act += h * (volt - res * i_act - ke * omega) / ind
            if fric_mode == 1:
                z_f, tau_f = lugre_step(z_f, omega, h, fric)
            elif fric_mode == 0:
                tau_f = coulomb_viscous_torque(omega, fric)
            else:
                tau_f = 0.0
            if n_terms > 0:
                theta = _few_dot(f_th, c_th, xm)
                if n_ripple > 0:
                    tau_per = _ripple_lookup(ripple, theta)
                else:
                    tau_per = _periodic(terms, KIND_TORQUE, theta)
                if has_screw:
                    u2 = _periodic(terms, KIND_SCREW, theta)
            else:
                tau_per = 0.0
            if lost:
                if not has_screw:
                    u2 = 0.0
                e = _few_dot(f_e, c_e, xm) + u2
                u2 += _lost_motion(e, gap, lift, soft) - e
            if nm > 0:
                tau_c = md * tau_a
                for j in range(nm):
                    tau_c += mc[j, 0] * xd[j, 0] + mc[j, 1] * xd[j, 1]
                for j in range(nm):
                    a0 = mad[j, 0, 0] * xd[j, 0] + mad[j, 0, 1] * xd[j, 1] + mbd[j, 0] * tau_a
                    a1 = mad[j, 1, 0] * xd[j, 0] + mad[j, 1, 1] * xd[j, 1] + mbd[j, 1] * tau_a
                    xd[j, 0] = a0
                    xd[j, 1] = a1
                u1 = 0.0
                u0 = kt * i_act - tau_f - tau_per - dist_k - tau_c
            else:
                tau_c = tau_a
                u1 = load[k]
                u0 = kt * i_act - tau_f - tau_per - dist_k
            if n >= _N_FAST:
                _zoh_step(ad, bd, xm, u0, u1, u2, xnew)
            else:
                for i in range(n):
                    acc = bd[i, 0] * u0 + bd[i, 1] * u1 + bd[i, 2] * u2
                    for j2 in range(n):
                        acc += ad[i, j2] * xm[j2]
                    xnew[i] = acc
            for i in range(n):
                xm[i] = xnew[i]
            ring[1, idx] = _few_dot(f_th, c_th, xm)
            ring[2, idx] = _dot(c_x, xm) + d_x * u2
        ring_idx[0] = idx
        out[k, 0] = i_cmd
        out[k, 1] = i_act
        out[k, 2] = omega_meas
        out[k, 3] = theta_enc
        out[k, 4] = _few_dot(f_om, c_om, xm)
        out[k, 5] = _few_dot(f_th, c_th, xm)
        out[k, 6] = x_scale
        out[k, 7] = ring[2, idx]
        out[k, 8] = _few_dot(f_v, cy[OUT_V], xm)
        alpha = _few_dot(f_al, cy[OUT_ALPHA], xm)
        out[k, 9] = alpha + dy[OUT_ALPHA, 0] * u0 + dy[OUT_ALPHA, 1] * u1
        out[k, 10] = _dot(cy[OUT_A], xm) + dy[OUT_A, 0] * u0 + dy[OUT_A, 1] * u1
        out[k, 11] = tau_f
        out[k, 12] = tau_c
    sc[_Z] = z_f
    sc[_I_ACT] = i_act
    sc[_I_INT] = i_int
    sc[_V_INT] = v_int
    sc[_ENC_PREV] = enc_prev
    sc[_TAU_F] = tau_f
    sc[_TAU_C] = tau_c


_OUT_NAMES = (
    "current_cmd",
    "current",
    "speed",
    "angle",
    "true_speed",
    "true_angle",
    "scale",
    "true_position",
    "true_velocity",
    "true_motor_acceleration",
    "true_acceleration",
    "friction_torque",
    "load_torque_motor",
)

#: Column names of the per-sample output array of :meth:`FeedDriveSim.advance_into`.
OUT_NAMES = _OUT_NAMES


class FeedDriveSim:
    """A resumable feed drive: :meth:`advance` continues from where it stopped.

    Parameters
    ----------
    params : the drive.
    sample_rate_hz : CNC sample (control) rate, Hz.
    substeps : plant integration steps per sample.
    seed : seed of the torque-noise generator.
    initial_angle_rad : motor angle at t = 0, rad (the load position follows through r_g).
    """

    def __init__(
        self,
        params: FeedDriveParams,
        sample_rate_hz: float,
        *,
        substeps: int = 10,
        seed: int = 0,
        initial_angle_rad: float = 0.0,
    ) -> None:
        self.params = params
        self.dt = 1.0 / sample_rate_hz
        self.substeps = substeps
        h = self.dt / substeps
        self._rng = np.random.default_rng(seed)
        plant = params.plant
        self._ad, self._bd = plant.discretise(h)
        self._cy = np.array(plant.c, dtype=np.float64, order="C", copy=True)
        self._dy = np.array(plant.d, dtype=np.float64, order="C", copy=True)
        sch = params.plant_schedule
        if sch is not None:
            disc = [p.discretise(h) for p in sch.plants]
            self._pad = np.ascontiguousarray(np.stack([e[0] for e in disc]))
            self._pbd = np.ascontiguousarray(np.stack([e[1] for e in disc]))
            self._pcy = np.ascontiguousarray(np.stack([p.c for p in sch.plants]))
            self._pdy = np.ascontiguousarray(np.stack([p.d for p in sch.plants]))
            pos = np.asarray(sch.positions, dtype=float)
            self._pgrid = np.array([pos[0], pos[1] - pos[0]])
            if self._pad.shape[1:] != self._ad.shape:
                raise ConfigError("feed drive: the plant schedule's states differ from the plant")
        else:
            n0 = self._ad.shape[0]
            self._pad = np.zeros((1, n0, n0))
            self._pbd = np.zeros((1, n0, 3))
            self._pcy = np.zeros((1, 6, n0))
            self._pdy = np.zeros((1, 6, 3))
            self._pgrid = np.array([0.0, 1.0])
        # initial state: every coordinate at the motor angle's position (unstressed)
        x0 = np.zeros(plant.a.shape[0])
        x0_unit = _position_direction(plant)
        x0[:] = x0_unit * initial_angle_rad
        self._xm = x0
        self._sched = np.array([params.mode_shift_per_m, params.mode_reference_position])
        self._sched_block = max(1, round(params.mode_update_s * sample_rate_hz))
        if params.modes is not None:
            self._mad, self._mbd = params.modes.discretise(h)
            # a private copy: the kernel rescales it in place (position-dependent modes)
            self._mc = np.array(params.modes.c, dtype=np.float64, order="C", copy=True)
            self._md = params.modes.d
            self._xd = np.zeros((params.modes.a.shape[0], 2))
            a0 = params.modes.a
            if params.mode_shift_per_m != 0.0 and not (
                np.allclose(a0[:, 0, 0], a0[:, 1, 1]) and np.allclose(a0[:, 0, 1], -a0[:, 1, 0])
            ):
                raise ConfigError(
                    "feed drive: position-dependent modes (mode_shift_pct_per_100mm) need every "
                    "disturbance mode underdamped (damping_ratio < 1)"
                )
            self._ma0 = np.ascontiguousarray(a0)
            self._mb0 = np.ascontiguousarray(params.modes.b)
            self._mc0 = self._mc.copy()
        else:
            self._mad = np.zeros((0, 2, 2))
            self._mbd = np.zeros((0, 2))
            self._mc = np.zeros((0, 2))
            self._md = 0.0
            self._xd = np.zeros((0, 2))
            self._ma0 = np.zeros((0, 2, 2))
            self._mb0 = np.zeros((0, 2))
            self._mc0 = np.zeros((0, 2))
        fp = params.friction
        if isinstance(fp, LuGre):
            fric_mode, self._fric = 1, fp.as_array()
        elif isinstance(fp, CoulombViscous):
            fric_mode, self._fric = 0, fp.as_array()
        else:
            fric_mode, self._fric = 2, np.zeros(1)
        self._terms = np.array(
            [[t.kind, t.wavenumber, t.amplitude, t.phase] for t in params.periodic],
            dtype=np.float64,
        ).reshape(-1, 4)
        d_s = round(params.dead_time_amplifier_s / h)
        d_m = round(params.dead_time_motor_encoder_s / h)
        d_t = round(params.dead_time_scale_s / h)
        length = max(d_s, d_m, d_t) + 1
        self._ring = np.zeros((3, length))
        self._ring[1, :] = initial_angle_rad
        self._ring[2, :] = self._cy[OUT_X] @ self._xm
        self._ring_idx = np.zeros(1, dtype=np.int64)
        q = 2.0 * math.pi / params.encoder_counts_rev
        cl = params.current_loop
        self._p = np.zeros(_N_P)
        self._p[_P_KT] = params.torque_constant
        self._p[_P_KP] = params.kp
        self._p[_P_KI] = params.ki
        self._p[_P_KV] = params.kv
        self._p[_P_ACUR] = 1.0 - math.exp(-2.0 * math.pi * params.current_bandwidth_hz * h)
        self._p[_P_QENC] = q
        self._p[_P_QLIN] = params.scale_resolution_m or 0.0
        self._p[_P_RG] = params.transmission
        self._p[_P_LG] = params.transmission / params.efficiency
        if cl is not None:
            self._p[_P_L] = cl.inductance
            self._p[_P_R] = cl.resistance
            self._p[_P_KE] = cl.back_emf
            self._p[_P_KPI] = cl.kp
            self._p[_P_KII] = cl.ki
        lm = params.lost_motion
        if lm is not None:
            self._c_e = np.ascontiguousarray(lm.stretch, dtype=np.float64)
            if self._c_e.shape != (plant.a.shape[0],):
                raise ConfigError("feed drive: lost_motion.stretch must have one entry per state")
            self._p[_P_GAP] = lm.half_gap
            self._p[_P_LIFT] = lm.lift
            self._p[_P_SOFT] = lm.ratio
        else:
            self._c_e = np.zeros(0)
        # coupled plants (the truth) look their motor-angle torque ripple up in a table over
        # one revolution when every torque term has an integer wavenumber (decision 0977:
        # interpolation error < 2e-4 of the amplitude at 48 per rev); others sum sines
        torque_terms = [t for t in params.periodic if t.kind == KIND_TORQUE]
        if (
            plant.a.shape[0] >= _N_FAST
            and torque_terms
            and all(float(t.wavenumber).is_integer() for t in torque_terms)
        ):
            self._ripple = ripple_table(params.periodic)
        else:
            self._ripple = np.zeros(0)
        self._ip = np.array(
            [
                substeps,
                d_s,
                d_m,
                d_t,
                fric_mode,
                0 if cl is None else 1,
                0 if params.position_feedback == "motor" else 1,
                1 if params.closed_loop else 0,
            ],
            dtype=np.int64,
        )
        self._sc = np.zeros(_N_SCALARS)
        # the first speed sample is not a jump from 0 to the initial angle
        self._sc[_ENC_PREV] = math.floor(initial_angle_rad / q) * q
        self.samples_done = 0
        self._no_injection = np.zeros(0)

    @property
    def dead_time_substeps(self) -> tuple[int, int, int]:
        """(T_s, T_m, T_t) as used, in substeps."""
        return int(self._ip[_IP_DS]), int(self._ip[_IP_DM]), int(self._ip[_IP_DT])

    def advance(
        self,
        pos_ref_rad: np.ndarray,
        vel_ff_rad_s: np.ndarray,
        load: np.ndarray,
        current_injection_a: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Simulate ``len(pos_ref_rad)`` samples.

        Parameters
        ----------
        pos_ref_rad : motor-side position reference, rad.
        vel_ff_rad_s : velocity feed-forward, rad/s.
        load : load at the table resisting motion, N (N·m rotary; or N·m at the motor for a
            plant built with ``load='torque'``).
        current_injection_a : current added to the controller's command, A (sine sweeps).

        Returns
        -------
        dict of per-sample arrays: ``current_cmd`` A (total command), ``current`` A (actual),
        ``speed`` rad/s (encoder difference), ``angle`` rad (encoder), ``scale`` (linear scale,
        m), ``true_speed``, ``true_angle``, ``true_position`` (load, m or rad),
        ``true_velocity``, ``true_motor_acceleration`` rad/s², ``true_acceleration`` (load),
        ``friction_torque`` N·m, ``load_torque_motor`` N·m (τ_c acting on the motor).
        """
        out = np.empty((len(pos_ref_rad), N_OUT))
        self.advance_into(pos_ref_rad, vel_ff_rad_s, load, out, current_injection_a)
        return {name: out[:, j] for j, name in enumerate(_OUT_NAMES)}

    def advance_into(
        self,
        pos_ref_rad: np.ndarray,
        vel_ff_rad_s: np.ndarray,
        load: np.ndarray,
        out: np.ndarray,
        current_injection_a: np.ndarray | None = None,
    ) -> None:
        """:meth:`advance` writing into ``out`` ((n, N_OUT) C-contiguous, columns in the
        order of :data:`OUT_NAMES`) instead of returning a dict (no per-call allocations
        beyond the noise; the simulator's block loop)."""
        n = len(pos_ref_rad)
        if out.shape != (n, N_OUT) or not out.flags.c_contiguous:
            raise InputDataError(f"feed drive: out must be C-contiguous ({n}, {N_OUT})")
        dist = self._rng.standard_normal(n) * self.params.torque_noise_nm
        if current_injection_a is None:
            if self._no_injection.shape[0] != n:
                self._no_injection = np.zeros(n)
            inj = self._no_injection  # read-only in the kernel
        else:
            inj = np.ascontiguousarray(current_injection_a, dtype=np.float64)
        self._run_kernel(
            np.ascontiguousarray(pos_ref_rad, dtype=np.float64),
            np.ascontiguousarray(vel_ff_rad_s, dtype=np.float64),
            np.ascontiguousarray(load, dtype=np.float64),
            inj,
            dist,
            out,
        )

    def draw_noise(self, n: int) -> np.ndarray:
        """The torque noise of the next ``n`` samples, N·m (the generator's next draws: the
        same values :meth:`advance_into` would draw over the same samples in any cuts)."""
        return self._rng.standard_normal(n) * self.params.torque_noise_nm

    def kernel_state(self, n: int) -> tuple[object, ...]:
        """The kernel's arguments that persist between calls (state arrays updated in place,
        parameters), in the order :func:`millsense.simulator.fast_block.drives_block` passes
        them; ``n`` the block length (a zero current injection of that length)."""
        if self._no_injection.shape[0] != n:
            self._no_injection = np.zeros(n)
        return (
            self._xm,
            self._xd,
            self._sc,
            self._ring,
            self._ring_idx,
            self._no_injection,
            self._ad,
            self._bd,
            self._cy,
            self._dy,
            self._mad,
            self._mbd,
            self._mc,
            float(self._md),
            self._fric,
            self._terms,
            self._p,
            self._ip,
            float(self.dt),
            self._ma0,
            self._mb0,
            self._mc0,
            self._sched,
            int(self._sched_block),
            self._pad,
            self._pbd,
            self._pcy,
            self._pdy,
            self._pgrid,
            self._c_e,
            self._ripple,
        )

    def _run_kernel(
        self,
        pos_ref_rad: np.ndarray,
        vel_ff_rad_s: np.ndarray,
        load: np.ndarray,
        inj: np.ndarray,
        dist: np.ndarray,
        out: np.ndarray,
    ) -> None:
        """The one call of :func:`feed_drive_kernel` on this drive's state (C-contiguous
        float64 inputs of one length, ``out`` (n, N_OUT))."""
        feed_drive_kernel(
            self._xm,
            self._xd,
            self._sc,
            self._ring,
            self._ring_idx,
            pos_ref_rad,
            vel_ff_rad_s,
            load,
            inj,
            dist,
            self._ad,
            self._bd,
            self._cy,
            self._dy,
            self._mad,
            self._mbd,
            self._mc,
            self._md,
            self._fric,
            self._terms,
            self._p,
            self._ip,
            self.dt,
            out,
            self._ma0,
            self._mb0,
            self._mc0,
            self._sched,
            self._sched_block,
            self.samples_done,
            self._pad,
            self._pbd,
            self._pcy,
            self._pdy,
            self._pgrid,
            self._c_e,
            self._ripple,
        )
        self.samples_done += pos_ref_rad.shape[0]

    def advance_block(
        self,
        pos_ref_rad: np.ndarray,
        vel_ff_rad_s: np.ndarray,
        load: np.ndarray,
        dist: np.ndarray,
        out: np.ndarray,
    ) -> None:
        """:meth:`advance_into` without the checks, with the torque noise ``dist`` drawn by
        :meth:`draw_noise` ahead (the simulator's block loop; every array C-contiguous
        float64 of the block's length, ``out`` (n, N_OUT))."""
        n = pos_ref_rad.shape[0]
        if self._no_injection.shape[0] != n:
            self._no_injection = np.zeros(n)
        self._run_kernel(pos_ref_rad, vel_ff_rad_s, load, self._no_injection, dist, out)


def _position_direction(plant: MechanicalPlant) -> np.ndarray:
    """State of the plant at rest with the motor at 1 rad and no spring stressed."""
    n = plant.a.shape[0]
    # a rigid displacement is in the null space of the stiffness part of A (positions are the
    # first n/2 states, velocities the rest)
    half = n // 2
    stiff = plant.a[half:, :half]
    if half == 1:
        vec = np.array([1.0])
    else:
        ns = scipy.linalg.null_space(stiff)
        vec = ns[:, 0]
    vec = vec / (plant.c[OUT_THETA, :half] @ vec)
    full = np.zeros(n)
    full[:half] = vec
    return full


def constant_velocity_sweep(
    params: FeedDriveParams,
    speeds_rad_s: np.ndarray,
    sample_rate_hz: float,
    *,
    duration_s: float = 1.0,
    accel_time_s: float = 0.1,
    seed: int = 0,
    torque_constant: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean motor torque ``K_t·i`` over the steady half of constant-speed moves (Aslan C1).

    ``torque_constant`` is the K_t the measured current is multiplied by: the one the
    identification believes (a nameplate value), default the simulated drive's own.

    Each speed is a separate air move from rest (ramp over ``accel_time_s``, hold to
    ``duration_s``). Returns (mean torque N·m, standard error of the mean N·m) per speed,
    the latter from the spread of 10 sub-window means.
    """
    n = round(duration_s * sample_rate_hz)
    t = np.arange(n) / sample_rate_hz
    means = np.empty(len(speeds_rad_s))
    sems = np.empty(len(speeds_rad_s))
    for j, v in enumerate(np.asarray(speeds_rad_s, dtype=float)):
        vel = np.where(t < accel_time_s, v * t / accel_time_s, v)
        pos = np.where(
            t < accel_time_s,
            0.5 * v * t**2 / accel_time_s,
            0.5 * v * accel_time_s + v * (t - accel_time_s),
        )
        sim = FeedDriveSim(params, sample_rate_hz, seed=seed + j)
        res = sim.advance(pos, vel, np.zeros(n))
        kt = params.torque_constant if torque_constant is None else torque_constant
        tau = kt * res["current"][n // 2 :]
        means[j] = float(np.mean(tau))
        parts = np.array([np.mean(c) for c in np.array_split(tau, 10)])
        sems[j] = float(np.std(parts, ddof=1) / math.sqrt(len(parts)))
    return means, sems
