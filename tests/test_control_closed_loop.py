"""Seed 000 V8 in closed loop on the virtual machine (issue 16 item 2): the adaptive feed
controller with and without the virtual look-ahead on a slot with a step-down (engagement jump
× 2.5) and an exit (``millsense.validation.cases.control_adaptive``; ≈ 20 s)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.validation.cases import control_adaptive as ca


@pytest.fixture(scope="module")
def runs() -> dict[str, ca.LoopRun]:
    return ca._v8_runs()


def test_lookahead_holds_the_reference(runs: dict[str, ca.LoopRun]) -> None:
    # seed 000 V8: ACwithVF stays within ±5 % of F_r = 325 N, no overshoot at the jump
    la = runs["with look-ahead"]
    assert np.max(la.force) <= 1.05 * ca.F_REF_V8
    after = (la.x_mm > 30.0) & (la.x_mm < 45.0)  # steady at the full depth
    assert np.all(np.abs(np.max(la.force[after]) / ca.F_REF_V8 - 1.0) <= 0.05)


def test_lookahead_never_speeds_up_at_the_exit(runs: dict[str, ca.LoopRun]) -> None:
    assert ca.exit_speedup_pct(runs["with look-ahead"]) <= 0.5


def test_conventional_overshoots_like_the_thesis(runs: dict[str, ca.LoopRun]) -> None:
    # seed 000 V8: ≈ 800 N at A (read off a figure): the jump × 2.5 at ≈ 133 % → ≈ 880 N in
    # the first revolution, before the once-per-revolution controller can act
    conv = runs["conventional"]
    assert 0.85 * 800.0 <= np.max(conv.force) <= 1.15 * 800.0
    i = int(np.argmax(conv.force))
    assert ca.STEP_X_MM <= conv.x_mm[i] <= ca.STEP_X_MM + 3.0  # at the step, not elsewhere


def test_conventional_speeds_up_at_the_exit(runs: dict[str, ca.LoopRun]) -> None:
    assert ca.exit_speedup_pct(runs["conventional"]) > 10.0


def test_plan_events_carry_nc_line_and_position() -> None:
    # the override events of the look-ahead run name the NC line and the plan position
    from millsense.control.adaptive_feed import AdaptiveFeedBlock
    from millsense.plan.virtual_plan import VirtualPlan

    plan = ca.step_plan(ca.DEPTH_LOW_MM, ca.DEPTH_HIGH_MM)
    assert isinstance(plan, VirtualPlan)
    blk = AdaptiveFeedBlock(plan=plan)
    assert set(blk.inputs) >= {"x/position_cmd", "y/position_cmd", "z/position_cmd"}
