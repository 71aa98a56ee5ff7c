"""The virtual machine's own truth for a preset: coupled mechanics, motor, friction, ripple.

The preset machine file (``millsense/data/machines/<name>.toml``) is what estimators may read;
the simulator runs the truth kept in its own data, ``millsense/simulator/data/``:

- ``<name>-truth-mechanics.toml`` — the coupled drives of :mod:`.truth_drive`, fitted by
  :mod:`.truth_fit` to resemble Aslan Table 3.4, with the fit error (decision 0973);
- ``<name>-truth.toml`` — what the estimators may only learn by identification: the motor's
  true K_t, its electrics and PI current loop, dead times, LuGre friction with a real Stribeck
  hump (Aslan Eq. 3.2–3.4; the preset's X/Y rows have none), torque ripple (cogging and
  current-ripple harmonics of the motor angle, Yamada §3.6 form), the screw stroke over which
  the plant is tabulated (decision 0975); optionally ``[[axes.<n>.periodic_disturbances]]``
  in the machine-file format (screw error, encoder and scale interpolation errors, thrust
  ripple of a wavelength of travel: Yamada §3.6; decision 1705).

``yamada-b`` has a truth of its own since decision 1705, ``yamada-a`` since decision 1711: the
mechanics fitted by :mod:`.truth_fit_stage` to Yamada Table 3-3 (and §3.4 for B).

:func:`truth_feed_params` turns one axis into the feed-drive kernel's parameters: the plant
tabulated on a uniform grid over the stroke (decision 0974), the CNC's servo gains designed as
the preset's (``K_p = J·ω_c``…) on the truth's inertia.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np

from millsense.core import units
from millsense.core.config import FeedAxisConfig, PeriodicDisturbanceConfig
from millsense.core.errors import ConfigError
from millsense.models.ball_screw import periodic_terms
from millsense.models.drive_plant import KIND_TORQUE, PeriodicTerm
from millsense.models.lugre import LuGre
from millsense.simulator.feed_drive import (
    ElectricalCurrentLoop,
    FeedDriveParams,
    LostMotion,
    PlantSchedule,
)
from millsense.simulator.truth_drive import CoupledDrive, ScrewGeometry

#: Presets with a truth of their own.
TRUTH_PRESETS = ("quaser-ux600", "yamada-a", "yamada-b")


@dataclass(frozen=True)
class TruthAxis:
    """One axis of the truth (SI)."""

    drive: CoupledDrive
    torque_constant: float
    current_loop: ElectricalCurrentLoop
    dead_time_amplifier_s: float
    dead_time_motor_encoder_s: float
    friction: LuGre
    ripple: tuple[PeriodicTerm, ...]
    current_noise_a: float
    stroke: tuple[float, float]
    grid_points: int
    substeps: int = 4
    backlash: float = 0.0
    preload_lift: float = math.inf


def read_truth_file(name: str) -> dict[str, Any]:
    """A TOML file of the simulator's truth data (``millsense/simulator/data/<name>``)."""
    path = resources.files("millsense.simulator") / "data" / name
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError as exc:
        raise ConfigError(f"machine truth: {name} not found in millsense/simulator/data") from exc


def drive_from_table(name: str, t: dict[str, Any]) -> CoupledDrive:
    """A :class:`CoupledDrive` from a ``[axes.<n>.mechanics]`` table (units in the keys)."""
    lin = t["kind"] == "linear"
    mu = "kg" if lin else "kg_m2"
    ku = "n_m" if lin else "nm_rad"
    screw = None
    mesh = None
    if lin:
        screw = ScrewGeometry(
            ea_n=float(t["screw_ea_n"]),
            span_m=float(t["screw_span_mm"]) * units.MM,
            offset_m=float(t["screw_offset_mm"]) * units.MM,
            support=t["screw_support"],
            nut_stiffness_n_m=float(t["nut_stiffness_n_m"]),
            bearing_stiffness_n_m=float(t["bearing_stiffness_n_m"]),
        )
    else:
        mesh = float(t["mesh_stiffness_nm_rad"])
    return CoupledDrive(
        kind=t["kind"],
        transmission=float(t["transmission"]),
        efficiency=float(t["efficiency"]),
        motor_inertia=float(t["motor_inertia_kg_m2"]),
        screw_inertia=float(t["screw_inertia_kg_m2"]),
        coupling_stiffness=float(t["coupling_stiffness_nm_rad"]),
        table_mass=float(t[f"table_mass_{mu}"]),
        base_mass=float(t[f"base_mass_{mu}"]),
        base_stiffness=float(t[f"base_stiffness_{ku}"]),
        attached_mass=tuple(float(v) for v in t[f"attached_mass_{mu}"]),
        attached_stiffness=tuple(float(v) for v in t[f"attached_stiffness_{ku}"]),
        damping_ratio=tuple(float(v) for v in t["damping_ratio"]),
        screw=screw,
        drive_stiffness=mesh,
        name=f"{name} truth",
    )


def load_truth(machine_name: str) -> dict[str, TruthAxis]:
    """Every axis of a preset's truth.

    Raises
    ------
    ConfigError if the preset has no truth or a table misses a key (one line, naming it).
    """
    if machine_name not in TRUTH_PRESETS:
        raise ConfigError(f"machine truth: no truth for machine '{machine_name}'")
    mech = read_truth_file(f"{machine_name}-truth-mechanics.toml")["axes"]
    rest = read_truth_file(f"{machine_name}-truth.toml")["axes"]
    out: dict[str, TruthAxis] = {}
    for ax, tab in rest.items():
        where = f"{machine_name}-truth.toml [axes.{ax}]"
        try:
            drive = drive_from_table(f"{machine_name} {ax}", mech[ax]["mechanics"])
            mot, fr, rp = tab["motor"], tab["friction"], tab.get("ripple", {})
            kt = float(mot["torque_constant_nm_a"])
            cl = ElectricalCurrentLoop.designed(
                float(mot["resistance_ohm"]),
                float(mot["inductance_mh"]) * 1e-3,
                float(mot["back_emf_v_s_rad"]),
                float(mot["current_bandwidth_hz"]),
            )
            fric = LuGre(
                sigma0=tuple(fr["sigma0_nm_rad"]),
                sigma1=tuple(fr["sigma1_nm_s_rad"]),
                sigma2=tuple(fr["viscous_nm_s_rad"]),
                static=tuple(fr["static_nm"]),
                coulomb=tuple(fr["coulomb_nm"]),
                stribeck_velocity=tuple(fr["stribeck_velocity_rad_s"]),
            )
            ripple = tuple(
                PeriodicTerm(KIND_TORQUE, float(n), float(a), float(ph))
                for n, a, ph in zip(
                    rp.get("per_motor_rev", []),
                    rp.get("amplitude_nm", []),
                    rp.get("phase_rad", []),
                    strict=True,
                )
            )
            extra = [PeriodicDisturbanceConfig(**d) for d in tab.get("periodic_disturbances", [])]
            ripple += periodic_terms(extra, drive.transmission)
            lo, hi = tab.get("stroke_mm", [0.0, 0.0])
            scale = units.MM if drive.kind == "linear" else math.pi / 180.0
            out[ax] = TruthAxis(
                drive=drive,
                torque_constant=kt,
                current_loop=cl,
                dead_time_amplifier_s=float(mot["dead_time_amplifier_ms"]) * 1e-3,
                dead_time_motor_encoder_s=float(mot["dead_time_motor_encoder_ms"]) * 1e-3,
                friction=fric,
                ripple=ripple,
                current_noise_a=float(mot["current_noise_a"]),
                stroke=(float(lo) * scale, float(hi) * scale),
                grid_points=int(tab.get("grid_points", 33)),
                substeps=int(tab.get("substeps", 4)),
                backlash=float(tab.get("backlash_arcsec", 0.0)) * math.pi / 648000.0
                if drive.kind == "rotary"
                else float(tab.get("backlash_um", 0.0)) * 1e-6,
                preload_lift=2.83 * float(tab["nut_preload_n"])
                if "nut_preload_n" in tab
                else math.inf,
            )
        except KeyError as exc:
            raise ConfigError(f"{where}: missing key {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: {exc}") from exc
    return out


def plant_schedule(truth: TruthAxis) -> PlantSchedule | None:
    """The drive's plant on ``grid_points`` uniform positions over the stroke (None when the
    mechanics do not depend on the position: rotary axes)."""
    d = truth.drive
    if d.screw is None or truth.grid_points < 2:
        return None
    xs = np.linspace(truth.stroke[0], truth.stroke[1], truth.grid_points)
    return PlantSchedule(xs, tuple(d.plant(float(x)) for x in xs))


def lost_motion(truth: TruthAxis) -> LostMotion | None:
    """Backlash of the transmission and preload lift-off of a linear axis' nut (decision
    0978): the lift-off force 2.83·F_p (a double nut preloaded by F_p unloads one half) as a
    stretch at the reference stiffness; beyond it the nut's stiffness halves, the series
    stiffness of shaft, nut and bearing drops to ``ratio``."""
    d = truth.drive
    if truth.backlash <= 0.0 and not math.isfinite(truth.preload_lift):
        return None
    row = np.zeros(2 * d.n_dof)
    row[: d.n_dof] = d.stretch()
    k = d.transmission_stiffness(d.reference_position)
    lift, ratio = 1e9, 1.0
    if math.isfinite(truth.preload_lift) and d.screw is not None:
        sc = d.screw
        ks = float(sc.shaft_stiffness(d.reference_position))
        soft = 1.0 / (1.0 / ks + 2.0 / sc.nut_stiffness_n_m + 1.0 / sc.bearing_stiffness_n_m)
        lift, ratio = truth.preload_lift / k, soft / k
    return LostMotion(row, 0.5 * truth.backlash, lift, ratio)


def truth_feed_params(axis: FeedAxisConfig, truth: TruthAxis) -> FeedDriveParams:
    """The kernel parameters of one truth axis.

    The CNC's settings (velocity bandwidth, position gain, encoder, feedback, scale) come from
    the machine file ``axis``; every physical property from the truth. Servo gains follow the
    preset's design rule on the truth's inertia (decision "feed-drive servo gains").
    """
    d = truth.drive
    j = d.inertia
    wc = 2.0 * math.pi * axis.velocity_bandwidth_hz
    kp = axis.velocity_kp_nm_s_rad or j * wc
    ki = axis.velocity_ki_nm_rad if axis.velocity_ki_nm_rad is not None else kp * wc / 4.0
    sched = plant_schedule(truth)
    plant = d.plant()
    return FeedDriveParams(
        plant=plant,
        torque_constant=truth.torque_constant,
        transmission=d.transmission,
        efficiency=d.efficiency,
        friction=truth.friction,
        kp=kp,
        ki=ki,
        kv=axis.position_gain(),
        current_bandwidth_hz=truth.current_loop.kp / truth.current_loop.inductance / (2 * math.pi),
        encoder_counts_rev=axis.encoder_counts_rev,
        torque_noise_nm=truth.current_noise_a * truth.torque_constant,
        current_loop=truth.current_loop,
        scale_resolution_m=(
            axis.scale_resolution_nm * 1e-9 if axis.scale_resolution_nm is not None else None
        ),
        position_feedback=axis.position_feedback,
        dead_time_amplifier_s=truth.dead_time_amplifier_s,
        dead_time_motor_encoder_s=truth.dead_time_motor_encoder_s,
        dead_time_scale_s=axis.dead_time_scale_ms * 1e-3,
        modes=None,
        periodic=truth.ripple,
        plant_schedule=sched,
        lost_motion=lost_motion(truth),
    )
