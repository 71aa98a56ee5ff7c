"""Configuration models: tool, material (cutting coefficients), machine, stock.

Files are TOML in the field's units, with the unit in every key name (``diameter_mm``,
``ktc_n_mm2``, ``inertia_kg_m2``); each model exposes SI values through ``*_m``/``*_rad``/...
properties, so conversion happens once, here, and nowhere else.

Invalid input raises :class:`~millsense.core.errors.ConfigError` with one line naming the
file, the key and the allowed range, e.g.::

    tool.toml: key 'diameter_mm' = -3 is out of range: must be > 0 and <= 200

Usage::

    tool = load_config(ToolConfig, "tool.toml")
    tool.diameter_m   # SI
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from millsense.core import units
from millsense.core.errors import ConfigError


class _Model(BaseModel):
    """Base for all configuration models: unknown keys are errors, instances are frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)


# --------------------------------------------------------------------------------------------
# Tool and material
# --------------------------------------------------------------------------------------------


class ToolConfig(_Model):
    """An end mill. Geometry follows Altintas' conventions (flat or ball end, helix, pitch)."""

    name: str = "end mill"
    shape: Literal["flat", "ball"] = "flat"
    diameter_mm: Annotated[float, Field(gt=0, le=200)]
    flutes: Annotated[int, Field(ge=1, le=16)]
    helix_deg: Annotated[float, Field(ge=0, lt=70)] = 0.0
    pitch_deg: list[Annotated[float, Field(gt=0, lt=360)]] | None = None
    """Angle from each flute to the next, in degrees; omitted means uniform 360/flutes."""
    runout_um: Annotated[float, Field(ge=0, le=1000)] = 0.0
    """Radial offset of the cutter axis from the spindle axis, µm."""
    runout_angle_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0
    stickout_mm: Annotated[float, Field(gt=0, le=1000)] | None = None

    @model_validator(mode="after")
    def _pitch_consistent(self) -> ToolConfig:
        if self.pitch_deg is not None:
            if len(self.pitch_deg) != self.flutes:
                raise ValueError(
                    f"pitch_deg has {len(self.pitch_deg)} angles but flutes = {self.flutes}"
                )
            if not math.isclose(sum(self.pitch_deg), 360.0, abs_tol=1e-6):
                raise ValueError(f"pitch_deg must sum to 360, got {sum(self.pitch_deg):g}")
        return self

    @property
    def diameter_m(self) -> float:
        return self.diameter_mm * units.MM

    @property
    def radius_m(self) -> float:
        return 0.5 * self.diameter_m

    @property
    def helix_rad(self) -> float:
        return self.helix_deg * units.DEG

    @property
    def pitch_rad(self) -> tuple[float, ...]:
        """Pitch angles in rad (uniform if not given)."""
        if self.pitch_deg is None:
            return (2.0 * math.pi / self.flutes,) * self.flutes
        return tuple(p * units.DEG for p in self.pitch_deg)

    @property
    def runout_m(self) -> float:
        return self.runout_um * units.UM

    @property
    def runout_angle_rad(self) -> float:
        return self.runout_angle_deg * units.DEG


class MaterialConfig(_Model):
    """Work material and its linear edge-force cutting coefficients (Altintas ch. 2).

    ``K_c`` shearing coefficients in N/mm² (= MPa), ``K_e`` edge coefficients in N/mm.
    """

    name: str = "material"
    ktc_n_mm2: Annotated[float, Field(gt=0, le=20000)]
    krc_n_mm2: Annotated[float, Field(ge=-5000, le=20000)]
    kac_n_mm2: Annotated[float, Field(ge=-5000, le=20000)] = 0.0
    kte_n_mm: Annotated[float, Field(ge=0, le=1000)] = 0.0
    kre_n_mm: Annotated[float, Field(ge=0, le=1000)] = 0.0
    kae_n_mm: Annotated[float, Field(ge=-1000, le=1000)] = 0.0
    source: str = ""

    @property
    def ktc(self) -> float:
        """Tangential shearing coefficient, N/m²."""
        return self.ktc_n_mm2 * units.N_PER_MM2

    @property
    def krc(self) -> float:
        return self.krc_n_mm2 * units.N_PER_MM2

    @property
    def kac(self) -> float:
        return self.kac_n_mm2 * units.N_PER_MM2

    @property
    def kte(self) -> float:
        """Tangential edge coefficient, N/m."""
        return self.kte_n_mm * units.N_PER_MM

    @property
    def kre(self) -> float:
        return self.kre_n_mm * units.N_PER_MM

    @property
    def kae(self) -> float:
        return self.kae_n_mm * units.N_PER_MM


# --------------------------------------------------------------------------------------------
# Machine
# --------------------------------------------------------------------------------------------


class FrictionConfig(_Model):
    """Friction on the motor side of a drive, per direction of motion (Aslan Eq. 3.2–3.4).

    Coulomb + viscous is the minimum; the LuGre fields (``sigma0``, ``sigma1``,
    ``stribeck_velocity``, ``static``) are optional. Tuples are (positive, negative) direction.
    """

    coulomb_nm: tuple[Annotated[float, Field(ge=0, le=1e4)], Annotated[float, Field(ge=0, le=1e4)]]
    viscous_nm_s_rad: tuple[
        Annotated[float, Field(ge=0, le=1e4)], Annotated[float, Field(ge=0, le=1e4)]
    ]
    static_nm: (
        tuple[Annotated[float, Field(ge=0, le=1e4)], Annotated[float, Field(ge=0, le=1e4)]] | None
    ) = None
    stribeck_velocity_rad_s: (
        tuple[Annotated[float, Field(gt=0, le=1e3)], Annotated[float, Field(gt=0, le=1e3)]] | None
    ) = None
    sigma0_nm_rad: (
        tuple[Annotated[float, Field(gt=0, le=1e9)], Annotated[float, Field(gt=0, le=1e9)]] | None
    ) = None
    sigma1_nm_s_rad: (
        tuple[Annotated[float, Field(ge=0, le=1e6)], Annotated[float, Field(ge=0, le=1e6)]] | None
    ) = None
    source: str = ""


class DisturbanceModesConfig(_Model):
    """Structural modes between the load at the table and the motor (Aslan Eq. 3.13, Table 3.4).

    ``Φ_d(s) = τ_c/τ_a = feedthrough + Σ (α_k + β_k·s)/(s² + 2ζ_k·ω_k·s + ω_k²)`` with
    ω_k = 2π·f_k in rad/s. ``damping_ratio`` is a fraction (0.05, not 5 %).
    """

    natural_frequency_hz: list[Annotated[float, Field(gt=0, le=1e5)]]
    damping_ratio: list[Annotated[float, Field(ge=0, le=10)]]
    alpha: list[float]
    beta: list[float]
    feedthrough: float = 0.0
    source: str = ""

    @model_validator(mode="after")
    def _same_length(self) -> DisturbanceModesConfig:
        n = len(self.natural_frequency_hz)
        if n == 0:
            raise ValueError("natural_frequency_hz must list at least one mode")
        for key in ("damping_ratio", "alpha", "beta"):
            if len(getattr(self, key)) != n:
                raise ValueError(
                    f"{key} has {len(getattr(self, key))} entries but natural_frequency_hz has {n}"
                )
        return self


class DisturbancePathConfig(_Model):
    """Identified path τ_a → C3 torque of a feed estimator (``millsense identify path``).

    A rational fit of the sampled FRF measured with the estimator's own C3 front end (Aslan C5;
    decision "Discretisation of the identified disturbance model")::

        Φ_d(s) = constant + Σ_k r_k/(s + 2π·g_k) + Σ_j [ρ_j/(s − p_j) + ρ̄_j/(s − p̄_j)]

    with ``p_j = ω_j·(−ζ_j + i·√(1 − ζ_j²))``, ``ω_j = 2π·natural_frequency_hz[j]``,
    ``ρ_j = residue_real_1_s[j] + i·residue_imag_1_s[j]``, ``g_k = real_pole_hz[k]``,
    ``r_k = real_residue_1_s[k]``, s in rad/s on the bilinear-warped axis of
    ``sample_rate_hz`` (the estimator discretises it by Tustin at that rate, exactly). Unlike
    ``disturbance_modes`` it keeps the real poles (the velocity loop seen through the C3 torque)
    and it is the estimator's model only, never the simulator's.
    """

    natural_frequency_hz: list[Annotated[float, Field(gt=0, le=1e5)]] = []
    damping_ratio: list[Annotated[float, Field(gt=0, lt=1)]] = []
    residue_real_1_s: list[float] = []
    residue_imag_1_s: list[float] = []
    real_pole_hz: list[Annotated[float, Field(gt=0, le=1e6)]] = []
    real_residue_1_s: list[float] = []
    constant: float = 0.0
    sample_rate_hz: Annotated[float, Field(gt=0, le=1e6)]
    rms_error: Annotated[float, Field(ge=0)] = 0.0
    source: str = ""

    @model_validator(mode="after")
    def _same_length(self) -> DisturbancePathConfig:
        n = len(self.natural_frequency_hz)
        for key in ("damping_ratio", "residue_real_1_s", "residue_imag_1_s"):
            if len(getattr(self, key)) != n:
                raise ValueError(
                    f"{key} has {len(getattr(self, key))} entries but natural_frequency_hz has {n}"
                )
        if len(self.real_residue_1_s) != len(self.real_pole_hz):
            raise ValueError(
                f"real_residue_1_s has {len(self.real_residue_1_s)} entries but real_pole_hz has "
                f"{len(self.real_pole_hz)}"
            )
        if n + len(self.real_pole_hz) == 0:
            raise ValueError("the path needs at least one pole")
        return self


class BallScrewConfig(_Model):
    """Dual- or triple-inertia ball-screw drive (Yamada Eq. 2-1/2-2, 2-45…2-47, Table 3-3).

    The motor-side inertia J_r is the axis' ``inertia_kg_m2``; this table holds the rest.
    Translational quantities are on the table side (N/µm, N·s/m, kg).
    """

    model: Literal["dual", "triple"] = "dual"
    table_mass_kg: Annotated[float, Field(gt=0, le=1e5)]
    """M_t."""
    table_damping_n_s_m: Annotated[float, Field(ge=0, le=1e7)] = 0.0
    """C_t (viscous damping of the table to ground)."""
    rotary_damping_nm_s_rad: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    """D_r (viscous damping of the motor and screw rotation)."""
    axial_stiffness_n_um: Annotated[float, Field(gt=0, le=1e5)]
    """K_r (nut–table spring)."""
    axial_damping_n_s_m: Annotated[float, Field(ge=0, le=1e7)] = 0.0
    """C_k (nut–table damper)."""
    nut_mass_kg: Annotated[float, Field(gt=0, le=1e5)] | None = None
    """M_n (triple inertia only)."""
    nut_damping_n_s_m: Annotated[float, Field(ge=0, le=1e7)] = 0.0
    """C_n (triple inertia only)."""
    screw_stiffness_n_um: Annotated[float, Field(gt=0, le=1e6)] | None = None
    """K_ω, motor–nut (screw torsion/axial) stiffness (triple inertia only)."""
    screw_damping_n_s_m: Annotated[float, Field(ge=0, le=1e7)] = 0.0
    """C_ω (triple inertia only)."""
    source: str = ""

    @model_validator(mode="after")
    def _triple_complete(self) -> BallScrewConfig:
        if self.model == "triple" and (
            self.nut_mass_kg is None or self.screw_stiffness_n_um is None
        ):
            raise ValueError(
                "a triple-inertia ball screw needs nut_mass_kg and screw_stiffness_n_um"
            )
        return self


class PeriodicDisturbanceConfig(_Model):
    """A position-periodic disturbance of a ball-screw drive (Yamada §3.6).

    ``kind``: ``thrust`` (force on the motor side, N, e.g. lead-periodic friction, ball
    circulation, torque ripple), ``screw_error`` (kinematic lead error between nut and screw,
    µm), ``motor_encoder`` / ``scale`` (interpolation error of the rotary encoder / linear scale,
    µm of table travel). The period is ``wavelength_mm`` of table travel or ``per_motor_rev``
    periods per motor revolution (one of the two).
    """

    kind: Literal["thrust", "screw_error", "motor_encoder", "scale"]
    wavelength_mm: Annotated[float, Field(gt=0, le=1e4)] | None = None
    per_motor_rev: Annotated[float, Field(gt=0, le=1e6)] | None = None
    amplitude_n: Annotated[float, Field(ge=0, le=1e5)] | None = None
    amplitude_um: Annotated[float, Field(ge=0, le=1e3)] | None = None
    phase_deg: float = 0.0
    source: str = ""

    @model_validator(mode="after")
    def _one_period_one_amplitude(self) -> PeriodicDisturbanceConfig:
        if (self.wavelength_mm is None) == (self.per_motor_rev is None):
            raise ValueError("give exactly one of wavelength_mm and per_motor_rev")
        if self.kind == "thrust":
            if self.amplitude_n is None or self.amplitude_um is not None:
                raise ValueError("a 'thrust' disturbance needs amplitude_n (and no amplitude_um)")
        elif self.amplitude_um is None or self.amplitude_n is not None:
            raise ValueError(f"a '{self.kind}' disturbance needs amplitude_um (and no amplitude_n)")
        return self

    @property
    def phase_rad(self) -> float:
        return self.phase_deg * units.DEG


class DisturbanceModesAtConfig(DisturbanceModesConfig):
    """Disturbance modes identified with the table at one position (one entry of
    ``[[axes.<axis>.disturbance_modes_at]]``, the position-scheduled feed estimator)."""

    position_mm: Annotated[float, Field(ge=-1e4, le=1e4)]
    """Table position of the identification, mm (machine coordinates, as ``position_cmd``)."""


class FeedEstimatorConfig(_Model):
    """Tuning of an axis' Kalman force estimator (``[axes.x.estimator]``, all optional).

    Absent keys are chosen at start-up (:meth:`millsense.estimation.feed.estimator.FeedAxisModel.
    from_config`): R from ``current_noise_a`` through the C3 low-pass, Q by the widest-band
    rule of :func:`millsense.estimation.feed.tuning.tune_q` (``band_hz``: the least-noise rule;
    ``mode_shift_pct`` > 0: the robust design of
    :func:`millsense.estimation.feed.tuning.tune_robust`).
    """

    r_nm2: Annotated[float, Field(gt=0, le=1e6)] | None = None
    """Per-sample variance of the low-passed C3 torque in an air cut, N²·m² (Aslan Eq. 3.30)."""
    q_nm2_s: Annotated[float, Field(gt=0, le=1e12)] | None = None
    """Spectral density of the disturbance torque's rate, (N·m)²/s (Aslan Eq. 3.30 Q)."""
    lowpass_hz: Annotated[float, Field(gt=0, le=1e5)] | None = None
    """Corner of the C3 torque low-pass, Hz (default 600 Hz)."""
    mode_shift_pct: Annotated[float, Field(ge=0, le=20)] = 0.0
    """Robustness margin: the disturbance-mode frequencies may lie anywhere within ± this
    percentage of the identified ones (position dependence); Q and the design damping maximise
    the worst-case ±3 dB band over that family
    (:func:`millsense.estimation.feed.tuning.tune_robust`).
    0 = nominal tuning on the identified modes only."""
    disturbance_path: DisturbancePathConfig | None = None
    """Identified τ_a → C3-torque path (``millsense identify path``, a sweep during a move);
    when given, the estimator uses it instead of the axis' ``disturbance_modes``."""
    disturbance_path_at_rest: DisturbancePathConfig | None = None
    """The same identified with the axis holding position (``millsense identify path`` of a
    sweep at rest); when given, the estimator runs both and follows the commanded speed
    (:class:`millsense.estimation.feed.condition.OperatingConditionFeedEstimator`)."""
    band_hz: Annotated[float, Field(gt=0, lt=1000)] | None = None
    """Band the estimate must keep, Hz: Q is the least-noise value whose compensated FRF on the
    identified model stays within ±1 dB up to here
    (:func:`millsense.estimation.feed.tuning.least_noise_q`); absent: the widest ±3 dB band under
    the noise limit. Leave about 25 % above the band needed on the machine (decision
    "Least-noise Q for a requested band")."""

    @model_validator(mode="after")
    def _one_q_rule(self) -> FeedEstimatorConfig:
        if self.band_hz is not None and self.q_nm2_s is not None:
            raise ValueError("give q_nm2_s or band_hz, not both")
        if self.band_hz is not None and self.mode_shift_pct > 0:
            raise ValueError("band_hz applies to the nominal tuning (mode_shift_pct = 0)")
        return self


class FeedAxisConfig(_Model):
    """A feed drive: rigid-body parameters, transmission, friction and servo gains."""

    kind: Literal["linear", "rotary"] = "linear"
    inertia_kg_m2: Annotated[float, Field(gt=0, le=100)]
    """Equivalent inertia J_e reflected to the motor (Aslan Table 3.1)."""
    torque_constant_nm_a: Annotated[float, Field(gt=0, le=100)]
    lead_mm_rev: Annotated[float, Field(gt=0, le=200)] | None = None
    """Ball-screw lead h_p for linear axes (Aslan Table 3.3)."""
    lead_rad_rev: Annotated[float, Field(gt=0, le=6.3)] | None = None
    """Output angle per motor revolution for rotary axes (worm: 2π/ratio)."""
    efficiency: Annotated[float, Field(gt=0, le=1)] = 1.0
    friction: FrictionConfig | None = None
    """Identified friction (``millsense identify friction``); absent in a nameplate file
    (docs/decisions/0991-nameplate-machine-files.md): see :meth:`friction_table`."""
    velocity_kp_nm_s_rad: Annotated[float, Field(gt=0, le=1e4)] | None = None
    velocity_ki_nm_rad: Annotated[float, Field(ge=0, le=1e7)] | None = None
    velocity_bandwidth_hz: Annotated[float, Field(gt=0, le=2000)] = 40.0
    """Used to design the velocity PI when the gains are not given."""
    current_bandwidth_hz: Annotated[float, Field(gt=0, le=20000)] = 1000.0
    current_noise_a: Annotated[float, Field(ge=0, le=100)] = 0.0
    """RMS noise of the current command in an air cut (Aslan Eq. 3.30 R is its square)."""
    encoder_counts_rev: Annotated[int, Field(ge=16, le=2**32)] = 2**20
    encoder_signal_periods_rev: Annotated[int, Field(ge=1, le=2**24)] | None = None
    """Sine signal periods per revolution of the motor encoder before interpolation (its line
    count; catalogue data). Its interpolation error repeats every lead/periods of travel
    (Yamada §2.8): the wavelength of the DOB's encoder notches. None = not known."""
    position_gain_1_s: Annotated[float, Field(gt=0, le=1e4)] | None = None
    """Position-loop gain K_v (1/s); designed from the velocity bandwidth when absent."""
    position_feedback: Literal["motor", "scale"] = "motor"
    """Semi-closed loop (motor encoder) or full-closed loop (linear scale)."""
    scale_resolution_nm: Annotated[float, Field(gt=0, le=1e5)] | None = None
    """Linear-scale count, nm; None = no linear scale (required for position_feedback 'scale')."""
    dead_time_amplifier_ms: Annotated[float, Field(ge=0, le=100)] = 0.0
    """T_s: current command to current loop (Yamada Table 3-3)."""
    dead_time_motor_encoder_ms: Annotated[float, Field(ge=0, le=100)] = 0.0
    """T_m: motor-angle measurement (Yamada Table 3-3)."""
    dead_time_scale_ms: Annotated[float, Field(ge=0, le=100)] = 0.0
    """T_t: table-position measurement (Yamada Table 3-3)."""
    disturbance_modes: DisturbanceModesConfig | None = None
    """Aslan Table 3.4 modes between the table load and the motor (rigid-body axes)."""
    disturbance_modes_at: list[DisturbanceModesAtConfig] = []
    """Φ_d identified at several table positions, ascending (linear axes): ``millsense
    estimate --method feed`` then runs the position-scheduled estimator
    (:mod:`millsense.estimation.feed.schedule`,
    docs/decisions/0116-position-scheduled-feed-estimator.md) interpolating by the commanded
    position; ``disturbance_modes`` is not used by the estimator then."""
    ball_screw: BallScrewConfig | None = None
    """Dual/triple-inertia ball screw (Yamada); replaces the rigid body when given."""
    periodic_disturbances: list[PeriodicDisturbanceConfig] = []
    estimator: FeedEstimatorConfig | None = None
    """Kalman force-estimator tuning (R, Q, low-pass); absent keys are chosen automatically."""
    mode_shift_pct_per_100mm: Annotated[float, Field(ge=-50, le=50)] = 0.0
    """Position-dependent disturbance modes (linear axes, simulator only): every mode frequency
    changes by this percentage per 100 mm of table travel from ``mode_reference_mm``,
    ``f_k(x) = f_k0·(1 + κ·(x − x_ref))`` (κ = value/100 per 100 mm;
    docs/decisions/0115-position-dependent-disturbance-modes-simulator.md). 0 (default): no position
    dependence."""
    mode_reference_mm: Annotated[float, Field(ge=-1e4, le=1e4)] = 0.0
    """Table position at which ``disturbance_modes`` hold, mm (machine coordinates)."""
    source: str = ""

    def friction_table(self, where: str = "machine", axis: str = "") -> FrictionConfig:
        """The friction table, or a one-line ConfigError naming the identification it needs.

        A nameplate machine file has no friction (decision
        docs/decisions/0991-nameplate-machine-files.md); whatever needs it (a simulated drive,
        the C3 stage of an estimator) says so instead of assuming a value.
        """
        if self.friction is None:
            key = f"axes.{axis}.friction" if axis else "friction"
            raise ConfigError(
                f"{where}: missing table '{key}' (identify it: millsense commission, then "
                "millsense identify friction, then millsense merge)"
            )
        return self.friction

    @model_validator(mode="after")
    def _scale_for_full_closed(self) -> FeedAxisConfig:
        if self.position_feedback == "scale" and self.scale_resolution_nm is None:
            raise ValueError("position_feedback 'scale' needs scale_resolution_nm")
        if self.disturbance_modes_at:
            if self.kind != "linear":
                raise ValueError("disturbance_modes_at is for linear axes only")
            pos = [m.position_mm for m in self.disturbance_modes_at]
            if any(b <= a for a, b in itertools.pairwise(pos)):
                raise ValueError(
                    f"disturbance_modes_at: position_mm must be strictly ascending, got {pos}"
                )
        return self

    @model_validator(mode="after")
    def _lead_given(self) -> FeedAxisConfig:
        if self.kind == "linear" and self.lead_mm_rev is None:
            raise ValueError("lead_mm_rev is required for a linear axis")
        if self.kind == "rotary" and self.lead_rad_rev is None:
            raise ValueError("lead_rad_rev is required for a rotary axis")
        return self

    @model_validator(mode="after")
    def _one_estimator_path(self) -> FeedAxisConfig:
        est = self.estimator
        if (
            self.disturbance_modes_at
            and est
            and (est.disturbance_path or est.disturbance_path_at_rest)
        ):
            raise ValueError(
                "give disturbance_modes_at (position-scheduled) or estimator.disturbance_path "
                "(and _at_rest), not both"
            )
        return self

    @model_validator(mode="after")
    def _mode_shift_linear_only(self) -> FeedAxisConfig:
        if self.kind == "rotary" and self.mode_shift_pct_per_100mm != 0.0:
            raise ValueError("mode_shift_pct_per_100mm applies to linear axes only")
        return self

    @property
    def transmission_m_rad(self) -> float:
        """r_g = h_p / 2π: load travel per motor radian (m/rad, or rad/rad for rotary)."""
        if self.kind == "linear":
            assert self.lead_mm_rev is not None
            return self.lead_mm_rev * units.MM / (2.0 * math.pi)
        assert self.lead_rad_rev is not None
        return self.lead_rad_rev / (2.0 * math.pi)

    def position_gain(self) -> float:
        """K_v (1/s): ``position_gain_1_s``, or the design from the velocity bandwidth where
        absent, a quarter of its angular frequency (the simulator's drives and their truth
        design it so)."""
        if self.position_gain_1_s is not None:
            return float(self.position_gain_1_s)
        return 2.0 * math.pi * self.velocity_bandwidth_hz / 4.0


class SpindleConfig(_Model):
    """Spindle drive (Aslan Table 5.1/5.2); the drive model itself lives in ``machine``."""

    max_rpm: Annotated[float, Field(gt=0, le=200000)]
    inertia_kg_m2: Annotated[float, Field(gt=0, le=100)]
    torque_constant_nm_a: Annotated[float, Field(gt=0, le=100)]
    viscous_nm_s_rad: Annotated[float, Field(ge=0, le=100)] = 0.0
    source: str = ""
    torque_constant_range2_nm_a: Annotated[float, Field(gt=0, le=100)] | None = None
    """K_tS above the winding switch (Aslan Table 5.1 range 2); None: same as range 1."""
    range_switch_rpm: Annotated[float, Field(gt=0, le=200000)] | None = None
    """Wye-delta winding switch speed (Aslan Ch. 5: 3300 rev/min); None: one range only."""
    coulomb_nm: Annotated[float, Field(ge=0, le=100)] = 0.0
    """Coulomb friction τ_coul,S (Aslan Eq. 5.2; not given in the thesis)."""
    back_emf_v_s_rad: Annotated[float, Field(ge=0, le=100)] | None = None
    """Back-EMF constant K_b (Aslan Fig. 5.1: 0.12 V/(rad/s))."""
    residual_modes: DisturbanceModesConfig | None = None
    """Identified residual structural modes G_sp of the velocity loop (``millsense identify
    spindle``; Aslan Ch. 5.2, App. E form)."""
    velocity_kp_a_s_rev: Annotated[float, Field(gt=0, le=1e4)] | None = None
    """Velocity PI proportional gain K_p, A per rev/s of speed error (Aslan Eq. 5.3: 20; the
    gains act on rev/s, decision "Spindle drive reading of Aslan Ch. 5")."""
    velocity_ki_a_rev: Annotated[float, Field(gt=0, le=1e7)] | None = None
    """Velocity PI integral gain K_i, A/s per rev/s of speed error = A/rev (Eq. 5.3: 600)."""
    velocity_loop_period_ms: Annotated[float, Field(gt=0, le=100)] | None = None
    """Velocity-loop sample period T_v, ms (Aslan P7: 0.2 ms)."""
    encoder_counts_rev: Annotated[int, Field(ge=16, le=2**32)] | None = None
    """Counts per revolution of the spindle motor's encoder (the velocity loop's speed); the
    chatter monitor reads it to tell where the drive's quantisation lines can stand (decision
    1697). None = not known."""
    speed_from_encoder_difference: bool = False
    """The velocity loop's speed is the motor encoder's angle difference over the loop's
    period, ``(θ_k − θ_{k−1})/T_v`` (the drive's data; a lag of T_v/2 against the speed at the
    instant), not the speed at the instant (Aslan's continuous Ω, Eq. 5.3). The spindle
    observer's response to the cutting torque (the engagement monitor's equaliser) models it;
    the observer itself is designed on the loop with the speed at the instant (decision
    1708)."""
    current_kp_v_a: Annotated[float, Field(gt=0, le=1e4)] | None = None
    """Current PI proportional gain, V/A (Aslan Eq. 5.3 G_I: 3.1)."""
    current_ki_v_a_s: Annotated[float, Field(gt=0, le=1e8)] | None = None
    """Current PI integral gain, V/(A·s) (Eq. 5.3 G_I: 1010)."""
    motor_a_v_s2_a: Annotated[float, Field(gt=0, le=1e3)] | None = None
    """Motor admittance ``I/V = 1/(a s² + b s + c)``: a, V·s²/A, range 1 (Aslan Eq. 5.7)."""
    motor_b_v_s_a: Annotated[float, Field(gt=0, le=1e3)] | None = None
    """Motor admittance b, V·s/A, range 1 (Eq. 5.7)."""
    motor_c_ohm: Annotated[float, Field(ge=0, le=1e3)] | None = None
    """Motor admittance c, V/A, range 1 (Eq. 5.7)."""
    motor_a_range2_v_s2_a: Annotated[float, Field(gt=0, le=1e3)] | None = None
    """Motor admittance a above the winding switch, V·s²/A (Eq. 5.7 range 2); None: range 1."""
    motor_b_range2_v_s_a: Annotated[float, Field(gt=0, le=1e3)] | None = None
    """Motor admittance b above the winding switch, V·s/A; None: range 1."""
    motor_c_range2_ohm: Annotated[float, Field(ge=0, le=1e3)] | None = None
    """Motor admittance c above the winding switch, V/A; None: range 1."""
    current_noise_a: Annotated[float, Field(ge=0, le=100)] = 0.0
    """RMS noise of the current command I_nom in air, A (the spindle observer's R is its square,
    Aslan Ch. 5.3; 0: the default of :mod:`millsense.estimation.from_config`)."""


class MachineLimitsConfig(_Model):
    """What the machine can deliver (``[limits]``): the plausibility layer
    (:mod:`millsense.core.plausibility`) warns when a plan exceeds them and the simulator raises
    a crash event when the cut does (decision 0942 "Machine limits and crash events").

    Every key is optional; an absent key is not checked.
    """

    spindle_power_kw: Annotated[float, Field(gt=0, le=1000)] | None = None
    """Continuous (S1) spindle motor power, kW: the mean cutting power must stay below it."""
    axis_force_n: Annotated[float, Field(gt=0, le=1e7)] | None = None
    """Largest force a linear feed axis can push against (drive peak torque through the ball
    screw), N: the load on any linear axis must stay below it."""
    max_feed_mm_min: Annotated[float, Field(gt=0, le=1e6)] | None = None
    """Largest programmable path feed (the rapid traverse rate), mm/min."""
    source: str = ""


class MachineConfig(_Model):
    """A machine tool: kinematics, feed axes by name, spindle, CNC sampling."""

    name: str
    kinematics: Literal["3-axis", "5-axis-trunnion-ac", "1-axis-stage"] = "3-axis"
    """``1-axis-stage``: a single feed stage on axis x (Yamada's test stands)."""
    sample_rate_hz: Annotated[float, Field(gt=0, le=1e6)] = 10000.0
    interpolator_period_ms: Annotated[float, Field(gt=0, le=100)] = 3.0
    axes: dict[str, FeedAxisConfig]
    spindle: SpindleConfig | None = None
    limits: MachineLimitsConfig | None = None
    """Power, force and feed limits (``[limits]``); None: nothing checked against the machine."""
    source: str = ""

    @model_validator(mode="after")
    def _axes_for_kinematics(self) -> MachineConfig:
        need = {
            "3-axis": {"x", "y", "z"},
            "5-axis-trunnion-ac": {"x", "y", "z", "a", "c"},
            "1-axis-stage": {"x"},
        }[self.kinematics]
        missing = need - set(self.axes)
        if missing:
            raise ValueError(
                f"kinematics '{self.kinematics}' needs axes {sorted(need)}; "
                f"missing {sorted(missing)}"
            )
        return self

    def axis(self, name: str) -> FeedAxisConfig:
        try:
            return self.axes[name]
        except KeyError:
            raise ConfigError(
                f"machine '{self.name}': no axis '{name}' (axes: {', '.join(self.axes)})"
            ) from None

    def with_axes(self, axes: str | list[str], kinematics: str) -> MachineConfig:
        """The same machine with only ``axes`` under ``kinematics`` (e.g. the X/Y/Z of a 5-axis
        machine as a 3-axis one); one-line error for an axis it does not have."""
        kept = {a: self.axis(a) for a in axes}
        return self.model_copy(update={"kinematics": kinematics, "axes": kept})


# --------------------------------------------------------------------------------------------
# Stock
# --------------------------------------------------------------------------------------------


class StockConfig(_Model):
    """Raw stock: an axis-aligned box (mm, machine coordinates), or an STL mesh."""

    kind: Literal["box", "stl"] = "box"
    min_mm: tuple[float, float, float] | None = None
    max_mm: tuple[float, float, float] | None = None
    stl_path: str | None = None
    material: str = ""

    @model_validator(mode="after")
    def _box_or_stl(self) -> StockConfig:
        if self.kind == "box":
            if self.min_mm is None or self.max_mm is None:
                raise ValueError("a box stock needs min_mm and max_mm")
            for lo, hi, ax in zip(self.min_mm, self.max_mm, "xyz", strict=True):
                if not hi > lo:
                    raise ValueError(f"max_mm must exceed min_mm in {ax} ({hi:g} <= {lo:g})")
        elif self.stl_path is None:
            raise ValueError("an stl stock needs stl_path")
        return self


# --------------------------------------------------------------------------------------------
# Loading and error messages
# --------------------------------------------------------------------------------------------

M = TypeVar("M", bound=BaseModel)


def _strip_optional(ann: Any) -> Any:
    args = getattr(ann, "__args__", None)
    if args and type(None) in args and getattr(ann, "__origin__", None) is None:
        rest = [a for a in args if a is not type(None)]
        return rest[0] if len(rest) == 1 else ann
    if args and type(None) in args:  # typing.Optional / Union
        rest = [a for a in args if a is not type(None)]
        return rest[0] if len(rest) == 1 else ann
    return ann


def _field_at(model: type[BaseModel], loc: tuple[int | str, ...]) -> tuple[Any, list[Any]]:
    """The annotation and constraint metadata of the value at ``loc`` inside ``model``."""
    ann: Any = model
    metadata: list[Any] = []
    for part in loc:
        ann = _strip_optional(ann)
        metadata = []
        while getattr(ann, "__metadata__", None) is not None:  # Annotated[...]
            ann = ann.__origin__
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            if isinstance(part, str) and part in ann.model_fields:
                f = ann.model_fields[part]
                ann, metadata = f.annotation, list(f.metadata)
                continue
            return None, []
        origin = getattr(ann, "__origin__", None)
        args: tuple[Any, ...] = tuple(getattr(ann, "__args__", ()) or ())
        if origin in (list, set, frozenset) and args:
            ann = args[0]
        elif origin is tuple and args:
            ann = args[0] if (len(args) == 2 and args[1] is Ellipsis) else args[int(part)]
        elif origin is dict and len(args) == 2:
            ann = args[1]
        else:
            return None, []
        ann = _strip_optional(ann)
        metadata = list(getattr(ann, "__metadata__", ()) or ())
    return ann, metadata


def _constraint_text(model: type[BaseModel], loc: tuple[int | str, ...]) -> str:
    """The allowed range of the value at ``loc``, from its declared constraints."""
    ann, metadata = _field_at(model, loc)
    if getattr(ann, "__origin__", None) is Literal:
        return "one of " + ", ".join(repr(v) for v in ann.__args__)
    flat: list[Any] = []
    for meta in metadata:  # a FieldInfo inside Annotated carries its constraints in .metadata
        flat.extend(getattr(meta, "metadata", None) or [meta])
    bounds = []
    for meta in flat:
        for attr, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            value = getattr(meta, attr, None)
            if value is not None:
                bounds.append(f"{sym} {value:g}")
    return " and ".join(bounds)


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The BaseModel class inside an annotation such as ``X | None`` or ``dict[str, X]``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model_in(arg)
        if found is not None:
            return found
    return None


def format_validation_error(source: str, model: type[BaseModel], err: ValidationError) -> str:
    """One line naming the source, the key and what is allowed (first error only)."""
    order = {"extra_forbidden": 0, "missing": 2}
    first = sorted(err.errors(), key=lambda e: order.get(e.get("type", ""), 1))[0]
    loc = tuple(first.get("loc", ()))
    key = ".".join(str(p) for p in loc) or "(top level)"
    kind = first.get("type", "")
    value = first.get("input")
    if kind == "extra_forbidden":
        parent = _model_in_loc(model, loc[:-1])
        allowed = ", ".join(parent.model_fields) if parent is not None else ""
        return f"{source}: unknown key '{key}'" + (f" (allowed: {allowed})" if allowed else "")
    if kind == "missing":
        rng = _constraint_text(model, loc)
        return f"{source}: missing required key '{key}'" + (f" (allowed: {rng})" if rng else "")
    if kind in {"greater_than", "greater_than_equal", "less_than", "less_than_equal"}:
        rng = _constraint_text(model, loc)
        return f"{source}: key '{key}' = {value!r} is out of range: must be {rng}"
    msg = first.get("msg", "invalid value")
    msg = msg.removeprefix("Value error, ")
    if kind in {"value_error", "assertion_error"}:
        where = f"key '{key}'" if loc else "configuration"
        return f"{source}: {where}: {msg}"
    rng = _constraint_text(model, loc)
    extra = f" (allowed: {rng})" if rng else ""
    return f"{source}: key '{key}' = {value!r}: {msg}{extra}"


def _model_in_loc(model: type[BaseModel], loc: tuple[int | str, ...]) -> type[BaseModel] | None:
    ann, _ = _field_at(model, loc)
    return _model_in(ann) if ann is not None else None


def parse_config(model: type[M], data: Mapping[str, Any], source: str) -> M:
    """Validate ``data`` as ``model``; errors become one-line :class:`ConfigError`."""
    try:
        return model.model_validate(dict(data))
    except ValidationError as err:
        raise ConfigError(format_validation_error(source, model, err)) from None


#: Parsed TOML files of this process by (path, mtime, size): a batch worker reads the same
#: machine file for every step of every recording (≈ 9 ms a parse); callers get a copy.
_TOML_CACHE: dict[tuple[str, int, int], dict[str, Any]] = {}
_TOML_CACHE_MAX = 32


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file; a missing file or a syntax error is a one-line ConfigError.

    A file read before and unchanged since (same modification time and size) is not parsed
    again: the caller gets a deep copy of the parse."""
    import copy

    p = Path(path)
    try:
        st = p.stat()
        key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
        hit = _TOML_CACHE.get(key)
        if hit is not None:
            return copy.deepcopy(hit)
        with p.open("rb") as fh:
            data = tomllib.load(fh)
        if len(_TOML_CACHE) >= _TOML_CACHE_MAX:
            _TOML_CACHE.pop(next(iter(_TOML_CACHE)))
        _TOML_CACHE[key] = copy.deepcopy(data)
        return data
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"{p}: is a directory, expected a TOML file") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not a text file") from None


def load_config(model: type[M], path: str | Path, table: str | None = None) -> M:
    """Load ``model`` from a TOML file, optionally from one of its tables (``[tool]``)."""
    data = read_toml(path)
    source = str(path)
    if table is not None:
        if table not in data or not isinstance(data[table], dict):
            raise ConfigError(f"{path}: missing table [{table}]")
        data = data[table]
        source = f"{path} [{table}]"
    return parse_config(model, data, source)
