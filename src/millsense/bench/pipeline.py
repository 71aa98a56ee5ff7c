"""The estimator path of the acceptance, in-process: nameplate → commission → identify → merge.

Issue 12 (docs/decisions/0993-acceptance-through-the-pipeline.md): an acceptance case may give
an estimator nothing of the simulator's. :func:`identified_machine` does for a set of feed axes
what a user does with the CLI on a machine:

1. **nameplate** — ``millsense/data/machines/<name>.toml`` (catalogue K_t, J_e, η, lead,
   encoder, CNC gains; no friction, modes or noise);
2. **commission** — the commissioning tests of :mod:`millsense.simulator.commissioning` run on
   the virtual machine (the simulator's own description, or a drive the case builds): constant-
   velocity friction moves, a presliding test, an accelerating move, a table-load sweep moving
   and/or at rest, an air cut moving and/or holding. Only CNC channels (current, motor speed,
   encoder angle, the applied load) are read back;
3. **identify** — the library functions behind ``millsense identify drive|friction|path``
   (:func:`millsense.ident.drive.rigid_body_from_acceleration`,
   :func:`millsense.ident.friction.lugre_static_from_moves`,
   :func:`millsense.ident.friction.fit_presliding`,
   :func:`millsense.estimation.feed.path_fit.fit_disturbance_path`) with the nameplate's K_t,
   each writing the same fragment keys as the CLI; plus R from the air cut
   (:func:`millsense.estimation.feed.tuning.air_cut_variance` of the C3 torque, Aslan Eq.
   3.28–3.30) as ``estimator.r_nm2``, which the CLI has no command for yet (there, R comes from
   ``current_noise_a`` or ``estimate --idle``);
4. **merge** — :func:`millsense.ident.fragment.merge` over the nameplate, validated as a machine
   (what ``millsense merge`` does).

The estimator is then built from the merged file by
:meth:`~millsense.estimation.feed.estimator.FeedAxisModel.from_config`, exactly as
``millsense estimate`` builds it (:func:`feed_model`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from millsense.core.config import MachineConfig, parse_config
from millsense.core.errors import ConfigError, InputDataError
from millsense.core.presets import preset_data
from millsense.core.recording import Recording
from millsense.estimation.feed.estimator import (
    FeedAxisModel,
    OperatingCondition,
    c3_front_end,
)
from millsense.estimation.feed.path_fit import SweepResult, fit_disturbance_path
from millsense.estimation.feed.tuning import air_cut_r
from millsense.ident import drive as ident_drive
from millsense.ident import friction as ident_friction
from millsense.ident.fragment import merge
from millsense.simulator import commissioning as com
from millsense.simulator.feed_drive import FeedDriveParams
from millsense.simulator.machine_file import simulated_feed_drive, simulator_machine

#: Fit band of the disturbance path, Hz (the default of ``millsense identify path``).
PATH_BAND_HZ = (3.0, 260.0)
#: Motor speed of the moving table-load sweep and of the moving air cut, rad/s.
SWEEP_SPEED_RAD_S = 10.0
AIR_CUT_SPEED_RAD_S = 5.0


@dataclass(frozen=True)
class AxisIdentification:
    """What the pipeline identified on one axis (for reports): the merged fragment and the
    path sweeps (FRF + fit) per operating condition."""

    fragment: dict[str, Any]
    sweeps: dict[str, SweepResult]
    notes: tuple[str, ...]
    r_at_rest: float | None = None
    """R of the at-rest air cut (holding position), N²·m²: the machine file has one R."""


@dataclass(frozen=True)
class PipelineResult:
    """The merged machine (nameplate + identified fragments) and what produced it."""

    machine: MachineConfig
    nameplate: MachineConfig
    axes: dict[str, AxisIdentification]


def commission_axis(
    sim: MachineConfig,
    axis: str,
    *,
    drive: FeedDriveParams | None = None,
    conditions: Sequence[OperatingCondition] = ("moving",),
    seed: int = 0,
) -> dict[str, Recording]:
    """The commissioning recordings of one rigid feed axis on the virtual machine.

    ``sim`` is the simulator's machine, ``drive`` optionally the simulated drive to use instead
    of the one built from ``sim`` (a case's commissioning machine). Keys: ``friction``,
    ``presliding``, ``acceleration``, ``table_load_sweep`` / ``table_load_sweep_at_rest``,
    ``air_cut`` / ``air_cut_at_rest`` (per condition).
    """
    speeds = np.geomspace(0.1, 30.0, 16)
    order = np.ravel(np.column_stack([speeds, -speeds]))
    friction = com.friction_test(sim, axis, order, hold_s=2.0, seed=seed, drive=drive)
    # the presliding steps from the breakaway the friction moves measured (decision 1799)
    kt = com.nameplate_axis(sim, axis).torque_constant_nm_a
    brk = com.breakaway_from_friction_test(friction, axis, kt)
    recs = {
        "friction": friction,
        "presliding": com.presliding_test(
            sim, axis, breakaway_nm=brk, seed=seed + 4, drive=drive
        ),
        "acceleration": com.acceleration_test(sim, axis, seed=seed + 1, drive=drive),
    }
    for cond in conditions:
        moving = cond == "moving"
        sfx = "" if moving else "_at_rest"
        recs[f"table_load_sweep{sfx}"] = com.table_load_sweep(
            sim,
            axis,
            speed_rad_s=SWEEP_SPEED_RAD_S if moving else 0.0,
            seed=seed + 2,
            drive=drive,
        )
        recs[f"air_cut{sfx}"] = com.air_cut_test(
            sim,
            axis,
            speed_rad_s=AIR_CUT_SPEED_RAD_S if moving else 0.0,
            seed=seed + 3,
            drive=drive,
        )
    return recs


def _ch(rec: Recording, name: str) -> np.ndarray:
    return np.asarray(rec.channel(name), dtype=float)


def identify_axis(
    base: dict[str, Any],
    axis: str,
    recs: Mapping[str, Recording],
    *,
    where: str,
) -> AxisIdentification:
    """Identify one axis from its commissioning recordings over the machine ``base`` (the
    nameplate's raw TOML mapping); returns the fragment (``{"axes": {axis: {...}}}``)."""
    fs = recs["friction"].sample_rate_hz
    notes: list[str] = []

    def machine(frags: dict[str, Any]) -> MachineConfig:
        return parse_config(MachineConfig, merge(base, frags), where)

    frag: dict[str, Any] = {"axes": {axis: {}}}
    ax_frag: dict[str, Any] = frag["axes"][axis]
    kt = machine(frag).axis(axis).torque_constant_nm_a  # nameplate K_t, never the simulator's
    # identify drive (acceleration test) → J_e
    acc = recs["acceleration"]
    rb = ident_drive.rigid_body_from_acceleration(
        _ch(acc, f"{axis}/current"), _ch(acc, f"{axis}/speed"), fs, torque_constant_nm_a=kt
    )
    ax_frag["inertia_kg_m2"] = rb.inertia
    notes.append(f"J_e {rb.inertia:.5g} kg·m² (K_t {kt:g} N·m/A nameplate)")
    # identify friction (constant-velocity moves + presliding) → [axes.<a>.friction]
    fr_rec = recs["friction"]
    segs = ident_friction.steady_segments(
        _ch(fr_rec, f"{axis}/velocity_ref"), min_samples=round(0.2 * fs)
    )
    w, t, s = ident_friction.move_means(
        _ch(fr_rec, f"{axis}/speed"), kt * _ch(fr_rec, f"{axis}/current"), segs
    )
    fit = ident_friction.lugre_static_from_moves(w, t, s)
    if "presliding" in recs:
        pr = recs["presliding"]
        try:
            pf = ident_friction.fit_presliding(
                _ch(pr, f"{axis}/current"),
                _ch(pr, f"{axis}/angle"),
                fs,
                inertia_kg_m2=rb.inertia,
                torque_constant_nm_a=kt,
                static=fit,
            )
        except InputDataError as exc:
            # what a user does when `identify friction` refuses the presliding record: run it
            # on the constant-velocity moves alone (static friction, no bristle parameters)
            notes.append(f"presliding not identified ({exc}); static friction only")
        else:
            fit = ident_friction.LuGreFit(
                fit.positive, fit.negative, (pf.sigma0,) * 2, (pf.sigma1,) * 2
            )
    table = fit.config_table()
    table["source"] = "millsense identify friction (bench pipeline)"
    ax_frag["friction"] = table
    # identify path (table-load sweeps) → estimator.disturbance_path[_at_rest]; R from air cuts
    sweeps: dict[str, SweepResult] = {}
    est: dict[str, Any] = {}
    for cond, sfx in (("moving", ""), ("at_rest", "_at_rest")):
        key = f"table_load_sweep{sfx}"
        if key not in recs:
            continue
        cfg = machine(frag).axis(axis)
        drive, lugre, lowpass = c3_front_end(axis, cfg, fs, where)
        rec = recs[key]
        per = rec.metadata.get("period_samples")
        sw = fit_disturbance_path(
            _ch(rec, f"{axis}/load"),
            _ch(rec, f"{axis}/current_cmd"),
            _ch(rec, f"{axis}/speed"),
            drive,
            lowpass,
            fs,
            period_samples=per if isinstance(per, int) and per > 0 else None,
            lugre=lugre,
            fit_band_hz=PATH_BAND_HZ,
        )
        sweeps[cond] = sw
        est[f"disturbance_path{sfx}"] = sw.fit.config_table(
            f"millsense identify path {key} {PATH_BAND_HZ[0]:g}-{PATH_BAND_HZ[1]:g} Hz "
            f"(bench pipeline, {cond})"
        )
        air = recs[f"air_cut{sfx}"]
        r = air_cut_r(
            _ch(air, f"{axis}/current_cmd"), _ch(air, f"{axis}/speed"), drive, lowpass, fs, lugre
        )
        est[f"r_nm2{sfx}"] = r
        notes.append(
            f"{cond}: path RMS error {sw.fit.rms_error:.3g} ({sw.fit.n_states} states), "
            f"R {r:.3g} N²·m²"
        )
    if not sweeps:
        raise ConfigError(f"bench pipeline {axis}: no table-load sweep recorded")
    # the machine file carries one R: the moving one, else the at-rest one
    r_moving = est.pop("r_nm2", None)
    r_rest = est.pop("r_nm2_at_rest", None)
    est["r_nm2"] = r_moving if r_moving is not None else r_rest
    ax_frag["estimator"] = est
    return AxisIdentification(frag, sweeps, tuple(notes), r_rest)


def identified_machine(
    machine: str,
    axes: Sequence[str],
    *,
    drives: Mapping[str, FeedDriveParams] | None = None,
    conditions: Sequence[OperatingCondition] = ("moving",),
    seed: int = 0,
) -> PipelineResult:
    """Nameplate → commission → identify → merge for ``axes`` of the preset ``machine``.

    Parameters
    ----------
    machine : preset name: the nameplate is ``millsense/data/machines/<machine>.toml``, the
        virtual machine the simulator's own description of it (or ``drives``).
    axes : the (rigid) feed axes commissioned.
    drives : per axis, the simulated drive to commission instead of
        :func:`~millsense.simulator.machine_file.simulated_feed_drive` (a case's machine at
        commissioning); only driven, never read.
    conditions : which table-load sweeps and air cuts are run (``moving``, ``at_rest``).
    seed : base seed of the simulated tests.

    Returns
    -------
    PipelineResult: the merged machine (validated), the nameplate, per axis what was identified.
    """
    base, source = preset_data(MachineConfig, machine)
    nameplate = parse_config(MachineConfig, base, source)
    sim = simulator_machine(machine)
    merged = base
    out: dict[str, AxisIdentification] = {}
    for a in axes:
        nameplate.axis(a)
        drive = (drives or {}).get(a) or simulated_feed_drive(machine, a)
        recs = commission_axis(sim, a, drive=drive, conditions=conditions, seed=seed)
        ident = identify_axis(base, a, recs, where=f"{source} + identified {a}")
        merged = merge(merged, ident.fragment)
        out[a] = ident
    final = parse_config(MachineConfig, merged, f"{source} + identified")
    return PipelineResult(final, nameplate, out)


def feed_model(
    result: PipelineResult,
    axis: str,
    condition: OperatingCondition = "moving",
    *,
    sample_rate_hz: float | None = None,
) -> FeedAxisModel:
    """The feed estimator's model of ``axis`` from the merged machine, built as ``millsense
    estimate`` builds it (:meth:`FeedAxisModel.from_config`); ``at_rest`` uses the at-rest path
    (as :func:`millsense.estimation.from_config` does for the operating-condition estimator)
    and the at-rest air cut's R (the CLI's machine file has one R, the moving one)."""
    m = result.machine
    fs = sample_rate_hz or m.sample_rate_hz
    cfg = m.axis(axis)
    where = f"{m.name} (identified)"
    if condition == "moving":
        return FeedAxisModel.from_config(axis, cfg, sample_rate_hz=fs, where=where)
    est = cfg.estimator
    if est is None or est.disturbance_path_at_rest is None:
        raise ConfigError(f"{where}: axis {axis} was not identified at rest")
    ident = result.axes.get(axis)
    r_rest = ident.r_at_rest if ident is not None and ident.r_at_rest is not None else est.r_nm2
    rest = cfg.model_copy(
        update={
            "estimator": est.model_copy(
                update={"disturbance_path": est.disturbance_path_at_rest, "r_nm2": r_rest}
            )
        }
    )
    model = FeedAxisModel.from_config(axis, rest, sample_rate_hz=fs, where=f"{where} (at rest)")
    return replace(model, condition="at_rest")


def identified_ball_screw_machine(machine: str, axis: str = "x") -> PipelineResult:
    """Nameplate → commission (drive sweep) → identify drive → merge for a ball-screw axis.

    The steps of ``millsense identify drive`` on a ``drive_sweep`` recording
    (:func:`millsense.ident.drive.reference_frf`, ``fit_amplifier_delay``, ``fit_dual_inertia``,
    ``drive_config_table``) with the nameplate's K_t, lead and current-loop bandwidth: the merged
    axis carries the identified dual-inertia parameters (``ball_screw``, J_r) and dead times
    (Yamada C11). A resonance of the motor FRF above the axial mode that the model cannot have
    ends the fitted band at 0.9 of its frequency (:func:`~millsense.ident.drive
    .fit_dual_inertia`) and is reported in the notes.
    """
    base, source = preset_data(MachineConfig, machine)
    nameplate = parse_config(MachineConfig, base, source)
    ax = nameplate.axis(axis)
    rec = com.drive_sweep(simulator_machine(machine), axis)
    fs = rec.sample_rate_hz
    per = rec.metadata.get("period_samples")
    if not isinstance(per, int):
        raise ConfigError(f"bench pipeline {axis}: drive sweep without its period")
    kt, bw = ax.torque_constant_nm_a, ax.current_bandwidth_hz
    lead = (ax.lead_mm_rev or 0.0) * 1e-3
    r, u = _ch(rec, f"{axis}/injection"), _ch(rec, f"{axis}/current_cmd")
    hm = ident_drive.reference_frf(r, u, _ch(rec, f"{axis}/angle"), fs, per, detrend=True)
    ht = ident_drive.reference_frf(r, u, _ch(rec, f"{axis}/scale"), fs, per, detrend=True)
    hi = ident_drive.reference_frf(r, u, _ch(rec, f"{axis}/current"), fs, per)
    ts, _ = ident_drive.fit_amplifier_delay(hi, sample_rate_hz=fs, current_loop_hz=bw)
    fit = ident_drive.fit_dual_inertia(
        hm,
        ht,
        lead_m=lead,
        torque_constant_nm_a=kt,
        current_loop_hz=bw,
        sample_rate_hz=fs,
        amplifier_delay_s=ts,
        band_hz=(10.0, min(1000.0, 0.45 * fs)),
    )
    frag = {"axes": {axis: ident_drive.drive_config_table(fit, kt)}}
    notes: tuple[str, ...] = (f"dual inertia: resonance {fit.params.resonance_hz(lead):.1f} Hz",)
    if fit.unmodelled_mode_hz is not None:
        f_u = fit.unmodelled_mode_hz
        notes += (f"unmodelled mode at {f_u:.1f} Hz: band ends at {0.9 * f_u:.0f} Hz",)
    merged = parse_config(MachineConfig, merge(base, frag), f"{source} + identified {axis}")
    return PipelineResult(merged, nameplate, {axis: AxisIdentification(frag, {}, notes)})
