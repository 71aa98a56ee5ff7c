"""Validation of the disturbance observers of seed 001 (Yamada 2017).

1. With exact parameters the MEDOB's F̂/F equals its output low-pass (Yamada §2.3, Eq.
   2-20/2-21): analytic (continuous plant, ideal differentiation, 4th-order Butterworth) and
   time-domain (the machine file's dual-inertia plant, Eq. 2-1/2-2, swept by a 20 N chirp
   load, proportional damping, no quantisation or dead time; F̂ against L(z)·F sample by
   sample and as an FRF). These are code checks: observer and plant share the exact
   parameters of the simulator's yamada-b file *by design* (they test the discrete
   observer's algebra, not an estimate of an unknown machine).
2. Table 4-7 on ``yamada-b``: error standard deviation of the MEDOB (with and without
   phase-lag compensation, with 0.5/1.5 M_tn, with and without notches) and of the thrust
   force, beside the thesis's.
3. Table 4-5: predictive notch frequencies.

Scenario for Table 4-7 (docs/decisions/0071-table-4-7-scenario-seed-001.md): Al A5052 with the
coefficients of Yamada Table 4-2 (K_tc, K_rc, K_ac = 1800, 820, 170 N/mm², no edge terms),
Ø6 mm 2-flute end mill, zero helix, down milling with radial depth r (slot for condition
<2>), force from :func:`millsense.process.forces.milling_forces` along the feed on the table.

Truth apart from belief (issue 12, decision 1705). The plant the observers are judged on is the
yamada-b truth (:func:`~millsense.simulator.machine_file.simulated_feed_drive`): a coupled
motor–screw–nut–table–bed drive fitted to Table 3-3 and §3.4 (408 Hz axial, 778.5 Hz screw
torsion, 1598 Hz bed modes of the servo-off structure; screw stiffness with the nut position),
a static table load reaching the motor as (R/η)·F (decision 0971), LuGre friction with a
Stribeck hump (5 % higher Coulomb and static levels in the cut than in the idling runs), the
§3.6 position-periodic disturbances, a PI current loop on the motor electrics, dead times,
encoder quantisation and a white current noise of 16 mA RMS (``current_noise_a`` of
``simulator/data/yamada-b-truth.toml``). The observers know only the nameplate (K_t, lead,
current-loop bandwidth) and what ``identify drive`` finds on the truth's commissioning drive
sweep (Yamada C11): J_r, M_t, D_r, C_t, K_r, C_k and T_s, T_m, T_t (:func:`_belief`), and the
frequency of the unmodelled mode the fixed notch removes (:func:`torsion_notch_hz`). The
thesis gives no noise level: 16 mA is the one amplitude chosen from its results — on the old
plant it made the "compensated disturbance" column of condition <1> 2.1 N against the thesis's
2.0 N; on the truth, unchanged, 2.11 N — so that column is a calibration, not a validation;
every other figure is predicted with it unchanged. The estimate is idle-compensated with a
table from 3 idling runs at the same feed (different noise seeds); errors are against the true
load through the same output filter L(z), delayed by the truth's motor-encoder dead time (the
lag of the plant's own measurement, which the judge reads from the truth; the estimator's
identified dead time is not used, decision 1790), over the steady cut.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import cache
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from millsense.validation import Calibration, Measured, case

if TYPE_CHECKING:
    from millsense.core.config import FeedAxisConfig
    from millsense.estimation.dob.observers import DriveParameters
    from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim

FS_B = 10000.0
CUTOFF_B = 500.0  # Table 4-3: 4th-order Butterworth 500 Hz
DURATION_S = 0.8
CUT_START_S = 0.3
SETTLE_S = 0.02


@dataclasses.dataclass(frozen=True)
class Condition:
    """One column of Yamada Table 4-7."""

    label: str
    spindle_rpm: float
    axial_mm: float
    radial_mm: float
    slot: bool
    feed_mm_s: float


CONDITIONS = {
    1: Condition("<1>", 2000.0, 0.5, 0.5, False, 2.0),
    2: Condition("<2>", 10000.0, 0.5, 6.0, True, 8.0),
    4: Condition("<4>", 1000.0, 0.3, 1.5, False, 1.0),
    5: Condition("<5>", 10000.0, 2.0, 1.5, False, 10.0),
}
# Table 4-7 (N): MEDOB with everything, without phase-lag comp., 0.5/1.5 M_tn, without notch,
# thrust force
THESIS = {
    1: {"medob": 5.7, "no_sync": 8.2, "m05": 5.4, "m15": 6.4, "thrust": 10.4},
    2: {"medob": 11.4, "m05": 11.3, "m15": 19.2, "thrust": 17.4},
    4: {"medob": 2.5, "no_notch": 3.3, "thrust": 3.7},
    5: {"medob": 5.7, "no_notch": 11.8, "thrust": 21.7},
}


def _axis() -> FeedAxisConfig:
    """The simulated stage (the virtual machine's yamada-b): drives the plant only."""
    from millsense.simulator.machine_file import simulator_machine

    return simulator_machine("yamada-b").axis("x")


@cache
def _belief() -> FeedAxisConfig:
    """What the estimators are given (issue 12, decision 0993): the yamada-b nameplate (K_t,
    lead, current-loop bandwidth) merged with ``identify drive`` on a simulated drive sweep
    (dead times T_s, T_m, T_t; :func:`millsense.bench.pipeline.identified_ball_screw_machine`)."""
    from millsense.bench.pipeline import identified_ball_screw_machine

    return identified_ball_screw_machine("yamada-b").machine.axis("x")


@cache
def _truth_substeps() -> int:
    from millsense.simulator.truth_machine import load_truth

    return load_truth("yamada-b")["x"].substeps


@cache
def _drive(friction_factor: float = 1.0) -> FeedDriveParams:
    """The plant the observers are judged on: the yamada-b truth (decision 1705; coupled
    motor–screw–nut–table–bed drive fitted to Table 3-3 and §3.4, LuGre friction, §3.6
    periodic disturbances, PI current loop on the motor electrics, dead times, 16 mA current
    noise), with its Coulomb and static friction scaled by ``friction_factor`` (the cut's
    +5 %)."""
    from millsense.models.lugre import LuGre
    from millsense.simulator.machine_file import simulated_feed_drive

    fp = simulated_feed_drive("yamada-b", "x")
    fr = fp.friction
    assert isinstance(fr, LuGre)
    scale = lambda v: (v[0] * friction_factor, v[1] * friction_factor)  # noqa: E731
    fr2 = dataclasses.replace(fr, coulomb=scale(fr.coulomb), static=scale(fr.static))
    return dataclasses.replace(fp, friction=fr2)


def _reference_lag_samples() -> int:
    """Samples by which the reference (the true load through L(z)) is delayed before it is
    compared with an estimate: the TRUTH's motor-encoder dead time (issue 12, decision 1790).

    An observer fed by the encoder cannot see the load before the encoder does; that lag is the
    plant's, known to the judge from the truth, and owed by no estimator. The estimator's own
    identified dead time (:func:`_belief`) is not used here: an error in it is the estimator's,
    and the comparison charges it."""
    return round(_drive().dead_time_motor_encoder_s * FS_B)


def _sim(fp: FeedDriveParams, seed: int) -> FeedDriveSim:
    from millsense.simulator.feed_drive import FeedDriveSim

    return FeedDriveSim(fp, FS_B, substeps=_truth_substeps(), seed=seed)


def _delays(compensate: bool) -> tuple[float, float, float]:
    from millsense.estimation.dob.phase_lag import sync_delays

    if not compensate:
        return (0.0, 0.0, 0.0)
    ax = _belief()
    return sync_delays(
        ax.dead_time_amplifier_ms * 1e-3,
        ax.dead_time_motor_encoder_ms * 1e-3,
        ax.dead_time_scale_ms * 1e-3,
    )


def _trajectory(feed_m_s: float, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    t = np.arange(n) / FS_B
    ta = 0.05
    vel = np.where(t < ta, feed_m_s * t / ta, feed_m_s)
    pos = np.where(t < ta, 0.5 * feed_m_s * t**2 / ta, 0.5 * feed_m_s * ta + feed_m_s * (t - ta))
    return pos, vel


@cache
def _identified() -> DriveParameters:
    """The observers' drive parameters: J_r, M_t, D_r, C_t, K_r, C_k of ``identify drive``
    (Yamada C11, the dual-inertia FRF fit of :func:`millsense.ident.drive.fit_dual_inertia`)
    on the commissioning drive sweep of the truth, merged onto the nameplate (K_t, lead):
    :func:`_belief`. Nothing comes from the truth's parameter objects (decision 1705).

    The time-domain identification (:func:`~millsense.estimation.dob.observers
    .identify_drive_parameters`) that the cases used on the old plant is not used: on the
    truth's chirp sweep with the identified delays (T_2 = 0.093 ms, a fraction of a sample)
    it gave M_r 1.5 kg and C_t < 0 (measured 2026-11-28, decision 1705)."""
    from millsense.estimation.dob.observers import DriveParameters

    return DriveParameters.from_axis_config(_belief())


#: The observer's design choice (Yamada Table 4-5 notches k = 1..4 of the encoder period): which
#: harmonics of the encoder interpolation error the notch bank removes. Not read from the truth.
NOTCH_HARMONICS = (1, 2, 3, 4)


@cache
def encoder_wavelength_m() -> float:
    """Travel per encoder signal period, lead / line count (Yamada §2.8, λ = ℓ/512), from the
    yamada-b nameplate the estimator starts from (``encoder_signal_periods_rev``, Table 3-2;
    the same values :func:`_belief` carries), not from the truth's periodic disturbances
    (issue 12)."""
    from millsense.core.config import MachineConfig
    from millsense.core.errors import ConfigError
    from millsense.core.presets import load_preset

    ax = load_preset(MachineConfig, "yamada-b").axis("x")
    if ax.encoder_signal_periods_rev is None or ax.lead_mm_rev is None:
        raise ConfigError("yamada-b nameplate: encoder_signal_periods_rev and lead_mm_rev needed")
    return ax.lead_mm_rev * 1e-3 / ax.encoder_signal_periods_rev


@cache
def torsion_notch_hz() -> float:
    """The mode the fixed notch removes, found as Yamada found the screw torsion (§3.4: a
    sharp peak above the axial resonance): :func:`~millsense.ident.drive
    .first_unmodelled_mode_hz` on the FRFs of the commissioning drive sweep that ``identify
    drive`` uses (:func:`_belief`)."""
    from millsense.core.errors import InputDataError
    from millsense.ident import drive as ident_drive
    from millsense.simulator import commissioning as com
    from millsense.simulator.machine_file import simulator_machine

    rec = com.drive_sweep(simulator_machine("yamada-b"), "x")
    fs = rec.sample_rate_hz
    per = int(rec.metadata["period_samples"])  # type: ignore[call-overload]
    r, u = rec["x/injection"], rec["x/current_cmd"]
    hm = ident_drive.reference_frf(r, u, rec["x/angle"], fs, per, detrend=True)
    ht = ident_drive.reference_frf(r, u, rec["x/scale"], fs, per, detrend=True)
    lead = (_belief().lead_mm_rev or 0.0) * 1e-3
    f = ident_drive.first_unmodelled_mode_hz(hm, ht, lead, min(1000.0, 0.45 * fs))
    if f is None:
        raise InputDataError("yamada-b drive sweep: no torsional mode above the axial one")
    return f


@cache
def _cutting_load(c: Condition) -> NDArray[np.float64]:
    """Load resisting the table motion (N) per sample: −(force on the table along +X)."""
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    n = int(DURATION_S * FS_B)
    t = np.arange(n) / FS_B
    tool = EndMill(6e-3, 2)
    coeffs = CuttingCoefficients(1800e6, 820e6, 170e6)
    eng = Engagement.slot() if c.slot else Engagement.radial(c.radial_mm * 1e-3, 6e-3, "down")
    fz = c.feed_mm_s * 1e-3 / (2.0 * c.spindle_rpm / 60.0)
    load = np.zeros(n)
    sel = t >= CUT_START_S
    f = milling_forces(
        tool, coeffs, eng, fz, c.axial_mm * 1e-3, 2.0 * np.pi * c.spindle_rpm / 60.0 * t[sel], 1
    )
    load[sel] = -f.fx_n  # table force along +X = tool force along the feed (slot_cut.py)
    return load


@cache
def _run(c: Condition, cut: bool, seed: int) -> dict[str, NDArray[np.float64]]:
    fp = _drive(1.05 if cut else 1.0)
    n = int(DURATION_S * FS_B)
    pos, vel = _trajectory(c.feed_mm_s * 1e-3, n)
    load = _cutting_load(c) if cut else np.zeros(n)
    r = fp.transmission
    out = _sim(fp, seed).advance(pos / r, vel / r, load)
    out["load"] = load
    return out


def idle_table_from_runs(
    positions: list[NDArray[np.float64]], forces: list[NDArray[np.float64]], bin_m: float = 0.2e-6
) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """Position-indexed disturbance table (Yamada §2.9): mean of the idling runs' estimates in
    bins of ``bin_m`` of table position, linearly interpolated (held beyond the ends).

    A minimal stand-in for ``millsense.ident.idle_table`` (another work item); the observers
    need only the callable.
    """
    x = np.concatenate(positions)
    f = np.concatenate(forces)
    edges = np.arange(x.min(), x.max() + bin_m, bin_m)
    idx = np.clip(np.digitize(x, edges) - 1, 0, len(edges) - 1)
    cnt = np.bincount(idx, minlength=len(edges))
    ok = cnt > 0
    xm = (np.bincount(idx, weights=x, minlength=len(edges))[ok]) / cnt[ok]
    fm = (np.bincount(idx, weights=f, minlength=len(edges))[ok]) / cnt[ok]

    def table(pos: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(np.interp(pos, xm, fm), dtype=float)

    return table


def _estimate(
    kind: str,
    c: Condition,
    out: dict[str, NDArray[np.float64]],
    *,
    sync: bool,
    mass: float,
    notch: bool,
) -> NDArray[np.float64]:
    from millsense.estimation.dob.notch import NotchBank, NotchBankSpec
    from millsense.estimation.dob.observers import medob_observer, with_table_mass

    p = with_table_mass(_identified(), mass)
    r = p.transmission_m_rad
    obs = medob_observer(
        p,
        FS_B,
        cutoff_hz=CUTOFF_B,
        delays_s=_delays(sync),
        current_loop_hz=_belief().current_bandwidth_hz,
    )
    if kind == "medob":
        est = obs.process(out["current_cmd"], [r * out["angle"], out["scale"]])
    else:  # thrust force K_t I/R through the same output filter, delayed by T_1 as the MEDOB's
        from millsense.estimation.dob.phase_lag import StreamingDelay

        cur = StreamingDelay(_delays(sync)[0] * FS_B).process(out["current_cmd"])
        est = obs.output_filter(p.force_constant_n_a * cur)
    if notch:
        spec = NotchBankSpec(
            wavelength_m=encoder_wavelength_m(),
            harmonics=NOTCH_HARMONICS,
            fixed_hz=(torsion_notch_hz(),),
            bandwidth_hz=20.0,
            max_hz=1300.0,
        )
        est = NotchBank(spec, FS_B).process(est, r * out["angle"])
    return est


@cache
def table47(
    key: int, kind: str = "medob", sync: bool = True, mass: float = 1.0, notch: bool = True
) -> tuple[float, float]:
    """(error std, compensated-disturbance std) in N for one Table 4-7 entry."""
    from millsense.estimation.dob.phase_lag import StreamingDelay  # noqa: F401

    c = CONDITIONS[key]
    idles = [_run(c, False, s) for s in (1, 2, 3)]
    kw = {"sync": sync, "mass": mass, "notch": notch}
    idle_est = [_estimate(kind, c, o, **kw) for o in idles]  # type: ignore[arg-type]
    table = idle_table_from_runs([o["scale"] for o in idles], idle_est)
    cut = _run(c, True, 7)
    est = _estimate(kind, c, cut, **kw) - table(cut["scale"])  # type: ignore[arg-type]
    from millsense.estimation.dob.observers import medob_observer

    ref_obs = medob_observer(_identified(), FS_B, cutoff_hz=CUTOFF_B)
    ref = ref_obs.output_filter(cut["load"])
    lag = _reference_lag_samples()
    ref = np.concatenate([np.full(lag, ref[0]), ref[: len(ref) - lag]])
    w = slice(int((CUT_START_S + SETTLE_S) * FS_B), len(ref))
    err = est[w] - ref[w]
    # compensated disturbance: a 4th idling run minus the table (non-repeatable residue)
    extra = _run(c, False, 4)
    dist = _estimate(kind, c, extra, **kw) - table(extra["scale"])  # type: ignore[arg-type]
    return float(np.std(err)), float(np.std(dist[w]))


# ---------------------------------------------------------------- 1. MEDOB FRF = low-pass


def medob_frf_analytic_deviation() -> float:
    """max over 1 Hz–2 kHz of |F̂/F ÷ Q − 1| and |F̂/I|·R/K_t, continuous, exact parameters."""
    from millsense.estimation.dob.observers import (
        DriveParameters,
        butterworth_analog,
        medob_model,
        rigid_sum_frf,
    )
    from millsense.models.ball_screw import plant_from_config

    ax = _axis()
    p = DriveParameters.from_axis_config(ax)
    f = np.linspace(1.0, 2000.0, 2000)
    q = butterworth_analog(4, CUTOFF_B)
    hf, hi = rigid_sum_frf(
        plant_from_config(ax),
        medob_model(p),
        [0, 1],
        f,
        torque_constant_nm_a=p.torque_constant_nm_a,
        transmission_m_rad=p.transmission_m_rad,
        lowpass=q,
    )
    qs = q(np.asarray(2j * np.pi * f, dtype=np.complex128))
    return float(max(np.max(np.abs(hf / qs - 1.0)), np.max(np.abs(hi / qs)) / p.force_constant_n_a))


def medob_sweep_records() -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    """(load, estimate, L(z)·load, frequencies of the FRF) of the exact-parameter sweep.

    Plant: the preset's dual inertia with proportional damping (α_c = C_t/M_t for both bodies,
    Yamada Eq. 2-29), ideal current loop, no friction, periodic terms, dead times or
    quantisation (2⁵⁰ counts/rev); closed loop holding position; load: 20 N logarithmic chirp
    1 Hz–1 kHz over 1 s, then 0.2 s of rest so that the record holds the whole response.
    """
    from scipy import signal

    from millsense.estimation.dob.observers import DriveParameters, medob_observer
    from millsense.models.ball_screw import dual_inertia_plant
    from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim

    ax = _axis()
    p0 = DriveParameters.from_axis_config(ax)
    ac = p0.table_damping_n_s_m / p0.table_mass_kg
    p = dataclasses.replace(p0, rotary_damping_nm_s_rad=ac * p0.rotor_inertia_kg_m2)
    plant = dual_inertia_plant(
        p.rotor_inertia_kg_m2,
        p.lead_m,
        p.table_mass_kg,
        p.axial_stiffness_n_m,
        p.axial_damping_n_s_m,
        p.table_damping_n_s_m,
        p.rotary_damping_nm_s_rad,
    )
    fp = dataclasses.replace(
        FeedDriveParams.from_config(ax, friction="none", periodic=False),
        plant=plant,
        current_bandwidth_hz=1e12,
        encoder_counts_rev=2**50,
        scale_resolution_m=None,
        dead_time_amplifier_s=0.0,
        dead_time_motor_encoder_s=0.0,
        dead_time_scale_s=0.0,
        torque_noise_nm=0.0,
    )
    n1, n2 = int(FS_B), int(0.2 * FS_B)
    t = np.arange(n1) / FS_B
    load = np.zeros(n1 + n2)
    load[:n1] = 20.0 * signal.chirp(t, 1.0, t[-1], 1000.0, method="logarithmic")
    out = FeedDriveSim(fp, FS_B).advance(np.zeros(n1 + n2), np.zeros(n1 + n2), load)
    obs = medob_observer(p, FS_B, cutoff_hz=CUTOFF_B)
    r = p.transmission_m_rad
    est = obs.process(out["current_cmd"], [r * out["angle"], out["scale"]])
    fr = np.asarray(np.fft.rfftfreq(n1 + n2, 1.0 / FS_B), dtype=np.float64)
    return load, est, obs.output_filter(load), fr


def medob_sweep_deviation() -> tuple[float, float]:
    """(time-domain max |F̂ − L·F| / max |L·F|, FRF max |Ĥ/L − 1| over 5–900 Hz)."""
    load, est, ref, fr = medob_sweep_records()
    td = float(np.max(np.abs(est - ref)) / np.max(np.abs(ref)))
    sel = (fr >= 5.0) & (fr <= 900.0)
    # the record ends at rest, so the DFT ratio is the FRF exactly (linear convolution)
    h = np.fft.rfft(est)[sel] / np.fft.rfft(load)[sel]
    lz = _sweep_output_filter_frf(fr[sel])
    return td, float(np.max(np.abs(h / lz - 1.0)))


def _sweep_output_filter_frf(f: NDArray[np.float64]) -> NDArray[np.complex128]:
    from millsense.estimation.dob.observers import DriveParameters, medob_observer

    p0 = DriveParameters.from_axis_config(_axis())
    ac = p0.table_damping_n_s_m / p0.table_mass_kg
    p = dataclasses.replace(p0, rotary_damping_nm_s_rad=ac * p0.rotor_inertia_kg_m2)
    return medob_observer(p, FS_B, cutoff_hz=CUTOFF_B).output_filter_frf(f)


@case(
    "estimation.dob.medob_frf_equals_lpf_analytic",
    self_check=True,  # plant = observer model by design (decision 1790)
    source="Yamada (2017) §2.3, Eq. 2-20/2-21 (digest: F̂/F = LPF exactly)",
    reference=0.0,
    unit="relative",
    abs_tol=1e-9,
    quick=True,
    description="Code check, exact parameters by design: MEDOB with the simulator file's yamada-b "
    "parameters, max |F̂/F ÷ Q − 1| and |F̂/I| (1 Hz-2 kHz)",
)
def _medob_analytic() -> float:
    return medob_frf_analytic_deviation()


@case(
    "estimation.dob.medob_frf_equals_lpf_sweep",
    self_check=True,  # plant = observer model by design (decision 1790)
    source="Yamada (2017) §2.3 (time-domain check of the discrete MEDOB, "
    "docs/decisions/0067-exact-discrete-medob-seed-001-observers.md)",
    reference=0.0,
    unit="relative",
    abs_tol=1e-9,
    quick=True,
    description="Code check, exact parameters by design: simulated 20 N chirp on the simulator "
    "file's dual-inertia plant, max of the time-domain and FRF deviations of F̂ from L(z)·F",
)
def _medob_sweep() -> Measured:
    td, fd = medob_sweep_deviation()
    return Measured(
        max(td, fd),
        f"time domain max |F̂ − L·F|/max|L·F| = {td:.2e}; FRF (5-900 Hz) max |Ĥ/L − 1| = {fd:.2e}",
    )


# ---------------------------------------------------------------- 2. Table 4-7


def table47_summary(key: int) -> dict[str, float]:
    """Every Table 4-7 row of one condition, N (notches only where the thesis used them)."""
    notch = key in (4, 5)
    out = {
        "medob": table47(key, notch=notch)[0],
        "disturbance": table47(key, notch=notch)[1],
        "no_sync": table47(key, sync=False, notch=notch)[0],
        "m05": table47(key, mass=0.5, notch=notch)[0],
        "m15": table47(key, mass=1.5, notch=notch)[0],
        "no_notch": table47(key, notch=False)[0],
        "thrust": table47(key, kind="thrust", notch=False)[0],
    }
    return out


def _table47_markdown() -> str:
    rows = [
        "| Condition | MEDOB | no phase-lag comp. | 0.5 M_tn | 1.5 M_tn | no notch | thrust | "
        "compensated disturbance |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key, c in CONDITIONS.items():
        s = table47_summary(key)
        th = THESIS[key]

        def cell(name: str, _s: dict[str, float] = s, _th: dict[str, float] = th) -> str:
            ref = _th.get(name)
            return f"{_s[name]:.2f}" + (f" ({ref})" if ref is not None else "")

        rows.append(
            f"| {c.label} {c.spindle_rpm:g} min⁻¹, a {c.axial_mm} r {c.radial_mm} mm, "
            f"{'slot' if c.slot else 'down'}, {c.feed_mm_s} mm/s | {cell('medob')} | "
            f"{cell('no_sync')} | {cell('m05')} | {cell('m15')} | {cell('no_notch')} | "
            f"{cell('thrust')} | {s['disturbance']:.2f} |"
        )
    p = _identified()
    rows.append("")
    rows.append(
        "Error standard deviations in N, millsense (thesis Table 4-7 in brackets). Identified "
        f"parameters: M_r {p.rotor_mass_kg:.1f} kg, M_t {p.table_mass_kg:.2f} kg, C_r "
        f"{p.rotor_damping_n_s_m:.0f} N·s/m, C_t {p.table_damping_n_s_m:.0f} N·s/m, K_r "
        f"{p.axial_stiffness_n_m / 1e6:.1f} N/µm from identify drive on the truth (Table 3-3: "
        f"82.1, 6.6, 10264, 820, 40.5); notch on the unmodelled mode found at "
        f"{torsion_notch_hz():.1f} Hz. "
        "Mismatch: the coupled truth (torsion, bed, η), friction +5 % in the cut, periodic "
        "disturbances, quantisation, dead times, 16 mA current noise (module docstring)."
    )
    return "\n".join(rows)


#: The one calibrated parameter of Table 4-7 (module docstring): the current-noise amplitude,
#: fitted on the "compensated disturbance" column of condition <1> (2.0 N in the thesis).
NOISE_CALIBRATION = Calibration(
    "current noise 16 mA RMS per sample (yamada-b Table 4-7 scenario)",
    ("estimation.dob.table47_c1_disturbance",),
    "the one amplitude that makes the compensated-disturbance column of condition <1> come out "
    "at the thesis's 2.0 N (the thesis gives no noise level); fitted on the old plant (2.1 N), "
    "kept unchanged on the yamada-b truth (2.11 N, decision 1705)",
)
#: Two-sided tolerance around each thesis value (Table 4-7 is one measurement per condition,
#: no spread given: ±50 %), and the realism flag: an error std below half the thesis's says the
#: simulated mismatch is more benign than the real machine (issue 12).
TABLE47_REL_TOL = 0.5
TABLE47_TOO_GOOD = 2.0


#: Measured reasons of the Table 4-7 figures the truth does not reproduce (decision 1705).
TABLE47_GAPS = {
    5: "on the yamada-b truth the error (14.3 N std) is the 333 Hz tooth line (measured with "
    "the identification before decision 1790: 11.5 of 12.0 N RMS in 300-370 Hz, the estimate "
    "1.76× the force at 38°): there, at 0.82 of the 408 Hz axial mode, the rigid sum "
    "amplifies the identified table mass's error (identify drive on the nameplate-designed "
    "sweep: 4.67 kg against the truth's 6.6 kg, 6.9 kg reflected through η = 0.95)",
}


def _make_table47_case(key: int) -> None:
    c = CONDITIONS[key]
    ref = THESIS[key]["medob"]

    @case(
        f"estimation.dob.table47_c{key}",
        source=f"Yamada (2017) Table 4-7 condition {c.label}: {ref} N",
        reference=ref,
        unit="N",
        rel_tol=TABLE47_REL_TOL,
        too_good_factor=TABLE47_TOO_GOOD,
        quick=False,
        calibration=NOISE_CALIBRATION,
        ci=key in (2, 4),
        gap=TABLE47_GAPS.get(key, ""),
        issue=12 if key in TABLE47_GAPS else None,
        description=f"MEDOB error std on yamada-b, condition {c.label}, against the thesis's "
        f"{ref} N (two-sided ±50 %; more than 2× better is flagged as too good)",
    )
    def _c() -> Measured:
        s = table47_summary(key)
        return Measured(s["medob"], _table47_markdown())


for _k in CONDITIONS:
    _make_table47_case(_k)


@case(
    "estimation.dob.table47_c1_disturbance",
    source="Yamada (2017) Table 4-7 condition <1>: compensated disturbance 2.0 N",
    reference=2.0,
    unit="N",
    rel_tol=0.1,
    quick=False,
    calibration=NOISE_CALIBRATION,
    description="Error std of the compensated disturbance, condition <1>: the figure the 16 mA "
    "current noise was fitted on (a calibration, not a validation)",
)
def _c1_disturbance() -> Measured:
    return Measured(table47_summary(1)["disturbance"], _table47_markdown())


@case(
    "estimation.dob.table47_c1_phase_lag_gain",
    source="Yamada (2017) Table 4-7 condition <1>: 8.2 / 5.7 N without / with compensation",
    reference=8.2 / 5.7,
    unit="ratio",
    abs_tol=8.2 / 5.7 - 1.05,
    quick=False,
    calibration=NOISE_CALIBRATION,
    gap="with the drive sweep designed from the nameplate's J and K_t (decision 1790, 4 % more "
    "current than from the simulator file's) identify drive finds M_t 4.67 kg, C_t 0, K_r "
    "32.2 N/µm (before: 5.52 kg, 1471 N·s/m, 37.6 N/µm; truth 6.6 kg, 44.3 N/µm); with that "
    "model the phase-lag compensation lowers the <1> error only from 2.74 to 2.70 N (1.01; "
    "<2> 1.02, <4> 1.01, <5> 1.02). With the identification of before and the same "
    "truth-delayed reference it was 2.54 / 2.39 N (1.06, a pass)",
    issue=12,
    description="Error std without / with phase-lag compensation, condition <1> (≥ 1.05: "
    "measurably worse)",
)
def _c1_sync() -> Measured:
    s = table47_summary(1)
    others = ", ".join(
        f"{CONDITIONS[k].label} {table47_summary(k)['no_sync'] / table47_summary(k)['medob']:.2f}"
        for k in (2, 4, 5)
    )
    return Measured(
        s["no_sync"] / s["medob"],
        f"<1>: {s['no_sync']:.2f} / {s['medob']:.2f} N; ratio in the other conditions: {others}",
    )


# ---------------------------------------------------------------- 3. Table 4-5

# rows: spindle speed min⁻¹ → {harmonic k: notch frequency Hz} (Table 4-5; 9.8/4.9/3.3/2.4 µm
# are k = 1..4 of the 9.77 µm rotary-encoder signal period)
TABLE45 = {
    1000: {2: 204.7, 3: 307.1, 4: 409.4},
    2000: {1: 204.7, 2: 409.4, 3: 614.1},
    3000: {1: 307.1, 2: 614.1},
    4000: {1: 409.4, 2: 818.8},
    5000: {1: 512.1, 2: 1023.5},
    6000: {1: 614.1},
    7000: {1: 716.5},
    8000: {1: 818.8},
    9000: {1: 921.2},
    10000: {1: 1023.5},
    11000: {1: 1125.9},
    12000: {1: 1228.2},
}


@case(
    "estimation.dob.table45_notch_frequencies",
    source="Yamada (2017) Table 4-5, §2.8 (f = k·v/λ, λ = 5 mm/512, v = f_z·z·S/60)",
    reference=0.0,
    unit="relative",
    abs_tol=1e-3,
    quick=True,
    description="Largest relative deviation of the predicted notch frequencies from Table 4-5",
)
def _table45() -> Measured:
    from millsense.estimation.dob.notch import encoder_notch_frequencies

    worst = 0.0
    lines = []
    for s_rpm, cells in TABLE45.items():
        v = 0.030e-3 * 2 * s_rpm / 60.0
        f = encoder_notch_frequencies([v], encoder_wavelength_m(), NOTCH_HARMONICS)[0]
        for k, ref in cells.items():
            dev = abs(f[k - 1] / ref - 1.0)
            worst = max(worst, dev)
            lines.append(f"{s_rpm} min⁻¹ k={k}: {f[k - 1]:.1f} Hz (thesis {ref})")
    return Measured(worst, "; ".join(lines))


# ---------------------------------------------------------------- 4. stationary axis

STATIONARY = ((1000.0, 2.0, 1.5), (4000.0, 2.0, 1.5), (10000.0, 2.0, 0.5))


@cache
def stationary_errors(spindle_rpm: float, axial_mm: float, radial_mm: float) -> dict[str, float]:
    """Cross-feed on the stationary X axis (Yamada §5.4, Table 5-1): mean and std of the error
    of the vibration-mode and rigid-mode (MEDOB) estimates, N.

    X holds its position; the Y axis feeds (f_z = 0.030 mm, down milling) and X carries the
    normal force of the cut. Both estimates are tared on the air interval before the cut (no
    idling test, as in the thesis).
    """
    from millsense.estimation.dob.mode_decoupled import VibrationModeObserver, rigid_mode_observer
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    p = _identified()
    fp = _drive()
    n = int(DURATION_S * FS_B)
    t = np.arange(n) / FS_B
    f = milling_forces(
        EndMill(6e-3, 2),
        CuttingCoefficients(1800e6, 820e6, 170e6),
        Engagement.radial(radial_mm * 1e-3, 6e-3, "down"),
        0.030e-3,
        axial_mm * 1e-3,
        2.0 * np.pi * spindle_rpm / 60.0 * t,
        1,
    )
    load = np.where(t >= CUT_START_S, -f.fy_n, 0.0)
    out = _sim(fp, 11).advance(np.zeros(n), np.zeros(n), load)
    r = p.transmission_m_rad
    d = _delays(True)
    loop = _belief().current_bandwidth_hz
    xm, xt = r * out["angle"], out["scale"]
    vib = VibrationModeObserver(p, FS_B, cutoff_hz=CUTOFF_B, delays_s=d).process(
        out["current_cmd"], xm, xt
    )
    rig = rigid_mode_observer(
        p, FS_B, cutoff_hz=CUTOFF_B, delays_s=d, current_loop_hz=loop
    ).process(out["current_cmd"], [xm, xt])
    ref = rigid_mode_observer(p, FS_B, cutoff_hz=CUTOFF_B).output_filter(load)
    lag = _reference_lag_samples()
    ref = np.concatenate([np.full(lag, ref[0]), ref[: n - lag]])
    w = slice(int((CUT_START_S + SETTLE_S) * FS_B), n)
    air = slice(int(0.1 * FS_B), int(CUT_START_S * FS_B))
    res = {}
    for name, e in (("vib", vib), ("rigid", rig)):
        err = (e - np.mean(e[air]))[w] - ref[w]
        res[f"{name}_mean"] = float(np.mean(err))
        res[f"{name}_std"] = float(np.std(err))
    res["force_std"] = float(np.std(ref[w]))
    return res


@case(
    "estimation.dob.stationary_vibration_mode",
    source="Yamada (2017) §5.4, Fig. 5-31: vibration-mode mean and std of error ≤ ~10 N",
    reference=10.0,
    unit="N",
    rel_tol=0.5,
    too_good_factor=2.0,
    quick=False,
    calibration=NOISE_CALIBRATION,
    ci=True,
    description="Stationary X axis, cross-feed force: worst |mean| or std of the "
    "vibration-mode error over Table 5-1 conditions, against the thesis's ~10 N read from Fig. "
    "5-31 (two-sided ±50 %; below 5 N, more than 2× better, is flagged as too good)",
)
def _stationary() -> Measured:
    worst = 0.0
    lines = []
    for cond in STATIONARY:
        e = stationary_errors(*cond)
        worst = max(worst, abs(e["vib_mean"]), e["vib_std"])
        lines.append(
            f"{cond[0]:g} min⁻¹ a {cond[1]} r {cond[2]}: vibration mode mean {e['vib_mean']:.1f}"
            f" std {e['vib_std']:.1f} N; rigid mode mean {e['rigid_mean']:.1f} std "
            f"{e['rigid_std']:.1f} N; force std {e['force_std']:.1f} N"
        )
    return Measured(worst, "; ".join(lines))
