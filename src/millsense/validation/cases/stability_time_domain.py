"""Validation cases of :mod:`millsense.stability.time_domain` (regenerative simulation)."""

from __future__ import annotations

import math
from typing import Literal

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


# --- Time-domain simulation against the SDM lobes (issue 3 acceptance) ----------------------
#
# At five speeds on each boundary, the simulation runs at 0.9× and 1.1× the SDM critical
# depth; its verdict must agree with SDM (stable below, unstable above). The structure is the
# Insperger 1-DOF benchmark (x only), 2 flutes, no helix; the SDM depths are the converged
# (Richardson 20/40) lobes of millsense.stability.lobes, computed by the stability cases.

_SLOT_SPEEDS = (6000.0, 8800.0, 12000.0, 15870.0, 21000.0)
_HALF_SPEEDS = (9000.0, 13000.0, 17000.0, 21727.0, 24500.0)
_TD_REVOLUTIONS = 400


def _td_sim(
    ratio: float, mode: Literal["down", "up"], rpm: float, depth_m: float
) -> TimeDomainMillingSim:
    """Insperger 1-DOF structure, radial immersion a/D = ``ratio``, at ``rpm`` and depth."""
    d = 10e-3
    eng = Engagement.slot() if ratio >= 1.0 else Engagement.radial(ratio * d, d, mode=mode)
    rev_hz = rpm / 60.0
    # ≥ 30 steps per cycle of the 922 Hz mode; even, so a tooth period is whole steps
    spr = max(100, 2 * math.ceil(15 * 922.0 / rev_hz))
    return TimeDomainMillingSim(
        EndMill(d, 2),
        _K,
        eng,
        0.05e-3,
        depth_m,
        rpm * 2 * math.pi / 60,
        _MODE,
        DirectionModes.rigid(),
        n_discs=1,
        steps_per_rev=spr,
    )


def _td_verdict(
    ratio: float, mode: Literal["down", "up"], rpm: float, depth_m: float
) -> tuple[bool, float]:
    sim = _td_sim(ratio, mode, rpm, depth_m)
    sim.run_revolutions(_TD_REVOLUTIONS)
    v = sim.verdict(last_revolutions=_TD_REVOLUTIONS // 2)
    return v.stable, v.multiplier_per_rev


def _agreement(ratio: float, mode: Literal["down", "up"], speeds: tuple[float, ...]) -> Measured:
    import numpy as np

    from millsense.validation.cases.stability import insperger_lobes

    lobes = insperger_lobes(ratio, np.array(speeds))
    rows, agree = [], 0
    for rpm, w in zip(speeds, lobes.critical_depth_m, strict=True):
        for f in (0.9, 1.1):
            stable, mult = _td_verdict(ratio, mode, rpm, f * float(w))
            ok = stable == (f < 1.0)
            agree += ok
            rows.append(
                f"| {rpm:.0f} | {w * 1e3:.4f} | {f:.1f} | {'stable' if stable else 'unstable'} "
                f"| {mult:.4f} | {'yes' if ok else '**no**'} |"
            )
    table = (
        "| rev/min | SDM depth [mm] | × depth | time-domain verdict | multiplier/rev | agrees |\n"
    )
    table += "|---|---|---|---|---|---|\n" + "\n".join(rows)
    return Measured(float(agree), table)


@case(
    "stability.time_domain_vs_sdm_slot",
    source="benchmarks.md §1 (Insperger 2003): SDM lobes vs time-domain simulation",
    reference=10.0,
    unit="agreeing verdicts",
    abs_tol=0.0,
    quick=False,
    description="1-DOF slotting: time-domain verdicts at 0.9× and 1.1× the SDM critical depth "
    "at five speeds (10 runs) that agree with SDM",
)
def _vs_sdm_slot() -> Measured:
    return _agreement(1.0, "down", _SLOT_SPEEDS)


@case(
    "stability.time_domain_vs_sdm_half_down",
    source="benchmarks.md §1 (Insperger 2003): SDM lobes vs time-domain simulation",
    reference=10.0,
    unit="agreeing verdicts",
    abs_tol=0.0,
    quick=False,
    description="1-DOF half-immersion down milling: time-domain verdicts at 0.9× and 1.1× the "
    "SDM critical depth at five speeds (10 runs) that agree with SDM",
)
def _vs_sdm_half() -> Measured:
    return _agreement(0.5, "down", _HALF_SPEEDS)


def _flip_point() -> tuple[float, float, float]:
    from millsense.validation.cases.stability import low_immersion_flip_check

    return low_immersion_flip_check()


@case(
    "stability.time_domain_vs_sdm_low_immersion",
    source="benchmarks.md §1 (period-doubling lobes, Insperger 2003; Merdol & Altintas 2004)",
    reference=2.0,
    unit="agreeing verdicts",
    abs_tol=0.0,
    quick=False,
    description="a/D = 0.05 down milling at SDM's deepest period-doubling point: the simulation "
    "is stable at 0.8× and chatters at 1.2× the SDM depth, where ZOA predicts stability at both",
)
def _vs_sdm_low() -> Measured:
    rpm, w_sdm, w_zoa = _flip_point()
    rows, agree = [], 0
    for f in (0.8, 1.2):
        stable, mult = _td_verdict(0.05, "down", rpm, f * w_sdm)
        ok = stable == (f < 1.0)
        agree += ok
        rows.append(f"| {f:.1f} | {'stable' if stable else 'unstable'} | {mult:.4f} |")
    head = (
        f"{rpm:.0f} rev/min: SDM flip at {w_sdm * 1e3:.3f} mm, ZOA limit {w_zoa * 1e3:.3f} mm.\n\n"
        "| × SDM depth | time-domain verdict | multiplier/rev |\n|---|---|---|\n"
    )
    return Measured(float(agree), head + "\n".join(rows))


@case(
    "stability.time_domain_flip_frequency",
    source="period doubling: chatter at odd multiples of half the tooth frequency",
    reference=0.5,
    unit="fraction of tooth frequency",
    abs_tol=0.03,
    quick=False,
    description="a/D = 0.05, 1.2× the SDM flip depth: fractional part of the dominant "
    "vibration frequency over the tooth frequency (0.5 for period doubling, not 0 or a Hopf "
    "value)",
)
def _flip_frequency() -> Measured:
    rpm, w_sdm, _ = _flip_point()
    sim = _td_sim(0.05, "down", rpm, 1.2 * w_sdm)
    out = sim.run_revolutions(_TD_REVOLUTIONS)
    x = out.x_m[-100 * sim.steps_per_rev :]
    f = sim.chatter_frequency_hz(x, exclude_harmonics=False)
    tooth_hz = 2 * rpm / 60.0
    frac = (f / tooth_hz) % 1.0
    return Measured(frac, f"dominant {f:.1f} Hz, tooth frequency {tooth_hz:.1f} Hz")
