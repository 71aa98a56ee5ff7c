"""The tool's simulated tap test against the truth (issue 12, decision 1750).

The chatter avoidance's lobes (``control.chatter_avoidance_*``, ``online.chatter_*``, the
demo's chatter pass) come from modes fitted to a simulated tap test of the plant's T1 tool at
rest (:mod:`millsense.simulator.tap_test`, :mod:`millsense.bench.tap_test`). These cases put
the fitted modes beside the table the plant runs (Aslan Tables 5.3-5.4, digest P9: x along the
feed = thesis Y, y = thesis X): each fitted mode against the table's mode of its direction
nearest in frequency; the figure is the worst signed relative error over the six modes.

Tolerances (two-sided: an error of either sign is an error) from what the test adds to the
table, not from the result:

- natural frequency ±0.5 %: the accelerometer's 5 g on the tip lowers each mode by
  m_a/(2 m_r), 0.25 % for the 546 Hz modes (modal mass k/ω² ≈ 1.0 kg), 0.09 % for 1.6 kHz;
  the noise moves them by less than 0.1 % (seeds 0 and 1, ten times the accelerometer noise;
  within 0.2 % on an otherwise perfect test, ``tests/test_tap_test.py``); twice the largest
  bias;
- damping ratio and modal stiffness ±5 %: the bias of the broad 282 Hz y mode (ζ = 5.3 %,
  the lowest and broadest peak in the band) plus twice the noise's part. The holder mode the
  table lacks (3.4 kHz) leaves a residual that varies over the band while the fit's residual
  is a constant; the 282 Hz mode absorbs it: −2.4 % in stiffness, +0.9 % in damping on
  noise-free records (+0.3 % in both without that mode, noise kept; the hammer's misalignment
  with the accelerometer's transverse sensitivity adds 0.2 %). The noise adds up to 1.7 % (damping)
  and 0.4 % (stiffness) at the default levels, where the H1 random error
  √(1 − γ²)/(|γ|√(2 n_d)) (Bendat & Piersol Eq. 9.90) is at most 1.9 % per line in the band
  (γ² ≥ 0.99, 10 hits): 0.9 + 2 × 1.7 and 2.4 + 2 × 0.4 %, rounded up to 5 %.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from millsense.validation import Measured, case

_SRC = (
    "issue 12 / decision 1750: the controller's T1 modes from a simulated tap test (seed 000 "
    "Ch. 4 tap tests, 200-1800 Hz fit) against Aslan Tables 5.3-5.4"
)


@cache
def errors() -> dict[str, Any]:
    """Per fitted mode: direction, fitted and table f [Hz], ζ, k [N/m], relative errors."""
    from millsense.bench.tap_test import tap_test_fits
    from millsense.ident.frf import h1_random_error
    from millsense.validation.cases.control_chatter_avoidance import truth_modes

    truth = truth_modes()
    rows = []
    eps = []
    for fit, d in zip(tap_test_fits(truth), (truth.x, truth.y), strict=True):
        band = fit.frf.band(*fit.fit.band_hz)
        eps.append(float(np.max(h1_random_error(band.coherence, band.n_averages))))
        for m in fit.modes:
            i = int(np.argmin(np.abs(d.natural_hz - m.natural_frequency_hz)))
            f0, z0, k0 = (float(d.natural_hz[i]), float(d.damping_ratio[i]),
                          float(d.stiffness_n_per_m[i]))  # fmt: skip
            rows.append(
                {
                    "dir": fit.direction,
                    "f": m.natural_frequency_hz,
                    "z": m.zeta,
                    "k": m.stiffness,
                    "f0": f0,
                    "z0": z0,
                    "k0": k0,
                    "ef": 100 * (m.natural_frequency_hz / f0 - 1),
                    "ez": 100 * (m.zeta / z0 - 1),
                    "ek": 100 * (m.stiffness / k0 - 1),
                    "coh": float(np.min(band.coherence)),
                }
            )
    return {"rows": rows, "eps": eps}


def _worst(key: str) -> float:
    vals = [r[key] for r in errors()["rows"]]
    return float(max(vals, key=abs))


def _table() -> str:
    e = errors()
    lines = [
        "| dir | f fit / table [Hz] | ζ fit / table [%] | k fit / table [N/m] | "
        "errors f / ζ / k [%] |",
        "|---|---|---|---|---|",
    ]
    for r in e["rows"]:
        lines.append(
            f"| {r['dir']} | {r['f']:.2f} / {r['f0']:.0f} | {100 * r['z']:.3f} / "
            f"{100 * r['z0']:.2f} | {r['k']:.4g} / {r['k0']:.3g} | {r['ef']:+.3f} / "
            f"{r['ez']:+.2f} / {r['ek']:+.2f} |"
        )
    lines.append(
        f"\nlargest H1 random error in the band (Bendat & Piersol Eq. 9.90): x "
        f"{100 * e['eps'][0]:.2f} %, y {100 * e['eps'][1]:.2f} %; modes fitted: {len(e['rows'])}"
    )
    return "\n".join(lines)


@case(
    "ident.tap_test_t1_frequency_error_pct",
    source=_SRC,
    reference=0.0,
    abs_tol=0.5,
    unit="%",
    quick=False,
    description="worst signed natural-frequency error of the six T1 modes fitted to the "
    "simulated tap test, against the plant's table; ±0.5 %: twice the accelerometer's "
    "mass-loading bias (module notes)",
)
def _freq() -> Measured:
    return Measured(_worst("ef"), _table())


@case(
    "ident.tap_test_t1_damping_error_pct",
    source=_SRC,
    reference=0.0,
    abs_tol=5.0,
    unit="%",
    quick=False,
    description="worst signed relative damping-ratio error of the six fitted T1 modes; ±5 %: "
    "the unlisted holder mode's residual and the H1 noise (module notes)",
)
def _damp() -> Measured:
    return Measured(_worst("ez"), _table())


@case(
    "ident.tap_test_t1_stiffness_error_pct",
    source=_SRC,
    reference=0.0,
    abs_tol=5.0,
    unit="%",
    quick=False,
    description="worst signed relative modal-stiffness (ω²/α) error of the six fitted T1 modes; "
    "±5 %: as the damping (module notes)",
)
def _stiff() -> Measured:
    return Measured(_worst("ek"), _table())


@case(
    "ident.tap_test_t1_mode_count",
    source=_SRC,
    reference=6.0,
    abs_tol=0.0,
    unit="modes",
    quick=False,
    description="modes the automatic order selection keeps in 200-1800 Hz over x and y (the "
    "table has three per direction; the holder mode at 3.4 kHz lies outside the band)",
)
def _count() -> Measured:
    return Measured(float(len(errors()["rows"])), _table())
