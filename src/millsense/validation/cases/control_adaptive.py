"""Acceptance of the adaptive feed control in closed loop on the virtual machine (issue 16,
item 2; seed 000 V8, seed 002 V6).

Part (both cases): the demo part's tool and material (Ø20 mm 2-flute 30° helix, Al7050,
1000 rev/min, 400 mm/min programmed — the conditions of seed 000 V8) slotting along X through a
60 × 80 mm block: shallow first (``DEPTH_LOW``), then the program steps down within 0.4 mm of
travel (the engagement jump "A" of Aslan Fig. 6.13) and the slot runs on and leaves the part
at X = 60 (the exit "C"). The virtual plan of the program (0.1 mm z-map, the nameplate tool) is
the controller's plan; the simulator (``quaser-ux600`` X/Y/Z, seed 0) is the live source, the
controller's override events go back to it every 10 ms chunk
(:func:`~millsense.control.closed_loop.run_closed_loop`).

What plant and controller share (decision 1740): the program, the block, the tool's nameplate
geometry and the material's nominal coefficients. What they do not share: the plant cuts its
own plan (:func:`plant_step_plan`: a 0.05 mm z-map, 5 µm of runout at 0.4 rad the controller
does not know) through the truth's process; the controller's expectation is :func:`step_plan`.
The regulated quantity is the peak resultant XY force per revolution, measured by a
dynamometer on the virtual machine (the simulator's true tool force, decision 1616).

V8 (seed 000): F_r = 325 N. With the virtual look-ahead the largest per-revolution peak must
stay within +5 % of the reference and the override must not rise while the tool leaves the part;
without it (the conventional RLS + GPC controller) the jump overshoots — the thesis shows about
800 N — and the feed rises at the exit.

V6 (seed 002): the same controller without look-ahead through the open-CNC override channel
(2.5 ms, continuous) and through the closed-CNC override switch (10 % steps, 120 ms) on a
depth step of the ratio of Munasinghe's test IIM (7.62 → 10.5 mm, × 1.38): the force rise above
the reference at the step. The thesis: ≈ 10 % (open, HOAM milling) and ≈ 75 % (closed, a Fanuc
lathe with the same algorithm).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from millsense.streaming.block import Event
from millsense.validation import Measured, case

if TYPE_CHECKING:
    from millsense.plan.stock import ZMapStock

FS = 10000.0
F_REF_V8 = 325.0
DEPTH_LOW_MM = 1.2
DEPTH_HIGH_MM = 3.0
#: seed 002 test IIM: 7.62 → 10.5 mm
V6_RATIO = 10.5 / 7.62
STEP_X_MM = 25.0
#: V8 is judged on the virtual machine with each of these seeds (its realism and the
#: dynamometer's noise): the look-ahead's peak and exit on the worst, the conventional
#: overshoot on the median, the conventional exit on every one (decision 1667).
V8_SEEDS = (0, 1, 2, 3, 4, 5)
#: V6: the stock's step (wall) at X = 30 mm; the tool's front meets it at X = 20 mm.
WALL_X_MM = 30.0
EXIT_X_MM = 60.0


def program(depth_low_mm: float, depth_high_mm: float, wall: bool = False) -> str:
    """The slot with its step-down at X = 25 mm and its exit at X = 60 mm; ``wall``: a slot at
    the full depth whose stock is lower before X = 30 mm (the depth step is met by the tool's
    front half, over a tool radius of travel)."""
    if wall:
        return (
            "(adaptive control: depth step at a wall of the stock)\n"
            "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\n"
            f"G1 Z{-depth_high_mm:.3f} F400\nX72\nG0 Z5\nM30\n"
        )
    return (
        "(adaptive control: engagement jump and exit)\n"
        "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\n"
        f"G1 Z{-depth_low_mm:.3f} F400\nX{STEP_X_MM:.1f}\n"
        f"X{STEP_X_MM + 0.4:.1f} Z{-depth_high_mm:.3f}\nX72\nG0 Z5\nM30\n"
    )


def _stock(cell_m: float, depth_low_mm: float, depth_high_mm: float, wall: bool) -> ZMapStock:
    """The 60 × 80 × 30 mm block on a z-map of cell ``cell_m``; with ``wall`` its top is
    lowered by the depth difference for X < 30 mm."""
    from millsense.core.units import MM
    from millsense.plan.stock import ZMapStock

    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], cell_m)
    if wall:
        lower = stock.x_centres_m < WALL_X_MM * MM
        stock.heights[:, lower] = -(depth_high_mm - depth_low_mm) * MM
    return stock


@functools.lru_cache(maxsize=4)
def step_plan(depth_low_mm: float, depth_high_mm: float, wall: bool = False) -> object:
    """The controller's virtual plan of :func:`program` on the block (0.1 mm z-map, the
    nameplate tool without runout)."""
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret
    from millsense.plan.virtual_plan import plan_program
    from millsense.validation.cases.simulator_plan import _tool_coeffs

    tool, coeffs = _tool_coeffs()
    stock = _stock(0.1 * MM, depth_low_mm, depth_high_mm, wall)
    prog = interpret(program(depth_low_mm, depth_high_mm, wall), source="adaptive_step.nc")
    return plan_program(prog, stock, tool, coeffs)


@functools.lru_cache(maxsize=4)
def plant_step_plan(depth_low_mm: float, depth_high_mm: float, wall: bool = False) -> object:
    """The virtual machine's own plan of :func:`program`
    (:func:`~millsense.simulator.plant_plan.plant_plan`): the same program, block, tool and
    material, planned on a 0.05 mm z-map by the tool with 5 µm of runout at 0.4 rad (the
    controller's plan :func:`step_plan` knows neither)."""
    from millsense.plan.gcode import interpret
    from millsense.simulator.plant_plan import plant_plan
    from millsense.validation.cases.simulator_plan import _tool_coeffs

    tool, coeffs = _tool_coeffs()
    prog = interpret(program(depth_low_mm, depth_high_mm, wall), source="adaptive_step.nc")
    stock = functools.partial(_stock, depth_low_mm=depth_low_mm, depth_high_mm=depth_high_mm,
                              wall=wall)  # fmt: skip
    return plant_plan([prog], stock, tool, coeffs)


@dataclass
class LoopRun:
    """Per-sample channels of one closed-loop run and its override events."""

    t: np.ndarray
    force: np.ndarray  # true resultant XY force, N
    peak: np.ndarray  # controller's per-revolution peak (held), N
    override: np.ndarray  # effective override (fraction)
    x_mm: np.ndarray
    flag: np.ndarray
    n_events: int
    events: tuple[Event, ...] = ()


@functools.lru_cache(maxsize=32)
def closed_loop_run(
    look_ahead: bool,
    channel: str = "open",
    depth_low_mm: float = DEPTH_LOW_MM,
    depth_high_mm: float = DEPTH_HIGH_MM,
    wall: bool = False,
    reference_n: float = F_REF_V8,
    reported_override: bool = True,
    seed: int = 0,
) -> LoopRun:
    """Simulate the slot in closed loop with the adaptive feed controller regulating the peak
    resultant force of the dynamometer (decision 1616; 2 N of noise, decision 1798); ``force``
    is the true force at the tool. The controller's plan is
    :func:`step_plan`; the virtual machine cuts its own (:func:`plant_step_plan`, decision
    1740)."""
    from millsense.control.adaptive_feed import (
        REPORTED_OVERRIDE,
        AdaptiveFeedBlock,
        AdaptiveFeedOptions,
    )
    from millsense.control.closed_loop import DYNAMOMETER_NOISE_N, Dynamometer, run_closed_loop
    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.simulator.interpolator import OverrideChannel
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.plan_job import plan_job
    from millsense.validation.cases.simulator_plan import machine_3axis

    plan = step_plan(depth_low_mm, depth_high_mm, wall)
    assert isinstance(plan, VirtualPlan)
    m = machine_3axis()
    job, proc, _, _ = plan_job(plant_step_plan(depth_low_mm, depth_high_mm, wall), m,
                               "adaptive_step.nc")  # fmt: skip
    ch = OverrideChannel.open_cnc() if channel == "open" else OverrideChannel.closed_cnc()
    sim = MachineSimulator(m, job, proc, SimulatorOptions(feed_channel=ch, seed=seed))
    opts = AdaptiveFeedOptions(reference=reference_n, look_ahead=look_ahead)
    # the override in effect as the CNC reports it (decision 1666)
    blk = AdaptiveFeedBlock(
        opts, plan, override_channel=REPORTED_OVERRIDE if reported_override else None
    )
    # the controller reads a dynamometer with 2 N of noise (as the on-line session's,
    # decision 1798); the cases judge the true force at the tool
    res = run_closed_loop(
        sim,
        [Dynamometer(noise_n=DYNAMOMETER_NOISE_N, seed=seed), blk],
        keep=("cnc/feed_override", "x/position_cmd", "truth/tool/force_x", "truth/tool/force_y"),
        chunk_samples=100,
    )
    c = res.channels
    return LoopRun(
        res.time_s,
        np.hypot(c["truth/tool/force_x"], c["truth/tool/force_y"]),
        c[f"{blk.name}/peak"],
        c["cnc/feed_override"],
        c["x/position_cmd"] * 1e3,
        c[f"{blk.name}/flag"],
        len(res.overrides()),
        tuple(res.events),
    )


def exit_speedup_pct(run: LoopRun) -> float:
    """Largest rise of the effective override while the tool still cuts after the last
    engagement maximum before the exit (X > 45 mm, force > 5 N), percentage points."""
    cut = (run.x_mm > EXIT_X_MM - 15.0) & (run.force > 5.0)
    if not cut.any():
        return math.nan
    idx = np.flatnonzero(cut)
    ov = run.override[idx[0] : idx[-1] + 1]
    return float(100.0 * (np.max(ov) - ov[0]))


def within_band(run: LoopRun, reference_n: float = F_REF_V8) -> float:
    """Fraction of the revolutions in full cut (X −5 … 50 mm, past the entry, before the
    exit) whose peak is within ±5 % of the reference (one sample of the held peak per
    revolution at 1000 rev/min)."""
    mask = (run.x_mm > -5.0) & (run.x_mm < 50.0)
    pk = run.peak[mask][:: int(0.06 * FS)]
    return float(np.mean(np.abs(pk / reference_n - 1.0) <= 0.05)) if pk.size else math.nan


def _describe(runs: dict[str, LoopRun]) -> str:
    lines = [
        "| run | largest peak force N | at X mm | steady peak after the jump N | "
        "override before/after jump % | exit override rise % | revolutions within ±5 % | "
        "override events |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for k, r in runs.items():
        i = int(np.argmax(r.force))
        steady = (r.x_mm > 35.0) & (r.x_mm < 45.0)
        pre = (r.x_mm > 15.0) & (r.x_mm < 20.0)
        lines.append(
            f"| {k} | {r.force[i]:.0f} | {r.x_mm[i]:.1f} | "
            f"{np.max(r.force[steady]) if steady.any() else math.nan:.0f} | "
            f"{100 * np.median(r.override[pre]):.0f} / "
            f"{100 * np.median(r.override[steady]):.0f} | "
            f"{exit_speedup_pct(r):+.1f} | {100 * within_band(r):.0f} % | {r.n_events} |"
        )
    return "\n".join(lines)


def _v8_runs(seed: int = 0) -> dict[str, LoopRun]:
    return {
        "with look-ahead": closed_loop_run(True, seed=seed),
        "conventional": closed_loop_run(False, seed=seed),
    }


def v8_seed_runs() -> dict[int, dict[str, LoopRun]]:
    """The V8 pair on the virtual machine with each of :data:`V8_SEEDS` (its realism and the
    dynamometer's noise): where the jump meets the revolution and what the RLS learned before
    it vary, and with them the conventional overshoot (743-941 N over these six) and, before
    decision 1667, whether the look-ahead held (two of six seeds peaked at 754 and 831 N)."""
    return {s: _v8_runs(s) for s in V8_SEEDS}


def _describe_seeds(by_seed: dict[int, dict[str, LoopRun]]) -> str:
    """One table of every seed's pair (seed 0 first, the run the tests examine)."""
    parts: list[str] = []
    for seed, runs in by_seed.items():
        rows = _describe({f"{k}, seed {seed}": r for k, r in runs.items()}).splitlines()
        parts += rows if not parts else rows[2:]
    return "\n".join(parts)


@case(
    "control.v8_lookahead_peak_force",
    source="seed 000 V8 (Aslan Fig. 6.13): ACwithVF stays within ±5 % of F_r = 325 N",
    reference=F_REF_V8,
    unit="N",
    rel_tol=0.05,
    quick=False,
    description=(
        "Largest resultant force over the slot (entry, step-down, exit) in closed loop with "
        "the virtual look-ahead, the largest of the machine's six seeds (V8_SEEDS)."
    ),
)
def _v8_la_peak() -> Measured:
    by_seed = v8_seed_runs()
    worst = max(float(np.max(r["with look-ahead"].force)) for r in by_seed.values())
    return Measured(worst, _describe_seeds(by_seed))


@case(
    "control.v8_lookahead_exit_no_speedup",
    source="seed 000 V8: ACwithVF does not speed up at the exit C (no burr)",
    reference=0.0,
    unit="% points",
    abs_tol=0.5,
    quick=False,
    description=(
        "Rise of the effective override while the tool leaves the part, look-ahead on, the "
        "largest of the six seeds."
    ),
)
def _v8_la_exit() -> Measured:
    by_seed = v8_seed_runs()
    worst = max(exit_speedup_pct(r["with look-ahead"]) for r in by_seed.values())
    return Measured(worst, _describe_seeds(by_seed))


@case(
    "control.v8_conventional_overshoot",
    source="seed 000 V8: conventional AC overshoots to about 800 N at the engagement jump A",
    reference=800.0,
    unit="N",
    rel_tol=0.15,
    quick=False,
    description=(
        "Largest resultant force without the look-ahead (RLS + GPC alone), the median over "
        "the machine's six seeds (V8_SEEDS: where the jump meets the revolution, and the "
        "override the controller meets it with, vary from run to run; 743-941 N); the "
        "thesis' figure is read off a plot (≈ 800 N), hence ±15 %."
    ),
)
def _v8_conv_peak() -> Measured:
    by_seed = v8_seed_runs()
    peaks = [float(np.max(r["conventional"].force)) for r in by_seed.values()]
    return Measured(float(np.median(peaks)), _describe_seeds(by_seed))


@case(
    "control.v8_conventional_exit_speedup",
    source="seed 000 V8: conventional AC speeds up at the exit C, leaving burrs",
    reference=1.0,
    unit="1 = speeds up",
    abs_tol=0.0,
    quick=False,
    description=(
        "1 if the override rises by more than 10 % points while leaving the part, on every "
        "one of the six seeds."
    ),
)
def _v8_conv_exit() -> Measured:
    by_seed = v8_seed_runs()
    every = all(exit_speedup_pct(r["conventional"]) > 10.0 for r in by_seed.values())
    return Measured(float(every), _describe_seeds(by_seed))


# ------------------------------------------------------------------------------ seed 002 V6


def _v6_runs(seed: int = 0) -> dict[str, LoopRun]:
    low = DEPTH_LOW_MM
    high = round(DEPTH_LOW_MM * V6_RATIO, 3)
    # the thesis' CNCs did not report the override in effect back: the controller knows only
    # what it commanded (decision 1666)
    return {
        k: closed_loop_run(False, ch, low, high, True, reported_override=False, seed=seed)
        for k, ch in (("open CNC", "open"), ("closed CNC", "closed"))
    }


def v6_seed_runs() -> dict[int, dict[str, LoopRun]]:
    """The V6 pair with each of :data:`V8_SEEDS`, judged as V8 is (decision 1667): the rises
    on the median, the longer settling on every seed."""
    return {s: _v6_runs(s) for s in V8_SEEDS}


def _median_rise(by_seed: dict[int, dict[str, LoopRun]], channel: str) -> float:
    return float(np.median([step_rise_pct(r[channel]) for r in by_seed.values()]))


def step_rise_pct(run: LoopRun, reference_n: float = F_REF_V8) -> float:
    """Largest force from the tool's first touch of the wall to 10 mm past it, above the
    reference, %."""
    win = (run.x_mm > WALL_X_MM - 10.5) & (run.x_mm < WALL_X_MM + 10.0)
    return float(100.0 * (np.max(run.force[win]) / reference_n - 1.0))


def _describe_v6(by_seed: dict[int, dict[str, LoopRun]]) -> str:
    lines = [
        "| channel | seed | force rise at the depth step % | settling into ±5 % s | "
        "override events |",
        "|---|---|---|---|---|",
    ]
    for seed, runs in by_seed.items():
        for k, r in runs.items():
            lines.append(
                f"| {k} | {seed} | {step_rise_pct(r):.1f} | {settle_s(r):.2f} | {r.n_events} |"
            )
    return "\n".join(lines)


@case(
    "control.v6_open_cnc_step_rise",
    source="seed 002 V6 (Munasinghe Figs 5.17–5.26, test IIM): ≈ 10 % through the open CNC",
    reference=10.0,
    unit="%",
    abs_tol=5.0,
    quick=False,
    issue=16,
    gap=(
        "a depth step met by a milling cutter engages the deeper layer at the front of the tool "
        "(φ ≈ 90°, full chip) at once, so the first revolution after it carries the whole step "
        "(× 1.38 → ≈ +38 %) before any once-per-revolution controller can act, whatever the "
        "override channel; Munasinghe's ≈ 10 % implies a step the controller saw grow over "
        "several revolutions, which the thesis does not describe (decision 1617)"
    ),
    description=(
        "Force rise above F_r at a × 1.38 depth step, conventional RLS + GPC, open-CNC "
        "override (2.5 ms, continuous); the median over the machine's six seeds."
    ),
)
def _v6_open() -> Measured:
    by_seed = v6_seed_runs()
    return Measured(_median_rise(by_seed, "open CNC"), _describe_v6(by_seed))


@case(
    "control.v6_closed_cnc_step_rise",
    source="seed 002 V6 (test IIL): ≈ 75 % through the closed-CNC override switch",
    reference=75.0,
    unit="%",
    abs_tol=20.0,
    quick=False,
    description=(
        "Force rise above F_r at the same depth step through the closed-CNC override switch "
        "(10 % steps, 120 ms); the median over the machine's six seeds. A pass here is weak "
        "evidence: the thesis' figure is from a lathe (2.5 → 4 mm, × 1.6, on a Fanuc switch); "
        "on the milled × 1.38 step the first revolution carries the step through either "
        "channel (≈ +34 %), and the largest force is the loop's own swing after it (on seed 0, "
        "after the cut to 30 % the override is raised in 10 % and 20 % steps to 140 % at "
        "X ≈ 23 mm and meets the step's still growing engagement: 50.6 %, the seeds' lowest; "
        "the others 58.5-59.6 %). The controller is run as the thesis' was: it knows what it "
        "commanded, not the override the CNC applied (decision 1666)."
    ),
)
def _v6_closed() -> Measured:
    by_seed = v6_seed_runs()
    return Measured(_median_rise(by_seed, "closed CNC"), _describe_v6(by_seed))


def settle_s(run: LoopRun, reference_n: float = F_REF_V8) -> float:
    """From the tool's first touch of the wall until the per-revolution peak is within ±5 % of
    the reference for good (up to 15 mm past the wall), s."""
    win = np.flatnonzero((run.x_mm > WALL_X_MM - 10.0) & (run.x_mm < WALL_X_MM + 15.0))
    out = np.abs(run.peak[win] / reference_n - 1.0) > 0.05
    if not out.any():
        return 0.0
    return float(run.t[win[np.flatnonzero(out)[-1]]] - run.t[win[0]])


@case(
    "control.v6_closed_cnc_settles_longer",
    source="seed 002 V6: transients last longer with the closed CNC (120 ms, 10 % steps)",
    reference=1.0,
    unit="1 = longer",
    abs_tol=0.0,
    quick=False,
    description=(
        "1 if the force settles into ±5 % of F_r after the depth step at least twice as slowly "
        "through the closed-CNC switch as through the open CNC, on every one of the six seeds."
    ),
)
def _v6_settle() -> Measured:
    by_seed = v6_seed_runs()
    every = all(
        settle_s(r["closed CNC"]) >= 2.0 * settle_s(r["open CNC"]) for r in by_seed.values()
    )
    return Measured(float(every), _describe_v6(by_seed))
