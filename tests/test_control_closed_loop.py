"""Seed 000 V8 in closed loop on the virtual machine (issue 16 item 2): the adaptive feed
controller with and without the virtual look-ahead on a slot with a step-down (engagement jump
× 2.5) and an exit (``millsense.validation.cases.control_adaptive``; ≈ 20 s)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.plan.virtual_plan import VirtualPlan
from millsense.validation.cases import control_adaptive as ca


@pytest.fixture(scope="module")
def runs() -> dict[str, ca.LoopRun]:
    return ca._v8_runs()


@pytest.fixture(scope="module")
def by_seed() -> dict[int, dict[str, ca.LoopRun]]:
    return ca.v8_seed_runs()


def test_lookahead_holds_the_reference(runs: dict[str, ca.LoopRun]) -> None:
    # seed 000 V8: ACwithVF stays within ±5 % of F_r = 325 N. On the plant's own plan and
    # material (decisions 1740, 1798) the look-ahead's one common factor κ, fitted in the
    # shallow cut at 50-124 % override, under-predicted the jump's peak at 29-36 % (the edge
    # force and the runout's chip do not scale with the feed): 343.3 N, +5.6 %. With the
    # two-part calibration (decision 1656) the ceiling sets 30.6 % and the largest peak is
    # 318 N, in the steady deep cut; no overshoot beyond +5 %
    la = runs["with look-ahead"]
    assert np.max(la.force) <= 1.05 * ca.F_REF_V8
    jump = (la.x_mm > ca.STEP_X_MM) & (la.x_mm < ca.STEP_X_MM + 3.0)
    assert np.max(la.force[jump]) <= 1.05 * ca.F_REF_V8  # 318 N measured at X 25-28 mm
    after = (la.x_mm > 30.0) & (la.x_mm < 45.0)  # steady at the full depth
    assert np.all(np.abs(np.max(la.force[after]) / ca.F_REF_V8 - 1.0) <= 0.05)


def test_lookahead_exit_hold_stands_until_the_machine_reads_air(
    runs: dict[str, ca.LoopRun],
) -> None:
    # the plant's own plan (0.05 mm z-map, decision 1740) cuts one plan row longer than the
    # controller's (0.1 mm z-map); the exit hold no longer ends where the controller's plan's
    # engagement ends but when a revolution reads air (decision 1741): no rise of the override
    # while the true force is still > 5 N (it rose 92.5 points in the extra row before)
    la = runs["with look-ahead"]
    ctrl = ca.step_plan(ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM)
    plant = ca.plant_step_plan(ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM)
    last = []
    for plan in (ctrl, plant):
        assert isinstance(plan, VirtualPlan)
        ap = np.asarray(plan["axial_depth_mm"])
        last.append(float(plan.xyz_m[np.flatnonzero(ap > 0)[-1], 0] * 1e3))
    assert last[1] > last[0] + 0.3  # the plant still cuts where the controller's plan is out
    held = (la.x_mm > ca.EXIT_X_MM - 15.0) & (la.force > 5.0)
    ov = la.override[held]
    assert float(100.0 * (np.max(ov) - ov[0])) <= 0.5
    assert ca.exit_speedup_pct(la) <= 0.5


def test_conventional_overshoots_at_the_step(runs: dict[str, ca.LoopRun]) -> None:
    # seed 000 V8: the conventional controller overshoots at the engagement jump A, before the
    # once-per-revolution controller can act: at least twice the reference, at the step
    conv = runs["conventional"]
    assert np.max(conv.force) >= 2.0 * ca.F_REF_V8
    i = int(np.argmax(conv.force))
    assert ca.STEP_X_MM <= conv.x_mm[i] <= ca.STEP_X_MM + 3.0  # at the step, not elsewhere


def test_conventional_overshoots_like_the_thesis(
    by_seed: dict[int, dict[str, ca.LoopRun]],
) -> None:
    # seed 000 V8: ≈ 800 N at A (read off a figure), ±15 %, on the median of the six seeds
    # (743-941 N: where the jump meets the revolution varies; 905 N measured 2026-11-29); every
    # seed overshoots at the step, at least twice the reference
    peaks = [float(np.max(r["conventional"].force)) for r in by_seed.values()]
    assert 0.85 * 800.0 <= float(np.median(peaks)) <= 1.15 * 800.0
    for r in by_seed.values():
        conv = r["conventional"]
        i = int(np.argmax(conv.force))
        assert conv.force[i] >= 2.0 * ca.F_REF_V8
        assert ca.STEP_X_MM <= conv.x_mm[i] <= ca.STEP_X_MM + 3.0


def test_lookahead_holds_the_reference_on_every_seed(
    by_seed: dict[int, dict[str, ca.LoopRun]],
) -> None:
    # decision 1667: on the machine's seeds 1 and 4 the RLS of the steady deep cut drifted to a
    # near-integrator and the GPC's move took the override 20 → 150 %: 831 and 754 N. With
    # the move bounded by twice the proportional cut's, the largest peak of every seed stays
    # within +5 % (312-333 N measured) and no seed speeds up at the exit
    for r in by_seed.values():
        la = r["with look-ahead"]
        assert np.max(la.force) <= 1.05 * ca.F_REF_V8
        assert ca.exit_speedup_pct(la) <= 0.5
        assert ca.exit_speedup_pct(r["conventional"]) > 10.0


def test_conventional_speeds_up_at_the_exit(runs: dict[str, ca.LoopRun]) -> None:
    assert ca.exit_speedup_pct(runs["conventional"]) > 10.0


def test_plan_events_carry_nc_line_and_position(runs: dict[str, ca.LoopRun]) -> None:
    # every override event of the look-ahead run names the NC line and the plan position; the
    # first move near the step-down is the feed-forward: a cut of the override, a warning,
    # before the tool reaches the deep slot at the end of the step-down ramp (line 8, X25.4
    # Z-3). The ramp's rows predict a light cut (its chip is cos 79° of the feed per tooth,
    # decision 1673), so the cut comes in the ramp, once the deep rows are within the
    # feed-forward's revolutions of travel (before decision 1673, on line 7 before X = 25 mm)
    ev = [e for e in runs["with look-ahead"].events if e.name == "feed_override"]
    assert ev and all(e.nc_line is not None and e.x_mm is not None for e in ev)
    assert all(e.nc_line >= 1 for e in ev if e.nc_line is not None)
    step = [e for e in ev if e.x_mm is not None and 20.0 <= e.x_mm <= 26.0]
    first = step[0]
    assert first.nc_line in (7, 8) and first.x_mm is not None
    assert first.x_mm < ca.STEP_X_MM + 0.4
    assert first.severity == "warning" and (first.value or 0.0) < 0.8 * 136.0
    assert "look-ahead ceiling" in first.message


def _override_at_first_contact(run: ca.LoopRun) -> float:
    """Effective override when the true force first exceeds seed 002's air threshold (80 N)."""
    k = int(np.argmax(run.force > 80.0))
    assert run.force[k] > 80.0
    return float(run.override[k])


def test_lookahead_meets_the_material_at_the_reentry_feed(runs: dict[str, ca.LoopRun]) -> None:
    # decision 1626: in air with the cut within the horizon, the look-ahead run enters at
    # V_max/3 = 50 % (seed 002's re-entry feed, applied before the contact), where the
    # conventional run (no plan) is still at seed 002's air feed V_max = 150 % when it hits
    # the part (the first loaded revolution is what tells it)
    assert _override_at_first_contact(runs["with look-ahead"]) == pytest.approx(0.5, abs=1e-9)
    assert _override_at_first_contact(runs["conventional"]) == pytest.approx(1.5, abs=1e-9)


def test_lookahead_entry_verdict_does_not_cycle(runs: dict[str, ca.LoopRun]) -> None:
    # decision 1626: the "cut ahead" verdict is taken over the horizon at V_max; at the
    # override in force the horizon shrinks with the feed the verdict sets, and in air the
    # feed cycled 150 % ↔ 50 % every revolution: here at most the air rule's 150 % and the
    # re-entry 50 % are commanded before the contact
    run = runs["with look-ahead"]
    k = int(np.argmax(run.force > 80.0))
    changes = int(np.count_nonzero(np.abs(np.diff(run.override[:k])) > 1e-9))
    assert changes <= 2
