"""Acceptance of the feed-drive force estimator on the simulated Quaser UX600 (issue 7 item 2).

Every figure is end to end on the virtual machine's *truth* (decision 1062,
:func:`~millsense.simulator.machine_file.simulated_feed_drive`: since 2026-11-28 the truth's
coupled drives, before that the simulator machine file's Aslan Eq. 3.1 + Eq. 3.13 drive, the
estimators' own model class): the estimator of each axis is built from the nameplate and what
commissioning on the truth identifies (:func:`~millsense.bench.pipeline.identified_machine`:
friction from constant-velocity moves, J_e from an accelerating move, Φ_d from a multisine
table-load sweep, R from an air cut, Q by bandwidth optimisation), then run as a streaming
block on the CNC channels of the truth with its friction drifted
(:func:`~millsense.simulator.drive_mismatch.perturbed_drive`).

Mismatch between the truth and the estimator (stated beside every figure):

- the truth is a coupled lumped-mass drive (motor, screw, nut, table, column) whose modes
  couple back to the motor and follow the table position, with lost motion, torque ripple,
  LuGre friction with Stribeck, current-loop electrics and dead times
  (:mod:`millsense.simulator.truth_drive`); the estimator is Aslan's rigid body + identified Φ_d
  (a rational fit of a noisy sweep), Coulomb + viscous friction and nameplate K_t, η, r_g;
- the truth's Coulomb and static friction are 15 % higher than at identification (drift);
- torque noise, 2²⁰-count encoder quantisation;
- position-scheduled case only: the truth's plant follows the table position by its own
  mechanics (:func:`~millsense.simulator.truth_machine.plant_schedule`); the estimator is a bank
  of models identified at :data:`N_BANK` positions and scheduled on the commanded position
  (:mod:`millsense.estimation.feed.schedule`;
  docs/decisions/0115-position-dependent-disturbance-modes-simulator.md,
  docs/decisions/0116-position-scheduled-feed-estimator.md).
  ``estimation.feed_robust_band_at_lti_limit`` compares the single robust design's worst-case band
  over ±2 % with the limit of any linear estimator
  (:func:`~millsense.estimation.feed.tuning.flatness_bound`).

The compensated FRF is measured, not computed, at another operating point than the identification's
(decision 1790: commissioning swept its table load at +10 rad/s from position 0 toward +): a
multisine table load (1–300 Hz, 1 Hz lines, 5 N·m RMS at the motor, 16 averaged periods) is applied
during a constant-velocity move at −6 rad/s (:data:`TEST_SPEED_RAD_S`), the linear axes over the −
half of the stroke, which the identification sweep did not visit (the truth's modes follow the
table position; :func:`test_start`), on the truth simulated with its own substeps as everywhere
else (:func:`~millsense.simulator.machine_file.simulated_feed_substeps`); the estimate (delayed by
the 60-sample smoother, realigned) is divided line by line by the applied load, and the ±3 dB band
is the first line leaving ±3 dB. The raw figure is the same with the current only,
``η·K_t·I_nom/r_g``.
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from millsense.validation import Measured, case

if TYPE_CHECKING:
    from millsense.bench.pipeline import PipelineResult
    from millsense.core.config import FeedAxisConfig
    from millsense.estimation.feed.estimator import FeedAxisModel, OperatingCondition
    from millsense.estimation.feed.path_fit import SweepResult
    from millsense.estimation.feed.schedule import FeedModelBank
    from millsense.simulator.feed_drive import FeedDriveParams
    from millsense.streaming.block import Block

FS_HZ = 10_000.0
AXES = ("x", "y", "z", "a", "c")
#: RMS of the multisine load at the motor, N·m, and periods (first discarded)
EXCITATION_NM = 5.0
N_PERIODS = 17
#: motor speed of the constant-velocity move of the V1 harmonic-FRF test, rad/s (no reversal
#: under load)
MOVE_SPEED_RAD_S = 10.0
#: Motor speed of the band acceptance move, rad/s (issue 12, decision 1790): not the operating
#: point of the identification (:data:`millsense.bench.pipeline.SWEEP_SPEED_RAD_S`, +10 rad/s
#: from position 0 toward +): 6 rad/s in the other direction, 688 mm/min on the 12 mm leads (a
#: finishing feed), 2.9 °/s at the A table and 3.8 °/s at the C table.
TEST_SPEED_RAD_S = -6.0
#: Clearance kept between the end of the acceptance move and the stroke end, m.
STROKE_END_CLEARANCE_M = 0.005


def _nameplate_axis(axis: str) -> FeedAxisConfig:
    """The nameplate axis table of the Quaser preset (catalogue values, decision 0991)."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset

    return load_preset(MachineConfig, "quaser-ux600").axis(axis)


@cache
def _pipeline(axis: str, condition: OperatingCondition = "moving") -> PipelineResult:
    """Nameplate → commission → identify → merge for one axis (decision 0993) on the truth's
    drive through :func:`~millsense.simulator.drive_mismatch.commissioning_drive`. The truth's
    coupled drive has no modal Φ_d (``params.modes is None``), so ``commissioning_drive`` adds
    no 420 Hz mode to it: commissioning runs on the truth's mechanics as they are (their own
    modes, above the fit band included), and the machine tested later
    (:func:`~millsense.simulator.drive_mismatch.perturbed_drive`) has the same mechanics, its
    Coulomb/static friction +15 %, another noise realisation and the same quantisation."""
    from millsense.bench.pipeline import identified_machine
    from millsense.simulator.drive_mismatch import commissioning_drive
    from millsense.simulator.machine_file import simulated_feed_drive

    params = simulated_feed_drive("quaser-ux600", axis)
    return identified_machine(
        "quaser-ux600",
        [axis],
        drives={axis: commissioning_drive(params)},
        conditions=(condition,),
    )


@cache
def _identified(
    axis: str, condition: OperatingCondition = "moving"
) -> tuple[FeedDriveParams, FeedAxisModel, SweepResult]:
    """(the simulated drive, the estimator's model built from the merged machine file as
    ``millsense estimate`` builds it, the path sweep it was identified from)."""
    from millsense.bench.pipeline import feed_model
    from millsense.simulator.machine_file import simulated_feed_drive

    res = _pipeline(axis, condition)
    model = feed_model(res, axis, condition, sample_rate_hz=FS_HZ)
    return simulated_feed_drive("quaser-ux600", axis), model, res.axes[axis].sweeps[condition]


@cache
def _tuned_for(axis: str, band_hz: float | None) -> tuple[FeedDriveParams, FeedAxisModel]:
    """The identified (moving) model of ``axis``: widest-band Q, or least-noise Q for
    ``band_hz`` (tuned once for the FRF and the air-noise measurements)."""
    params, model, _ = _identified(axis)
    return params, model if band_hz is None else model.tuned(0.0, band_hz=band_hz)


@cache
def test_start(axis: str) -> float:
    """Start of the band acceptance move (load position: m linear, rad rotary).

    Linear axes: the move at :data:`TEST_SPEED_RAD_S` (toward −) ends
    :data:`STROKE_END_CLEARANCE_M` inside the − stroke end (:data:`STROKE_M`), so it runs over
    the half of the stroke the identification sweep (from 0 toward +) did not visit (the
    truth's modes follow the table position). Rotary axes: from
    0 toward − (the truth's worm mesh does not depend on the angle; the direction differs)."""
    if axis not in "xyz":
        return 0.0
    travel = abs(_test_travel_rad()) * _nameplate_axis(axis).transmission_m_rad
    start = -STROKE_M[axis] / 2 + STROKE_END_CLEARANCE_M + travel
    if start > 0.0:
        raise ValueError(
            f"{axis}: the acceptance move ({travel * 1e3:.0f} mm) does not fit in "
            "the − half of the stroke"
        )
    return start


#: Run-in before the multisine and the reserve after it (the estimator's smoother lag) that the
#: acceptance move's travel is planned with, s.
TEST_LEAD_S = 0.3
TEST_TAIL_S = 0.1


def _test_travel_rad() -> float:
    """Planned motor travel of the band acceptance move, rad (signed)."""
    from millsense.simulator.commissioning import ramp_move

    n = round((TEST_LEAD_S + N_PERIODS + TEST_TAIL_S) * FS_HZ)
    return float(ramp_move(TEST_SPEED_RAD_S, n, FS_HZ)[0][-1])


def stream_estimate(
    est: Block,
    channels: dict[str, np.ndarray],
    output: str,
    chunk: int = 100,
) -> np.ndarray:
    """Run a (reset) estimator block over CNC channels in chunks; one output channel, whole.

    ``channels`` maps input channel names to equal-length arrays (at ``FS_HZ``); the block
    sees each chunk as the engine would hand it (10 ms by default).
    """
    from millsense.streaming.block import Chunk

    n = len(next(iter(channels.values())))
    parts = [
        est.process(
            Chunk(s, FS_HZ, 0.0, {k: v[s : s + chunk] for k, v in channels.items()})
        ).channels[output]
        for s in range(0, n, chunk)
    ]
    return np.concatenate(parts)


@cache
def compensated_bandwidth(
    axis: str, frequency_scale: float = 1.0, band_hz: float | None = None
) -> dict[str, float]:
    """Measured ±3 dB bands (Hz) of the compensated estimate and of the raw current.

    ``band_hz``: the identified model re-tuned by the least-noise rule for that band
    (``FeedAxisModel.tuned(0, band_hz=...)``) instead of the widest-band Q.
    """
    from millsense.estimation.feed.estimator import FeedAxisEstimator
    from millsense.estimation.kalman.design import bandwidth_3db
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.simulator.commissioning import run_table_load_sweep
    from millsense.simulator.drive_mismatch import perturbed_drive
    from millsense.simulator.machine_file import simulated_feed_substeps

    params, model = _tuned_for(axis, band_hz)
    machine = perturbed_drive(params, frequency_scale=frequency_scale)
    per = round(1.0 * FS_HZ)
    d = model.drive  # nameplate K_t, r_g, η (the estimator's belief), identified J_e
    lg = d.transmission / d.efficiency
    load, _ = multisine_signal(FS_HZ, per, 1.0, 300.0, N_PERIODS, rms=EXCITATION_NM / lg)
    est = FeedAxisEstimator(model)
    if est.lag > TEST_TAIL_S * FS_HZ:
        raise ValueError(f"{axis}: estimator lag {est.lag} beyond the planned move")
    # the truth as it runs everywhere (its substeps), at the acceptance operating point: another
    # speed, direction and stretch of the stroke than the identification sweep (decision 1790)
    res, _, lead = run_table_load_sweep(
        machine,
        FS_HZ,
        np.concatenate([load, np.zeros(est.lag)]),
        speed_rad_s=TEST_SPEED_RAD_S,
        lead_s=TEST_LEAD_S,
        seed=11,
        start_position=test_start(axis),
        substeps=simulated_feed_substeps("quaser-ux600", axis),
    )
    est.reset(FS_HZ)
    cur, spd = res["current_cmd"], res["speed"]
    cnc = {f"{axis}/current_cmd": cur, f"{axis}/motor_speed": spd}
    load_est = stream_estimate(est, cnc, f"{axis}/load_est")
    load_est = load_est[lead + est.lag : lead + est.lag + len(load)]
    raw = (d.efficiency / d.transmission * d.torque_constant * cur)[lead : lead + len(load)]
    h = multisine_frf(load, load_est, FS_HZ, per, skip_periods=1)
    hr = multisine_frf(load, raw, FS_HZ, per, skip_periods=1)
    f = np.concatenate([[0.0], h.freq_hz])
    db = 20 * np.log10(np.abs(h.h1))
    in_180 = h.freq_hz <= (180.0 if model.kind == "linear" else 120.0)
    # the slowest motor speed in the direction of travel under the load (> 0: no reversal)
    along = np.sign(TEST_SPEED_RAD_S) * spd[lead : lead + len(load)]
    return {
        "min_speed_rad_s": float(np.min(along)),
        "start": test_start(axis),
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
        "[Hz] | raw at 1 Hz [dB] | Kalman states | R [N²m²] | Q [(Nm)²/s] | move start | "
        "slowest motor speed along the move [rad/s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for ax in AXES:
        r = compensated_bandwidth(ax, frequency_scale)
        tgt = 180 if ax in "xyz" else 120
        start = f"{r['start'] * 1e3:.0f} mm" if ax in "xyz" else f"{np.degrees(r['start']):.0f}°"
        rows.append(
            f"| {ax.upper()} | {tgt} | {r['compensated_hz']:.1f} | {r['worst_db_in_target']:.2f} | "
            f"{r['raw_hz']:.1f} | {r['raw_dc_db']:.2f} | {r['states']:.0f} | {r['r']:.4f} | "
            f"{r['q']:.0f} | {start} | {r['min_speed_rad_s']:.2f} |"
        )
    return "\n".join(rows) + "\n\n" + _OPERATING_POINT


_OPERATING_POINT = (
    f"Acceptance move (decision 1790): motor speed {TEST_SPEED_RAD_S:g} rad/s (toward −) from "
    "the start above, the linear moves ending 5 mm inside the − stroke end; the identification "
    "swept the same multisine at +10 rad/s from position 0 toward + (bench/pipeline.py). The "
    "truth runs with its own substeps, as everywhere else."
)


_MISMATCH = (
    "Mismatch: the truth's coupled drive (modes from the mechanics, position-dependent, lost "
    "motion, ripple, current-loop electrics) against the identified rigid body + rational Φ_d "
    "fit of a noisy sweep with nameplate K_t, η, r_g; LuGre friction +15 % in the truth vs "
    "the estimator's identified friction (LuGre where a presliding test was fitted, its "
    "Stribeck curve flat where the moves did not resolve one, decision 1695; Coulomb+viscous "
    "where the fit was refused, decision 1603); torque noise; encoder quantisation"
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
    # at the identification's own operating point (+10 rad/s from position 0) Z failed with
    # 4.87 dB (a dip/peak pair at 174-176 Hz); at the acceptance move (decision 1790) X, Y, Z
    # stay within 0.45, 0.34 and 2.18 dB (2026-11-28)
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
    gap="on the truth at the acceptance move (-6 rad/s, decision 1790; 2026-11-28) A stays "
    "within 2.84 dB to 120 Hz, but C deviates by up to 3.38 dB (its band ends at 104.9 Hz): "
    "the identified 9-state C path under-represents the truth's C dynamics there (3.28 dB at "
    "the identification's own operating point before)",
    issue=12,
    description="largest |deviation| from 0 dB of the measured compensated A/C torque FRF "
    "over 1-120 Hz (flat within ±3 dB to 120 Hz). " + _MISMATCH,
)
def _rotary() -> Measured:
    return _worst_db("rotary", 1.0)


#: Thesis figures of the raw current (seed 000 V3 / C3: flat only to about 10-15 Hz) and of the
#: compensated estimate (Fig. 3.8, C6: 180 Hz linear, 120 Hz rotary).
RAW_BAND_HZ = 12.5
TARGET_HZ = {"x": 180.0, "y": 180.0, "z": 180.0, "a": 120.0, "c": 120.0}
#: Axes whose raw-current band is a known failure on the truth, and why (measured 2026-11-28 at
#: the acceptance move, decision 1790; on the machine-file drive of before, with Table 3.4's
#: static gains as physical, every axis but Y left ±3 dB from about 1 Hz).
RAW_BAND_GAP = {
    "x": "on the truth at the acceptance move (-6 rad/s) the raw X current stays within ±3 dB "
    "to 20.3 Hz (-0.7 dB at 1 Hz): wider than the thesis's 10-15 Hz; the truth's X drive is "
    "fitted to Table 3.4's frequencies (decision 0973), not to the raw current's band",
    "z": "on the truth at the acceptance move (-6 rad/s) the raw Z current stays within ±3 dB "
    "to 16.8 Hz, just above the thesis's 10-15 Hz (the truth is fitted to Table 3.4's "
    "frequencies, decision 0973)",
    "a": "on the truth at the acceptance move (-6 rad/s) the raw A current's ±3 dB band ends "
    "at 2.3 Hz (+1.5 dB at 1 Hz): the truth's A viscous friction, Aslan Table 3.2's "
    "σ2 = 4.25 N·m·s/rad at the motor, is 9x the velocity loop's k_p (0.45 N·m·s/rad, the "
    "preset's 30 Hz design on J = 0.0024 kg·m²), so above a few hertz the friction, not the "
    "current, carries the load; the nameplate η·K_t/r_g is 13 % above the truth's (+1.1 dB "
    "at 1 Hz); the multisine briefly reverses the A motor at -6 rad/s (slowest speed along "
    "the move -0.06 rad/s)",
    "c": "on the truth at the acceptance move (-6 rad/s) the raw C current stays within ±3 dB "
    "to 43.6 Hz (-1.2 dB at 1 Hz), twice its 21.2 Hz at the identification's +10 rad/s: "
    "the raw band depends on the operating point and is wider than the thesis's 10-15 Hz (the "
    "truth is fitted to Table 3.4's frequencies, decision 0973)",
}


def _raw_case(axis: str) -> None:
    # every axis judged (issue 12): one case per axis, not the best of five
    @case(
        f"estimation.feed_raw_current_band_{axis}",
        source="seed 000 V3 / C3: raw current flat only to about 10-15 Hz",
        reference=RAW_BAND_HZ,
        unit="Hz",
        abs_tol=2.5,
        quick=False,
        gap=RAW_BAND_GAP.get(axis, ""),
        issue=12 if axis in RAW_BAND_GAP else None,
        description=f"{axis.upper()} axis: ±3 dB band of the raw current force η·K_t·I/r_g "
        "(thesis: 10-15 Hz)",
    )
    def _raw() -> Measured:
        return Measured(compensated_bandwidth(axis, 1.0)["raw_hz"], _table(1.0))


#: Axes whose compensated band on the truth is a known failure, and why (none on 2026-11-28 at
#: the acceptance move, decision 1790: A 120.9 and C 104.9 Hz pass; X, Y and Z reach the 300 Hz
#: end of the measurement, "too good": the truth is more benign there than the thesis's
#: machine. At the identification's own operating point before, Z was 174.0 and A 272.9 Hz).
BAND_GAP: dict[str, str] = {}


def _band_case(axis: str) -> None:
    tgt = TARGET_HZ[axis]

    @case(
        f"estimation.feed_compensated_band_{axis}",
        source=f"seed 000 V3 (Aslan Fig. 3.8, C6): {tgt:g} Hz on the "
        f"{'linear' if axis in 'xyz' else 'rotary'} axes",
        reference=tgt,
        unit="Hz",
        rel_tol=0.25,
        too_good_factor=1.5,
        lower_is_better=False,
        quick=False,
        ci=axis == "c",  # within the thesis band at the acceptance move (X, Y, Z: too good)
        gap=BAND_GAP.get(axis, ""),
        issue=12 if axis in BAND_GAP else None,
        description=f"{axis.upper()} axis: measured ±3 dB band of the compensated estimate "
        f"(multisine 1-300 Hz, so 300 Hz means at least 300) against the thesis's {tgt:g} Hz: "
        "two-sided ±25 %, more than 1.5× wider is flagged as too good (a replica far wider than "
        "the thesis's measured band says the simulated plant is too benign). " + _MISMATCH,
    )
    def _band() -> Measured:
        return Measured(compensated_bandwidth(axis, 1.0)["compensated_hz"], _table(1.0))


for _ax in AXES:
    _raw_case(_ax)
    _band_case(_ax)


#: Band asked of the least-noise tuning, × the axis target (decision "Least-noise Q for a
#: requested band": ±1 dB on the model to 1.25 × the target keeps ±3 dB on the machine).
LEAST_NOISE_BAND_FACTOR = 1.25


@cache
def air_noise_rms(axis: str, band_hz: float | None = None) -> float:
    """Measured RMS of the load estimate (N, N·m rotary) in an air move on the mismatched machine.

    The identified model (widest-band Q, or re-tuned for ``band_hz`` as in
    :func:`compensated_bandwidth`) streams 1.5 s of a constant-velocity air move at the band
    acceptance move's speed and start on
    :func:`~millsense.simulator.drive_mismatch.perturbed_drive`; the RMS
    about the mean over the last second is the estimate's noise (current noise through the
    filter, quantisation, friction-model error).
    """
    from millsense.estimation.feed.estimator import FeedAxisEstimator
    from millsense.simulator.commissioning import ramp_move
    from millsense.simulator.drive_mismatch import perturbed_drive
    from millsense.simulator.feed_drive import FeedDriveSim
    from millsense.simulator.machine_file import simulated_feed_substeps

    params, model = _tuned_for(axis, band_hz)
    n = round(1.5 * FS_HZ)
    pos, vel = ramp_move(TEST_SPEED_RAD_S, n, FS_HZ)
    q0 = test_start(axis) / params.transmission
    sub = simulated_feed_substeps("quaser-ux600", axis)
    sim = FeedDriveSim(perturbed_drive(params), FS_HZ, substeps=sub, seed=31, initial_angle_rad=q0)
    res = sim.advance(pos + q0, vel, np.zeros(n))
    est = FeedAxisEstimator(model)
    est.reset(FS_HZ)
    cnc = {f"{axis}/current_cmd": res["current_cmd"], f"{axis}/motor_speed": res["speed"]}
    tail = stream_estimate(est, cnc, f"{axis}/load_est")[round(0.5 * FS_HZ) :]
    return float(np.std(tail))


def _least_noise_table() -> tuple[float, str]:
    rows = [
        "| Axis | target [Hz] | band asked (±1 dB on the model) [Hz] | Q widest / least-noise "
        "[(Nm)²/s] | measured ±3 dB band widest / least-noise [Hz] | worst dB to target "
        "widest / least-noise | air-move noise RMS widest / least-noise | noise ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    from millsense.core.errors import InputDataError

    worst = 0.0
    refused = []
    for ax in AXES:
        tgt = 180.0 if ax in "xyz" else 120.0
        band = LEAST_NOISE_BAND_FACTOR * tgt
        wide = compensated_bandwidth(ax)
        n_wide = air_noise_rms(ax)
        unit = "N" if ax in "xyz" else "N·m"
        try:
            low = compensated_bandwidth(ax, 1.0, band)
        except InputDataError as exc:
            # the tuning refuses the band (`estimate --band-hz` stops with this message): the
            # user keeps the widest design, whose figure is counted
            worst = max(worst, wide["worst_db_in_target"])
            refused.append(f"{ax.upper()}: {exc}")
            rows.append(
                f"| {ax.upper()} | {tgt:.0f} | {band:.0f} | {wide['q']:.0f} / refused | "
                f"{wide['compensated_hz']:.1f} / - | {wide['worst_db_in_target']:.2f} / - | "
                f"{n_wide:.1f} / - {unit} | - |"
            )
            continue
        n_low = air_noise_rms(ax, band)
        worst = max(worst, low["worst_db_in_target"])
        rows.append(
            f"| {ax.upper()} | {tgt:.0f} | {band:.0f} | {wide['q']:.0f} / {low['q']:.0f} | "
            f"{wide['compensated_hz']:.1f} / {low['compensated_hz']:.1f} | "
            f"{wide['worst_db_in_target']:.2f} / {low['worst_db_in_target']:.2f} | "
            f"{n_wide:.1f} / {n_low:.1f} {unit} | {n_wide / n_low:.2f} |"
        )
    notes = "".join(f"\n\nRefused (the widest design counted): {r}" for r in refused)
    return worst, "\n".join(rows) + notes


@case(
    "estimation.feed_least_noise_band_flat",
    source="seed 000 V3 (Aslan Fig. 3.8, C6: 180/120 Hz; Q tuned by hand in Eq. 3.30)",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    gap="on the truth at the acceptance move (-6 rad/s, decision 1790; 2026-11-28) the "
    "least-noise C design deviates by up to 3.07 dB within 120 Hz (its widest design 3.38 dB, "
    "estimation.feed_rotary_flat_to_120hz); the tuning refuses ±1 dB to 225 Hz on Z, which "
    "keeps its widest design (2.18 dB); the least-noise designs of X, Y, A stay within 1.36, "
    "0.69 and 2.27 dB with 2.3-3.2x less noise in an air move",
    issue=12,
    description="largest |deviation| from 0 dB of the measured compensated force FRF over "
    "1-180 Hz (X/Y/Z) and 1-120 Hz (A/C) when Q is the LEAST-NOISE value keeping the "
    "identified model within ±1 dB up to 1.25 × the target (tuning.least_noise_q, the "
    "`band_hz` key / `estimate --band-hz`) instead of the widest ±3 dB band under the noise "
    "limit; details: Q, measured bands and the measured noise of the estimate in an air move "
    "for both rules. " + _MISMATCH,
)
def _least_noise() -> Measured:
    worst, table = _least_noise_table()
    return Measured(worst, table)


# ---------------------------------------------------------------------------------------------
# Position-dependent modes: the position-scheduled estimator (issue 7)
# ---------------------------------------------------------------------------------------------

#: Axis strokes of the Quaser UX600, m (X 600 / Y 450 / Z 450 mm as stated in the issue-7
#: brief; not checked against a Quaser data sheet, which is not among the sources: assumption).
STROKE_M = {"x": 0.600, "y": 0.450, "z": 0.450}
#: Change of every disturbance-mode frequency over the whole stroke, relative (±2 % about the
#: stroke centre, where Table 3.4 is taken to hold: decision "Position-dependent disturbance
#: modes").
MODE_CHANGE_OVER_STROKE = 0.04
#: Identification positions per axis (decision "Position-scheduled feed estimator": the
#: smallest N whose analytic worst case over an interval is within 3 dB − 0.5 dB margin).
N_BANK = 3
#: Motor speed of the bank sweeps and of the acceptance moves per axis, rad/s, and the RMS load
#: at the motor of both, N·m: the slowest speed at which that load does not reverse the motor
#: (measured minimum motor speed, details table; X at 2 rad/s dips to −0.2 rad/s). 2 rad/s =
#: 3.8 mm/s: the 13.3 s sweep travels 51 mm, a fifth of the 10 rad/s sweep's 254 mm.
SCHED_SPEED_RAD_S = {"x": 3.0, "y": 2.0, "z": 2.0}
SCHED_EXCITATION_NM = 2.0


def scheduled_params(axis: str) -> FeedDriveParams:
    """The preset drive with position-dependent modes: the truth as it is (its plant follows the
    position by its mechanics), the machine-file drive with its modes ±2 % over the stroke."""
    from dataclasses import replace

    from millsense.simulator.machine_file import simulated_feed_drive

    params = simulated_feed_drive("quaser-ux600", axis)
    if params.modes is None:  # the truth: its plant follows the position by its mechanics
        return params
    return replace(
        params,
        mode_shift_per_m=MODE_CHANGE_OVER_STROKE / STROKE_M[axis],
        mode_reference_position=0.0,
    )


def bank_positions(axis: str, n: int = N_BANK) -> tuple[float, ...]:
    """Identification positions, m: ``n`` evenly spaced from one stroke end to the other, each
    end inset by half a sweep's travel (the sweep is a move centred on its position and must
    stay inside the stroke)."""
    from millsense.bench.feed_bank import sweep_travel

    s = STROKE_M[axis]
    lead = _nameplate_axis(axis).transmission_m_rad
    d = 0.5 * sweep_travel(lead, SCHED_SPEED_RAD_S[axis], FS_HZ)
    return tuple(float(x) for x in np.linspace(-s / 2 + d, s / 2 - d, n))


@cache
def _bank(axis: str, n: int = N_BANK) -> FeedModelBank:
    from millsense.bench.feed_bank import identify_feed_bank
    from millsense.simulator.drive_mismatch import commissioning_drive

    params = scheduled_params(axis)
    nameplate = _nameplate_axis(axis)
    lg = nameplate.transmission_m_rad / nameplate.efficiency
    bank, _ = identify_feed_bank(
        commissioning_drive(params),
        axis,
        "linear",
        bank_positions(axis, n) if n > 1 else (0.0,),
        sample_rate_hz=FS_HZ,
        sweep_speed_rad_s=SCHED_SPEED_RAD_S[axis],
        sweep_force_rms=SCHED_EXCITATION_NM / lg,
        design="auto",
        nameplate=nameplate,
    )
    return bank


def _test_travel(axis: str) -> float:
    from millsense.simulator.commissioning import ramp_move

    p = scheduled_params(axis)
    n = round((0.3 + N_PERIODS + 0.01) * FS_HZ)
    return float(ramp_move(SCHED_SPEED_RAD_S[axis], n, FS_HZ)[0][-1] * p.transmission)


def test_places(axis: str) -> dict[str, float]:
    """Centres of the acceptance moves, m: midway between the two lowest identification
    positions (the analytic worst place of the interval, modes below their centre values: Z's
    183 Hz mode nearer the band) and as close to each stroke end as the move allows."""
    pos = bank_positions(axis)
    half = 0.5 * _test_travel(axis)
    s = STROKE_M[axis] / 2
    return {"midway": 0.5 * (pos[0] + pos[1]), "low end": -s + half, "high end": s - half}


@cache
def scheduled_frf(axis: str, centre_m: float, n: int = N_BANK) -> dict[str, float]:
    """Measured compensated FRF of the bank of ``n`` (1: one model from the stroke centre) on the
    machine with position-dependent modes, during a move centred at ``centre_m``.

    The multisine test of :func:`compensated_bandwidth` at :data:`SCHED_SPEED_RAD_S` and
    :data:`SCHED_EXCITATION_NM`, on :func:`~millsense.simulator.drive_mismatch.perturbed_drive` of
    :func:`scheduled_params`: on the truth (``modes is None``) that adds no 420 Hz mode and no
    frequency shift, so the machine tested has the mechanics the bank was identified on (their
    position dependence included) with Coulomb/static friction +15 %, its own noise realisation,
    encoder quantisation and current loop; the block reads the commanded position
    ``{axis}/position_cmd``.
    """
    from millsense.estimation.feed.schedule import ScheduledFeedEstimator
    from millsense.estimation.kalman.design import bandwidth_3db
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.simulator.commissioning import ramp_move
    from millsense.simulator.drive_mismatch import perturbed_drive
    from millsense.simulator.feed_drive import FeedDriveSim

    params = scheduled_params(axis)
    bank = _bank(axis, n)
    machine = perturbed_drive(params, frequency_scale=1.0)
    per = round(1.0 * FS_HZ)
    lg = params.transmission / params.efficiency
    load, _ = multisine_signal(FS_HZ, per, 1.0, 300.0, N_PERIODS, rms=SCHED_EXCITATION_NM / lg)
    lead = round(0.3 * FS_HZ)
    est = ScheduledFeedEstimator(bank)
    total = len(load) + lead + est.lag
    start = centre_m - 0.5 * _test_travel(axis)
    q0 = start / params.transmission
    pos, vel = ramp_move(SCHED_SPEED_RAD_S[axis], total, FS_HZ)
    pos = pos + q0
    full = np.concatenate([np.zeros(lead), load, np.zeros(est.lag)])
    res = FeedDriveSim(machine, FS_HZ, seed=11, initial_angle_rad=q0).advance(pos, vel, full)
    est.reset(FS_HZ)
    cur, spd, x_cmd = res["current_cmd"], res["speed"], pos * params.transmission
    cnc = {
        f"{axis}/current_cmd": cur,
        f"{axis}/motor_speed": spd,
        f"{axis}/position_cmd": x_cmd,
    }
    chunks = [stream_estimate(est, cnc, f"{axis}/load_est")]
    load_est = np.concatenate(chunks)[lead + est.lag : lead + est.lag + len(load)]
    h = multisine_frf(load, load_est, FS_HZ, per, skip_periods=1)
    db = 20 * np.log10(np.abs(h.h1))
    f = np.concatenate([[0.0], h.freq_hz])
    x_true = res["true_position"][lead : lead + len(load)]
    return {
        "worst_db": float(np.max(np.abs(db[h.freq_hz <= 180.0]))),
        "band_hz": bandwidth_3db(f, np.concatenate([[1.0], h.h1])),
        "scale_lo": float(params.mode_scale(x_true.min())),
        "scale_hi": float(params.mode_scale(x_true.max())),
        "min_speed": float(np.min(res["true_speed"][lead:])),
    }


@cache
def _lti_bound_over_stroke(axis: str) -> float:
    """flatness_bound of the centre model's Φ_d for modes anywhere within ±2 % (one LTI
    estimator over the whole stroke), dB over 1-180 Hz."""
    from millsense.estimation.feed import tuning
    from millsense.estimation.feed.estimator import measurement_model

    m = _bank(axis, 1).models[0]
    f = np.concatenate([np.arange(0.0, 300.0, 0.05), np.arange(300.0, 1000.5, 1.0)])
    fam = tuning.mode_family(m.disturbance, MODE_CHANGE_OVER_STROKE / 2, 9)
    plants = np.array([tuning.model_frf(measurement_model(x, m.lowpass_hz, m.dt), f) for x in fam])
    return tuning.flatness_bound(plants, f, 180.0)[0]


def _scheduled_table() -> tuple[float, str]:
    rows = [
        "| Axis | estimator | identified at [mm] | measured half shift [%] | analytic worst dB "
        "nominal / robust members | move | mode scale during the move | worst dB 1-180 Hz | "
        "±3 dB band [Hz] | min motor speed [rad/s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    worst = 0.0
    for ax in ("x", "y", "z"):
        places = test_places(ax)
        for n in (N_BANK, 1):
            bank = _bank(ax, n)
            at = ", ".join(f"{1e3 * p:.0f}" for p in bank.positions)
            hs = ", ".join(f"{100 * h:.2f}" for h in bank.half_shifts)
            label = (
                f"scheduled, N = {n}, {bank.design} members"
                if n > 1
                else "one model (stroke centre)"
            )
            an = " / ".join(f"{v:.2f}" for v in bank.analytic_db) if n > 1 else "-"
            sel = places if n > 1 else {k: v for k, v in places.items() if k != "midway"}
            for name, c in sel.items():
                r = scheduled_frf(ax, c, n)
                if n > 1:
                    worst = max(worst, r["worst_db"])
                rows.append(
                    f"| {ax.upper()} | {label} | {at} | {hs} | {an} | {name} ({1e3 * c:.0f} mm) | "
                    f"{r['scale_lo']:.4f}-{r['scale_hi']:.4f} | {r['worst_db']:.2f} | "
                    f"{r['band_hz']:.1f} | {r['min_speed']:.2f} |"
                )
        rows.append(
            f"| {ax.upper()} | any single LTI estimator, modes ±2 % (tuning.flatness_bound) | - "
            f"| - | - | - | 0.98-1.02 | ≥ {_lti_bound_over_stroke(ax):.2f} | - | - |"
        )
    return worst, "\n".join(rows)


@case(
    "estimation.feed_linear_flat_to_180hz_position_scheduled",
    source="seed 000 V3 (Aslan Fig. 3.8, C6) with position-dependent modes (issue 7)",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    gap="on the truth (2026-11-28) X and Y stay within 1.13 and 0.55 dB at every place, Z "
    "within 2.79 dB midway and at the low end but 4.28 dB at the high end of the stroke (one "
    "model: 4.93 dB): the lightly damped Z mode near 175 Hz moves with the table and the "
    "bank's three models do not follow it there",
    issue=12,
    description="largest |deviation| from 0 dB of the measured compensated X/Y/Z force FRF over "
    "1-180 Hz on the truth, whose plant follows the table position by its own mechanics (its "
    "'mode scale' is 1: the ±2 % mode shift belongs to the machine-file drive), "
    "estimated by the position-scheduled bank (Φ_d identified at "
    f"{N_BANK} positions from end to end of the stroke, estimates interpolated linearly by the "
    "commanded position), during moves midway between two identification positions and at both "
    "stroke ends (X 3, Y/Z 2 rad/s; 2 N·m RMS multisine at the motor); details: the same moves "
    "with one "
    "model identified at the stroke centre, and the LTI limit for one estimator over ±2 %. "
    "Rotary axes: no angle dependence is modelled (decision 'Position-dependent disturbance "
    "modes'), their acceptance is estimation.feed_rotary_flat_to_120hz. " + _MISMATCH,
)
def _linear_scheduled() -> Measured:
    worst, table = _scheduled_table()
    return Measured(worst, table)


#: relative mode shifts of the analytic robustness table
ANALYTIC_SHIFTS = (-0.02, -0.01, 0.0, 0.01, 0.02)


@cache
def robustness(axis: str) -> dict[str, float]:
    """Analytic compensated FRF (estimator × shifted identified model), robust vs nominal design.

    Plants: the identified Φ_d with every mode frequency × (1 + s) in series with the C3
    low-pass (what the estimator's own tuning evaluates); estimators: the smoothed output of the
    robust design (:func:`~millsense.estimation.feed.tuning.tune_robust` for ±2 %, the
    ``mode_shift_pct = 2`` option) and of the design tuned on the identified model alone
    (``tune_q``, the default).
    """
    from millsense.estimation.feed import tuning
    from millsense.estimation.feed.estimator import ASLAN_LAG_SAMPLES, measurement_model
    from millsense.estimation.kalman.design import bandwidth_3db

    _, model, _ = _identified(axis)
    fit, lp, dt = model.disturbance, model.lowpass_hz, model.dt
    target = 180.0 if model.kind == "linear" else 120.0
    f = np.concatenate([np.arange(0.0, 300.0, 0.05), np.arange(300.0, 1000.5, 1.0)])
    sel = (f >= 1.0) & (f <= target)
    fam = tuning.mode_family(fit, 0.02, 9)
    plants = np.array([tuning.model_frf(measurement_model(m, lp, dt), f) for m in fam])
    bound_db, bound_band = tuning.flatness_bound(plants, f, target)
    nominal, robust = model.tuned(0.0), model.tuned(0.02)
    designs = {"robust": robust.design(), "nominal": nominal.design()}
    out = {
        "bound_db": bound_db,
        "bound_band_hz": bound_band,
        "damping": robust.design_damping,
        "q": robust.q,
        "q_nominal": nominal.q,
    }
    nominal_model = nominal.measurement_model()
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
    source="self-consistency check, not an acceptance figure: the reference is the project's "
    "own bound (tuning.flatness_bound, closed form), no external figure exists (issue 12)",
    reference=1.0,
    unit="-",
    abs_tol=0.02,
    quick=False,
    gap="on the path identified on the truth's Y drive (2026-11-28; lightly damped modes, the "
    "LTI limit over modes ±2 % itself only 99.1 Hz) the robust design's common band is 93.6 "
    "Hz, 94.4 % of the limit; the other axes reach it (capped at their targets)",
    issue=12,
    self_check=True,
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
#: Seeds of the simulated noise (torque noise, quantisation phase) the V1 errors are averaged
#: over: one realisation scatters by ±1 point at 3000 rev/min on Y (decision "V1 figure: mean
#: over noise realisations").
V1_SEEDS = (21, 22, 23, 24, 25)
#: (axis, rev/min) → (min, max) harmonic-design error over V1_SEEDS, filled by v1_errors.
V1_SPREAD: dict[tuple[str, float], tuple[float, float]] = {}
#: Aslan V1 compensated and raw errors at the tooth frequency and harmonics (digest §4)
V1_THESIS = {
    "x": ((0.18, 0.06, 0.04, 0.12, 0.32, 0.17), (1.61, 3.41, 0.22, 0.64, 1.58, 0.49)),
    "y": ((0.06, 0.06, 0.04, 0.07, 0.11, 0.19), (0.42, 1.03, 1.13, 0.54, 0.32, 1.75)),
}
V1_MAX_HARMONIC_HZ = 200.0
#: teeth of the V1 cutter (Ø20 mm 2-flute, preset aslan-d20-2flute)
V1_TEETH = 2
#: V1 run: air before the first contact and the steady slot after the entry, samples at FS_HZ
#: (the entry between them lasts R/v_f: 1.5 s at 1000 rev/min, 0.27 s at 5500 rev/min)
V1_AIR_SAMPLES, V1_CUT_SAMPLES = round(0.5 * FS_HZ), round(1.0 * FS_HZ)


def whole_period_block(
    tooth_hz: float, fs: float = FS_HZ, max_periods: int = 1000
) -> tuple[int, int]:
    """Shortest record of whole tooth periods on the sample grid: (samples, periods).

    The tooth period ``fs/f_t`` need not be a whole number of samples (5500 rev/min, 2 flutes:
    54.55 samples); ``p`` periods span ``p·fs/f_t`` samples, the first whole number wins, so
    every tooth harmonic falls exactly on a DFT line of a record made of such blocks.

    Parameters
    ----------
    tooth_hz : tooth-passing frequency f_t, Hz.
    fs : sample rate, Hz.
    max_periods : largest number of periods tried.

    Raises
    ------
    InputDataError
        When no ``p ≤ max_periods`` makes ``p·fs/f_t`` whole (to 10⁻⁶ sample).
    """
    from millsense.core.errors import InputDataError

    per = fs / tooth_hz
    for p in range(1, max_periods + 1):
        n = p * per
        if abs(n - round(n)) < 1e-6:
            return round(n), p
    raise InputDataError(f"V1: tooth frequency {tooth_hz:g} Hz has no whole-period block")


def _harmonic_error(est: np.ndarray, true: np.ndarray, tooth_hz: float, teeth: int = 1) -> float:
    """Relative error of the complex amplitudes at the tooth harmonics ≤ 200 Hz.

    ``sqrt(Σ_k |Ê_k − E_k|²) / sqrt(Σ_k |E_k|²)`` over k·f_t ≤ 200 Hz (at least k = 1), from the
    DFT of whole periods of the steady cut (the estimate realigned by the smoother lag); the
    record is a whole number of :func:`whole_period_block` blocks, so the harmonics sit on
    DFT lines even when the period is not a whole number of samples. ``teeth``: the blocks are
    whole spindle revolutions (f_t/teeth), so that the spindle orders of a cutter with runout
    fall on their own lines and do not leak onto the tooth harmonics (the V1 load, decision
    1710); 1: whole tooth periods.
    """
    block, revs_per_block = whole_period_block(tooth_hz / teeth)
    n = (len(true) // block) * block
    e_hat = np.fft.rfft(est[:n])
    e_true = np.fft.rfft(true[:n])
    revs = (n // block) * revs_per_block
    ks = [k for k in range(1, 10) if k * tooth_hz <= V1_MAX_HARMONIC_HZ + 1e-9] or [1]
    idx = [k * teeth * revs for k in ks]
    num = np.sqrt(np.sum(np.abs(e_hat[idx] - e_true[idx]) ** 2))
    den = np.sqrt(np.sum(np.abs(e_true[idx]) ** 2))
    return float(num / den)


def _v1_cut(rpm: float) -> tuple[dict[str, np.ndarray], float, float, int]:
    """V1 slot with runout, the truth spindle's speed and the entry
    (:func:`~millsense.validation.cases._v1_load.v1_load`): table forces along +X/+Y (N), the
    feed (m/s), the tooth frequency (Hz) and the first sample at full engagement."""
    from millsense.validation.cases._v1_load import v1_load

    load = v1_load(rpm, V1_AIR_SAMPLES, V1_CUT_SAMPLES, FS_HZ)
    return {"x": load.table_x, "y": load.table_y}, load.feed, load.tooth_hz, load.n_full


def v1_run(
    axis: str,
    rpm: float,
    model: FeedAxisModel,
    machine: FeedDriveParams,
    *,
    lag: int | None = None,
    seed: int = 21,
    harmonics: bool = False,
    harmonic_q_ratio: float | None = None,
) -> tuple[float, float]:
    """One V1 speed on one axis: (compensated error, raw-current error) at the tooth harmonics.

    ``model`` is the estimator's belief, ``machine`` the simulated drive that cuts (both
    explicit so that an error budget can swap either); X feeds at the V1 feed, Y holds position.
    ``harmonics``: the estimator adds the tooth harmonics ≤ 200 Hz (Aslan's full model,
    Eq. 3.16–3.20) from the commanded spindle speed ``spindle/speed_cmd`` (the V1 speed from
    the start of the record, i.e. through the 0.5 s air phase) and the 2 teeth;
    ``harmonic_q_ratio`` overrides κ (default the estimator's).
    """
    from millsense.estimation.feed.estimator import (
        HARMONIC_Q_RATIO,
        SPINDLE_SPEED_CMD,
        FeedAxisEstimator,
    )
    from millsense.estimation.kalman.smoother import ASLAN_LAG_SAMPLES
    from millsense.simulator.feed_drive import FeedDriveSim

    table, feed, tooth_hz, n_full = _v1_cut(rpm)
    n = len(table[axis])
    t = np.arange(n) / FS_HZ
    v = feed / machine.transmission if axis == "x" else 0.0
    vel = np.minimum(t / 0.2, 1.0) * v
    pos = np.cumsum(vel) / FS_HZ
    res = FeedDriveSim(machine, FS_HZ, seed=seed).advance(pos, vel, -table[axis])
    est = FeedAxisEstimator(
        model,
        ASLAN_LAG_SAMPLES if lag is None else lag,
        teeth=V1_TEETH if harmonics else None,
        harmonic_q_ratio=HARMONIC_Q_RATIO if harmonic_q_ratio is None else harmonic_q_ratio,
    )
    est.reset(FS_HZ)
    cur, spd = res["current_cmd"], res["speed"]
    cnc = {f"{axis}/current_cmd": cur, f"{axis}/motor_speed": spd}
    if harmonics:
        cnc[SPINDLE_SPEED_CMD] = np.full(n, rpm * 2 * np.pi / 60)
    f_est = stream_estimate(est, cnc, f"{axis}/force_est")
    lag_ = est.lag
    d = model.drive
    raw = -d.efficiency / d.transmission * d.torque_constant * cur
    # judged: whole revolutions of the steady slot from 0.3 s after full engagement (the
    # thesis's errors are at the tooth harmonics of the steady cut; the entry is in the record
    # the estimator runs through, not in the DFT window, whose lines it would smear)
    k0 = n_full + round(0.3 * FS_HZ)
    true = table[axis][k0 : n - lag_]
    comp = f_est[k0 + lag_ : n]
    raw_s = raw[k0 : n - lag_]
    return (
        _harmonic_error(comp, true, tooth_hz, V1_TEETH),
        _harmonic_error(raw_s - raw_s.mean(), true, tooth_hz, V1_TEETH),
    )


def v1_condition(axis: str, rpm: float) -> OperatingCondition:
    """Operating condition of ``axis`` in the V1 cut at ``rpm``, from the commanded speed only.

    The CNC commands the feed on X and nothing on Y (it holds position), so
    :func:`~millsense.estimation.feed.estimator.operating_condition` of the commanded motor speed
    picks the moving model for X and the at-rest model for Y.
    """
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.feed.estimator import operating_condition
    from millsense.validation.cases._v1_load import v1_feed

    feed = v1_feed(rpm, V1_TEETH)
    lead = load_preset(MachineConfig, "quaser-ux600").axis(axis).transmission_m_rad
    return operating_condition(feed / lead if axis == "x" else 0.0)


@cache
def v1_errors() -> dict[str, list[tuple[float, float, float, float]]]:
    """Per axis and V1 speed: (rev/min, random-walk error, harmonic error, raw-current error),
    each the mean over the noise realisations :data:`V1_SEEDS` (decision "V1 figure: mean over
    noise realisations"; the harmonic design's range is kept in :data:`V1_SPREAD`).

    Each axis's estimator is the model identified in the operating condition the CNC commands
    (:func:`v1_condition`: X moving, Y at rest), run twice on the same simulated cut: the
    random-walk design (Aslan Eq. 3.21–3.23, the model the thesis used) and the harmonic
    design (Eq. 3.16–3.20, tooth harmonics ≤ 200 Hz from the commanded spindle speed).
    """
    from millsense.simulator.drive_mismatch import perturbed_drive

    out: dict[str, list[tuple[float, float, float, float]]] = {"x": [], "y": []}
    for axis in ("x", "y"):
        for rpm in V1_RPM:
            params, model, _ = _identified(axis, v1_condition(axis, rpm))
            machine = perturbed_drive(params, frequency_scale=1.0)
            runs = np.array(
                [
                    (
                        *v1_run(axis, rpm, model, machine, seed=s),
                        *v1_run(axis, rpm, model, machine, seed=s, harmonics=True),
                    )
                    for s in V1_SEEDS
                ]
            )  # columns: random walk, raw, harmonic, raw (same cut)
            comp_rw, raw, comp_h = runs[:, 0].mean(), runs[:, 1].mean(), runs[:, 2].mean()
            out[axis].append((rpm, float(comp_rw), float(comp_h), float(raw)))
            V1_SPREAD[(axis, rpm)] = (float(runs[:, 2].min()), float(runs[:, 2].max()))
    return out


def _v1(axis: str) -> Measured:
    res = v1_errors()[axis]
    comp_th, raw_th = V1_THESIS[axis]
    rows = [
        "| rev/min | harmonic (full model, Eq. 3.16-3.20), mean (range) | random walk (thesis' "
        "model, "
        "Eq. 3.21-3.23) | thesis compensated | raw current | thesis raw |",
        "|---|---|---|---|---|---|",
    ]
    worst = 0.0
    for (rpm, c_rw, c_h, r), ct, rt in zip(res, comp_th, raw_th, strict=True):
        lo, hi = V1_SPREAD[(axis, rpm)]
        rows.append(
            f"| {rpm:.0f} | {c_h:.1%} ({lo:.1%}-{hi:.1%}) | {c_rw:.1%} | {ct:.0%} | {r:.1%} | "
            f"{rt:.0%} |"
        )
        worst = max(worst, c_h)
    return Measured(worst, "\n".join(rows))


_V1_DESC = (
    "largest compensated error at the tooth harmonics ≤ 200 Hz, mean over 5 noise realisations "
    "(seeds of the simulated noise), over 1000-5500 rev/min of the HARMONIC estimator (Aslan's "
    "full disturbance model Eq. 3.16-3.20: random walk plus one undamped pair per tooth harmonic "
    "≤ 200 Hz, from the commanded spindle speed and the 2 teeth), against the thesis's largest "
    "over the same speeds: two-sided ±50 %, more than 2× better is flagged as too good; the "
    "table also shows the random-walk estimator (Eq. 3.21-3.23, the model the thesis used) on "
    "the same cut. Ø20 mm 2-flute slot, 4 mm, 0.2 mm/tooth, Al7050; the load is a real cut's "
    "(decision 1710): 37 µm radial runout (seed 000 Ch. 4.5, Aslan's Ø20 mm 2-flute), the tool "
    "turned by the Quaser truth spindle under the cut's torque (speed dip at the entry, "
    "ripple in the cut), the entry into the workpiece's edge at the feed (R/v_f, 0.27-1.5 s); "
    "judged on whole revolutions of the steady slot from 0.3 s after full engagement (the "
    "entry runs through the estimator but would smear the DFT lines). X feeds, Y holds "
    "position; each axis uses "
    "the model identified in the condition its commanded speed selects (X moving, Y at rest; "
    "docs/decisions/0106-holding-axis-phi-d-and-r-identified-at-rest-issue-7-v1.md). " + _MISMATCH
)


@case(
    "estimation.feed_v1_x_harmonic_errors",
    source="seed 000 V1 (Aslan Ch. 3.5), largest 32%: X 18/6/4/12/32/17 %",
    reference=max(V1_THESIS["x"][0]),
    rel_tol=0.5,
    too_good_factor=2.0,
    unit="-",
    quick=False,
    description=_V1_DESC + ". X stays too good with the real cut's load (5.4 % before, 5.3 % "
    "after, decision 1710): the estimator is linear, so its error at a tooth line is the "
    "mismatch of the identified path and the truth's at that line; runout adds spindle orders "
    "that are not judged and the truth spindle's speed ripple is 0.5 % at 1000 rev/min, 0.02 % "
    "at 5500. The truth's X drive is more benign than the thesis's machine (its compensated "
    "band reaches the 300 Hz end of estimation.feed_compensated_band_x, thesis 180 Hz)",
)
def _v1x() -> Measured:
    return _v1("x")


@case(
    "estimation.feed_v1_y_harmonic_errors",
    source="seed 000 V1 (Aslan Ch. 3.5), largest 19%: Y 6/6/4/7/11/19 %",
    reference=max(V1_THESIS["y"][0]),
    rel_tol=0.5,
    too_good_factor=2.0,
    unit="-",
    quick=False,
    description=_V1_DESC,
)
def _v1y() -> Measured:
    return _v1("y")


def harmonic_frf_departure(axis: str, rpm: float, harmonics: bool = True) -> dict[str, float]:
    """Measured compensated FRF of a non-periodic load under a running harmonic design.

    The multisine test of :func:`compensated_bandwidth` (1–300 Hz, 1 Hz lines, 16 averaged
    periods, moving model, constant-velocity move, the same mismatched machine) with the
    commanded spindle speed held at ``rpm`` and 2 teeth, so the harmonic design for the tooth
    harmonics ≤ 200 Hz runs while the load has energy on every line in between. Not a pass/fail
    case: it reports how far the harmonic design departs from 0 dB between the tooth lines.

    Returns
    -------
    ``worst_db``: largest |dB| over 1–180 Hz; ``worst_db_off_lines``: the same excluding the
    1 Hz lines on the tooth harmonics; ``band_hz``: the ±3 dB band; ``at_lines``: largest
    complex error |H − 1| on the tooth-harmonic lines.
    """
    from millsense.estimation.feed.estimator import (
        SPINDLE_SPEED_CMD,
        FeedAxisEstimator,
        tooth_harmonics,
    )
    from millsense.estimation.kalman.design import bandwidth_3db
    from millsense.ident.frf import multisine_frf, multisine_signal
    from millsense.simulator.commissioning import ramp_move
    from millsense.simulator.drive_mismatch import perturbed_drive
    from millsense.simulator.feed_drive import FeedDriveSim

    params, model, _ = _identified(axis)
    machine = perturbed_drive(params, frequency_scale=1.0)
    per = round(1.0 * FS_HZ)
    lg = model.drive.transmission / model.drive.efficiency
    load, _ = multisine_signal(FS_HZ, per, 1.0, 300.0, N_PERIODS, rms=EXCITATION_NM / lg)
    lead = round(0.3 * FS_HZ)
    est = FeedAxisEstimator(model, teeth=V1_TEETH if harmonics else None)
    pos, vel = ramp_move(MOVE_SPEED_RAD_S, len(load) + lead + est.lag, FS_HZ)
    full = np.concatenate([np.zeros(lead), load, np.zeros(est.lag)])
    res = FeedDriveSim(machine, FS_HZ, seed=11).advance(pos, vel, full)
    est.reset(FS_HZ)
    cur, spd = res["current_cmd"], res["speed"]
    cnc = {f"{axis}/current_cmd": cur, f"{axis}/motor_speed": spd}
    if harmonics:
        cnc[SPINDLE_SPEED_CMD] = np.full(len(cur), rpm * 2 * np.pi / 60)
    load_est = stream_estimate(est, cnc, f"{axis}/load_est")
    load_est = load_est[lead + est.lag : lead + est.lag + len(load)]
    h = multisine_frf(load, load_est, FS_HZ, per, skip_periods=1)
    f = h.freq_hz
    db = 20 * np.log10(np.abs(h.h1))
    lines = np.array(tooth_harmonics(rpm / 60 * V1_TEETH))
    on = np.isin(np.round(f, 6), np.round(lines, 6))
    sel = f <= 180.0
    return {
        "worst_db": float(np.max(np.abs(db[sel]))),
        "worst_db_off_lines": float(np.max(np.abs(db[sel & ~on]))),
        "band_hz": bandwidth_3db(np.concatenate([[0.0], f]), np.concatenate([[1.0], h.h1])),
        "at_lines": float(np.max(np.abs(h.h1[on] - 1))) if np.any(on) else float("nan"),
    }
