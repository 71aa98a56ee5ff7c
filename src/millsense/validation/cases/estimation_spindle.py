"""Acceptance of the spindle torque observer on the simulated Quaser spindle (issue 7 item 3).

The observer is identified on the virtual machine's truth spindle
(:mod:`millsense.simulator.truth_spindle`, decision 1210) by
:func:`millsense.bench.spindle_commissioning.identify_spindle` — range 1 at standstill, range 2
at 4000 rev/min, as in the thesis' sweeps (digest P7) — and tuned by Nelder–Mead
(:func:`~millsense.estimation.spindle_observer.tune_spindle_q`); it never sees the truth's
parameters, only I_nom of simulated tests.

Mismatch between the truth and the observer, stated beside every figure: the observer's G_dτ
is a 20-state rational fit of a noisy simulated sweep (white noise of 0.01 A on I_nom, 5 N·m
RMS multisine at the tool changing every CNC sample as a cut's torque does, 12 averaged
periods) read at the velocity-loop rate (decision 1696); the truth is a four-inertia torsional
chain (modes from the mechanics) with R-L electrics, a current PI sampled at 20 kHz with dead
time, an encoder-differenced speed, Coulomb and speed-dependent bearing drag and torque ripple
of the rotor angle (linear only in part); the observer's estimate is new every 0.2 ms and held
over two CNC samples (a line at f passes at |cos(πf·0.1 ms)|, 0.82 at 1.94 kHz); in the V6
replica the speed differs from the identification speed (1000–5500 vs 0/4000 rev/min), the
spindle slows under load, and the resultant force of the simulator is the full mechanistic
model of Al7050 (edge forces, K_rc/K_tc of the material) against the observer's Eq. 5.34
(K_rc = 0.5·K_tc, no edge forces). Before decision 1210 the plant was Aslan's Ch. 5 model
itself (the observer's model class).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from millsense.validation import Measured, case

if TYPE_CHECKING:
    from millsense.core.config import SpindleConfig
    from millsense.estimation.spindle_observer import SpindleIdentification, SpindleTuning
    from millsense.models.friction import CoulombViscous
    from millsense.simulator.truth_spindle import TruthSpindle

FS_HZ = 10_000.0
NOISE_A = 0.01
V6_RPM = (1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 5500.0)
V6_THESIS = (0.15, 0.18, 0.32, 0.19, 0.27, 0.24)


@cache
def plant() -> TruthSpindle:
    """The virtual machine's truth spindle (what the observer is identified and judged on)."""
    from millsense.simulator.truth_spindle import load_truth_spindle

    return load_truth_spindle("quaser-ux600")


@cache
def nameplate_spindle() -> SpindleConfig:
    """The spindle section of the quaser-ux600 nameplate machine file: what the commissioning
    knows of the drive (its velocity-loop period and range switch), not the truth's values."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset

    spindle = load_preset(MachineConfig, "quaser-ux600").spindle
    assert spindle is not None and spindle.velocity_loop_period_ms is not None
    return spindle


@cache
def observers() -> dict[int, tuple[SpindleIdentification, SpindleTuning]]:
    """Identified and tuned observer design per speed range (0: range 1, 1: range 2)."""
    from millsense.bench.spindle_commissioning import identify_spindle
    from millsense.estimation.spindle_observer import tune_spindle_q

    params = plant()
    out: dict[int, tuple[SpindleIdentification, SpindleTuning]] = {}
    for rng, rpm in ((0, 0.0), (1, 4000.0)):
        period = float(nameplate_spindle().velocity_loop_period_ms or 0.0) * 1e-3
        ident = identify_spindle(
            params, velocity_period_s=period, speed_rpm=rpm, sample_rate_hz=FS_HZ,
            current_noise_a=NOISE_A, seed=rng,
        )  # fmt: skip
        out[rng] = (ident, tune_spindle_q(ident.model, ident.r))
    return out


@cache
def friction() -> CoulombViscous:
    """Spindle friction identified through the observers from air runs."""
    from millsense.bench.spindle_commissioning import identify_spindle_friction

    designs = {k: v[1].design for k, v in observers().items()}
    return identify_spindle_friction(plant(), designs,
                                     range_switch_rpm=nameplate_spindle().range_switch_rpm,
                                     sample_rate_hz=FS_HZ, current_noise_a=NOISE_A)  # fmt: skip


@cache
def flatness() -> dict[int, tuple[float, float, float]]:
    """Per range: (worst |dB| of the true compensated FRF 1–2500 Hz, ±3 dB band Hz, states)."""
    from millsense.estimation.kalman.design import bandwidth_3db
    from millsense.estimation.spindle_observer import compensated
    from millsense.simulator.truth_spindle import sampled_disturbance_frf

    out = {}
    for rng, (_, tun) in observers().items():
        # the truth's G_dτ at the velocity-loop rate (range 1 at 0 rev/min; range 2 measured
        # the same way on the range-2 electrics: the mechanics do not depend on the range)
        truth = plant()
        if rng == 1:
            truth = replace(truth, ranges=(truth.ranges[1], truth.ranges[1]))
        f, g = sampled_disturbance_frf(truth, sample_rate_hz=FS_HZ)
        sel = f <= 2500.0
        f, g = f[sel], g[sel]
        h = compensated(g, tun.design, f)
        db = 20 * np.log10(np.abs(h))
        band = bandwidth_3db(np.concatenate([[0.0], f]), np.concatenate([[1.0], h]))
        out[rng] = (float(np.max(np.abs(db))), band, float(tun.design.n_states))
    return out


@case(
    "estimation.spindle_flat_to_2500hz",
    source="seed 000 C11 / Eq. 5.23 (Aslan Fig. 5.x): G_cτ ≈ 1 up to 2500 Hz",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=False,
    gap="on the truth spindle (decision 1210) the Nelder-Mead tuning (SNR > 10 dB) trades "
    "band for noise: R from the air run holds the 2^20-count encoder's quantisation noise and, "
    "at standstill (range 1), the velocity loop's limit cycle on it (R 1.2e-3 A² vs 1e-4 from "
    "the added noise alone), so range 1 is flat to ±3 dB only to 646 Hz (−9.8 dB at 1.5 kHz, "
    "−6.5 dB of it the design's own); range 2 to 1255 Hz, its worst −6.2 dB at 2313 Hz a "
    "narrow feature of the rational fit of the noisy sweep (the design predicts −0.3 dB "
    "there), and 0.73/0.86 at the V5 T4 chatter band 1943/2278 Hz. The truth's G_dτ is the "
    "response to a torque that changes every CNC sample, as a cut's does (decision 1696); to "
    "a torque held over the velocity period the loop is up to 4.3 dB stiffer near 2.3 kHz",
    issue=12,
    description="largest |deviation| from 0 dB over 1-2500 Hz of the true sampled G_dτ "
    "of the truth spindle (velocity loop 0.2 ms, multisine changing every CNC sample, read at "
    "the velocity-loop instants) times the identified, "
    "Nelder-Mead-tuned observer, both speed ranges. Mismatch: 20-state rational fit of a noisy "
    "simulated sweep (0.01 A noise) vs the truth's torsional chain (module notes)",
)
def _flat() -> Measured:
    res = flatness()
    rows = ["| Range | states | worst dB 1-2500 Hz | ±3 dB band [Hz] |", "|---|---|---|---|"]
    for rng, (worst, band, n) in res.items():
        rows.append(f"| {rng + 1} | {n:.0f} | {worst:.2f} | {band:.0f} |")
    return Measured(max(v[0] for v in res.values()), "\n".join(rows))


@cache
def v6_errors() -> list[tuple[float, float, float, float]]:
    """Per V6 speed: (rpm, peak error, mean error, RMS-difference error) of F_res."""
    from millsense.bench.spindle_commissioning import speed_range
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import load_preset
    from millsense.estimation.spindle_observer import SpindleTorqueObserver
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill
    from millsense.simulator.truth_spindle import TruthSpindleSim
    from millsense.streaming.block import Chunk

    params = plant()
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    radius = tool.radius_m
    rng_noise = np.random.default_rng(7)
    out = []
    for rpm in V6_RPM:
        w = rpm * 2 * math.pi / 60
        n_air, n_cut = round(0.6 * FS_HZ), round(0.8 * FS_HZ)
        n = n_air + n_cut
        t = np.arange(n) / FS_HZ
        speed_ref = np.minimum(t / 0.3, 1.0) * w
        angle = np.cumsum(speed_ref) / FS_HZ
        cut = milling_forces(
            tool, coeffs, Engagement.slot(), 0.2e-3, 4e-3, angle[n_air:], n_discs=20
        )
        torque = np.concatenate([np.zeros(n_air), cut.torque_nm])
        res = TruthSpindleSim(params, FS_HZ).advance(speed_ref, torque)
        inom = res["current_cmd"] + rng_noise.normal(0.0, NOISE_A, n)
        _, tun = observers()[speed_range(rpm, nameplate_spindle().range_switch_rpm)]
        fr = friction()
        obs = SpindleTorqueObserver(tun.design, FS_HZ, radius, friction=fr)
        obs.reset(FS_HZ)
        spd = res["speed"]
        parts = [
            obs.process(
                Chunk(
                    s,
                    FS_HZ,
                    0.0,
                    {"spindle/current_cmd": inom[s : s + 100], "spindle/speed": spd[s : s + 100]},
                )
            ).channels["spindle/force_resultant_est"]
            for s in range(0, n, 100)
        ]
        est = np.concatenate(parts)[n_air:]
        true = cut.resultant_n()
        # steady part: skip 0.2 s of entry transient; tooth periods of the nominal speed
        per = round(FS_HZ * 60 / rpm / tool.n_flutes)
        k0 = round(0.2 * FS_HZ)
        k1 = k0 + ((n_cut - k0) // per) * per
        pe = est[k0:k1].reshape(-1, per).max(axis=1).mean()
        pt = true[k0:k1].reshape(-1, per).max(axis=1).mean()
        me, mt = est[k0:k1].mean(), true[k0:k1].mean()
        rms = math.sqrt(float(np.mean((est[k0:k1] - true[k0:k1]) ** 2)) / float(np.mean(true**2)))
        out.append((rpm, abs(pe - pt) / pt, abs(me - mt) / mt, rms))
    return out


@case(
    "estimation.spindle_v6_resultant_force",
    source="seed 000 V6 (Aslan Ch. 5.5.2): errors 15/18/32/19/27/24 % at 1000-5500 rev/min",
    reference=0.32,
    rel_tol=0.5,
    too_good_factor=2.0,
    unit="-",
    quick=False,
    description="largest relative error of the peak resultant force per tooth period (mean over "
    "the steady cut) from the spindle observer, Ø20 mm 2-flute slot 4 mm, 0.2 mm/tooth, Al7050, "
    "1000-5500 rev/min, against the thesis's worst 32 % (two-sided ±50 %; below 16 %, more "
    "than 2× better, is flagged as too good). Mismatch: see the "
    "module (fit of a noisy sweep, 10 kHz plant, speeds off the identification speeds, Eq. 5.34 "
    "vs the full mechanistic force)",
)
def _v6() -> Measured:
    rows = [
        "| rev/min | thesis | peak error | mean error | RMS-difference error |",
        "|---|---|---|---|---|",
    ]
    res = v6_errors()
    for (rpm, pk, mn, rms), th in zip(res, V6_THESIS, strict=True):
        rows.append(f"| {rpm:.0f} | {th:.0%} | {pk:.1%} | {mn:.1%} | {rms:.1%} |")
    return Measured(max(r[1] for r in res), "\n".join(rows))


@case(
    "estimation.spindle_resultant_factor",
    source="seed 000 Eq. 5.34 (Aslan Ch. 5.5.2): F_res ≈ 1.11·F_t",
    reference=1.11,
    unit="-",
    rel_tol=0.01,
    quick=True,
    description="F_res/(τ/r) from the mechanistic model (process.forces) under Eq. 5.34's "
    "assumptions (one flute in cut, no helix, no edge forces, K_rc = 0.5 K_tc): √1.25 = 1.118 "
    "against the printed 1.11",
)
def _factor() -> float:
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    tool = EndMill(diameter_m=0.02, n_flutes=1)
    f = milling_forces(
        tool,
        CuttingCoefficients(ktc=758e6, krc=379e6),
        Engagement.slot(),
        0.2e-3,
        4e-3,
        np.linspace(0.2, 2.9, 10),
        n_discs=4,
    )
    return float(np.mean(f.resultant_n() / (f.torque_nm / tool.radius_m)))
