"""Seed 000's virtual threshold on a two-flute tool (decision 1742): a broken flute's
revolution keeps its torque because the other flute cuts its chip and rises; every flute below
the plan (the plan's error), or one flute losing its chip to runout while the other keeps its
own, is no broken flute, though the revolution's bound (1 − 0.5/2 − 0.1 = 65 %) passes both."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.monitoring.breakage import BreakageBlock
from millsense.streaming.block import Chunk

FS, RPM, FLUTES = 10000.0, 1000.0, 2
TOOTH = round(FS * 60 / RPM / FLUTES)  # 300 samples
EXPECTED = 3.0  # N·m per tooth period, the plan's
STEP = 100  # the period from which the cut changes


def _alarms(share_a: float, share_b: float) -> list:
    """The detector on 200 periods: both flutes at the plan's 3 N·m, from period STEP flute A
    (even periods) at ``share_a`` and flute B at ``share_b`` of it (0.1 chunks)."""
    m = np.arange(200 * TOOTH) // TOOTH
    share = np.where(m < STEP, 1.0, np.where(m % 2 == 0, share_a, share_b))
    tq = EXPECTED * share
    blk = BreakageBlock(FLUTES, "virtual", signal_channels=("tq",), speed_channel="w",
                        expected_channel="ex", min_expected_nm=0.5)  # fmt: skip
    blk.reset(FS)
    w = np.full(tq.size, RPM * 2 * math.pi / 60)
    ex = np.full(tq.size, EXPECTED)
    events = []
    for a in range(0, tq.size, 1000):
        data = {"tq": tq[a : a + 1000], "w": w[a : a + 1000], "ex": ex[a : a + 1000]}
        events += blk.process(Chunk(a, FS, 0.0, data)).events
    return events


@pytest.mark.parametrize(
    ("share_a", "share_b", "why"),
    [
        # the plan's error at every flute: A −44 %, B −24 % (revolution 66 %: in the bound)
        (0.56, 0.76, "every flute below the plan by more than half the band"),
        # runout: A cuts 35 % of its chip, B its own (revolution 68 %): B has not risen
        (0.35, 1.0, "the other flute does not cut the lost chip"),
    ],
)
def test_no_broken_flute_where_the_other_flute_does_not_rise(
    share_a: float, share_b: float, why: str
) -> None:
    """Both steps change the cut by a breakage's size at once (decision 1729's change) and
    flute A leaves the 40 % band each revolution, locked: before decision 1742 each alarmed at
    A's third violating period."""
    assert _alarms(share_a, share_b) == [], why


def test_a_broken_flute_of_two_is_still_found_in_three_violations() -> None:
    """Flute A broken: its edge force left (10 % of its torque), B cuts its chip (+70 %, the
    revolution 90 %): alarmed at the third violating period, A's drop, B's rise, A's drop
    again (period STEP + 2), as before decision 1742."""
    events = _alarms(0.1, 1.7)
    assert len(events) == 1
    period = round(events[0].time_s * FS / TOOTH) - 1
    assert period == STEP + 2
