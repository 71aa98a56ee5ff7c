"""Validation cases of :mod:`millsense.stability.time_domain` (regenerative simulation)."""

from __future__ import annotations

import math

from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.geometry import EndMill
from millsense.stability.time_domain import DirectionModes, TimeDomainMillingSim
from millsense.validation import Measured, case

# benchmarks.md §1: Insperger 1-DOF slotting, 0.3174 mm critical at 15 870 rev/min.
_K = CuttingCoefficients(ktc=6e8, krc=2e8)
_MODE = DirectionModes.from_arrays([922.0], [0.011], [1.34005e6])
_OMEGA = 15870.0 * 2 * math.pi / 60
_A_CRIT = 0.3174e-3


def _sim(factor: float) -> TimeDomainMillingSim:
    return TimeDomainMillingSim(
        EndMill(10e-3, 2),
        _K,
        Engagement.slot(),
        0.05e-3,
        factor * _A_CRIT,
        _OMEGA,
        _MODE,
        DirectionModes.rigid(),
        n_discs=1,
        steps_per_rev=100,
    )


@case(
    "stability.time_domain_insperger_chatter_hz",
    source="benchmarks.md §1 (Insperger 2003)",
    reference=932.0,
    unit="Hz",
    rel_tol=0.01,
    description="Chatter frequency of the time-domain simulation at 1.2 × 0.3174 mm, "
    "15 870 rev/min, 1-DOF slotting (last 60 revolutions)",
)
def _chatter_hz() -> float:
    sim = _sim(1.2)
    out = sim.run_revolutions(150)
    return sim.chatter_frequency_hz(out.x_m[-60 * sim.steps_per_rev :])


@case(
    "stability.time_domain_insperger_verdicts",
    source="benchmarks.md §1 (Insperger 2003)",
    reference=4.0,
    unit="agreeing verdicts",
    abs_tol=0.0,
    description="Time-domain verdicts at 0.8, 0.9, 1.1, 1.2 × the critical depth at "
    "15 870 rev/min (1-DOF slotting) that agree with stable/unstable",
)
def _verdicts() -> Measured:
    rows = []
    agree = 0
    for f in (0.8, 0.9, 1.1, 1.2):
        sim = _sim(f)
        sim.run_revolutions(200)
        v = sim.verdict()
        ok = v.stable == (f < 1.0)
        agree += ok
        rows.append(
            f"| {f:.1f} | {'stable' if v.stable else 'unstable'} | {v.multiplier_per_rev:.4f} "
            f"| {v.decay_ratio:.3g} | {v.spread_ratio:.3g} |"
        )
    table = "| depth / 0.3174 mm | verdict | multiplier/rev | decay | spread |\n"
    table += "|---|---|---|---|---|\n" + "\n".join(rows)
    return Measured(float(agree), table)
