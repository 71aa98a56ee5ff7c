"""Seed 002 V6 in closed loop (issue 16 item 2): the conventional adaptive controller at a
× 1.38 depth step through the open-CNC channel and the closed-CNC override switch (10 % steps,
120 ms). Pins the documented gap of the first peak (decision 1617) and the reproduced longer
transient of the closed CNC (≈ 20 s)."""

from __future__ import annotations

import pytest

from millsense.validation.cases import control_adaptive as ca


@pytest.fixture(scope="module")
def runs() -> dict[str, ca.LoopRun]:
    return ca._v6_runs()


def test_first_peak_carries_the_step_through_either_channel(runs) -> None:
    # the deeper layer engages at the tool's front at once: the first revolution carries most
    # of the × 1.38 step (+38 % at the same feed) whatever the channel (decision 1617); on the
    # plant's own plan (decision 1740: 5 µm of runout the controller's plan does not know on
    # top of the step) 39.6 % open and 51.5 % closed were measured (34.0 / 44.3 % when the
    # plant cut the controller's plan); far from the thesis' 10 % either way
    for k in ("open CNC", "closed CNC"):
        assert 30.0 <= ca.step_rise_pct(runs[k]) <= 55.0


def test_closed_cnc_settles_at_least_twice_as_slowly(runs) -> None:
    # seed 002 V6: transients last longer with the closed CNC (120 ms against 2.5 ms)
    # (measured 1.17 s and 2.73 s on the plant's own plan, decision 1740)
    a, b = ca.settle_s(runs["open CNC"]), ca.settle_s(runs["closed CNC"])
    assert a <= 1.3
    assert b >= 2.0 * a


def test_closed_cnc_needs_more_moves(runs) -> None:
    # the 10 % quantisation makes the closed-CNC loop hunt: more override commands
    assert runs["closed CNC"].n_events >= 2 * runs["open CNC"].n_events
