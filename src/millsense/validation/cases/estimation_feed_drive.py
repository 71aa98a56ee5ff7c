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
- "shifted" cases only: all disturbance-mode frequencies 2 % higher (position dependence).

The compensated FRF is measured, not computed: a multisine table load (1–300 Hz, 1 Hz lines,
5 N·m RMS at the motor, 16 averaged periods) is applied during a constant-velocity move, the estimate (delayed by the
60-sample smoother, realigned) is divided line by line by the applied load, and the ±3 dB band is
the first line leaving ±3 dB. The raw figure is the same with the current only,
``η·K_t·I_nom/r_g``.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from millsense.validation import Measured, case

FS_HZ = 10_000.0
AXES = ("x", "y", "z", "a", "c")
#: RMS of the multisine load at the motor, N·m, and periods (first discarded)
EXCITATION_NM = 5.0
N_PERIODS = 17
#: motor speed of the constant-velocity move during the test, rad/s (no reversal under load)
MOVE_SPEED_RAD_S = 10.0


@cache
def _identified(axis: str) -> object:
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
        FeedAxisModel,
        perturbed_drive,
        ramp_move,
    )
    from millsense.estimation.kalman import bandwidth_3db
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.machine.feed_drive import FeedDriveParams, FeedDriveSim
    from millsense.online.block import Chunk

    params, model, _ = _identified(axis)  # type: ignore[misc]
    assert isinstance(params, FeedDriveParams) and isinstance(model, FeedAxisModel)
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
