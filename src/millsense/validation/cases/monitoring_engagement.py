"""Acceptance of the depth-of-cut / runout monitor (seed 004 ch. 2, Tables 2.3–2.5).

Replica in simulation of Lee's constant-DOC experiments (Table 2.2: Ø6 mm square end mills,
35° helix, 1, 2 and 4 flutes, 1200 min⁻¹, 0.025 mm/tooth, down milling): for every row of
Tables 2.3–2.5 the process model of the virtual machine (:func:`millsense.process.forces.
milling_forces`: chip with runout, clipped at zero, *with* edge forces — the thesis' model has
none, a real cut has them) gives 10 revolutions of cutting torque at 10 kHz, plus 2 % white
noise (a dynamometer-like channel: the thesis used the z-force at 1 MHz; the spindle observer's
bandwidth would not reach the notch). Runout as measured in the thesis: 1.5 µm (4-flute),
1 µm (2-flute rows 1-4) and 4.4 µm (rows 5-8, digest assumption), none for 1 flute; direction
0.7 rad. The monitor's per-revolution values are averaged over the revolutions (the thesis
averages over the path).

Coefficients: the Al7050 preset's K_tc, K_te (the thesis' brass is not in the presets; only
ratios matter for the depths, and K_te/K_tc sets the model mismatch: K_te/(K_tc c) = 1.3 at
c = 25 µm). The monitor runs as a user would run it, with its default ``edge=True`` (it fits an
edge-force coefficient on the tooth-passing harmonics; for N ≥ 3 its runout solver adds the
edge force's first harmonic to Eq. 2.18 re-derived, decision 1540) and the channel's air
torque, 0 (a tared dynamometer), as a setting: where the harmonics do not observe the edge
coefficient, the mean torque gives it (decision 1806).

Judging (issue 12, decision 1780): every acceptance figure is measured on the plant with edge
forces, which the monitor's model (the thesis' Eqs. 2.1-2.10) does not contain. The axial-depth
cases are two-sided around the thesis' own worst error of the table (computed from the printed
rows below) and flagged *too good* beyond 2× better; the runout keeps issue 15's ±0.3 µm bound
and is also compared with the thesis' worst 4-flute runout error. The edge-free runout figure
(plant = the monitor's own model class) survives only as a self-check.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from millsense.validation import Measured, case

FS = 10000.0
RPM = 1200.0
C_MM = 0.025
D_MM = 6.0
HELIX_DEG = 35.0
#: harmonics of ω_n the monitor uses: up to ≈ 60 ω_n (1.2 kHz), K = 60/N tooth harmonics
HARMONICS_OF_OMEGA = 60
#: (d_r, d_a) mm of each table row, and the thesis' monitored d_a (mm) and σ (seed-004 digest §4.1)
TABLE_2_3 = (
    (1, 0.5, 0.466, 0.88), (1, 0.5, 0.453, 0.83), (2, 0.5, 0.473, 0.91), (5, 0.5, 0.494, 0.98),
    (0.5, 2, 1.921, 0.93), (0.5, 3, 2.968, 0.98), (0.5, 5, 5.441, 0.90), (1, 5, 4.632, 0.89),
    (1, 2, 2.041, 0.97), (3, 2, 2.176, 0.88),
)  # fmt: skip
TABLE_2_4 = (
    (0.5, 5, 5.269, 0.94), (1, 0.5, 0.529, 0.92), (3, 0.5, 0.527, 0.91), (5, 0.5, 0.453, 0.83),
    (0.5, 1, 0.907, 0.84), (0.5, 2, 2.041, 0.97), (0.5, 3, 3.265, 0.88), (1, 5, 5.164, 0.96),
)  # fmt: skip
TABLE_2_5 = (
    (1, 0.5, 0.453, 0.85), (3, 0.5, 0.51, 0.97), (5, 0.5, 0.453, 0.85), (0.5, 0.5, 0.480, 0.94),
    (0.5, 1, 1.134, 0.87), (0.5, 2, 2.128, 0.93), (0.5, 3, 3.080, 0.97),
)  # fmt: skip
TABLES = {1: TABLE_2_3, 2: TABLE_2_4, 4: TABLE_2_5}
#: The channel's torque with the tool out of the cut: 0 for this dynamometer-like channel (a
#: dynamometer under the workpiece is tared and sees no spindle friction), given to the
#: monitor as the setting a user of such a sensor knows (decision 1806; not fitted).
AIR_TORQUE_NM = 0.0
#: Table 2.5's monitored runout (µm), one per row, against the dial gauge's 1.5 µm
THESIS_RUNOUT_2_5 = (1.50, 1.71, 1.43, 1.44, 1.28, 1.04, 1.19)
DIAL_GAUGE_RUNOUT_2_5_UM = 1.5


def thesis_max_da_error(n_flutes: int) -> float:
    """The thesis' largest |relative error| of the monitored d_a in the table of ``n_flutes``
    (%): 9.4 (Table 2.3), 9.4 (2.4), 13.4 (2.5)."""
    return max(abs(mon / da - 1.0) for _, da, mon, _ in TABLES[n_flutes]) * 100


#: the thesis' largest |monitored − dial-gauge runout| of Table 2.5, µm (0.46, row d_a = 2 mm)
THESIS_MAX_RUNOUT_ERROR_UM = max(abs(e - DIAL_GAUGE_RUNOUT_2_5_UM) for e in THESIS_RUNOUT_2_5)
#: Two-sided tolerance of a worst-error replica around the thesis' worst error, and the
#: factor beyond which a better replica is flagged too good (decision 1780): the worst of 7-10
#: rows is itself a noisy statistic (the thesis' three tables give 9.4, 9.4 and 13.4 %), and
#: ±50 % / 2× is what the registry's other worst-error replicas use (seed 000 V1, seed 003
#: Table 4.6, Aslan ch. 4).
WORST_REL_TOL = 0.5
WORST_TOO_GOOD = 2.0


@dataclass(frozen=True)
class RowResult:
    """Designed and monitored values of one row (mm, µm)."""

    n_flutes: int
    dr: float
    da: float
    runout_um: float
    mon_dr: float
    mon_da: float
    mon_runout_um: float
    sigma: float
    thesis_sigma: float
    thesis_da: float = math.nan
    thesis_runout_um: float = math.nan

    @property
    def err_da(self) -> float:
        return (self.mon_da - self.da) / self.da

    @property
    def thesis_err_da(self) -> float:
        return (self.thesis_da - self.da) / self.da

    @property
    def err_dr(self) -> float:
        return (self.mon_dr - self.dr) / self.dr


def _row(
    n: int,
    dr: float,
    da: float,
    runout_um: float,
    thesis_sigma: float,
    seed: int,
    edge: bool,
    thesis_da: float = math.nan,
    thesis_runout_um: float = math.nan,
) -> RowResult:
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.monitoring.engagement import EngagementBlock
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill
    from millsense.validation.cases.monitoring_breakage import run_block

    tool = EndMill(
        D_MM * 1e-3,
        n,
        helix_rad=math.radians(HELIX_DEG),
        runout_offset_m=runout_um * 1e-6,
        runout_angle_rad=0.7,
    )
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    if not edge:
        coeffs = CuttingCoefficients(ktc=coeffs.ktc, krc=coeffs.krc)
    omega = RPM * 2 * math.pi / 60
    t = np.arange(int(10 * 60 / RPM * FS)) / FS
    eng = Engagement.radial(dr * 1e-3, D_MM * 1e-3, "down")
    f = milling_forces(tool, coeffs, eng, C_MM * 1e-3, da * 1e-3, omega * t, n_discs=60)
    rng = np.random.default_rng(seed)
    tq = f.torque_nm + 0.02 * np.mean(f.torque_nm) * rng.standard_normal(t.size)
    block = EngagementBlock(
        n,
        D_MM,
        HELIX_DEG,
        feed_per_tooth_mm=C_MM,
        n_harmonics=HARMONICS_OF_OMEGA // n,
        air_torque_nm=AIR_TORQUE_NM,
    )
    run_block(block, {"spindle/torque_est": tq, "spindle/speed": np.full(t.size, omega)}, 1000)
    ests = [e for _, e in block.estimates if e is not None]
    return RowResult(
        n,
        dr,
        da,
        runout_um,
        float(np.mean([e.radial_depth_m for e in ests]) * 1e3),
        float(np.mean([e.axial_depth_m for e in ests]) * 1e3),
        float(np.mean([e.runout_m for e in ests]) * 1e6),
        float(np.mean([e.reliability for e in ests])),
        thesis_sigma,
        thesis_da,
        thesis_runout_um,
    )


@functools.lru_cache(maxsize=4)
def table(n_flutes: int, edge: bool = True) -> tuple[RowResult, ...]:
    """Monitored values of every row of the table of ``n_flutes`` (2.3, 2.4 or 2.5); with the
    edge forces of the preset (the plant every acceptance figure is judged on), or a shear-only
    cut (the thesis' model, Eqs. 2.1-2.10: the monitor's own model class, a self-check only)."""
    out = []
    for i, (dr, da, thesis_da, sig) in enumerate(TABLES[n_flutes]):
        runout = {1: 0.0, 2: 1.0 if i < 4 else 4.4, 4: 1.5}[n_flutes]
        thesis_runout = THESIS_RUNOUT_2_5[i] if n_flutes == 4 else math.nan
        out.append(
            _row(n_flutes, dr, da, runout, sig, 10 * n_flutes + i, edge, thesis_da, thesis_runout)
        )
    return tuple(out)


def _details(rows: tuple[RowResult, ...]) -> str:
    lines = [
        "| d_r | d_a | mon. d_r | mon. d_a | err d_a | thesis err d_a | ε sim µm | mon. ε µm "
        "| thesis ε µm | σ | thesis σ |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.dr:g} | {r.da:g} | {r.mon_dr:.3f} | {r.mon_da:.3f} | {r.err_da * 100:+.1f} % "
            f"| {r.thesis_err_da * 100:+.1f} % | {r.runout_um:g} | {r.mon_runout_um:.2f} "
            f"| {r.thesis_runout_um:.2f} | {r.sigma:.3f} | {r.thesis_sigma:.2f} |"
        )
    return "\n".join(lines)


def _max_da_error(n: int) -> Measured:
    rows = table(n)
    worst = max(abs(r.err_da) for r in rows) * 100
    issue = "within" if worst <= 10.0 else "outside"
    return Measured(
        worst,
        f"Thesis' worst error of this table {thesis_max_da_error(n):.1f} %; replica "
        f"{worst:.2f} % ({thesis_max_da_error(n) / worst:.2g}× better than the thesis; "
        f"{issue} issue 15's ±10 %).\n\n" + _details(rows),
    )


_CaseFn = Callable[[], float | Measured]


def _axial_case(case_id: str, table_no: str, n: int) -> Callable[[_CaseFn], _CaseFn]:
    ref = thesis_max_da_error(n)
    flutes = "1 flute" if n == 1 else f"{n} flutes"
    return case(
        case_id,
        source=f"seed 004 Table {table_no} ({flutes}): the thesis' worst d_a error {ref:.1f} % "
        "(printed rows; issue 15: within about ±10 %)",
        reference=ref,
        unit="%",
        rel_tol=WORST_REL_TOL,
        too_good_factor=WORST_TOO_GOOD,
        quick=False,
        description=(
            f"Largest |relative error| of the monitored axial depth over the Table {table_no} "
            "rows, on the plant with edge forces, against the thesis' own worst error of the "
            f"table (two-sided ±{WORST_REL_TOL * 100:g} %; more than {WORST_TOO_GOOD:g}× "
            "better is flagged too good: the replica has no setup, flatness or tool-length "
            "errors, so a far smaller error says the simulation is too benign; decision 1780)."
        ),
    )


@_axial_case("monitoring.engagement.table23_axial_depth", "2.3", 1)
def _t23() -> Measured:
    return _max_da_error(1)


@_axial_case("monitoring.engagement.table24_axial_depth", "2.4", 2)
def _t24() -> Measured:
    return _max_da_error(2)


@_axial_case("monitoring.engagement.table25_axial_depth", "2.5", 4)
def _t25() -> Measured:
    return _max_da_error(4)


def _max_runout_error(rows: tuple[RowResult, ...]) -> float:
    return max(abs(r.mon_runout_um - r.runout_um) for r in rows)


def _runout_details() -> str:
    rows = table(4)
    return (
        f"Worst |monitored − simulated runout| on the plant with edge forces "
        f"{_max_runout_error(rows):.2f} µm; the thesis' worst |monitored − dial-gauge runout| "
        f"{THESIS_MAX_RUNOUT_ERROR_UM:.2f} µm (monitored 1.04-1.71 µm against 1.5 µm).\n\n"
        + _details(rows)
    )


@case(
    "monitoring.engagement.table25_runout",
    source="issue 15: 4-flute runout within ±0.3 µm of the simulated runout (seed 004 Table "
    "2.5: monitored 1.04-1.71 µm against 1.5 µm)",
    reference=0.0,
    unit="µm",
    abs_tol=0.3,
    quick=False,
    description=(
        "Largest |monitored − simulated runout| over the Table 2.5 rows (4 flutes), on the "
        "plant with edge forces (the thesis' model, Eqs. 2.1-2.10, has none; a real cut has "
        "them). Issue 15's bound, kept as the issue states it (it is tighter than the thesis' "
        "own worst row, 0.46 µm); the thesis comparison is table25_runout_thesis. Met since "
        "decision 1806 (K_e from the mean torque where the tooth-passing harmonics do not "
        "observe it: row d_r 3 mm, one tooth pitch engaged, 0.39 → 0.09 µm)."
    ),
)
def _t25_runout() -> Measured:
    return Measured(_max_runout_error(table(4)), _runout_details())


@case(
    "monitoring.engagement.table25_runout_thesis",
    source="seed 004 Table 2.5: worst 4-flute runout error "
    f"{THESIS_MAX_RUNOUT_ERROR_UM:.2f} µm (monitored 1.04-1.71 µm against the dial gauge's 1.5 µm)",
    reference=THESIS_MAX_RUNOUT_ERROR_UM,
    unit="µm",
    rel_tol=WORST_REL_TOL,
    too_good_factor=WORST_TOO_GOOD,
    quick=False,
    description=(
        "Largest |monitored − simulated runout| over the Table 2.5 rows on the plant with edge "
        "forces, against the thesis' worst |monitored − dial-gauge runout| (two-sided "
        f"±{WORST_REL_TOL * 100:g} %; more than {WORST_TOO_GOOD:g}× better flagged too good; "
        "decision 1780)."
    ),
)
def _t25_runout_thesis() -> Measured:
    return Measured(_max_runout_error(table(4)), _runout_details())


@case(
    "monitoring.engagement.table25_runout_shear_only",
    source="self-consistency check, not an acceptance figure: the plant is the monitor's own "
    "model class (Eqs. 2.1-2.10, no edge forces), issue 12",
    reference=0.0,
    unit="µm",
    abs_tol=0.3,
    quick=False,
    self_check=True,
    description=(
        "Largest |monitored − simulated runout| over the Table 2.5 rows on a shear-only cut: "
        "checks the runout solver (Eq. 2.18 re-derived, digest V1/V2) on the model it inverts; "
        "the acceptance figures are table25_runout and table25_runout_thesis."
    ),
)
def _t25_runout_shear_only() -> Measured:
    rows = table(4, edge=False)
    return Measured(_max_runout_error(rows), _details(rows))


@case(
    "monitoring.engagement.reliability_vs_error",
    source="seed 004 Fig. 2.15: σ is high where the DOC errors are small",
    reference=-1.0,
    unit="1",
    abs_tol=0.7,
    quick=False,
    description=(
        "Spearman rank correlation between σ and |err d_a| + |err d_r| over all 25 rows "
        "(negative: σ falls as the error grows; pass if ≤ −0.3)."
    ),
)
def _reliability() -> Measured:
    from scipy import stats

    rows = table(1) + table(2) + table(4)
    err = [abs(r.err_da) + abs(r.err_dr) for r in rows]
    rho = float(stats.spearmanr([r.sigma for r in rows], err).statistic)
    return Measured(rho, _details(rows))
