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
    # of the × 1.38 step (+38 % at the same feed) whatever the channel (decision 1617), far
    # from the thesis' 10 % through the open CNC; the closed channel (10 % steps, 120 ms)
    # cannot take the feed back sooner than the open one. Measured on the plant's own plan and
    # material (decisions 1740, 1798): 39.8 % open, 51.0 % closed since the RLS projection
    # (decision 1657; 37.3 / 59.0 % before it, 39.6 / 51.5 % on the preset's coefficients,
    # 34.0 / 44.3 % when the plant cut the controller's plan)
    open_, closed = (ca.step_rise_pct(runs[k]) for k in ("open CNC", "closed CNC"))
    assert 30.0 <= open_ <= 55.0
    assert closed >= open_


def test_closed_cnc_settles_at_least_twice_as_slowly(runs) -> None:
    # seed 002 V6: transients last longer with the closed CNC (120 ms against 2.5 ms)
    # (measured 2.07 s and 4.59 s on the plant's own plan and material, decision 1798; 1.17 s
    # and 2.73 s on the preset's coefficients, decision 1740)
    a, b = ca.settle_s(runs["open CNC"]), ca.settle_s(runs["closed CNC"])
    assert a <= 2.5
    assert b >= 2.0 * a


def test_closed_cnc_needs_more_moves(runs) -> None:
    # the 10 % quantisation makes the closed-CNC loop hunt: more override commands
    assert runs["closed CNC"].n_events >= 2 * runs["open CNC"].n_events


def test_over_the_six_seeds() -> None:
    # decision 1667: V6 judged as V8, on the machine's six seeds. Open: median 37.7 %
    # (37.2-39.8 %), the documented gap of decision 1617 on every seed. Closed: median 59.5 %
    # (50.6-59.6 %), inside the thesis' 75 % ± 20 % (from a lathe), and above the open
    # channel's on every seed; the closed CNC settles at least twice as slowly on every seed
    by_seed = ca.v6_seed_runs()
    rises = {k: [ca.step_rise_pct(r[k]) for r in by_seed.values()] for k in ca._v6_runs()}
    assert all(30.0 <= v <= 55.0 for v in rises["open CNC"])
    assert all(c > o for c, o in zip(rises["closed CNC"], rises["open CNC"], strict=True))
    med = sorted(rises["closed CNC"])
    assert 55.0 <= 0.5 * (med[2] + med[3]) <= 95.0
    for r in by_seed.values():
        assert ca.settle_s(r["closed CNC"]) >= 2.0 * ca.settle_s(r["open CNC"])
