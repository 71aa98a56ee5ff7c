"""Decision 1707: seed 002's dual detector without a plan alarms at a broken flute's drop and
the next flute's rise, not at a change of the whole cut.

A 2-flute tool at 1000 rev/min (300 samples a tooth period), tooth-period torques with a
little noise, seed 002's detector learning its thresholds on the first 5 revolutions of a
steady 3 N·m cut; the tooth-period levels make the cut's events: a broken flute (its periods
0.2 N·m, the next flute's 5.5 N·m: it cuts the chip as well), an exit (the torque falls to
0.3 N·m over 3 revolutions), a step (it rises to 4.5 N·m within a revolution), an entry into a
cavity (it falls to 1.5 N·m within a revolution).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.monitoring.breakage import BreakageBlock
from millsense.validation.cases.monitoring_breakage import run_block

FS = 10000.0
RPM = 1000.0
TOOTH = 300  # samples a tooth period, 2 flutes
AT = 100  # the period where the event starts


def _data(levels: np.ndarray) -> dict[str, np.ndarray]:
    period = np.arange(levels.size * TOOTH) // TOOTH
    rng = np.random.default_rng(5)
    return {
        "tq": levels[period] + 0.02 * rng.standard_normal(period.size),
        "w": np.full(period.size, RPM * 2 * math.pi / 60),
    }


def _block(check: bool) -> BreakageBlock:
    return BreakageBlock(2, "dual", signal_channels=("tq",), speed_channel="w", flute_check=check)


def _events(levels: np.ndarray, check: bool) -> list:
    events, _ = run_block(_block(check), _data(levels), 100)
    return events


def _levels(kind: str) -> np.ndarray:
    p = np.arange(200)
    steady = np.full(p.size, 3.0)
    if kind == "break":
        return np.where(p >= AT, np.where(p % 2 == AT % 2, 0.2, 5.5), steady)
    if kind == "exit":
        return np.interp(p, [AT, AT + 6], [3.0, 0.3])
    if kind == "step":
        return np.interp(p, [AT, AT + 2], [3.0, 4.5])
    return np.interp(p, [AT, AT + 2], [3.0, 1.5])  # a cavity


@pytest.mark.parametrize("kind", ["exit", "step", "cavity"])
def test_a_change_of_the_whole_cut_is_no_breakage(kind: str) -> None:
    """Seed 002's detector alarms at the exit, the step and the cavity (both residuals beyond
    their thresholds); with the flute check none is a broken flute: neighbouring flutes move
    the same way."""
    assert _events(_levels(kind), check=False)
    assert _events(_levels(kind), check=True) == []


def test_a_broken_flute_alarms_at_the_next_flutes_rise() -> None:
    """The break alarms once with the check, at the next flute's rise (its own residuals beyond
    both thresholds), one period after the seed's alarm at the drop."""
    seed = _events(_levels("break"), check=False)
    checked = _events(_levels("break"), check=True)
    assert [e.values["tooth_period"] for e in seed] == [AT]
    assert [e.values["tooth_period"] for e in checked] == [AT + 1]
    ev = checked[0]
    assert ev.sample == (AT + 2) * TOOTH  # reported at the end of the rise's period
    assert abs(ev.values["residual2_nm"]) > ev.values["limit2_nm"]
    assert "one flute's drop and the next flute's rise" in ev.message


@pytest.mark.parametrize(("rise", "alarms"), [(3.4, 0), (4.0, 1), (9.0, 0)])
def test_the_rise_is_the_drops_chip(rise: float, alarms: int) -> None:
    """Flute 0 drops from 3.0 to 1.0 N·m (2 N·m); the next flute's rise alarms where it is
    between 0.4 and 2.5 times the drop (1 − edge share 0.5 − tolerance 0.1: it cuts the drop's
    chip without a second edge force): +1.0 N·m (0.5×) is one; +0.4 N·m (0.2×: the cut's torque
    fell) and +6 N·m (3×: the cut's torque rose) are not."""
    p = np.arange(200)
    levels = np.where(p >= AT, np.where(p % 2 == AT % 2, 1.0, rise), 3.0)
    assert len(_events(levels, check=True)) == alarms


def test_the_next_flutes_rise_may_come_first() -> None:
    """The break may fall before the periods' boundary: the next flute's period rises first
    (it cut what the broken flute left), the broken flute's drops after it; the pair alarms at
    the drop."""
    p = np.arange(200)
    levels = np.where(p >= AT, np.where(p % 2 == AT % 2, 4.0, 1.0), 3.0)
    ev = _events(levels, check=True)
    assert [e.values["tooth_period"] for e in ev] == [AT + 1]


def test_a_pair_completed_by_a_period_inside_the_thresholds_alarms_there() -> None:
    """After a flute's drop the next residual ε2 = Δ_N x − φ̂2·Δ_N x(m−1) is small where φ̂2 < 0
    (here −0.5, held by a small covariance) and the rise is half the drop: the rise's period
    does not violate, and completes the pair of the drop's violation. The alarm comes there,
    with the drop's residuals and the line saying so."""
    from millsense.monitoring import _tooth_kernels as k
    from millsense.streaming.block import Chunk

    p = np.arange(200)
    data = _data(np.where(p >= AT, np.where(p % 2 == AT % 2, 1.0, 4.0), 3.0))
    blk = _block(True)
    blk.reset(FS)
    split = (AT - 4) * TOOTH
    blk.process(Chunk(0, FS, 0.0, {c: v[:split] for c, v in data.items()}))
    blk._det[k.DET_PHI2] = -0.5
    blk._det[k.DET_P2] = 1e-9
    out = blk.process(Chunk(split, FS, 0.0, {c: v[split:] for c, v in data.items()}))
    (ev,) = out.events
    assert ev.values["tooth_period"] == AT + 1
    assert abs(ev.values["residual2_nm"]) < ev.values["limit2_nm"]  # the rise's own
    assert abs(ev.values["violation_residual2_nm"]) > ev.values["limit2_nm"]  # the drop's
    assert "at the period before" in ev.message
