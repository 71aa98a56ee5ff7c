"""Acceptance of the feed-drive force estimator on the simulated Quaser UX600 (issue 7 item 2).

Every figure is end to end: the estimator of each axis is *identified* on the drive simulator
(:func:`millsense.estimation.feed_drive.identify_feed_axis`: friction from constant-velocity
moves, J_e from an accelerating move, Φ_d from a multisine table-load sweep, R from an air cut,
Q by bandwidth optimisation), then run as a streaming block on the CNC channels of a *different*
simulated machine (:func:`~millsense.estimation.feed_drive.perturbed_drive`).

Mismatch between simulator and estimator (stated beside every figure):

- identified, not true parameters (friction line fit, J_e, a rational fit of a noisy sweep);
- the simulator runs LuGre friction (Table 3.2), the estimator Coulomb + viscous, and the
  simulator's Coulomb and static friction are 15 % higher than at identification (drift);
- an unmodelled mode at 420 Hz (ζ 3 %, α 2·10⁵) above the identification band;
- torque noise (Eq. 3.30), 2²⁰-count encoder quantisation, the 1 kHz current loop between the
  current command the estimator reads and the motor torque;
- "shifted" cases only: all disturbance-mode frequencies 2 % higher, or lower (position
  dependence). The estimator is designed for modes anywhere within ±2 % of the identified ones
  (:func:`millsense.estimation.tuning.tune_robust`); ``estimation.feed_robust_band_at_lti_limit``
  compares its worst-case band with the limit of any linear estimator
  (:func:`~millsense.estimation.tuning.flatness_bound`) and tabulates the analytic deviation
  per shift (docs/decisions.md, "Robust feed estimator for position-dependent modes").

The compensated FRF is measured, not computed: a multisine table load (1–300 Hz, 1 Hz lines,
5 N·m RMS at the motor, 16 averaged periods) is applied during a constant-velocity move, the
estimate (delayed by the 60-sample smoother, realigned) is divided line by line by the applied
load, and the ±3 dB band is the first line leaving ±3 dB. The raw figure is the same with the
current only, ``η·K_t·I_nom/r_g``.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from millsense.validation import Measured, case

if TYPE_CHECKING:
    from millsense.estimation.feed_drive import FeedAxisModel, SweepResult
    from millsense.machine.feed_drive import FeedDriveParams

FS_HZ = 10_000.0
AXES = ("x", "y", "z", "a", "c")
#: RMS of the multisine load at the motor, N·m, and periods (first discarded)
EXCITATION_NM = 5.0
N_PERIODS = 17
#: motor speed of the constant-velocity move during the test, rad/s (no reversal under load)
MOVE_SPEED_RAD_S = 10.0


@cache
def _identified(axis: str) -> tuple[FeedDriveParams, FeedAxisModel, SweepResult]:
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.feed_drive import identify_feed_axis
    from millsense.machine.feed_drive import FeedDriveParams

    ax = load_preset(MachineConfig, "quaser-ux600").axis(axis)
    params = FeedDriveParams.from_config(ax)
    model, sweep = identify_feed_axis(params, axis, ax.kind, sample_rate_hz=FS_HZ)
    return params, model, sweep


@cache
def compensated_bandwidth(axis: str, frequency_scale: float = 1.0) -> dict[str, float]:
    """Measured ±3 dB bands (Hz) of the compensated estimate and of the raw current."""
    from millsense.estimation.feed_drive import (
        FeedAxisEstimator,
        perturbed_drive,
        ramp_move,
    )
    from millsense.estimation.kalman import bandwidth_3db
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.machine.feed_drive import FeedDriveSim
    from millsense.online.block import Chunk

    params, model, _ = _identified(axis)
    machine = perturbed_drive(params, frequency_scale=frequency_scale)
    per = round(1.0 * FS_HZ)
    lg = params.transmission / params.efficiency
    load, _ = multisine_signal(FS_HZ, per, 1.0, 300.0, N_PERIODS, rms=EXCITATION_NM / lg)
    lead = round(0.3 * FS_HZ)
    est = FeedAxisEstimator(model)
    pos, vel = ramp_move(MOVE_SPEED_RAD_S, len(load) + lead + est.lag, FS_HZ)
    full = np.concatenate([np.zeros(lead), load, np.zeros(est.lag)])
    res = FeedDriveSim(machine, FS_HZ, seed=11).advance(pos, vel, full)
    est.reset(FS_HZ)
    cur, spd = res["current_cmd"], res["speed"]
    chunks = []
    for s in range(0, len(cur), 100):
        data = {f"{axis}/current_cmd": cur[s : s + 100], f"{axis}/motor_speed": spd[s : s + 100]}
        chunks.append(est.process(Chunk(s, FS_HZ, 0.0, data)).channels[f"{axis}/load_est"])
    load_est = np.concatenate(chunks)[lead + est.lag : lead + est.lag + len(load)]
    raw = (params.efficiency / params.transmission * params.torque_constant * cur)[
        lead : lead + len(load)
    ]
    h = multisine_frf(load, load_est, FS_HZ, per, skip_periods=1)
    hr = multisine_frf(load, raw, FS_HZ, per, skip_periods=1)
    f = np.concatenate([[0.0], h.freq_hz])
    db = 20 * np.log10(np.abs(h.h1))
    in_180 = h.freq_hz <= (180.0 if model.kind == "linear" else 120.0)
    return {
        "compensated_hz": bandwidth_3db(f, np.concatenate([[1.0], h.h1])),
        "raw_hz": bandwidth_3db(f, np.concatenate([[1.0], hr.h1])),
        "raw_dc_db": float(20 * np.log10(np.abs(hr.h1[0]))),
        "worst_db_in_target": float(np.max(np.abs(db[in_180]))),
        "q": model.q,
        "r": model.r,
        "states": float(model.design().n_states),
    }


def _table(frequency_scale: float) -> str:
    rows = [
        "| Axis | target [Hz] | compensated ±3 dB [Hz] | worst dB to target | raw current ±3 dB "
        "[Hz] | raw at 1 Hz [dB] | Kalman states | R [N²m²] | Q [(Nm)²/s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for ax in AXES:
        r = compensated_bandwidth(ax, frequency_scale)
        tgt = 180 if ax in "xyz" else 120
        rows.append(
            f"| {ax.upper()} | {tgt} | {r['compensated_hz']:.1f} | {r['worst_db_in_target']:.2f} | "
            f"{r['raw_hz']:.1f} | {r['raw_dc_db']:.2f} | {r['states']:.0f} | {r['r']:.4f} | "
            f"{r['q']:.0f} |"
        )
    return "\n".join(rows)


_MISMATCH = (
    "Mismatch: identified parameters (rational fit of a simulated sweep, friction line fit, "
    "J_e from an accelerating move), LuGre friction +15 % in the simulator vs Coulomb+viscous in "
    "the estimator, unmodelled 420 Hz mode, torque noise (Eq. 3.30), encoder quantisation, "
    "1 kHz current loop"
)


def _worst_db(kind: str, frequency_scale: float) -> Measured:
    axes = [a for a in AXES if (a in "xyz") == (kind == "linear")]
    worst = max(compensated_bandwidth(a, frequency_scale)["worst_db_in_target"] for a in axes)
    return Measured(worst, _table(frequency_scale))


@case(
    "estimation.feed_linear_flat_to_180hz",
    source="seed 000 V3 (Aslan Fig. 3.8, C6): 180 Hz on the linear axes",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    description="largest |deviation| from 0 dB of the measured compensated X/Y/Z force FRF "
    "over 1-180 Hz (flat within ±3 dB to 180 Hz). " + _MISMATCH,
)
def _linear() -> Measured:
    return _worst_db("linear", 1.0)


@case(
    "estimation.feed_rotary_flat_to_120hz",
    source="seed 000 V3 (Aslan Fig. 3.8, C6): 120 Hz on the rotary axes",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    description="largest |deviation| from 0 dB of the measured compensated A/C torque FRF "
    "over 1-120 Hz (flat within ±3 dB to 120 Hz). " + _MISMATCH,
)
def _rotary() -> Measured:
    return _worst_db("rotary", 1.0)


@case(
    "estimation.feed_linear_flat_to_180hz_modes_shifted_2pct",
    source="seed 000 V3; sensitivity to position-dependent modes (not in the thesis)",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    description="as estimation.feed_linear_flat_to_180hz with every disturbance-mode "
    "frequency 2 % higher in the simulator than at identification. " + _MISMATCH,
)
def _linear_shift() -> Measured:
    return _worst_db("linear", 1.02)


@case(
    "estimation.feed_raw_current_band",
    source="seed 000 V3 / C3: raw current flat only to about 10-15 Hz",
    reference=12.5,
    unit="Hz",
    abs_tol=2.5,
    quick=False,
    description="largest ±3 dB band of the raw current force over the five axes (thesis: "
    "10-15 Hz; the printed Table 3.4 static gains 0.49-1.02 put X and Z near -5 dB at DC, "
    "so their raw band is ~0 Hz)",
)
def _raw() -> Measured:
    worst = max(compensated_bandwidth(a, 1.0)["raw_hz"] for a in AXES)
    return Measured(worst, _table(1.0))


@case(
    "estimation.feed_linear_flat_to_180hz_modes_shifted_minus_2pct",
    source="seed 000 V3; sensitivity to position-dependent modes (not in the thesis)",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    description="as estimation.feed_linear_flat_to_180hz with every disturbance-mode "
    "frequency 2 % lower in the simulator than at identification (Z's 183 Hz mode, ζ 0.3 %, "
    "then lies at 179.6 Hz; tuning.flatness_bound: no LTI estimator stays within 6.9 dB of it "
    "for modes anywhere in ±2 %). " + _MISMATCH,
)
def _linear_shift_minus() -> Measured:
    return _worst_db("linear", 0.98)


#: relative mode shifts of the analytic robustness table
ANALYTIC_SHIFTS = (-0.02, -0.01, 0.0, 0.01, 0.02)


@cache
def robustness(axis: str) -> dict[str, float]:
    """Analytic compensated FRF (estimator × shifted identified model), robust vs nominal design.

    Plants: the identified Φ_d with every mode frequency × (1 + s) in series with the C3
    low-pass (what the estimator's own tuning evaluates); estimators: the smoothed output of the
    robust design (``identify_feed_axis`` default) and of the design tuned on the identified
    model alone (``tune_q``, the design before issue 7's robustness work).
    """
    from millsense.estimation import tuning
    from millsense.estimation.feed_drive import ASLAN_LAG_SAMPLES, measurement_model
    from millsense.estimation.kalman import augment_disturbance, bandwidth_3db, design_kalman

    _, model, _ = _identified(axis)
    fit, lp, dt = model.disturbance, model.lowpass_hz, model.dt
    target = 180.0 if model.kind == "linear" else 120.0
    f = np.concatenate([np.arange(0.0, 300.0, 0.05), np.arange(300.0, 1000.5, 1.0)])
    sel = (f >= 1.0) & (f <= target)
    fam = tuning.mode_family(fit, 0.02, 9)
    plants = np.array([tuning.model_frf(measurement_model(m, lp, dt), f) for m in fam])
    bound_db, bound_band = tuning.flatness_bound(plants, f, target)
    nominal_model = measurement_model(fit, lp, dt)
    q_nom = tuning.tune_q(nominal_model, model.r).q
    designs = {
        "robust": model.design(),
        "nominal": design_kalman(augment_disturbance(nominal_model), q_nom * dt, model.r),
    }
    out = {
        "bound_db": bound_db,
        "bound_band_hz": bound_band,
        "damping": model.design_damping,
        "q": model.q,
        "q_nominal": q_nom,
    }
    for name, d in designs.items():
        est = tuning.estimator_frf(d, f, ASLAN_LAG_SAMPLES)
        comp = plants * est[None, :]
        out[f"{name}_family_band_hz"] = min(bandwidth_3db(f, h) for h in comp)
        out[f"{name}_family_db"] = max(float(np.max(tuning.deviation_db(h[sel]))) for h in comp)
        for s in ANALYTIC_SHIFTS:
            h = tuning.model_frf(nominal_model, f)
            if s != 0.0:
                m = tuning.mode_family(fit, abs(s), 3)[0 if s < 0 else 2]
                h = tuning.model_frf(measurement_model(m, lp, dt), f)
            out[f"{name}_{s:+.2f}_db"] = float(np.max(tuning.deviation_db((h * est)[sel])))
    return out


def _robust_table() -> str:
    shifts = " | ".join(f"{s:+.0%}" for s in ANALYTIC_SHIFTS)
    rows = [
        f"| Axis | design | γ | Q [(Nm)²/s] | worst dB to target at mode shift {shifts} | "
        "worst dB over ±2 % | common ±3 dB band over ±2 % [Hz] | LTI limit dB / band [Hz] |",
        "|---|---|---|---|" + "---|" * len(ANALYTIC_SHIFTS) + "---|---|---|",
    ]
    for ax in AXES:
        r = robustness(ax)
        for name in ("nominal", "robust"):
            vals = " | ".join(f"{r[f'{name}_{s:+.2f}_db']:.2f}" for s in ANALYTIC_SHIFTS)
            gamma = 0.0 if name == "nominal" else r["damping"]
            q = r["q_nominal"] if name == "nominal" else r["q"]
            rows.append(
                f"| {ax.upper()} | {name} | {gamma:.4f} | {q:.0f} | {vals} | "
                f"{r[f'{name}_family_db']:.2f} | {r[f'{name}_family_band_hz']:.1f} | "
                f"{r['bound_db']:.2f} / {r['bound_band_hz']:.1f} |"
            )
    return "\n".join(rows)


@case(
    "estimation.feed_robust_band_at_lti_limit",
    source="issue 7 (position-dependent modes); tuning.flatness_bound (closed form)",
    reference=1.0,
    unit="-",
    abs_tol=0.02,
    quick=False,
    description="smallest over the five axes of (common ±3 dB band of the robust design over "
    "modes ±2 %, capped at the axis target) / (the largest any LTI estimator can reach, "
    "tuning.flatness_bound, capped likewise); analytic: identified Φ_d scaled, C3 low-pass, "
    "smoothed estimator FRF. Details: worst deviation per shift, robust vs the design tuned on "
    "the identified model only",
)
def _robust_at_limit() -> Measured:
    ratios = []
    for ax in AXES:
        r = robustness(ax)
        tgt = 180.0 if ax in "xyz" else 120.0
        ratios.append(min(r["robust_family_band_hz"], tgt) / min(r["bound_band_hz"], tgt))
    return Measured(min(ratios), _robust_table())


V1_RPM = (1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 5500.0)
#: Aslan V1 compensated and raw errors at the tooth frequency and harmonics (digest §4)
V1_THESIS = {
    "x": ((0.18, 0.06, 0.04, 0.12, 0.32, 0.17), (1.61, 3.41, 0.22, 0.64, 1.58, 0.49)),
    "y": ((0.06, 0.06, 0.04, 0.07, 0.11, 0.19), (0.42, 1.03, 1.13, 0.54, 0.32, 1.75)),
}
V1_MAX_HARMONIC_HZ = 200.0


def _harmonic_error(est: np.ndarray, true: np.ndarray, per: int, n_flutes: int) -> float:
    """Relative error of the complex amplitudes at the tooth harmonics ≤ 200 Hz.

    ``sqrt(Σ_k |Ê_k − E_k|²) / sqrt(Σ_k |E_k|²)`` over k·f_t ≤ 200 Hz (at least k = 1), from the
    DFT of whole tooth periods of the steady cut (the estimate realigned by the smoother lag).
    """
    n = (len(true) // per) * per
    e_hat = np.fft.rfft(est[:n])
    e_true = np.fft.rfft(true[:n])
    periods = n // per
    f_t = FS_HZ / per
    ks = [k for k in range(1, 10) if k * f_t <= V1_MAX_HARMONIC_HZ] or [1]
    idx = [k * periods for k in ks]
    num = np.sqrt(np.sum(np.abs(e_hat[idx] - e_true[idx]) ** 2))
    den = np.sqrt(np.sum(np.abs(e_true[idx]) ** 2))
    del n_flutes
    return float(num / den)


@cache
def v1_errors() -> dict[str, list[tuple[float, float, float]]]:
    """Per axis and V1 speed: (rev/min, compensated error, raw-current error)."""
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.feed_drive import FeedAxisEstimator, perturbed_drive
    from millsense.machine.feed_drive import FeedDriveSim
    from millsense.online.block import Chunk
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    out: dict[str, list[tuple[float, float, float]]] = {"x": [], "y": []}
    for rpm in V1_RPM:
        w = rpm * 2 * np.pi / 60
        n_air, n_cut = round(0.5 * FS_HZ), round(1.0 * FS_HZ)
        n = n_air + n_cut
        t = np.arange(n) / FS_HZ
        cut = milling_forces(
            tool, coeffs, Engagement.slot(), 0.2e-3, 4e-3, w * t[n_air:], n_discs=20
        )
        feed = 0.2e-3 * tool.n_flutes * rpm / 60  # m/s, table along +X
        # force on the table along +X / +Y (machine.slot_cut frames); the load is its opposite
        table = {
            "x": np.concatenate([np.zeros(n_air), cut.fx_n]),
            "y": np.concatenate([np.zeros(n_air), cut.fy_n]),
        }
        for axis in ("x", "y"):
            params, model, _ = _identified(axis)
            v = feed / params.transmission if axis == "x" else 0.0
            vel = np.minimum(t / 0.2, 1.0) * v
            pos = np.cumsum(vel) / FS_HZ
            sim = FeedDriveSim(perturbed_drive(params, frequency_scale=1.0), FS_HZ, seed=21)
            res = sim.advance(pos, vel, -table[axis])
            est = FeedAxisEstimator(model)
            est.reset(FS_HZ)
            cur, spd = res["current_cmd"], res["speed"]
            parts = [
                est.process(
                    Chunk(
                        s,
                        FS_HZ,
                        0.0,
                        {
                            f"{axis}/current_cmd": cur[s : s + 100],
                            f"{axis}/motor_speed": spd[s : s + 100],
                        },
                    )
                ).channels[f"{axis}/force_est"]
                for s in range(0, n, 100)
            ]
            f_est = np.concatenate(parts)
            lag = est.lag
            raw = -params.efficiency / params.transmission * params.torque_constant * cur
            per = round(FS_HZ * 60 / rpm / tool.n_flutes)
            k0 = n_air + round(0.3 * FS_HZ)
            true = table[axis][k0 : n - lag]
            comp = f_est[k0 + lag : n]
            raw_s = raw[k0 : n - lag]
            out[axis].append(
                (
                    rpm,
                    _harmonic_error(comp, true, per, tool.n_flutes),
                    _harmonic_error(raw_s - raw_s.mean(), true, per, tool.n_flutes),
                )
            )
    return out


def _v1(axis: str) -> Measured:
    res = v1_errors()[axis]
    comp_th, raw_th = V1_THESIS[axis]
    rows = [
        "| rev/min | compensated | thesis compensated | raw current | thesis raw |",
        "|---|---|---|---|---|",
    ]
    excess = []
    for (rpm, c, r), ct, rt in zip(res, comp_th, raw_th, strict=True):
        rows.append(f"| {rpm:.0f} | {c:.1%} | {ct:.0%} | {r:.1%} | {rt:.0%} |")
        excess.append(c - ct)
    return Measured(max(excess), "\n".join(rows))


_V1_DESC = (
    "largest (millsense - thesis) compensated error at the tooth harmonics ≤ 200 Hz over "
    "1000-5500 rev/min (passes when millsense is at or below the thesis at every speed); "
    "Ø20 mm 2-flute slot, 4 mm, 0.2 mm/tooth, Al7050; X feeds, Y holds position. " + _MISMATCH
)


@case(
    "estimation.feed_v1_x_harmonic_errors",
    source="seed 000 V1 (Aslan Ch. 3.5): X 18/6/4/12/32/17 %",
    reference=-0.5,
    abs_tol=0.5,
    unit="-",
    quick=False,
    description=_V1_DESC,
)
def _v1x() -> Measured:
    return _v1("x")


@case(
    "estimation.feed_v1_y_harmonic_errors",
    source="seed 000 V1 (Aslan Ch. 3.5): Y 6/6/4/7/11/19 %",
    reference=-0.5,
    abs_tol=0.5,
    unit="-",
    quick=False,
    description=_V1_DESC,
)
def _v1y() -> Measured:
    return _v1("y")
