"""Decision 1731: when a breakage shows, from the virtual machine's truth."""

import math

import numpy as np
import pytest

from millsense.validation.cases._breakage_effect import EFFECT_DROP, TruthTorque, effect_onset_s

FS = 10000.0
TOOTH_S = 0.0025  # 25 samples


def _torque(seconds: float = 2.0) -> np.ndarray:
    t = np.arange(int(seconds * FS)) / FS
    return 2.0 + 0.3 * np.sin(2 * math.pi * t / TOOTH_S)  # a tooth-periodic cut


def test_a_step_loss_shows_when_the_tooth_mean_has_lost_five_percent():
    # closed form: a loss of a fraction L from t_d lowers the tooth period's mean by
    # L·(t − t_d)/T (the ripple's mean over a whole period is 0): 5 % after 0.05·T/L
    intact = _torque()
    broken = intact.copy()
    t_d, loss = 1.0 + 2.0 * TOOTH_S, 0.5
    broken[int(t_d * FS) :] *= 1.0 - loss
    onset = effect_onset_s(broken, intact, FS, TOOTH_S, break_s=1.0)
    # the mean ripple term is not exactly 0 over a partial period: one sample's slack
    assert onset == pytest.approx(t_d + EFFECT_DROP * TOOTH_S / loss, abs=1.5 / FS)


def test_no_loss_after_the_break_never_shows_and_a_difference_before_it_is_ignored():
    intact = _torque()
    broken = intact.copy()
    broken[1000:1500] *= 0.2  # before the break: not the break's effect
    assert math.isinf(effect_onset_s(broken, intact, FS, TOOTH_S, break_s=1.0))


def test_a_rise_is_no_breakage_effect():
    intact = _torque()
    broken = intact.copy()
    broken[12000:] *= 1.5  # the torque rose: a break takes torque away
    assert math.isinf(effect_onset_s(broken, intact, FS, TOOTH_S, break_s=1.0))


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="positive tooth period"):
        effect_onset_s(_torque(), _torque(), FS, 0.0, 1.0)
    with pytest.raises(ValueError, match="two torque records"):
        effect_onset_s(np.zeros(0), _torque(), FS, TOOTH_S, 1.0)


def test_truth_torque_keeps_the_chunks_in_order():
    from millsense.streaming.block import Chunk

    grab = TruthTorque()
    x = np.arange(250.0)
    for i in range(0, 250, 100):
        grab(Chunk(i, FS, 0.0, {TruthTorque.CHANNEL: x[i : i + 100]}), {}, [])
    assert np.array_equal(grab.torque, x)
    assert grab.sample_rate_hz == FS


def test_latency_counts_the_first_alarm_after_the_break_from_the_origin():
    from millsense.validation.cases._breakage_effect import latency_periods

    alarms = [0.5, 1.004, 1.010]  # one before the break (not this break's), then two
    assert latency_periods(alarms, 1.0, 1.001, 0.001) == pytest.approx(3.0)
    assert latency_periods(alarms, 1.0, 1.0, 0.001) == pytest.approx(4.0)
    assert latency_periods(alarms, 1.0, 1.006, 0.001) == pytest.approx(-2.0)  # before it showed
    assert math.isinf(latency_periods([0.5], 1.0, 1.0, 0.001))
    assert math.isinf(latency_periods(alarms, 1.0, math.inf, 0.001))
