"""Low-immersion validation cases of the robust SDM lobes (Insperger et al. 2003, issue 14).

The Insperger 1-DOF benchmark (benchmarks.md §1) at a/D = 0.1 and 0.05, up and down milling.
There the lowest lobe over 5000–25000 rev/min is a period-doubling (flip) lobe a few tens of
rev/min wide, which ZOA cannot show and a 100 rev/min grid misses.

Reference values [computed] by :func:`converged_minimum`, independently of the robust search:
a brute-force loop over ``sdm.analyse`` (one depth at a time, 2 % geometric grid from 0.3× the
depth, then Brent) at m = 100 and m = 200 steps, Richardson-extrapolated (O(m⁻²)),
minimised over speed (bounded, 0.5 rev/min) within ±6 rev/min of the chart's refined minimum:

| a/D, mode | speed [rev/min] | converged depth [mm] | m = 100 | m = 200 |
|---|---|---|---|---|
| 0.1 down | 18 129 | 0.74152 | 0.74473 | 0.74232 |
| 0.1 up | 18 763 | 0.62407 | 0.62807 | 0.62507 |
| 0.05 down | 18 190 | 1.07752 | 1.08145 | 1.07850 |
| 0.05 up | 18 691 | 0.94777 | 0.95251 | 0.94895 |

The measured value is the default chart (5000–25000 rev/min every 100 rev/min, m = 20,
10 steps per chatter cycle, adaptive Richardson, minima refined to 1 rev/min). The
time-domain cases run the regenerative simulation at 0.9× and 1.1× the converged depth at
the converged speed, either side of each flip minimum.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import scipy.optimize

from millsense.stability.milling import immersion_angles, milling_dde
from millsense.stability.robust import RobustLobeResult, robust_lobes
from millsense.stability.sdm import analyse
from millsense.validation import Measured, case
from millsense.validation.cases.stability import FLUTES, FN, INSPERGER, KN, KT

Mode = Literal["down", "up"]

#: (a/D, mode) -> (speed [rev/min], converged depth [mm]) from :func:`converged_minimum`.
REFERENCE: dict[tuple[float, Mode], tuple[float, float]] = {
    (0.1, "down"): (18128.8, 0.74152),
    (0.1, "up"): (18763.5, 0.62407),
    (0.05, "down"): (18190.3, 1.07752),
    (0.05, "up"): (18691.0, 0.94777),
}


def _family(ratio: float, mode: Mode):  # type: ignore[no-untyped-def]
    st, ex = immersion_angles(ratio, 1.0, mode)

    def fam(n: float, m: int):  # type: ignore[no-untyped-def]
        return milling_dde(INSPERGER, FLUTES, KT, KN, st, ex, n, m)

    return fam


def default_chart(ratio: float, mode: Mode) -> RobustLobeResult:
    """The chart a case file with default ``[lobes]`` settings gives."""
    rpm = np.arange(5000.0, 25001.0, 100.0)
    return robust_lobes(_family(ratio, mode), rpm, 2 * FN, 20, 0.02, 10.0)


def brute_force_depth(ratio: float, mode: Mode, rpm: float, m: int, start: float) -> float:
    """Lowest unstable depth [m] by a 2 % grid from ``start`` (stable) and Brent, per depth."""
    fam = _family(ratio, mode)(rpm, m)

    def rho(w: float) -> float:
        return analyse(fam.step_means(w)).spectral_radius

    if rho(start) >= 1.0:
        raise ValueError(f"start depth {start} m is unstable at {rpm} rev/min")
    w = start
    while rho(w * 1.02) < 1.0:
        w *= 1.02
        if w > 0.05:
            return math.inf
    return float(scipy.optimize.brentq(lambda x: rho(x) - 1.0, w, w * 1.02, rtol=1e-6))


def converged_depth(ratio: float, mode: Mode, rpm: float, guess: float) -> float:
    """Richardson from m = 100 and 200 of :func:`brute_force_depth` [m]."""
    w1 = brute_force_depth(ratio, mode, rpm, 100, 0.3 * guess)
    w2 = brute_force_depth(ratio, mode, rpm, 200, 0.3 * guess)
    return w2 + (w2 - w1) / 3.0


def converged_minimum(ratio: float, mode: Mode, rpm: float, guess: float) -> tuple[float, float]:
    """(speed, depth [m]) of the converged minimum within ±6 rev/min of ``rpm``."""
    res = scipy.optimize.minimize_scalar(
        lambda n: converged_depth(ratio, mode, float(n), guess),
        bounds=(rpm - 6.0, rpm + 6.0),
        method="bounded",
        options={"xatol": 0.5},
    )
    return float(res.x), float(res.fun)


def _chart_case(ratio: float, mode: Mode) -> Measured:
    res = default_chart(ratio, mode)
    n_ref, w_ref = REFERENCE[(ratio, mode)]
    mn = res.minima[0]
    w_here = converged_depth(ratio, mode, mn.rpm, mn.depth)
    rows = [
        "| | speed [rev/min] | depth [mm] | type |",
        "|---|---|---|---|",
        f"| chart minimum (refined) | {mn.rpm:.0f} | {mn.depth * 1e3:.5f} | {mn.bifurcation} |",
        f"| converged there (m = 100/200) | {mn.rpm:.0f} | {w_here * 1e3:.5f} | |",
        f"| converged minimum (reference) | {n_ref:.1f} | {w_ref:.5f} | flip |",
        f"| lowest grid point of the chart | {res.rpm[res.min_index]:.0f} | "
        f"{res.critical_depth_m[res.min_index] * 1e3:.5f} | {res.bifurcation[res.min_index]} |",
    ]
    ok_kind = mn.bifurcation == "flip" and abs(mn.rpm / n_ref - 1) < 0.005
    value = mn.depth * 1e3 if ok_kind else math.nan
    return Measured(value, "\n".join(rows))


def _td_case(ratio: float, mode: Mode) -> Measured:
    from millsense.validation.cases.stability_time_domain import _td_verdict

    n_ref, w_ref = REFERENCE[(ratio, mode)]
    rows, agree = [], 0
    for f in (0.9, 1.1):
        stable, mult = _td_verdict(ratio, mode, n_ref, f * w_ref * 1e-3)
        ok = stable == (f < 1.0)
        agree += ok
        rows.append(f"| {f:.1f} | {'stable' if stable else 'unstable'} | {mult:.4f} |")
    head = (
        f"{n_ref:.1f} rev/min, converged flip minimum {w_ref:.5f} mm.\n\n"
        "| × depth | time-domain verdict | multiplier/rev |\n|---|---|---|\n"
    )
    return Measured(float(agree), head + "\n".join(rows))


def _chatter_case(ratio: float, mode: Mode) -> Measured:
    from millsense.stability.robust import solve_speed
    from millsense.stability.scan import structure_peak_gain
    from millsense.validation.cases.stability_time_domain import _td_sim

    n_ref, w_ref = REFERENCE[(ratio, mode)]
    fam = _family(ratio, mode)
    sol = solve_speed(fam, n_ref, 2 * FN, 20, 0.02, structure_peak_gain(fam(n_ref, 20)))
    sim = _td_sim(ratio, mode, n_ref, 1.1 * w_ref * 1e-3)
    out = sim.run_revolutions(400)
    f_td = sim.chatter_frequency_hz(out.x_m[-100 * sim.steps_per_rev :], exclude_harmonics=False)
    details = (
        f"{n_ref:.1f} rev/min: SDM {sol.bifurcation}, critical eigenvector "
        f"{sol.chatter_hz:.2f} Hz; "
        f"time domain at 1.1x the depth {f_td:.2f} Hz (last 100 revolutions)"
    )
    return Measured(abs(f_td / sol.chatter_hz - 1.0), details)


def _register(ratio: float, mode: Mode) -> None:
    tag = f"ad{str(ratio).replace('.', '')}_{mode}"
    n_ref, w_ref = REFERENCE[(ratio, mode)]

    @case(
        f"stability.low_immersion.{tag}_flip_min_depth",
        source="Insperger et al. 2003 low-immersion cases; reference [computed] by brute force "
        "m = 100/200 + Richardson (module docstring)",
        reference=w_ref,
        unit="mm",
        rel_tol=0.015,
        quick=False,
        description=f"1-DOF a/D = {ratio} {mode} milling: minimum of the default robust chart "
        f"(a flip lobe near {n_ref:.0f} rev/min; NaN if the minimum is not that flip lobe)",
    )
    def _depth() -> Measured:
        return _chart_case(ratio, mode)

    @case(
        f"stability.low_immersion.{tag}_time_domain",
        source="time-domain regenerative simulation either side of the converged flip minimum",
        reference=2.0,
        unit="agreeing verdicts",
        abs_tol=0.0,
        quick=False,
        description=f"1-DOF a/D = {ratio} {mode} milling at {n_ref:.0f} rev/min: stable at "
        "0.9x and chatter at 1.1x the converged flip-minimum depth",
    )
    def _td() -> Measured:
        return _td_case(ratio, mode)

    @case(
        f"stability.low_immersion.{tag}_chatter_branch",
        source="time-domain regenerative simulation (decision 0903)",
        reference=0.0,
        unit="relative difference",
        abs_tol=0.01,
        quick=False,
        description=f"1-DOF a/D = {ratio} {mode} milling at {n_ref:.0f} rev/min: chatter "
        "frequency of the critical eigenvector vs the simulation's dominant frequency at 1.1x",
    )
    def _branch() -> Measured:
        return _chatter_case(ratio, mode)


for _ratio, _mode in REFERENCE:
    _register(_ratio, _mode)
