"""Validation of the spindle drives against Aslan Ch. 5 (Quaser UX600).

Two spindles (decision 1210, issue 12 "spindle likewise"):

- the truth the virtual machine runs (:mod:`millsense.simulator.truth_spindle`): a torsional
  chain with motor electrics, sampled current and velocity loops, an encoder, bearing drag and
  ripple, *tuned to resemble* the thesis's measured figures. The attenuation table and the
  current-loop bandwidths are the figures it was fitted on (status ``calibrated``, two-sided
  ±3 dB / ±10 %, the fit error shown); the closed velocity-loop bandwidth (measured 38 Hz) is
  held out of the fit and judged as a validation;
- Aslan's printed Ch. 5 model (:mod:`millsense.simulator.spindle`, ``--ideal``, the observer's
  model class): the quick cases check its implementation against independent computations;
  its gaps to the stated figures are in decision 0032 and ``tests/test_spindle.py``.
"""

from __future__ import annotations

import math
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from millsense.validation import Calibration, Measured, case

if TYPE_CHECKING:
    from millsense.models.spindle_plant import SpindleDriveParams
    from millsense.simulator.truth_spindle import TruthSpindle

_STATED_ATT = ((457.0, -32.0), (945.0, -39.0), (1380.0, -31.0), (1811.0, -35.0), (2320.0, -29.0))

TRUTH_FIT = Calibration(
    "truth spindle (quaser-ux600-truth*.toml [spindle]): motor inductance per range, three "
    "torsional stiffnesses, three modal damping ratios, the split of J_eS over four inertias",
    (
        *(f"simulator.spindle_attenuation_{int(f)}hz" for f, _ in _STATED_ATT),
        "simulator.spindle_current_bw_range1",
        "simulator.spindle_current_bw_range2",
    ),
    "python -m millsense.simulator.truth_spindle_fit (least squares; decision 1210)",
)

_ATT_GAP = (
    "a chain of inertias under the drive's loops cannot be below the rigid-body loop at "
    "457/945 Hz (the table: −3/−4 dB) and above it at 1380-2320 Hz (+6…+14 dB) with J_eS = "
    "0.0316 kg·m² kept: the least-squares compromise (decision 1210, RMS 3.35 dB, max 4.99 dB) "
    "stays near the rigid level below 1 kHz (+3.5, +5.0 dB) and undershoots the 1380 Hz point "
    "(−4.3 dB); the truth is not tuned further to a validation figure"
)

_VEL_GAP = (
    "the truth keeps Aslan's J_eS = 0.0316 kg·m², K_t within 2 % of Table 5.1 and the Eq. 5.3 "
    "velocity PI per rev/s (decision 0032); with them the rigid loop closes at ≈ 28 Hz, and "
    "the thesis's own figures (J_eS, gains, 38 Hz) do not agree with one another (digest P7 "
    "caveat). Not fitted: decision 1210"
)


def _params() -> SpindleDriveParams:
    from millsense.models.spindle_plant import SpindleDriveParams

    return SpindleDriveParams.aslan_quaser()


@cache
def _truth() -> TruthSpindle:
    from millsense.simulator.truth_spindle import load_truth_spindle

    return load_truth_spindle("quaser-ux600")


def _attenuation_case(f_hz: float, stated_db: float) -> None:
    @case(
        f"simulator.spindle_attenuation_{int(f_hz)}hz",
        source="Aslan Ch. 5.4 text (G_dτ attenuation, range 1, measured)",
        reference=stated_db,
        unit="dB",
        abs_tol=3.0,
        quick=False,
        calibration=TRUTH_FIT,
        gap=_ATT_GAP,
        issue=12,
        description=f"|G_dτ| = |I_nom/τ_d| at {f_hz:g} Hz of the truth spindle (range 1, "
        "0 rev/min, sine torque at the tool, linear part), the figure the truth was tuned to "
        "resemble (two-sided ±3 dB); beside it Aslan's printed Ch. 5 model (--ideal)",
    )
    def _att() -> Measured:
        from millsense.models.spindle_plant import disturbance_frf
        from millsense.simulator.truth_spindle import sine_response

        truth_db = 20 * math.log10(abs(sine_response(_truth().linear(), f_hz, settle_s=0.3)))
        model_db = 20 * math.log10(abs(disturbance_frf(_params(), np.array([f_hz]))[0]))
        return Measured(
            truth_db,
            f"Truth (sine at the tool, kernel) {truth_db:.2f} dB; stated {stated_db:g} dB; "
            f"error {truth_db - stated_db:+.1f} dB. Aslan's printed model (--ideal, "
            f"decision 0032) {model_db:.2f} dB ({model_db - stated_db:+.1f} dB).",
        )


for _f, _db in _STATED_ATT:
    _attenuation_case(_f, _db)


@case(
    "simulator.spindle_current_bw_range1",
    source="Aslan Fig. 5.2a (measured 385 Hz; his simulation 360 Hz)",
    reference=385.0,
    unit="Hz",
    rel_tol=0.1,
    quick=False,
    calibration=TRUTH_FIT,
    description="−3 dB bandwidth of the truth's current loop (drive PI sampled at 20 kHz, one "
    "period of dead time, R-L electrics, rotor held), range 1; Aslan's printed model gives "
    "≈ 280 Hz",
)
def _cur_bw1() -> Measured:
    from millsense.models.spindle_plant import current_loop_bandwidth_hz as ideal_bw
    from millsense.simulator.truth_spindle import current_loop_bandwidth_hz

    v = current_loop_bandwidth_hz(_truth(), 0)
    return Measured(v, f"Truth {v:.1f} Hz; printed model (--ideal) {ideal_bw(_params(), 0):.1f} Hz")


@case(
    "simulator.spindle_current_bw_range2",
    source="Aslan Fig. 5.2b (measured 1190 Hz; his simulation 1240 Hz)",
    reference=1190.0,
    unit="Hz",
    rel_tol=0.1,
    quick=False,
    calibration=TRUTH_FIT,
    description="−3 dB bandwidth of the truth's current loop, range 2; Aslan's printed model "
    "gives ≈ 1584 Hz",
)
def _cur_bw2() -> Measured:
    from millsense.models.spindle_plant import current_loop_bandwidth_hz as ideal_bw
    from millsense.simulator.truth_spindle import current_loop_bandwidth_hz

    v = current_loop_bandwidth_hz(_truth(), 1)
    return Measured(v, f"Truth {v:.1f} Hz; printed model (--ideal) {ideal_bw(_params(), 1):.1f} Hz")


@case(
    "simulator.spindle_velocity_bw_range1",
    source="Aslan Fig. 5.4 (measured 38 Hz; his simulation 34 Hz)",
    reference=38.0,
    unit="Hz",
    rel_tol=0.15,
    quick=False,
    calibration=TRUTH_FIT,
    gap=_VEL_GAP,
    issue=12,
    description="−3 dB bandwidth of the truth's closed velocity loop (encoder speed / "
    "reference, sine responses of the linear part), range 1; held out of the truth's fit "
    "(two-sided ±15 %); Aslan's printed model gives ≈ 91 Hz",
)
def _vel_bw1() -> Measured:
    from millsense.models.spindle_plant import velocity_loop_bandwidth_hz as ideal_bw
    from millsense.simulator.truth_spindle import velocity_loop_bandwidth_hz

    v = velocity_loop_bandwidth_hz(_truth())
    return Measured(v, f"Truth {v:.1f} Hz; printed model (--ideal) {ideal_bw(_params(), 0):.1f} Hz")


@case(
    "simulator.spindle_current_bw_printed_eq58",
    source="seed-000 digest P7 derived caveat: printed Eq. 5.8 gives ≈ 286 Hz",
    reference=286.0,
    unit="Hz",
    rel_tol=0.02,
    quick=True,
    description="−3 dB bandwidth of the printed G_m1 (Eq. 5.8), independent of the model build",
)
def _printed_bw() -> float:
    from millsense.models.spindle_plant import current_loop_bandwidth_hz

    return current_loop_bandwidth_hz(_params(), 0, printed=True)


@case(
    "simulator.spindle_time_vs_discrete_frf",
    source="exact z-domain FRF of the ZOH-discretised loop (independent of the kernel)",
    reference=0.0,
    unit="",
    abs_tol=1e-6,
    quick=True,
    description="max relative error of the simulated sine response I_nom/τ_d vs the exact "
    "discrete FRF at 20, 457, 945, 2320 Hz (velocity loop every sample)",
)
def _time_vs_frf() -> Measured:
    from dataclasses import replace

    from millsense.simulator.spindle import SpindleDriveSim, discrete_disturbance_frf, measured_frf

    p = replace(_params(), velocity_period_s=1e-4)
    sim = SpindleDriveSim(p)
    errs = []
    for f in (20.0, 457.0, 945.0, 2320.0):
        errs.append(abs(measured_frf(p, f) / discrete_disturbance_frf(sim, np.array([f]))[0] - 1.0))
    return Measured(max(errs), "Relative errors: " + ", ".join(f"{e:.1e}" for e in errs))
