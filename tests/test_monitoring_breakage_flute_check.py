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
    assert "at the violating period before" in ev.message


def _flute_levels(n_flutes: int, changes: dict[int, float]) -> np.ndarray:
    """Tooth-period levels of an N-flute tool in a steady 3 N·m cut; from period AT on, the
    periods AT + j of every revolution change by ``changes[j]`` N·m (a break's lasting
    pattern: one revolution later the lag-N differences are back at zero)."""
    p = np.arange(100 * n_flutes)
    levels = np.full(p.size, 3.0)
    for j, d in changes.items():
        levels[(p >= AT) & ((p - AT) % n_flutes == j)] += d
    return levels


def _flute_events(n_flutes: int, levels: np.ndarray, check: bool = True) -> list:
    tooth = round(FS * 60.0 / RPM / n_flutes)
    period = np.arange(levels.size * tooth) // tooth
    rng = np.random.default_rng(5)
    data = {
        "tq": levels[period] + 0.02 * rng.standard_normal(period.size),
        "w": np.full(period.size, RPM * 2 * math.pi / 60),
    }
    blk = BreakageBlock(n_flutes, "dual", signal_channels=("tq",), speed_channel="w",
                        flute_check=check)  # fmt: skip
    events, _ = run_block(blk, data, 100)
    return events


@pytest.mark.parametrize("n_flutes", [3, 4])
def test_the_next_flutes_rise_may_come_a_period_later(n_flutes: int) -> None:
    """Decision 1724: a flute's torque in a slot spans half a revolution, more than one tooth
    period of a 3- or 4-flute tool. The broken flute's drop (−2 N·m) and the next flute's rise
    (+1 N·m) then fall in periods two apart, the period between them keeping its torque (the
    rest of the drop and the start of the rise cancel), as the virtual machine's 3-flute slot
    at 1500 rev/min shows (−2.0, +0.0, +0.9 N·m). The pair alarms at the rise; decision
    1707's consecutive pair saw none."""
    levels = _flute_levels(n_flutes, {0: -2.0, 2: 1.0})
    seed = _flute_events(n_flutes, levels, check=False)
    assert seed[0].values["tooth_period"] == AT  # the seed's first, at the drop
    (ev,) = _flute_events(n_flutes, levels)
    assert ev.values["tooth_period"] == AT + 2
    assert abs(ev.values["residual2_nm"]) > ev.values["limit2_nm"]  # the rise's own
    assert "the next flute's rise" in ev.message


def test_a_pair_beyond_half_a_revolution_is_no_breakage() -> None:
    """Decision 1724's reach is ⌈N/2⌉ periods: a 4-flute tool's drop and a rise three periods
    later (the flute before it, not the next one) is no broken flute's pattern; the seed's
    detector alarms at the drop."""
    levels = _flute_levels(4, {0: -2.0, 3: 1.0})
    assert _flute_events(4, levels, check=False)
    assert _flute_events(4, levels) == []


def test_the_reach_is_half_the_flutes() -> None:
    """⌈N/2⌉ periods, consecutive (1) for a 2-flute tool as decision 1707 had it."""
    from millsense.monitoring._tooth_kernels import pair_reach

    assert [pair_reach(n) for n in (1, 2, 3, 4, 5, 6)] == [1, 1, 2, 2, 3, 3]


def test_a_rise_inside_the_thresholds_completes_a_drop_two_periods_before() -> None:
    """Decision 1724 with decision 1707's waiting violation: a 3-flute tool's drop violates,
    the period after it keeps its torque, and the rise two periods after the drop is no
    violation (φ̂1 = 0.5 held: ε1 = Δx − φ̂1·Δx(m−1) = 1 − 0.5·2 = 0, inside a threshold of
    0.1 N·m). The rise completes the
    drop's pair and alarms, with the drop's residuals."""
    from millsense.monitoring import _tooth_kernels as k
    from millsense.streaming.block import Chunk

    n = 3
    tooth = round(FS * 60.0 / RPM / n)
    levels = _flute_levels(n, {0: -2.0, 2: 1.0})
    period = np.arange(levels.size * tooth) // tooth
    rng = np.random.default_rng(5)
    data = {"tq": levels[period] + 0.02 * rng.standard_normal(period.size),
            "w": np.full(period.size, RPM * 2 * math.pi / 60)}  # fmt: skip
    blk = BreakageBlock(n, "dual", signal_channels=("tq",), speed_channel="w", flute_check=True)
    blk.reset(FS)
    split = (AT - 4) * tooth
    blk.process(Chunk(0, FS, 0.0, {c: v[:split] for c, v in data.items()}))
    blk._det[k.DET_PHI1] = 0.5
    blk._det[k.DET_P1] = 1e-9
    blk._det[k.DET_THR1] = blk._det[k.DET_THR2] = 0.1  # the noise's 0.01 N·m would be too fine
    events = []
    for i in range(split, period.size, 100):
        chunk = Chunk(i, FS, 0.0, {c: v[i : i + 100] for c, v in data.items()})
        events += blk.process(chunk).events
    (ev,) = events
    assert ev.values["tooth_period"] == AT + 2
    assert abs(ev.values["residual1_nm"]) < ev.values["limit1_nm"]  # the rise's own
    assert abs(ev.values["violation_residual1_nm"]) > ev.values["limit1_nm"]  # the drop's
    assert abs(ev.values["violation_residual2_nm"]) > ev.values["limit2_nm"]
    assert "at the violating period before" in ev.message


def _constant_events(levels: np.ndarray, check: bool) -> list:
    blk = BreakageBlock(2, "constant", signal_channels=("tq",), speed_channel="w",
                        flute_check=check)  # fmt: skip
    events, _ = run_block(blk, _data(levels), 100)
    return events


def _sudden(kind: str) -> np.ndarray:
    """The whole cut changed within a period: a G0 retract out of a slot (3.0 -> 0.1 N·m), or a
    jump into more material (3.0 -> 4.5 N·m)."""
    p = np.arange(200)
    after, between = (0.1, 1.5) if kind == "retract" else (4.5, 4.5)
    return np.where(p > AT, after, np.where(p == AT, between, 3.0))


@pytest.mark.parametrize("kind", ["retract", "jump"])
def test_the_constant_reference_takes_no_whole_cut_for_a_breakage(kind: str) -> None:
    """Decision 1724: the constant reference alarms at a retract and at a sudden jump of the
    cut, where every flute's torque leaves the reference's band on the same side (seed 000's
    false alarm, which `monitor` without a plan gave at every retract of a 3-flute cut); with
    the flute check, none: no flute moves the other way."""
    assert _constant_events(_sudden(kind), check=False)
    assert _constant_events(_sudden(kind), check=True) == []


def test_the_constant_reference_alarms_at_a_broken_flute_with_the_check() -> None:
    """Decision 1724: a broken flute's drop and the next flute's rise over one revolution ago
    start the constant reference's running violation: the checked detector alarms at the same
    period as the seed's, its third violating period."""
    seed = _constant_events(_levels("break"), check=False)
    checked = _constant_events(_levels("break"), check=True)
    assert seed
    assert [e.values["tooth_period"] for e in checked] == [seed[0].values["tooth_period"]]
    assert "the next flute's rise" in checked[0].message
