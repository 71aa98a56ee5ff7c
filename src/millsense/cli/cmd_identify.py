"""``millsense identify``: from commissioning recordings to machine-configuration fragments.

``millsense identify KIND RECORDING... -o FRAGMENT.toml [--plot FIT.png]`` with KIND one of

- ``frf``      FRF between ``--input-channel`` and ``--output-channel`` (multisine when the
  recording states its period, Welch otherwise) → ``[frf]`` table;
- ``modal``    modal fit of that FRF in ``--band`` → ``[axes.<axis>.disturbance_modes]``; with
  one sweep per table position, ``[[axes.<axis>.disturbance_modes_at]]`` at the mean
  commanded position of each (the position-scheduled feed estimator);
- ``path``     table-load sweep (``--input-channel`` the measured table load) through the feed
  estimator's own C3 front end (``--machine``: K_t, lead, η, friction, inertia) → rational fit
  on the sampled axis → ``[axes.<axis>.estimator.disturbance_path]`` (Aslan C5);
- ``friction`` constant-velocity moves (+ a presliding test) → ``[axes.<axis>.friction]``;
- ``drive``    current-injection sweep (+ an acceleration test) → ``[axes.<axis>]`` and
  ``[axes.<axis>.ball_screw]``;
- ``spindle``  velocity-loop sweep (+ constant-speed runs) → ``[spindle]`` (the inertia from
  the sweep's rigid body with the file's K_t and the motor admittance of the sweep's speed
  range, decision 1708; the friction) and its residual modes;
- ``idle``     repeated air cuts → a CSV table and ``[axes.<axis>.idle_table]`` referencing it.

Known quantities (torque constant, lead, inertia, current-loop bandwidth, spindle gains) come
from the recording's metadata or from ``--machine`` (a preset name or machine TOML).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError, InputDataError

_KINDS = ("frf", "modal", "path", "friction", "drive", "spindle", "idle", "noise")


def _parse_band(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(p) for p in text.split(":"))
    except ValueError:
        raise ConfigError(f"--band-hz {text!r}: expected LO:HI in Hz") from None
    if not (0 <= lo < hi and math.isfinite(hi)):
        raise ConfigError(f"--band-hz {text!r}: allowed 0 <= LO < HI")
    return lo, hi


class _Ctx:
    """Recordings, options and the machine, with look-ups that fail with one line."""

    def __init__(self, recs: list[Any], paths: list[Path], axis: str, machine: Any) -> None:
        self.recs = recs
        self.paths = paths
        self.axis = axis
        self.machine = machine

    def channel(self, rec: Any, path: Path, name: str) -> Any:
        if name not in rec:
            raise InputDataError(
                f"{path}: no channel {name!r} (has: {', '.join(rec.channel_names)})"
            )
        return rec.channel(name)

    def known(self, rec: Any, meta_key: str, what: str, from_machine: Any) -> float:
        """A value the identification is given: the machine file's (``--machine``, the
        user's belief, e.g. the nameplate K_t) first, else the recording's metadata (decision
        docs/decisions/0992-bench-reads-the-nameplate.md)."""
        if self.machine is not None:
            val = from_machine(self.machine)
            if val is not None:
                return float(val)
        v = rec.metadata.get(meta_key)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
        raise InputDataError(
            f"{what} is needed: not in the recording's metadata ({meta_key!r}); give --machine"
        )

    def axis_cfg(self) -> Any:
        if self.machine is None:
            return None
        return self.machine.axis(self.axis)


def _by_test(ctx: _Ctx, test: str) -> list[tuple[Any, Path]]:
    return [
        (r, p) for r, p in zip(ctx.recs, ctx.paths, strict=True) if r.metadata.get("test") == test
    ]


def _estimate(rec: Any, path: Path, inp: str, out: str, resolution: float) -> Any:
    from millsense.ident.frf import check_records, multisine_frf, welch_frf

    if inp not in rec or out not in rec:
        missing = inp if inp not in rec else out
        raise InputDataError(
            f"{path}: no channel {missing!r} (has: {', '.join(rec.channel_names)})"
        )
    u, y = rec.channel(inp), rec.channel(out)
    names = (inp, out)
    check_records(u, y, rec.sample_rate_hz, names=names)
    level = float(abs(y).max()) if len(y) else 0.0
    if float(y.std()) <= 1e-12 * max(level, 1e-300):
        raise InputDataError(f"{path}: channel {out!r} carries no response (constant)")
    per = rec.metadata.get("period_samples")
    if isinstance(per, int) and per > 0:
        return multisine_frf(u, y, rec.sample_rate_hz, per, names=names)
    return welch_frf(u, y, rec.sample_rate_hz, resolution_hz=resolution, names=names)


def _frf(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    from millsense.report.ident_plots import plot_frf_fit

    if not o["input"] or not o["output"]:
        raise ConfigError("identify frf/modal: give --input-channel and --output-channel")
    rec, path = ctx.recs[0], ctx.paths[0]
    est = _estimate(rec, path, o["input"], o["output"], o["resolution"])
    if o["band"] is not None:
        est = est.band(*o["band"])
    if o["plot"] is not None:
        plot_frf_fit(est, None, o["plot"], title=f"{o['output']} / {o['input']}")
    frag: dict[str, object] = {
        "frf": {
            "input": o["input"],
            "output": o["output"],
            "freq_hz": [float(v) for v in est.freq_hz],
            "real": [float(v) for v in est.h1.real],
            "imag": [float(v) for v in est.h1.imag],
            "coherence": [float(v) for v in est.coherence],
        }
    }
    return frag, [
        f"FRF {o['output']}/{o['input']} from {path} ({est.method}, {est.n_averages} averages)"
    ]


def _modal(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    if not o["input"] or not o["output"]:
        raise ConfigError("identify frf/modal: give --input-channel and --output-channel")
    if len(ctx.recs) == 1:
        one, one_notes = _modal_table(ctx, o, ctx.recs[0], ctx.paths[0], o["plot"])
        return {"axes": {ctx.axis: {"disturbance_modes": one}}}, one_notes
    # one sweep per table position: [[axes.<axis>.disturbance_modes_at]], the position being the
    # mean commanded position of each record
    # (docs/decisions/0117-position-scheduled-estimator-from-the-machine-file-issue-7.md)
    import numpy as np

    from millsense.core import units

    tables: list[tuple[float, dict[str, object]]] = []
    notes: list[str] = []
    for i, (rec, path) in enumerate(zip(ctx.recs, ctx.paths, strict=True)):
        pos = np.asarray(ctx.channel(rec, path, f"{ctx.axis}/position_cmd"), dtype=float)
        plot = o["plot"]
        if plot is not None:
            plot = Path(plot).with_name(f"{Path(plot).stem}-{i}{Path(plot).suffix}")
        table, n = _modal_table(ctx, o, rec, path, plot)
        position_mm = float(np.mean(pos)) / units.MM
        tables.append((position_mm, {"position_mm": position_mm, **table}))
        notes += [f"{path.name} at {position_mm:.1f} mm: {n[0]}"]
    tables.sort(key=lambda t: t[0])
    pos_mm = [p for p, _ in tables]
    if any(b <= a for a, b in itertools.pairwise(pos_mm)):
        raise InputDataError(
            f"identify modal: two sweeps at the same commanded position ({pos_mm} mm)"
        )
    return {"axes": {ctx.axis: {"disturbance_modes_at": [t for _, t in tables]}}}, notes


def _modal_table(
    ctx: _Ctx, o: dict[str, Any], rec: Any, path: Path, plot: Path | None
) -> tuple[dict[str, object], list[str]]:
    """Modal fit of one sweep recording → the keys of a ``disturbance_modes`` table."""
    from millsense.ident.modal_fit import fit_modes
    from millsense.report.ident_plots import plot_frf_fit, plot_stabilisation

    est = _estimate(rec, path, o["input"], o["output"], o["resolution"])
    band = o["band"] or (float(est.freq_hz[0]), float(est.freq_hz[-1]))
    fit = fit_modes(est, band, max_modes=o["max_modes"])
    if plot is not None:
        plot_frf_fit(est, fit, plot, title=f"{o['output']} / {o['input']}")
        stab = Path(plot).with_name(Path(plot).stem + "-stabilisation.png")
        if fit.diagram is not None:
            plot_stabilisation(fit, stab, est)
    modes = fit.modes
    table = {
        "natural_frequency_hz": [m.natural_frequency_hz for m in modes],
        "damping_ratio": [m.damping_ratio for m in modes],
        "alpha": [m.alpha for m in modes],
        "beta": [m.beta for m in modes],
        "feedthrough": float(fit.residual),
        "source": f"millsense identify modal {path.name} {band[0]:g}-{band[1]:g} Hz",
    }
    notes = [f"{len(modes)} modes, relative RMS error {fit.rms_error:.3g}"]
    return table, notes + _poor_fit(fit.rms_error, f"the modal fit of {path.name}", band)


#: Relative RMS error of an FRF fit above which `identify` warns: the fitted modes leave a
#: third of the measured response unexplained (good sweeps fit to a few per cent).
POOR_FIT = 0.3


def _poor_fit(rms_error: float, what: str, band: tuple[float, float]) -> list[str]:
    """A ``warning:`` note where a fit's relative RMS error exceeds :data:`POOR_FIT`."""
    if rms_error <= POOR_FIT:
        return []
    return [
        f"warning: {what} leaves {rms_error:.0%} (relative RMS) of the measured FRF unexplained "
        f"over {band[0]:g}-{band[1]:g} Hz: check the band, the input and output channels and "
        "the excitation before using the fragment"
    ]


def _path(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    """Φ_d of the feed estimator from one table-load sweep (decision "Identified disturbance
    path in the machine file")."""
    import numpy as np

    from millsense.estimation.feed.estimator import c3_front_end
    from millsense.estimation.feed.path_fit import fit_disturbance_path
    from millsense.report.ident_plots import plot_frf_fit

    if ctx.machine is None:
        raise ConfigError(
            "identify path: give --machine (torque constant, lead, efficiency, friction and "
            "inertia of the estimator's C3 stage)"
        )
    if not o["input"]:
        raise ConfigError("identify path: give --input-channel, the measured table-load channel")
    if len(ctx.recs) != 1:
        raise ConfigError("identify path: give one sweep recording")
    rec, path, a = ctx.recs[0], ctx.paths[0], ctx.axis
    cfg = ctx.axis_cfg()
    load = np.asarray(ctx.channel(rec, path, o["input"]), dtype=float)
    current = np.asarray(ctx.channel(rec, path, f"{a}/current_cmd"), dtype=float)
    speed_name = f"{a}/motor_speed" if f"{a}/motor_speed" in rec else f"{a}/speed"
    speed = np.asarray(ctx.channel(rec, path, speed_name), dtype=float)
    if float(np.std(load)) == 0.0:
        raise InputDataError(f"{path}: channel {o['input']!r} carries no load (constant)")
    drive, lugre, lowpass = c3_front_end(a, cfg, rec.sample_rate_hz, ctx.machine.name)
    per = rec.metadata.get("period_samples")
    band = o["band"] or (3.0, 260.0)
    try:
        sweep = fit_disturbance_path(
            load,
            current,
            speed,
            drive,
            lowpass,
            rec.sample_rate_hz,
            period_samples=per if isinstance(per, int) and per > 0 else None,
            lugre=lugre,
            fit_band_hz=band,
            welch_resolution_hz=o["resolution"],
        )
    except InputDataError as exc:
        if o["band"] is None:
            raise
        # a band above Nyquist or beside the excited lines: say which option and recording
        raise InputDataError(f"{path}: --band-hz {band[0]:g}:{band[1]:g}: {exc}") from None
    fit = sweep.fit
    if o["plot"] is not None:
        fb = np.linspace(band[0], band[1], 3000)
        plot_frf_fit(
            sweep.frf,
            None,
            o["plot"],
            overlay=(fb, fit.frf(fb), f"rational fit, {fit.n_states} states"),
            title=f"Φ_d = τ_c/τ_a of {a} ({path.name})",
        )
    condition = o["condition"]
    if condition == "auto":
        condition = _commanded_condition(rec, path, a, cfg.transmission_m_rad)
    table = fit.config_table(
        f"millsense identify path {path.name} {band[0]:g}-{band[1]:g} Hz "
        f"({'LuGre' if lugre is not None else 'Coulomb + viscous'} C3 stage, {condition})"
    )
    key = "disturbance_path_at_rest" if condition == "at_rest" else "disturbance_path"
    notes = [
        f"{len(fit.complex_poles)} complex pairs + {len(fit.real_poles)} real poles, relative "
        f"RMS error {fit.rms_error:.3g} over {band[0]:g}-{band[1]:g} Hz ({sweep.frf.method}, "
        f"{sweep.frf.n_averages} averages); axis {condition.replace('_', ' ')} → {key}"
    ]
    notes += _poor_fit(fit.rms_error, f"the path fit of {path.name}", band)
    return {"axes": {a: {"estimator": {key: table}}}}, notes


def _noise(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    """R of the feed estimator from an air cut: the variance of the C3 torque after the first
    0.2 s, its slow trend removed (Aslan Eq. 3.28–3.30; the same computation as the bench
    pipeline, decision 0993)."""
    import numpy as np

    from millsense.estimation.feed.estimator import c3_front_end
    from millsense.estimation.feed.tuning import air_cut_r

    if ctx.machine is None:
        raise ConfigError(
            "identify noise: give --machine (torque constant, lead, efficiency, friction and "
            "inertia of the estimator's C3 stage)"
        )
    if len(ctx.recs) != 1:
        raise ConfigError("identify noise: give one air-cut recording")
    rec, path, a = ctx.recs[0], ctx.paths[0], ctx.axis
    fs = rec.sample_rate_hz
    current = np.asarray(ctx.channel(rec, path, f"{a}/current_cmd"), dtype=float)
    speed_name = f"{a}/motor_speed" if f"{a}/motor_speed" in rec else f"{a}/speed"
    speed = np.asarray(ctx.channel(rec, path, speed_name), dtype=float)
    skip = round(0.2 * fs)
    if len(current) < skip + round(0.5 * fs):
        raise InputDataError(f"{path}: an air cut of at least 0.7 s is needed for R")
    drive, lugre, lowpass = c3_front_end(a, ctx.axis_cfg(), fs, ctx.machine.name)
    r = air_cut_r(current, speed, drive, lowpass, fs, lugre, skip_s=skip / fs)
    notes = [
        f"R = {r:.4g} N²·m² (C3 torque variance in air over {(len(current) - skip) / fs:.2f} s)"
    ]
    return {"axes": {a: {"estimator": {"r_nm2": float(r)}}}}, notes


def _commanded_condition(rec: Any, path: Path, axis: str, transmission: float) -> str:
    """``moving`` or ``at_rest`` from the sweep's commanded motion (decision "Holding axis"):
    ``{axis}/velocity_ref`` (motor rad/s) or ``{axis}/position_cmd`` (m, rad rotary)."""
    import numpy as np

    from millsense.estimation.feed.commanded import commanded_velocity
    from millsense.estimation.feed.estimator import operating_condition

    if f"{axis}/velocity_ref" in rec:
        v = np.asarray(rec.channel(f"{axis}/velocity_ref"), dtype=float)
    elif f"{axis}/position_cmd" in rec:
        v = commanded_velocity(rec, axis, str(path)) / transmission
    else:
        raise InputDataError(
            f"{path}: no channel '{axis}/velocity_ref' or '{axis}/position_cmd': the sweep's "
            "commanded motion decides whether it is the moving or the at-rest path (or give "
            "--condition moving|at_rest)"
        )
    return operating_condition(v)


def _friction(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    import numpy as np

    from millsense.ident import friction as fr
    from millsense.report.ident_plots import plot_stribeck

    a = ctx.axis
    moves = [
        (r, p)
        for r, p in zip(ctx.recs, ctx.paths, strict=True)
        if r.metadata.get("test") != "presliding"
    ]
    pres = _by_test(ctx, "presliding")
    if not moves:
        raise InputDataError("identify friction: no constant-velocity recording given")
    cur_ch = o["input"] or f"{a}/current"
    spd_ch = o["output"] or f"{a}/speed"
    ws, ts, ses = [], [], []
    kt = 0.0
    for rec, path in moves:
        kt = ctx.known(
            rec,
            "torque_constant_nm_a",
            "the torque constant",
            lambda m: m.axis(a).torque_constant_nm_a,
        )
        ref = ctx.channel(rec, path, f"{a}/velocity_ref")
        segs = fr.steady_segments(ref, min_samples=round(0.2 * rec.sample_rate_hz))
        if not segs:
            raise InputDataError(f"{path}: no constant-velocity plateau of 0.2 s or more")
        w, t, s = fr.move_means(
            ctx.channel(rec, path, spd_ch), kt * ctx.channel(rec, path, cur_ch), segs
        )
        ws.append(w)
        ts.append(t)
        ses.append(s)
    w, t, s = np.concatenate(ws), np.concatenate(ts), np.concatenate(ses)
    fit = fr.lugre_static_from_moves(w, t, s)
    notes = [f"{len(w)} constant-velocity moves, K_t = {kt:g} N·m/A"]
    if pres:
        rec, path = pres[0]
        cfg = ctx.axis_cfg()
        if cfg is None:
            raise InputDataError("identify friction: the presliding fit needs --machine (inertia)")
        try:
            pf = fr.fit_presliding(
                ctx.channel(rec, path, f"{a}/current"),
                ctx.channel(rec, path, f"{a}/angle"),
                rec.sample_rate_hz,
                inertia_kg_m2=cfg.inertia_kg_m2,
                torque_constant_nm_a=kt,
                static=fit,
            )
        except fr.PreslidingNotIdentified as exc:
            notes.append(f"presliding not identified ({exc}): static friction only")
        else:
            fit = fr.LuGreFit(fit.positive, fit.negative, (pf.sigma0,) * 2, (pf.sigma1,) * 2)
            notes.append(
                f"presliding: peak {pf.peak_angle_rad * 1e3:.3g} mrad, RMS residual "
                f"{pf.rms_residual_rad * 1e6:.3g} µrad"
            )
    if o["plot"] is not None:
        plot_stribeck(w, t, fit, o["plot"], std_error_nm=s)
    table = fit.config_table()
    table["source"] = "millsense identify friction"
    return {"axes": {a: {"friction": table}}}, notes


def _drive(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    from millsense.ident import drive as dr
    from millsense.report.ident_plots import plot_drive_fit

    a = ctx.axis
    sweeps = _by_test(ctx, "drive_sweep")
    accel = _by_test(ctx, "acceleration")
    if not sweeps and not accel:
        raise InputDataError(
            "identify drive: needs a drive sweep or an acceleration test recording "
            "(metadata 'test')"
        )
    table: dict[str, object] = {}
    notes: list[str] = []
    if accel:
        rec, path = accel[0]
        kt = ctx.known(
            rec,
            "torque_constant_nm_a",
            "the torque constant",
            lambda m: m.axis(a).torque_constant_nm_a,
        )
        rb = dr.rigid_body_from_acceleration(
            ctx.channel(rec, path, o["input"] or f"{a}/current"),
            ctx.channel(rec, path, o["output"] or f"{a}/speed"),
            rec.sample_rate_hz,
            torque_constant_nm_a=kt,
        )
        table.update({"inertia_kg_m2": rb.inertia, "torque_constant_nm_a": kt})
        notes.append(
            f"acceleration test: J_e = {rb.inertia:.5g} kg·m² (K_t {kt:g} N·m/A "
            f"assumed known), Coulomb {rb.coulomb[0]:.3g}/{rb.coulomb[1]:.3g} N·m"
        )
    if sweeps:
        rec, path = sweeps[0]
        fs = rec.sample_rate_hz
        kt = ctx.known(
            rec,
            "torque_constant_nm_a",
            "the torque constant",
            lambda m: m.axis(a).torque_constant_nm_a,
        )
        lead = ctx.known(
            rec,
            "lead_m",
            "the ball-screw lead",
            lambda m: (m.axis(a).lead_mm_rev or 0) * 1e-3 or None,
        )
        bw = ctx.known(
            rec,
            "current_bandwidth_hz",
            "the current-loop bandwidth",
            lambda m: m.axis(a).current_bandwidth_hz,
        )
        per = rec.metadata.get("period_samples")
        if not isinstance(per, int):
            raise InputDataError(f"{path}: metadata 'period_samples' (sweep period) missing")
        r = ctx.channel(rec, path, f"{a}/injection")
        u = ctx.channel(rec, path, f"{a}/current_cmd")
        hm = dr.reference_frf(
            r,
            u,
            ctx.channel(rec, path, f"{a}/angle"),
            fs,
            per,
            detrend=True,
            names=(f"{a}/injection", f"{a}/current_cmd", f"{a}/angle"),
        )
        ht = dr.reference_frf(
            r,
            u,
            ctx.channel(rec, path, f"{a}/scale"),
            fs,
            per,
            detrend=True,
            names=(f"{a}/injection", f"{a}/current_cmd", f"{a}/scale"),
        )
        ts = 0.0
        if f"{a}/current" in rec:
            hi = dr.reference_frf(r, u, rec.channel(f"{a}/current"), fs, per)
            ts, _ = dr.fit_amplifier_delay(hi, sample_rate_hz=fs, current_loop_hz=bw)
        band = o["band"] or (10.0, min(1000.0, 0.45 * fs))
        fit = dr.fit_dual_inertia(
            hm,
            ht,
            lead_m=lead,
            torque_constant_nm_a=kt,
            current_loop_hz=bw,
            sample_rate_hz=fs,
            amplifier_delay_s=ts,
            band_hz=band,
        )
        table.update(dr.drive_config_table(fit, kt))
        p = fit.params
        t1, t2, t3 = dr.compensation_delays(
            max(p.dead_time_amplifier, 0), max(p.dead_time_motor, 0), max(p.dead_time_table, 0)
        )
        notes.append(
            f"dual inertia from {path.name}: resonance {p.resonance_hz(lead):.1f} Hz, "
            f"RMS log error {fit.rms_log_error:.3g}"
        )
        if fit.unmodelled_mode_hz is not None:
            notes.append(
                f"a mode the dual-inertia model cannot have at {fit.unmodelled_mode_hz:.1f} Hz "
                f"(e.g. screw torsion): fitted band ends at {0.9 * fit.unmodelled_mode_hz:.0f} Hz"
            )
        notes.append(
            f"phase-lag compensation T1, T2, T3 = {t1 * 1e3:.3f}, {t2 * 1e3:.3f}, "
            f"{t3 * 1e3:.3f} ms (Yamada Fig. 2-5)"
        )
        if o["plot"] is not None:
            plot_drive_fit(fit, o["plot"])
    return {"axes": {a: table}}, notes


def _spindle(ctx: _Ctx, o: dict[str, Any]) -> tuple[dict[str, object], list[str]]:
    import numpy as np

    from millsense.ident import friction as fr
    from millsense.ident import spindle as isp
    from millsense.models.spindle_plant import SpindleDriveParams
    from millsense.report.ident_plots import plot_spindle_fit

    sweeps = _by_test(ctx, "spindle_sweep")
    fric = _by_test(ctx, "spindle_friction")
    if ctx.machine is None or ctx.machine.spindle is None:
        raise InputDataError("identify spindle: give --machine with a [spindle] table (J, K_t)")
    sp = ctx.machine.spindle
    table: dict[str, object] = {}
    notes: list[str] = []
    viscous = sp.viscous_nm_s_rad
    if fric:
        rec, path = fric[0]
        segs = fr.steady_segments(
            ctx.channel(rec, path, "spindle/speed_ref"), min_samples=round(0.5 * rec.sample_rate_hz)
        )
        kt_ch = ctx.channel(rec, path, "spindle/torque_constant")
        w, t, _ = fr.move_means(
            ctx.channel(rec, path, "spindle/speed"),
            kt_ch * ctx.channel(rec, path, "spindle/current"),
            segs,
        )
        coul, viscous = fr.spindle_friction_from_moves(w, t)
        table.update({"coulomb_nm": max(coul, 0.0), "viscous_nm_s_rad": max(viscous, 0.0)})
        notes.append(
            f"spindle friction from {len(w)} runs: τ_coul {coul:.4g} N·m, B {viscous:.4g} N·m·s/rad"
        )
    if sweeps:
        rec, path = sweeps[0]
        md = rec.metadata
        kp, ki = md.get("velocity_kp"), md.get("velocity_ki")
        if o["kp"] is not None:
            kp = o["kp"]
        if o["ki"] is not None:
            ki = o["ki"]
        if not isinstance(kp, (int, float)) or not isinstance(ki, (int, float)):
            raise InputDataError("identify spindle: velocity gains unknown; give --kp and --ki")
        unit = o["error_unit"] or str(md.get("velocity_error_unit", "rev/s"))
        vp = md.get("velocity_period_s", 2e-4)
        period = float(vp) if isinstance(vp, (int, float)) else 2e-4
        ctl = isp.VelocityController(float(kp), float(ki), unit, period)
        per = md.get("period_samples")
        if not isinstance(per, int):
            raise InputDataError(f"{path}: metadata 'period_samples' (sweep period) missing")
        band = o["band"] or (5.0, min(2500.0, 0.25 * rec.sample_rate_hz))
        ref = ctx.channel(rec, path, "spindle/speed_ref")
        # the sweep's speed range (its K_t, its admittance keys), as the drive switches
        drive = SpindleDriveParams.from_config(sp)
        r = drive.range_index(float(np.mean(np.abs(ref))))
        fit = isp.fit_spindle(
            ref,
            ctx.channel(rec, path, "spindle/speed"),
            ctx.channel(rec, path, "spindle/current_cmd"),
            ctx.channel(rec, path, "spindle/current"),
            rec.sample_rate_hz,
            per,
            controller=ctl,
            inertia_kg_m2=sp.inertia_kg_m2,
            viscous_nm_s_rad=viscous,
            torque_constant_nm_a=drive.ranges[r].torque_constant,
            band_hz=band,
            identify_inertia=True,
            current_pi=(drive.current_kp, drive.current_ki, drive.back_emf),
        )
        # J/K_t and the current loop from the sweep, J with the file's K_t (decision 1708):
        # what the observer's G_dτ needs at a cut's tooth harmonics
        table["inertia_kg_m2"] = float(f"{fit.inertia:.6g}")
        assert fit.admittance is not None
        keys = ("motor_a_v_s2_a", "motor_b_v_s_a", "motor_c_ohm")
        if r == 1:
            keys = ("motor_a_range2_v_s2_a", "motor_b_range2_v_s_a", "motor_c_range2_ohm")
        for key, v in zip(keys, fit.admittance, strict=True):
            table[key] = float(f"{v:.6g}")
        a, b, c = fit.admittance
        notes.append(
            f"spindle (range {r + 1}) from the sweep: inertia {fit.inertia:.5g} kg·m² by the rigid "
            f"body at 5-50 Hz with K_t {drive.ranges[r].torque_constant:g} N·m/A (machine file "
            f"{sp.inertia_kg_m2:.5g}); motor admittance a {a:.4g}, b {b:.4g}, c {c:.4g} at 5-500 "
            f"Hz (machine file {', '.join(f'{v:.4g}' for v in drive.ranges[r].admittance)})"
        )
        if fit.residual.modes:
            modes = isp.residual_modes_table(fit)
            modes["source"] = f"millsense identify spindle {path.name} (residual R, Aslan App. E)"
            table["residual_modes"] = modes
        else:
            notes.append(
                "residual R: no stable mode in the band, none written (rigid-body G_dτ; "
                "decision 1210)"
            )
        g = fit.disturbance_frf(fit.freq_hz)
        notes.append(
            f"residual R: {len(fit.residual.modes)} modes, RMS error "
            f"{fit.residual.rms_error:.3g}; |G_dτ| {20 * np.log10(abs(g[0])):.1f} dB "
            f"at {fit.freq_hz[0]:g} Hz, current loop ≈ {fit.current_loop_hz:.0f} Hz; "
            f"CNC gains vs measured G_Ω ≤ {fit.controller_mismatch_db():.2f} dB"
        )
        if o["plot"] is not None:
            plot_spindle_fit(fit, o["plot"])
    if not table:
        raise InputDataError("identify spindle: no spindle_sweep or spindle_friction recording")
    return {"spindle": table}, notes


def _idle_csv(out: Path, axis: str) -> Path:
    """The CSV of an idle table beside its fragment ``out``."""
    return out.with_name(f"{out.stem}-{axis}-idle.csv")


def _idle(ctx: _Ctx, o: dict[str, Any], out: Path) -> tuple[dict[str, object], list[str]]:
    from millsense.ident import friction as fr
    from millsense.ident.idle_table import build_idle_table
    from millsense.report.ident_plots import plot_idle_table

    a = ctx.axis
    runs = []
    feed = 0.0
    for rec, path in zip(ctx.recs, ctx.paths, strict=True):
        r = ctx.known(
            rec, "transmission_m_rad", "the transmission", lambda m: m.axis(a).transmission_m_rad
        )
        pos_ch = o["input"] or f"{a}/angle"
        pos = ctx.channel(rec, path, pos_ch)
        unit = rec.info(pos_ch).unit
        pos = pos * r if unit == "rad" else pos
        if o["output"]:
            est = ctx.channel(rec, path, o["output"])
            quantity, est_unit = o["output"].split("/")[-1], rec.info(o["output"]).unit
        else:
            kt = ctx.known(
                rec,
                "torque_constant_nm_a",
                "the torque constant",
                lambda m: m.axis(a).torque_constant_nm_a,
            )
            est = kt * ctx.channel(rec, path, f"{a}/current_cmd") / r
            quantity, est_unit = "thrust", "N"
        sel = slice(None)
        if f"{a}/velocity_ref" in rec:
            segs = fr.steady_segments(
                rec.channel(f"{a}/velocity_ref"),
                min_samples=round(0.1 * rec.sample_rate_hz),
                settle_fraction=0.05,
            )
            if segs:
                sel = max(segs, key=lambda s: s.stop - s.start)
                feed = float(rec.channel(f"{a}/velocity_ref")[sel.start]) * r
        runs.append((pos[sel], est[sel]))
    table = build_idle_table(
        runs, bin_m=o["bin_um"] * 1e-6, feed_m_s=feed, quantity=quantity, unit=est_unit, min_runs=2
    )
    csv = _idle_csv(out, a)
    table.to_csv(csv)
    if o["plot"] is not None:
        plot_idle_table(table, o["plot"], runs)
    notes = [
        f"{len(runs)} air cuts averaged over {len(table.position_m)} bins of "
        f"{o['bin_um']:g} µm; table in {csv.name}"
    ]
    return {"axes": {a: {"idle_table": table.config_table(csv.name)}}}, notes


@app.command()
def identify(
    kind: str = typer.Argument(
        ..., help="frf | modal | path | friction | drive | spindle | idle | noise"
    ),
    recordings: list[Path] = typer.Argument(..., help="Recording files (.h5)."),
    out: Path = typer.Option(..., "-o", "--output", help="TOML fragment written."),
    input_ch: str | None = typer.Option(
        None, "--input-channel", help="Input (or current) channel of the recordings."
    ),
    output_ch: str | None = typer.Option(
        None, "--output-channel", help="Output (or speed) channel of the recordings."
    ),
    band: str | None = typer.Option(None, "--band-hz", help="Fitting band LO:HI [Hz]."),
    plot: Path | None = typer.Option(None, "--plot", help="PNG of the fit."),
    axis: str = typer.Option("x", "--axis", help="Axis name of the fragment."),
    machine: str | None = typer.Option(
        None, "--machine", help="Machine preset or TOML for known quantities."
    ),
    resolution: float = typer.Option(1.0, "--resolution-hz", help="Welch FRF resolution [Hz]."),
    max_modes: int = typer.Option(16, "--max-modes", help="Largest modal order tried."),
    kp: float | None = typer.Option(
        None, "--kp", help="Spindle velocity P gain of the CNC [A·s per unit of --error-unit]."
    ),
    ki: float | None = typer.Option(
        None, "--ki", help="Spindle velocity I gain of the CNC [A per unit of --error-unit·s]."
    ),
    error_unit: str | None = typer.Option(
        None, "--error-unit", help="Unit of the spindle velocity error: rev/s or rad/s."
    ),
    bin_um: float = typer.Option(2.0, "--bin-um", help="Idle-table bin width [µm]."),
    condition: str = typer.Option(
        "auto",
        "--condition",
        help="path: the axis during the sweep, moving or at_rest; auto reads the sweep's "
        "commanded motion.",
    ),
) -> None:
    """Identify machine parameters from recordings and write a TOML configuration fragment."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.ident.fragment import write_fragment
    from millsense.io.recording_file import read_recording

    if kind not in _KINDS:
        raise ConfigError(f"identify: unknown kind {kind!r} (use one of {', '.join(_KINDS)})")
    if error_unit is not None and error_unit not in ("rev/s", "rad/s"):
        raise ConfigError(f"--error-unit {error_unit!r}: allowed 'rev/s' or 'rad/s'")
    if not bin_um > 0:
        raise ConfigError(f"--bin-um {bin_um}: must be positive")
    if condition not in ("auto", "moving", "at_rest"):
        raise ConfigError(f"--condition {condition!r}: allowed auto, moving or at_rest")
    from millsense.io.safe_output import check_outputs

    inputs: list[tuple[str, Path | str | None]] = [("one of the recordings", p) for p in recordings]
    inputs.append(("the machine file", machine))
    outputs: dict[str, Path | None] = {"-o": out, "--plot": plot}
    if kind == "idle":
        outputs["the idle table"] = _idle_csv(out, axis)
    check_outputs(inputs, outputs, suffixes={"-o": ".toml"})
    recs = [read_recording(p) for p in recordings]
    mach = load_preset(MachineConfig, machine) if machine is not None else None
    ctx = _Ctx(recs, list(recordings), axis, mach)
    o: dict[str, Any] = {
        "input": input_ch,
        "output": output_ch,
        "band": _parse_band(band),
        "plot": plot,
        "resolution": resolution,
        "max_modes": max_modes,
        "kp": kp,
        "ki": ki,
        "error_unit": error_unit,
        "bin_um": bin_um,
        "condition": condition,
    }
    if kind == "frf":
        frag, notes = _frf(ctx, o)
    elif kind == "modal":
        frag, notes = _modal(ctx, o)
    elif kind == "path":
        frag, notes = _path(ctx, o)
    elif kind == "friction":
        frag, notes = _friction(ctx, o)
    elif kind == "drive":
        frag, notes = _drive(ctx, o)
    elif kind == "spindle":
        frag, notes = _spindle(ctx, o)
    elif kind == "noise":
        frag, notes = _noise(ctx, o)
    else:
        frag, notes = _idle(ctx, o, out)
    head = [f"millsense identify {kind} " + " ".join(p.name for p in recordings), *notes]
    write_fragment(out, frag, head)
    for line in notes:
        if line.startswith("warning: "):  # also in the fragment's header
            typer.echo(f"millsense: {line}", err=True)
        else:
            typer.echo(line)
    typer.echo(f"wrote {out}" + (f" and {plot}" if plot is not None else ""))
