"""Chatter avoidance (issue 16 item 3): the lobe speed rule, the stability check, the block,
seed 001's pitch shift (Table 6-4) and seed 002's depth reduction by program rewriting."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from millsense.control.chatter_avoidance import (
    AvoidanceSettings,
    ChatterAvoidanceBlock,
    SpeedLimits,
    StabilityModel,
    choose_spindle_speed,
    lobe_speeds_rpm,
)
from millsense.control.depth_reduction import (
    cutting_passes,
    split_deep_passes,
    write_split_program,
)
from millsense.control.pitch_shift import phase_difference_rad, pitch_shift_rad, turret_offsets_m
from millsense.core.errors import ConfigError, ProgramError
from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings
from millsense.stability.cases import compute_lobes
from millsense.streaming.block import Chunk, EventKind, Severity

FS = 10_000.0

# ------------------------------------------------------------------------------------------
# the speed rule
# ------------------------------------------------------------------------------------------


def test_lobe_speeds_are_the_closed_form() -> None:
    # Ω_j = 60 f_c / (N j): 511.3 Hz, 5 flutes → 6135.6, 3067.8, 2045.2 rev/min
    got = lobe_speeds_rpm(511.3, 5, [1, 2, 3])
    np.testing.assert_allclose(got, [6135.6, 3067.8, 2045.2], rtol=1e-12)


@pytest.mark.parametrize(("f_c", "rpm", "flutes"), [(511.3, 4500.0, 5), (937.0, 6000.0, 4),
                                                    (771.0, 5000.0, 2)])  # fmt: skip
def test_without_model_nearest_faster_lobe_is_smith_tlusty(
    f_c: float, rpm: float, flutes: int
) -> None:
    """Independent computation: j = ⌊f_c / f_t⌋ with f_t = N·rpm/60 (decision 1508's
    suggested speed), when inside the limits."""
    rec = choose_spindle_speed(f_c, flutes, rpm, limits=SpeedLimits(50, 150))
    assert rec is not None
    j = math.floor(f_c / (flutes * rpm / 60.0))
    expect = 60.0 * f_c / (flutes * j)
    assert rec.lobe_number == j
    assert rec.spindle_rpm == pytest.approx(expect, rel=1e-12)
    assert rec.override_pct == pytest.approx(100 * expect / rpm, rel=1e-12)
    assert rec.spindle_rpm > rpm and not rec.checked
    assert math.isnan(rec.margin_mm) and "not checked" in rec.reason


def test_limits_are_never_exceeded() -> None:
    # 511.3 Hz, 5 flutes at 4000 rev/min: lobe 1 is 6135.6 rev/min = 153 % (beyond 150 %), so
    # the nearest faster lobe inside is absent and the nearest slower one (j = 2, 76.7 %) wins
    rec = choose_spindle_speed(511.3, 5, 4000.0, limits=SpeedLimits(50, 150))
    assert rec is not None and rec.lobe_number == 2
    assert rec.override_pct == pytest.approx(100 * 3067.8 / 4000.0, rel=1e-9)
    assert "nearest slower" in rec.reason
    for c in rec.candidates:
        assert 50.0 <= c.override_pct <= 150.0
    # a machine speed ceiling of 3000 rev/min removes lobe 2 as well
    rec = choose_spindle_speed(511.3, 5, 4000.0, limits=SpeedLimits(50, 150, max_rpm=3000.0))
    assert rec is not None and rec.spindle_rpm <= 3000.0 and rec.lobe_number == 3
    # nothing inside 95-105 %: no recommendation
    assert choose_spindle_speed(511.3, 5, 4000.0, limits=SpeedLimits(95, 105)) is None
    with pytest.raises(ConfigError):
        SpeedLimits(110, 150)
    with pytest.raises(ConfigError):
        choose_spindle_speed(-1.0, 5, 4000.0)


_MODEL: list[StabilityModel] = []


def _t1(depth_mm: float) -> StabilityModel:
    """The T1 V5 replica's stability case as the controller has it (validation.cases.
    control_chatter_avoidance: the modes fitted to a simulated tap test of the Aslan Table
    5.3-5.4 tool, decision 1750; 5 flutes, slot, Al7050), one cache for all depths."""
    from millsense.validation.cases.control_chatter_avoidance import stability_case

    if not _MODEL:
        _MODEL.append(StabilityModel(stability_case(), 1.0))
    return _MODEL[0].at_depth(depth_mm)


def _zoa_pocket(model: StabilityModel, rpm: float, lo: float, hi: float) -> tuple[float, float]:
    """The stable speeds around ``rpm`` at the model's depth on a fine ZOA scan (independent of
    the block's 0.5 % grid): (lowest, highest) rev/min inside [lo, hi]."""
    grid = np.geomspace(lo, hi, 4001)
    ok = compute_lobes(model.case, method="zoa", rpm=grid).critical_depth_m * 1e3 > model.depth_mm
    i = int(np.argmin(np.abs(grid - rpm)))
    assert ok[i]
    below = np.flatnonzero(~ok[:i])
    above = np.flatnonzero(~ok[i:])
    first = below[-1] + 1 if below.size else 0
    last = i + above[0] - 1 if above.size else grid.size - 1
    return float(grid[first]), float(grid[last])


def test_with_model_the_largest_margin_wins_and_is_stable() -> None:
    """Chatter at 511.3 Hz (the closed-loop case's alarm) at 4500 rev/min, 1.2 mm: the
    candidates inside 50-150 % are j = 1 (6135.6 rev/min, 136 %) and j = 2 (3067.8, 68 %).
    Independent computation: the zero-order (Altintas-Budak) limit of the same case, which for
    this full-immersion 5-flute cut agrees with SDM within 2 % (its approximation error).
    Decision 1635: the speed commanded is the geometric centre of lobe 1's stable pocket (cut
    by the 150 % limit at 6750 rev/min), within the 0.5 % grid of the fine scan's."""
    model = _t1(1.2)
    rec = choose_spindle_speed(511.3, 5, 4500.0, limits=SpeedLimits(50, 150), model=model)
    assert rec is not None and rec.checked
    assert [c.lobe for c in rec.candidates] == [1, 2]
    speeds = np.array([c.spindle_rpm for c in rec.candidates])
    zoa = compute_lobes(model.case, method="zoa", rpm=speeds).critical_depth_m * 1e3
    np.testing.assert_allclose([c.lowest_unstable_depth_mm for c in rec.candidates], zoa, rtol=0.02)
    assert rec.lobe_number == int(np.argmax(zoa)) + 1 == 1
    lo, hi = _zoa_pocket(model, 6135.6, 2250.0, 6750.0)
    assert hi == pytest.approx(6750.0)
    np.testing.assert_allclose(rec.pocket_rpm, (lo, hi), rtol=0.006)
    assert rec.spindle_rpm == pytest.approx(math.sqrt(lo * hi), rel=0.006)
    assert rec.speed_margin == pytest.approx(math.sqrt(hi / lo) - 1.0, abs=0.006)
    assert rec.margin_mm == pytest.approx(rec.lowest_unstable_depth_mm - 1.2)
    assert rec.predicted_stable and rec.margin_mm > 1.0
    # lobe 2 is unstable at 1.2 mm: the nearest-lobe rule alone could have picked it
    assert rec.candidates[1].lowest_unstable_depth_mm < 1.2


def test_centred_speed_survives_a_softer_tool_where_the_lobe_speed_does_not() -> None:
    """Decision 1635 on the T1 session's alarm (554.1 Hz at 4500 rev/min, 1.2 mm): the lobe
    speed 60 f_c/N = 6649 rev/min lies on the steep right flank of lobe 1; with every tool mode
    8 % softer than the model's (the truth's modes under the slot's load) it is unstable at
    1.2 mm, while the centred speed keeps a margin. Independent: ZOA of the softened case."""
    from dataclasses import replace

    from millsense.stability.modal import ModalModel, Mode

    model = _t1(1.2)
    rec = choose_spindle_speed(554.1, 5, 4500.0, limits=SpeedLimits(50, 150), model=model)
    assert rec is not None and rec.predicted_stable and rec.lobe_number == 1
    lobe_rpm = 60.0 * 554.1 / 5
    assert rec.spindle_rpm < 0.95 * lobe_rpm

    def soft(ms: tuple[Mode, ...]) -> tuple[Mode, ...]:
        return tuple(Mode(m.omega * 0.92, m.zeta, m.alpha * 0.92**2) for m in ms)

    st = model.case.structure
    case = replace(model.case, structure=ModalModel(x=soft(st.x), y=soft(st.y)))
    depth = compute_lobes(case, method="zoa", rpm=np.array([lobe_rpm, rec.spindle_rpm]))
    lobe_mm, centred_mm = depth.critical_depth_m * 1e3
    assert lobe_mm < 1.2 < centred_mm


def test_with_model_no_stable_candidate_says_reduce_the_depth() -> None:
    rec = choose_spindle_speed(511.3, 5, 4500.0, limits=SpeedLimits(50, 150), model=_t1(5.0))
    assert rec is not None and not rec.predicted_stable and rec.lobe_number == 1
    assert rec.margin_mm == pytest.approx(rec.lowest_unstable_depth_mm - 5.0)
    assert "reduce the depth" in rec.reason


# ------------------------------------------------------------------------------------------
# the block on a synthetic signal
# ------------------------------------------------------------------------------------------


def _signal(dur: float = 2.6, rpm: float = 4500.0, onset: float = 1.2, fc: float = 511.3,
            flutes: int = 5, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Air (noise) for 0.6 s, then a cut: tooth-passing harmonics of ``flutes`` teeth; from
    ``onset`` a chatter line at ``fc`` (speed in rad/s)."""
    rng = np.random.default_rng(seed)
    n = int(dur * FS)
    t = np.arange(n) / FS
    ang = 2 * np.pi * rpm / 60 * t
    x = sum(np.cos(k * flutes * ang + 0.2 * k) / k for k in range(1, 12)) * (t >= 0.6)
    x = x + 0.02 * rng.standard_normal(n)
    x = x + 3.0 * np.clip((t - onset) / 0.02, 0, 1) * np.cos(2 * np.pi * fc * t)
    return np.asarray(x), np.full(n, rpm * 2 * np.pi / 60)


def _block(act: bool = True, settle_s: float = 0.8) -> ChatterAvoidanceBlock:
    mon = ChatterMonitor(ChatterSettings(method="chatter-comb", signal="s", n_flutes=5))
    return ChatterAvoidanceBlock(mon, AvoidanceSettings(act=act, settle_s=settle_s))


def _run(block: ChatterAvoidanceBlock, x: np.ndarray, spd: np.ndarray, chunk: int,
         nc: np.ndarray | None = None):  # type: ignore[no-untyped-def]  # fmt: skip
    block.reset(FS)
    outs: dict[str, list[np.ndarray]] = {}
    events = []
    for s in range(0, len(x), chunk):
        data = {"s": x[s : s + chunk], "spindle/speed": spd[s : s + chunk]}
        o = block.process(Chunk(s, FS, 0.0, data))
        for k, v in o.channels.items():
            outs.setdefault(k, []).append(np.asarray(v))
        events += o.events
    return {k: np.concatenate(v) for k, v in outs.items()}, events


def test_block_passes_the_alarm_and_commands_the_lobe_speed() -> None:
    x, spd = _signal()
    block = _block()
    ch, ev = _run(block, x, spd, 1000)
    alarms = [e for e in ev if e.kind is EventKind.ALARM and e.name == "chatter"]
    cmds = [e for e in ev if e.kind is EventKind.OVERRIDE]
    assert len(alarms) == 1 and alarms[0].source == "chatter-comb"  # passed on unchanged
    c = cmds[0]
    assert c.name == "spindle_override" and c.source == "chatter_avoidance"
    assert c.time_s == alarms[0].time_s and c.severity is Severity.WARNING
    # independent: Ω = 60 f_c / (N j) with the detected f_c, j = ⌊f_c / f_t⌋ = 1
    f_c = float(alarms[0].value or 0.0)
    assert f_c == pytest.approx(511.3, abs=1.5)  # the monitor's frequency resolution
    assert c.value == pytest.approx(100 * 60 * f_c / 5 / 4500.0, rel=1e-6)
    assert f"{60 * f_c / 5:.0f} rev/min" in c.message
    # the held output follows the command from its sample on
    k = c.sample
    out = ch["chatter_avoidance/spindle_override_pct"]
    k2 = cmds[1].sample if len(cmds) > 1 else len(out)
    assert np.all(out[:k] == 100.0) and np.all(out[k:k2] == pytest.approx(c.value))
    # chatter persists (the synthetic speed does not change): the block acts again on the
    # monitor's next chatter decision after the settle time, never sooner
    assert all(b.time_s - a.time_s >= 0.8 - 1e-9 for a, b in itertools.pairwise(cmds))
    assert "chatter-comb/chatter_hz" in ch


def test_recommendation_only_when_not_acting() -> None:
    x, spd = _signal()
    _, ev = _run(_block(act=False), x, spd, 1000)
    assert not [e for e in ev if e.kind is EventKind.OVERRIDE]
    notes = [e for e in ev if e.name == "spindle_recommendation"]
    assert len(notes) == 1 and notes[0].kind is EventKind.NOTE
    assert notes[0].severity is Severity.WARNING and "recommended" in notes[0].message


def test_block_acts_again_on_persisting_chatter_after_the_settle_time() -> None:
    """A speed change that does not cure the chatter (the synthetic stream keeps it): the
    monitor flags chatter at the new speed only once its window is steady; the block acts
    again no earlier than settle_s after its first command, and stays inside the limits."""
    x, spd = _signal(dur=4.0)
    block = _block(settle_s=0.5)
    _, ev = _run(block, x, spd, 1000)
    cmds = [e for e in ev if e.kind is EventKind.OVERRIDE]
    assert cmds
    times = [e.time_s for e in cmds]
    assert all(b - a >= 0.5 - 1e-9 for a, b in itertools.pairwise(times))
    assert all(50.0 <= float(e.value or 0.0) <= 150.0 for e in cmds)


@pytest.mark.parametrize("chunk", [1, 7, 100])
def test_chunk_size_invariance(chunk: int) -> None:
    x, spd = _signal(dur=1.9)
    whole_ch, whole_ev = _run(_block(settle_s=0.3), x, spd, len(x))
    ch, ev = _run(_block(settle_s=0.3), x, spd, chunk)
    assert [e.as_dict() for e in ev] == [e.as_dict() for e in whole_ev]
    assert any(e.kind is EventKind.OVERRIDE for e in ev)
    for k, v in whole_ch.items():
        np.testing.assert_array_equal(ch[k], v, err_msg=k)


def test_block_with_a_model_never_commands_a_speed_predicted_unstable() -> None:
    """At 5 mm no lobe speed of the T1 case is stable inside 50-150 %: the block warns and
    advises a depth reduction (seed 002) instead of changing the speed."""
    x, spd = _signal()
    mon = ChatterMonitor(ChatterSettings(method="chatter-comb", signal="s", n_flutes=5))
    block = ChatterAvoidanceBlock(mon, model=_t1(5.0))
    _, ev = _run(block, x, spd, 1000)
    assert not [e for e in ev if e.kind is EventKind.OVERRIDE]
    warn = [e for e in ev if e.name == "no_stable_speed"]
    assert len(warn) == 1 and warn[0].severity is Severity.WARNING
    assert "reduce the depth" in warn[0].message
    assert warn[0].values["margin_mm"] < 0
    # at 1.2 mm the same alarm gives the lobe-1 speed with a positive margin
    block = ChatterAvoidanceBlock(mon, model=_t1(1.2))
    _, ev = _run(block, x, spd, 1000)
    cmd = next(e for e in ev if e.kind is EventKind.OVERRIDE)
    assert cmd.values["lobe_number"] == 1 and cmd.values["margin_mm"] > 1.0


def test_depth_channel_judges_the_lobes_at_the_plans_depth() -> None:
    """The model built at 1.2 mm but the plan's depth channel at 5 mm where it chatters: the
    block judges at 5 mm (no stable speed, as the model built at 5 mm says); at 1.2 mm from the
    channel it commands the lobe-1 speed."""
    from dataclasses import replace

    x, spd = _signal()
    mon = ChatterMonitor(ChatterSettings(method="chatter-comb", signal="s", n_flutes=5))
    settings = AvoidanceSettings(depth_channel="plan/axial_depth")
    for depth_m, expect_cmd in ((5.0e-3, False), (1.2e-3, True)):
        block = ChatterAvoidanceBlock(mon, replace(settings), model=_t1(1.2))
        block.reset(FS)
        events = []
        for a in range(0, len(x), 1000):
            data = {"s": x[a : a + 1000], "spindle/speed": spd[a : a + 1000],
                    "plan/axial_depth": np.full(len(x[a : a + 1000]), depth_m)}  # fmt: skip
            events += block.process(Chunk(a, FS, 0.0, data)).events
        cmds = [e for e in events if e.kind is EventKind.OVERRIDE]
        assert bool(cmds) is expect_cmd
        if not expect_cmd:
            warn = [e for e in events if e.name == "no_stable_speed"]
            assert warn and warn[0].values["margin_mm"] < 0


def test_events_carry_the_monitor_location() -> None:
    x, spd = _signal()

    def locate(t: float, nc: int | None) -> tuple[int | None, float, float, float]:
        return 42, 1.0 + t, 2.0, -1.2

    mon = ChatterMonitor(ChatterSettings(method="chatter-comb", signal="s", n_flutes=5), locate)
    block = ChatterAvoidanceBlock(mon)
    _, ev = _run(block, x, spd, 1000)
    cmd = next(e for e in ev if e.kind is EventKind.OVERRIDE)
    alarm = next(e for e in ev if e.kind is EventKind.ALARM)
    assert (cmd.nc_line, cmd.x_mm, cmd.y_mm, cmd.z_mm) == (42, alarm.x_mm, 2.0, -1.2)


# ------------------------------------------------------------------------------------------
# seed 001: pitch shift in parallel turning
# ------------------------------------------------------------------------------------------


def test_pitch_shift_5_52_degrees() -> None:
    # Yamada Eq. 6-10, m = 0, S = 1200 min⁻¹, f_c = 652 Hz: 5.52° printed (rounded to 0.01°),
    # so the tolerance is ± half the last digit
    deg = math.degrees(float(pitch_shift_rad(652.0, 1200.0)))
    assert deg == pytest.approx(5.52, abs=0.005)
    # closed form: π·1200/(60·652) rad
    assert float(pitch_shift_rad(652.0, 1200.0)) == pytest.approx(math.pi * 1200 / 39120, 1e-14)
    # Eq. 6-9 inverts Eq. 6-10: Δε = π (m = 0), 3π (m = 1)
    for m in (0, 1, 3):
        d = pitch_shift_rad(652.0, 1200.0, m)
        assert float(phase_difference_rad(d, 652.0, 1200.0)) == pytest.approx((2 * m + 1) * np.pi)


#: Table 6-4 (f_c = 652 Hz, S = 1200 min⁻¹): Δε/π, Δθ/2 °, d mm, Δx₁ µm, Δy′₁ µm.
TABLE_6_4 = [
    (0.5, 1.38, 23.4, 3.4, 281.8), (0.6, 1.66, 23.7, 5.0, 343.3), (0.7, 1.94, 24.1, 6.9, 407.9),
    (0.8, 2.21, 24.5, 9.1, 472.4), (0.9, 2.49, 24.5, 11.6, 532.2), (1.1, 3.05, 22.9, 16.2, 609.2),
    (1.15, 3.19, 22.5, 17.4, 626.0), (1.2, 3.32, 24.9, 20.9, 721.0),
]  # fmt: skip


@pytest.mark.parametrize("row", TABLE_6_4)
def test_table_6_4(row: tuple[float, float, float, float, float]) -> None:
    """Eq. 6-9 and the turret-1 offsets on the printed angles.

    The printed Δθ/2 are the angles set on the turret: they differ from Eq. 6-10 of the
    nominal Δε by up to 0.015° (Δε 1.15π: 3.175° by the equation, 3.19° printed), more than
    their 0.005° rounding, so Eq. 6-9 of the printed angle must give the nominal Δε within
    0.006π (the largest such deviation, 0.0055π at 1.15π; 0.005° of rounding alone is
    0.0036π). The offsets Δx₁ = d/2 (1 − cos Δθ/2), Δy′₁ = d/2 sin Δθ/2 of the printed angle
    and diameter reproduce the table to half its last digit (0.05 µm)."""
    eps, half_deg, d_mm, dx_um, dy_um = row
    dtheta = 2.0 * math.radians(half_deg)
    assert float(phase_difference_rad(dtheta, 652.0, 1200.0)) / np.pi == pytest.approx(
        eps, abs=0.006
    )
    # and Eq. 6-10 (with Δε for 2π(m + ½)) inverts Eq. 6-9 exactly
    m_half = eps / 2.0  # Δε = 2π·m_half
    assert float(pitch_shift_rad(652.0, 1200.0, 0)) * m_half / 0.5 == pytest.approx(
        eps * np.pi * 1200.0 / (60.0 * 652.0), rel=1e-14
    )
    dx, dy = turret_offsets_m(dtheta, d_mm * 1e-3)
    assert float(dx) * 1e6 == pytest.approx(dx_um, abs=0.05)
    assert float(dy) * 1e6 == pytest.approx(dy_um, abs=0.05)


# ------------------------------------------------------------------------------------------
# seed 002: depth reduction by program rewriting
# ------------------------------------------------------------------------------------------

PROGRAM = """(slot 6 mm deep and a shallow slot with a ramp)
G21 G90 G17
T1 M6
S1000 M3
G0 X-12 Y20 Z5
G1 Z-6 F400
X72
G0 Z5
G0 X-12 Y50
G1 Z-1.5 F300
X30
X30.4 Z-2
X72
G0 Z5
M30
"""


def _stock_after(text: str) -> np.ndarray:
    from millsense.plan.gcode import interpret
    from millsense.plan.stock import ZMapStock

    tp = interpret(text)
    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], 0.5e-3)
    pts = np.concatenate([tp.start[:1, :3], tp.end[:, :3]])
    stock.remove_path(10e-3, "flat", pts[:, 0], pts[:, 1], pts[:, 2])
    return stock.heights.copy()


def test_deep_pass_split_into_passes_at_or_below_the_limit() -> None:
    res = split_deep_passes(PROGRAM, 2.5)
    # 6 mm → ⌈6/2.5⌉ = 3 passes at 2, 4, 6 mm; the 2 mm slot stays one pass
    assert [p.depth_mm for p in res.passes_before] == pytest.approx([6.0, 2.0])
    assert [p.depth_mm for p in res.passes_after] == pytest.approx([2.0, 4.0, 6.0, 2.0])
    assert len(res.split) == 1 and res.split[0][1] == 3
    steps = np.diff([0.0, *[p.depth_mm for p in res.passes_after[:3]]])
    assert np.all(steps <= 2.5 + 1e-9)
    # the same geometry finally reached: the swept stock is identical, and so is the end point
    np.testing.assert_array_equal(_stock_after(res.text), _stock_after(PROGRAM))
    from millsense.plan.gcode import interpret

    a, b = interpret(PROGRAM), interpret(res.text)
    np.testing.assert_allclose(b.end[-1], a.end[-1])
    assert float(b.end[:, 2].min()) == pytest.approx(-6e-3)


def test_ramp_pass_and_a_limit_above_every_pass() -> None:
    res = split_deep_passes(PROGRAM, 1.0)
    # 6 mm → 6 passes, the 2 mm ramp → 2 (1.0 and 2.0 mm)
    assert [round(p.depth_mm, 6) for p in res.passes_after] == [1, 2, 3, 4, 5, 6, 1, 2]
    np.testing.assert_array_equal(_stock_after(res.text), _stock_after(PROGRAM))
    same = split_deep_passes(PROGRAM, 6.0)
    assert same.text == PROGRAM and not same.split


def test_pass_entered_by_a_rapid_beside_the_part_keeps_each_pass_at_its_level() -> None:
    """CAM posts rapid down beside the part (in air) and feed in: 'G0 Z-6' at X-12, then
    'G1 X60'. The copies started at Z-6 and ramped up to their level, and after the retract
    to Z2 the programmed pass ran at Z2, in air: a 4 mm slot where 6 mm was programmed
    (2 passes reported for 3). Each copy now starts at its level, the last at Z-6: passes
    at 2, 4 and 6 mm and the stock of the programmed slot."""
    text = "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\nG0 Z-6\nG1 X60 F400\nG0 Z5\nM30\n"
    res = split_deep_passes(text, 2.5)
    assert [p.depth_mm for p in res.passes_after] == pytest.approx([2.0, 4.0, 6.0], abs=1e-9)
    np.testing.assert_array_equal(_stock_after(res.text), _stock_after(text))


def test_write_split_program_atomic_and_never_onto_its_input(tmp_path: Path) -> None:
    src = tmp_path / "slot.nc"
    src.write_text(PROGRAM)
    dst = tmp_path / "slot_2p5.nc"
    res = write_split_program(src, dst, 2.5)
    assert dst.read_text() == res.text
    assert len(cutting_passes(dst.read_text())) == 4
    assert not list(tmp_path.glob(".*tmp*"))
    with pytest.raises(ConfigError):
        write_split_program(src, src, 2.5)
    with pytest.raises(ProgramError):
        split_deep_passes("G91\nG1 Z-3 F100\n", 1.0)


def test_pocket_is_judged_on_the_truth_softened_at_the_slot_load() -> None:
    """Decision 1750: the stable-pocket case reads the plant's table softened as under the
    cut's load. Independent: the mean slot torque in closed form, T = R a N (2 K_tc h + π K_te)
    / 2π (full immersion, sin φ integrates to 2 over the half turn) for T1 at 0.1 mm/tooth and
    1.2 mm with the plant's true coefficients (decision 1798: K_tc 758 × 1.06, K_te 25 × 1.15
    N/mm²), 5.99 N·m, through the realism's scale 1 − 0.184 T/T_ref (T_ref 10 N·m) and
    1 − 0.03 (Ω/Ω_max)² (24000 rev/min), rounded to 1 %: 0.89 at 6107 rev/min."""
    from millsense.simulator.plant_plan import PLANT_LOT_FACTORS
    from millsense.simulator.realism import LOAD_SHIFT
    from millsense.validation.cases.control_chatter_avoidance import (
        load_scale,
        truth_case,
        truth_modes,
    )

    ktc, kte = 758e6 * PLANT_LOT_FACTORS["ktc"], 25e3 * PLANT_LOT_FACTORS["kte"]
    torque = 0.025 * 1.2e-3 * 5 * (2 * ktc * 0.1e-3 + math.pi * kte) / (2 * math.pi)
    scale = (1 - LOAD_SHIFT * torque / 10.0) * (1 - 0.03 * (6107.0 / 24000.0) ** 2)
    assert load_scale(6107.0) == pytest.approx(round(scale, 2), abs=1e-12) == 0.89
    soft = truth_case(0.9).structure
    np.testing.assert_allclose([m.natural_frequency_hz for m in soft.y],
                               0.9 * truth_modes().y.natural_hz, rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose([m.stiffness for m in soft.y],
                               truth_modes().y.stiffness_n_per_m, rtol=1e-12)  # fmt: skip
