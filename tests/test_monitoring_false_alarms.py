"""False alarms of the chatter monitors: the short CI version of
``monitoring.chatter.false_alarms_10min`` (60 s instead of 600 s, sensor channel only).

The stream (:func:`~millsense.validation.cases.monitoring_chatter.stable_stream`) is stable by
construction (static mechanistic forces, no regeneration): 5 s segments with speed changes,
80-120 % overrides, depth steps and air cuts, the feed force through a 1500 Hz resonance plus a
steady 1234 Hz tone and noise. Any chatter alarm is a false alarm.
"""

from __future__ import annotations

import pytest

from millsense.validation.cases.monitoring_chatter import detect, stable_stream


@pytest.mark.parametrize("seed", [1, 2])
def test_no_false_alarm_in_a_minute_of_stable_cutting(seed: int) -> None:
    d = stable_stream(60.0, seed=seed, spindle=False)
    for method, threshold in (("chatter-comb", 1.5), ("chatter-sdft", 0.5)):
        ev, ratio = detect(d["sensor"], d["spindle/speed"], 2, method)
        assert ev == []
        assert ratio.max() < 0.7 * threshold  # a margin, not a near miss
