"""Design checks of the Kalman toolkit on Aslan's printed models (seed 000, Table 3.4, Eq. 3.30).

Design check, plant = estimator model by design: every case here evaluates the thesis's
printed estimator (Table 3.4 disturbance path, R and Q of Eq. 3.30) on that same printed model
as the plant, so plant and estimator share every parameter. They check the toolkit
(augmentation, Van Loan discretisation, steady-state gain, compensated FRF) and what the
printed design can reach at best; they are not acceptance figures of an estimator on a
machine (decision 1712). The acceptance of the rotary (and linear) axes' estimates is measured
on the virtual machine's truth, with the estimator built only from nameplate and
identification: ``estimation.feed_rotary_flat_to_120hz``,
``estimation.feed_compensated_band_a`` / ``_c`` and ``estimation.feed_raw_current_band_a`` /
``_c`` (:mod:`millsense.validation.cases.estimation_feed_drive`).

The disturbance path Φ_d = τ_c/τ_a of the C axis is realised from the Table 3.4 modes (ζ as
fractions, digest P5) in 2×2 blocks, augmented with the random-walk disturbance state
(Eq. 3.21–3.23) and given R = 1.4903 (per-sample variance) and Q = 10000 (spectral density of
τ̇_a, discretised by Van Loan at 10 kHz). The compensated FRF τ̂_a/τ_a = Φ_d·Φ_KF and its ±3 dB
band are computed with the model itself as the plant.

The thesis reports 120 Hz for the rotary axes (Fig. 3.8, V3), measured with the *measured*
Φ_d, which carries dynamics above the fitted band the filter does not model; on the model
alone the band is wider
(docs/decisions/0050-c-axis-compensated-bandwidth-against-aslan-s-120-hz.md). The bandwidth case
therefore keeps the thesis's figure as reference and fails honestly. The flatness cases apply
issue 7's rule ("flat within ±3 dB up to 120 Hz") to the printed design on its own model; the
acceptance of that rule on a machine is ``estimation.feed_rotary_flat_to_120hz`` on the truth
(decision 1213).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from millsense.validation import Measured, case

F_GRID_HZ = np.linspace(0.0, 1000.0, 20001)
PRINTED_K_LAST = {"x": 0.6076, "y": 0.9306, "z": 0.656, "a": -0.372, "c": 0.911}


@cache
def _axis_results() -> dict[str, tuple[int, float, float, float]]:
    """Per axis: (augmented states, bandwidth Hz, K_f of the τ_a state, worst |dB| 0-120 Hz)."""
    from millsense.estimation.kalman.design import (
        augment_disturbance,
        bandwidth_3db,
        compensated_frf,
        design_kalman,
    )
    from millsense.validation.cases._thesis_models import aslan_disturbance_model, aslan_r_q

    out = {}
    for axis in ("x", "y", "z", "a", "c"):
        model = aslan_disturbance_model(axis)
        r, q = aslan_r_q(axis)
        design = design_kalman(augment_disturbance(model), q, r, dt=1e-4)
        h = compensated_frf(model, design, F_GRID_HZ)
        band = F_GRID_HZ <= 120.0
        worst = float(np.max(np.abs(20 * np.log10(np.abs(h[band])))))
        out[axis] = (
            design.n_states,
            bandwidth_3db(F_GRID_HZ, h),
            float(design.k_filter[-1, 0]),
            worst,
        )
    return out


def _table() -> str:
    rows = [
        "| Axis | States | ±3 dB band [Hz] | K (τ_a) | printed K [3.31] | worst dB 0-120 Hz |",
        "|---|---|---|---|---|---|",
    ]
    for axis, (n, bw, k, worst) in _axis_results().items():
        rows.append(
            f"| {axis.upper()} | {n} | {bw:.1f} | {k:.4f} | {PRINTED_K_LAST[axis]} | {worst:.2f} |"
        )
    return (
        "\n".join(rows)
        + "\n\nModel-only compensated FRFs (Table 3.4 modes as the plant, R and Q of Eq. 3.30, "
        "Van Loan at 10 kHz). The τ_a entry of the gain is basis independent; the printed "
        "values are matched with Q scaled by 1.86 (X), 1.86 (Y), 1.82 (Z), 2.0 (A), 1.56 (C), "
        "so the thesis's Q convention differs from Eq. 3.28 read literally (digest P4)."
    )


@case(
    "estimation.kalman_c_axis_bandwidth",
    self_check=True,  # plant = estimator model by design (decision 1790)
    source="Aslan (seed 000) Fig. 3.8 / V3: 120 Hz on the rotary axes; Table 3.4, Eq. 3.30",
    reference=120.0,
    unit="Hz",
    rel_tol=0.15,
    quick=False,
    gap="the thesis's 120 Hz is the filter applied to the measured drive FRF, which has "
    "dynamics above the fitted band; with the Table 3.4 model as plant the band is an upper "
    "bound (docs/decisions/0050-c-axis-compensated-bandwidth-against-aslan-s-120-hz.md); the "
    "acceptance of issue 7's rule (flat within ±3 dB to 120 Hz) on a machine is "
    "estimation.feed_rotary_flat_to_120hz, on the truth",
    issue=12,
    description="Design check, plant = estimator model by design (Table 3.4's printed C model "
    "is both; the acceptance on the truth is estimation.feed_compensated_band_c): ±3 dB band "
    "of the C-axis compensated FRF (model as plant, R=1.4903, Q=1e4); expected to exceed the "
    "thesis's measured-FRF figure (see decisions)",
)
def _c_axis_bandwidth() -> Measured:
    return Measured(_axis_results()["c"][1], _table())


@case(
    "estimation.kalman_c_axis_flat_to_120hz",
    self_check=True,  # plant = estimator model by design (decision 1790)
    source="design check of issue 7's rule (Aslan V3: flat within ±3 dB up to 120 Hz on rotary "
    "axes) on the printed model; the acceptance is estimation.feed_rotary_flat_to_120hz",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=True,
    description="Design check, plant = estimator model by design (Table 3.4's printed C model "
    "is both; the acceptance on the truth is estimation.feed_rotary_flat_to_120hz): largest "
    "|20·log10|τ̂_a/τ_a|| of the C-axis compensated FRF over 0-120 Hz",
)
def _c_axis_flat() -> Measured:
    return Measured(_axis_results()["c"][3], _table())


# Every rotary axis judged (issue 12): the A axis on the same rule as C.
@case(
    "estimation.kalman_a_axis_flat_to_120hz",
    self_check=True,  # plant = estimator model by design (decision 1790)
    source="design check of issue 7's rule (Aslan V3: flat within ±3 dB up to 120 Hz on rotary "
    "axes) on the printed model; the acceptance is estimation.feed_rotary_flat_to_120hz",
    reference=0.0,
    unit="dB",
    abs_tol=3.0,
    quick=True,
    gap="with the printed A-axis modes of Table 3.4 (ζ read as fractions, 0.12-0.69, the modes "
    "merge: docs/decisions/0038-aslan-table-3-4-damping-and-static-gain.md) and R, Q of Eq. "
    "3.30 the model-only compensated FRF leaves ±3 dB at about 107 Hz, below the thesis's 120 Hz",
    issue=12,
    description="Design check, plant = estimator model by design (Table 3.4's printed A model "
    "is both; the acceptance on the truth is estimation.feed_rotary_flat_to_120hz): largest "
    "|20·log10|τ̂_a/τ_a|| of the A-axis compensated FRF over 0-120 Hz",
)
def _a_axis_flat() -> Measured:
    return Measured(_axis_results()["a"][3], _table())
