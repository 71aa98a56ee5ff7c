"""Validation of the accelerometer estimators (issue 7 item 5).

İlme (seed 003): the 12-test matrix of Table 4.5 replicated in simulation, Y force from the
angular-harmonic Kalman filter against the simulated truth; peak and RMS errors (Table 4.6
definitions, |est − true|/true) must be ≤ 10 % in every test. The estimator uses an FRF from a
simulated impact test (interpolated at the tooth harmonics, no modal fit), R the variance of a
simulated free-state record of each test (spindle in air, no cutting force: the harness's structure,
DAQ filter and accelerometer noise, another realisation than the cut's) plus a persistent model
error of 20 % of the acceleration counted once per record (the FRF varies by up to 25 % along the
pass, İlme §4.1), Q = 1e-3 for all tests, and q_0 from the machine's material preset (Al7050) with
30 % standard deviation. Mismatch of the simulator against the estimator: sliced force model with 2
µm runout (estimator: Eq. 2.38, no runout); residues drifting along the pass by 16/30/10/10 %
(estimator: one FRF tapped mid-pass); 5 % cross accelerance X force → Y acceleration; 0.2 m/s²
accelerometer noise; a 5.6 kHz mode above the harmonic band; cutting coefficients of İlme Table 3.1
(estimator prior: Al7050 preset, K_tc +8 %, K_rc +26 %). The estimator's helix is the tools'
catalogue value (İlme Table 4.4: all 45°, :data:`ILME_TOOL_HELIX_RAD`), not the simulator's
constant.

Aslan Ch. 4 (seed 000 V4 Case 2): quarter immersion at 9000 rev/min, Ø20 mm 2-flute, a = 5 mm, 0.1
mm/tooth, Z load 37 N; fused force error ≤ 8 %. The estimator's filters come from a speed × load
map of simulated tap tests (7500/9000/10500 rev/min × 0/50/100/230/330/430 N), fitted by vector
fitting in Aslan's 200–1800 Hz band, the node nearest to the speed and the PLANNED Z load (the
process model's mean axial force with the Al7050 preset, which has no axial coefficient: 0 N, so
the node 9000 rev/min, 0 N; decision 1790: never the simulated cut's true load); R per sensor is
the variance of the double-integrated acceleration of a simulated air cut (9000 rev/min, no cutting
force, the harness's structure, DAQ filter and noise, another realisation). Mismatch: the true load
is 37 N (node 0 N: dominant mode 964.5 vs 980 Hz); a 2300 Hz mode outside the fitting band; 37 µm
runout; accelerometer noise 0.05 m/s²; tap-test noise. Error = RMS(F̂ − F)/RMS(F) over the steady
cut, both limited to the identified band (the accelerometers carry nothing below the 150 Hz leak of
the double integration; above 1800 Hz the model is not identified, as in Aslan's discussion of the
2500 Hz harmonic). The full-band figure is in the details.
"""

from __future__ import annotations

import math
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from millsense.validation import Calibration, Measured, case

if TYPE_CHECKING:
    from millsense.validation.cases._accel_sim import IlmeTest

ILME_Q = 1e-3
ILME_PRIOR_SD = 0.3
#: Relative persistent model error of the reconstructed acceleration, one value for all tests:
#: İlme §4.1 reports the FRF gain varying by up to 25 % along the pass (decision "İlme filter:
#: persistent model error in R").
ILME_MODEL_ERROR = 0.2
#: ε = 0.2 was picked from a sweep on this very 12-test matrix (decision 0105: 0.05 → 18.8 %,
#: 0.2 → 8.8 % worst peak error), so the İlme figures are calibrations, not validations; the
#: prior alone already gives 4-9 % (issue 12). No held-out İlme case exists yet.
ILME_CALIBRATION = Calibration(
    "İlme persistent model error ε = 0.2 (estimate_harmonic_kf model_error)",
    ("estimation.accel.ilme_worst_peak_error", "estimation.accel.ilme_worst_rms_error"),
    "picked by a sweep of ε on the simulated 12-test matrix (decision 0105)",
)
#: Thesis worst over the 12 tests (seed-003 digest §4.2, Table 4.6): peak 19.8 % (Test 3),
#: RMS 28.6 % (Test 6); its mean: 7.4 % and 8.4 %.
ILME_THESIS_WORST = {"peak": 19.8, "rms": 28.6}
ILME_THESIS_MEAN = {"peak": 7.4, "rms": 8.4}
ILME_SKIP_S = 0.1  # start after the entry transient (İlme cuts the record at a landmark)
#: The tools' helix as catalogued in İlme's thesis (Table 4.4: all tools 45°; Table 2.2 too):
#: the estimator's own tool data, not the simulator's constant (issue 12).
ILME_TOOL_HELIX_RAD = math.radians(45.0)
#: Free-state (air) records: seed and length; a realisation other than the cut's (seed 1).
ILME_AIR_SEED = 101
ILME_AIR_S = 1.0


def _ilme_r(test: IlmeTest) -> float:
    """İlme's R for one test: variance of the Y acceleration of a simulated free-state record
    (the spindle at the test's speed in air, no cutting force), through the harness's
    structure, DAQ filter and accelerometer noise, as a user measures it before the cut."""
    from millsense.validation.cases import _accel_sim as sim

    air = sim.simulate_ilme(test, ILME_AIR_S, seed=ILME_AIR_SEED, cutting=False)
    return float(np.var(air.accel_y))


@cache
def _ilme_table() -> tuple[tuple[int, float, float, float, float, float, float], ...]:
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.accel.harmonic_kf import STATE_SCALE, CutSetup, estimate_harmonic_kf
    from millsense.validation.cases import _accel_sim as sim

    mat = load_preset(MaterialConfig, "al7050")
    prior = np.array([mat.ktc_n_mm2, mat.krc_n_mm2, mat.kte_n_mm, mat.kre_n_mm])
    frf = sim.ilme_frf()
    rows = []
    for test in sim.ILME_TESTS:
        r = _ilme_r(test)
        rec = sim.simulate_ilme(test, 1.0 + ILME_SKIP_S)
        k0 = round(ILME_SKIP_S * rec.sample_rate_hz)
        entry, exit_ = test.immersion_rad
        cut = CutSetup(
            test.n_flutes,
            test.diameter_mm * 1e-3,
            ILME_TOOL_HELIX_RAD,
            test.ap_mm * 1e-3,
            entry,
            exit_,
            test.feed_per_tooth_m,
        )
        res = estimate_harmonic_kf(
            {"y": rec.accel_y[k0:]},
            rec.spindle_angle_rad[k0:],
            rec.sample_rate_hz,
            test.rpm,
            cut,
            {"y": (frf.freq_hz, frf.h1)},
            q=ILME_Q,
            r=r,
            x0=prior * STATE_SCALE,
            p0=np.diag((ILME_PRIOR_SD * prior) ** 2),
            model_error=ILME_MODEL_ERROR,
        )
        n = res.n_used
        window = slice(n // 2, n)  # the converged second half ("a specific time period")
        true = rec.force_y_true[k0 : k0 + n][window]
        est = res.force_y_converged[window]
        pk_t, pk_e = float(true.max()), float(est.max())
        rms_t = float(np.sqrt(np.mean(true**2)))
        rms_e = float(np.sqrt(np.mean(est**2)))
        rows.append(
            (
                test.number,
                pk_t,
                pk_e,
                abs(pk_e - pk_t) / pk_t * 100,
                rms_t,
                rms_e,
                abs(rms_e - rms_t) / rms_t * 100,
            )
        )
    return tuple(rows)


def _ilme_details() -> str:
    rows = _ilme_table()
    mean_pk = float(np.mean([r[3] for r in rows]))
    mean_rms = float(np.mean([r[6] for r in rows]))
    lines = [
        f"Mean over the 12 tests: peak {mean_pk:.1f} % (thesis {ILME_THESIS_MEAN['peak']} %), "
        f"RMS {mean_rms:.1f} % (thesis {ILME_THESIS_MEAN['rms']} %).",
        "",
        "| Test | Peak true/est [N] | Peak err | RMS true/est [N] | RMS err |",
        "|---|---|---|---|---|",
    ]
    for t, pt, pe, ep, rt, re_, er in rows:
        lines.append(
            f"| {t} | {pt:.1f} / {pe:.1f} | {ep:.1f} % | {rt:.1f} / {re_:.1f} | {er:.1f} % |"
        )
    return "\n".join(lines)


@case(
    "estimation.accel.ilme_worst_peak_error",
    source=f"İlme Table 4.6, seed-003 digest §4.2: worst peak error {ILME_THESIS_WORST['peak']} %",
    reference=ILME_THESIS_WORST["peak"],
    unit="%",
    rel_tol=0.5,
    too_good_factor=2.0,
    quick=False,
    calibration=ILME_CALIBRATION,
    description="İlme 12-test matrix in simulation: worst Y peak-force error of the harmonic KF "
    "against the thesis's worst (two-sided ±50 %, more than 2× better flagged); ε fitted here",
)
def _ilme_peak() -> float | Measured:
    worst = max(r[3] for r in _ilme_table())
    return Measured(worst, _ilme_details())


@case(
    "estimation.accel.ilme_worst_rms_error",
    source=f"İlme Table 4.6, seed-003 digest §4.2: worst rms error {ILME_THESIS_WORST['rms']} %",
    reference=ILME_THESIS_WORST["rms"],
    unit="%",
    rel_tol=0.5,
    too_good_factor=2.0,
    quick=False,
    calibration=ILME_CALIBRATION,
    description="İlme 12-test matrix in simulation: worst Y RMS-force error of the harmonic KF "
    "against the thesis's worst (two-sided ±50 %, more than 2× better flagged); ε fitted here",
)
def _ilme_rms() -> float | Measured:
    worst = max(r[6] for r in _ilme_table())
    return Measured(worst, _ilme_details())


ASLAN_SPEEDS_RPM = (7500.0, 9000.0, 10500.0)
ASLAN_LOADS_N = (0.0, 50.0, 100.0, 230.0, 330.0, 430.0)
ASLAN_HIGHPASS_HZ = 150.0
ASLAN_BAND_HZ = (200.0, 1800.0)
#: The air cut for R: speed of the cut, 1 s, a realisation other than the cut's (seed 5).
ASLAN_AIR_SEED = 21
ASLAN_AIR_S = 1.0
ASLAN_SETTLE_SAMPLES = 2000  # double-integrator start-up left out of the variance


def _aslan_r(speed_rpm: float = 9000.0) -> list[float]:
    """Aslan's R per sensor: variance of the double-integrated acceleration (Aslan's
    displacement channel, 150 Hz leak) of a simulated air cut at ``speed_rpm``: no cutting
    force, the harness's structure, DAQ filter and accelerometer noise."""
    from millsense.estimation.accel.fusion import DoubleIntegrator
    from millsense.validation.cases import _accel_sim as sim

    air = sim.simulate_aslan_cut(
        speed_rpm, 0.0, duration_s=ASLAN_AIR_S, seed=ASLAN_AIR_SEED, cutting=False
    )
    fs = air.sample_rate_hz
    return [
        float(np.var(DoubleIntegrator(fs, ASLAN_HIGHPASS_HZ).process(a)[ASLAN_SETTLE_SAMPLES:]))
        for a in air.accel
    ]


#: The true Z load of the simulated cut, N (Aslan Ch. 4 Case 2): the plant's, never the
#: estimator's (issue 12, decision 1790).
ASLAN_TRUE_LOAD_N = 37.0


def aslan_planned_load_n(speed_rpm: float = 9000.0) -> float:
    """The Z load a real system plans for the Case 2 cut, N: the mean axial force of millsense's
    process model (:func:`~millsense.process.forces.milling_forces`) for the planned cut (Ø20 mm
    2-flute 30° helix catalogue tool, no runout; a = 5 mm, 5 mm radial down, 0.1 mm/tooth) with
    the machine's material preset (Al7050), over one revolution. The map node is chosen with
    this, not with the simulated cut's true load (:data:`ASLAN_TRUE_LOAD_N`)."""
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    mat = load_preset(MaterialConfig, "al7050")
    coeffs = CuttingCoefficients(
        mat.ktc_n_mm2 * 1e6,
        mat.krc_n_mm2 * 1e6,
        mat.kac_n_mm2 * 1e6,
        mat.kte_n_mm * 1e3,
        mat.kre_n_mm * 1e3,
        mat.kae_n_mm * 1e3,
    )
    tool = EndMill(diameter_m=0.020, n_flutes=2, helix_rad=math.radians(30))
    eng = Engagement.radial(5e-3, 0.020, "down")
    phi = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    return abs(float(np.mean(milling_forces(tool, coeffs, eng, 0.1e-3, 5e-3, phi, 60).fz_n)))


@cache
def _aslan_quarter() -> tuple[float, float, tuple[float, ...], str]:
    import scipy.signal

    from millsense.estimation.accel.fusion import (
        DynamicsMap,
        MapNode,
        design_fusion,
        run_fusion,
    )
    from millsense.ident.modal_fit import fit_batch
    from millsense.validation.cases import _accel_sim as sim

    raw = sim.aslan_map(ASLAN_SPEEDS_RPM, ASLAN_LOADS_N)
    jobs = []
    for _, _, frfs in raw:
        for e in frfs:  # accelerance → receptance, then the modal fit
            jobs.append((e.freq_hz, e.h1 / (-((2 * np.pi * e.freq_hz) ** 2))))
    fits = fit_batch(jobs, ASLAN_BAND_HZ, max_modes=8)
    k = 1 + sim.ASLAN_N_SENSORS
    nodes = tuple(
        MapNode(n, load, tuple(fits[k * i + 1 : k * i + k]), fits[k * i])
        for i, (n, load, _) in enumerate(raw)
    )
    planned = aslan_planned_load_n(9000.0)  # what the system knows, not the truth's 37 N
    node = DynamicsMap(nodes).select(9000.0, planned)
    fs = sim.ASLAN_FS_HZ
    r = _aslan_r(9000.0)  # R: a simulated air cut through the harness
    filters = design_fusion(node, fs, 9000.0, r, highpass_hz=ASLAN_HIGHPASS_HZ)
    rec = sim.simulate_aslan_cut(9000.0, ASLAN_TRUE_LOAD_N)
    res = run_fusion(filters, rec.accel)
    # reference: the truth without what the accelerometers cannot see (the leak high-pass)
    wc = 2 * np.pi * ASLAN_HIGHPASS_HZ
    b_hp, a_hp = scipy.signal.bilinear([1.0, 0.0, 0.0], [1.0, 2 * wc, wc * wc], fs)
    ref = scipy.signal.lfilter(b_hp, a_hp, rec.force_true)  # analog s²/(s + ω_hp)²
    band = scipy.signal.butter(6, ASLAN_BAND_HZ[1], fs=fs, output="sos")
    start = round(0.2 * fs)
    stop = ref.size - res.delay_samples

    def err(est: np.ndarray, delay: int, limit: bool) -> float:
        e, t = est, ref
        if limit:
            e, t = scipy.signal.sosfiltfilt(band, est), scipy.signal.sosfiltfilt(band, ref)
        e, t = e[start + delay : stop + delay], t[start:stop]
        return float(np.sqrt(np.mean((e - t) ** 2)) / np.sqrt(np.mean(t**2)) * 100)

    fused_band = err(res.force, res.delay_samples, True)
    fused_full = err(res.force, res.delay_samples, False)
    lag = filters.smoother_lag
    singles = tuple(err(res.force_per_sensor[m], lag, True) for m in range(len(r)))
    singles_full = tuple(err(res.force_per_sensor[m], lag, False) for m in range(len(r)))
    details = (
        f"Node used: {node.speed_rpm:.0f} rev/min, {node.load_n:.0f} N, chosen with the planned "
        f"load {planned:.1f} N (the process model's mean axial force with the Al7050 preset); "
        f"the cut's true load is {ASLAN_TRUE_LOAD_N:.0f} N. "
        f"Fused error in band {fused_band:.1f} %, full band {fused_full:.1f} %. Single sensors "
        "in band "
        + "/".join(f"{v:.1f}" for v in singles)
        + " %, full band "
        + "/".join(f"{v:.1f}" for v in singles_full)
        + " % (Aslan: singles 14/16/15/21/18 %, fused max 8 %)."
    )
    return fused_band, fused_full, singles, details


@case(
    "estimation.accel.aslan_quarter_fused_error",
    source="Aslan Ch. 4 Case 2 (seed-000 digest V4): fused maximum 8 % (singles 14-21 %)",
    reference=8.0,
    unit="%",
    rel_tol=0.5,
    too_good_factor=2.0,
    quick=False,
    description="Aslan Ch. 4 quarter immersion 9000 rev/min: fused force error (fitted band) "
    "against the thesis's 8 % (two-sided ±50 %; below 4 %, more than 2× better, flagged)",
)
def _aslan_fused() -> float | Measured:
    band, _, _, details = _aslan_quarter()
    return Measured(band, details)
