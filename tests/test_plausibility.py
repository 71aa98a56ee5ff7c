"""The plausibility layer, the work ceilings and the simulator's crash events (issue 21)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core import budget
from millsense.core.config import MachineLimitsConfig, MaterialConfig, ToolConfig
from millsense.core.errors import ConfigError, ProgramError
from millsense.core.plausibility import (
    Findings,
    check_against_limits,
    check_cutting_moves,
    check_depth,
    check_feed_limit,
    check_modes,
    check_width,
)
from millsense.core.presets import load_preset
from millsense.plan.gcode import interpret
from millsense.plan.path import sample_path, vertex_path
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import EngagementSchedule, ProcessCoupling
from millsense.streaming.block import EventKind


def _label(k: int) -> str:
    return f"p.nc:{k + 10}"


# ------------------------------------------------------------------ depth, width, feed


def test_depth_500_mm_on_a_20_mm_tool_is_an_error() -> None:
    with pytest.raises(ConfigError, match=r"--depth-mm: axial depth 500 mm is more than 5 times"):
        check_depth(500.0, 20.0, "--depth-mm", Findings())


def test_depth_between_3_and_5_diameters_is_a_warning() -> None:
    f = Findings()
    check_depth(61.0, 20.0, "--depth-mm", f)  # 3.05 D
    assert len(f.warnings) == 1 and "61 mm" in f.warnings[0]
    check_depth(60.0, 20.0, "--depth-mm", f)  # exactly 3 D: plausible
    assert len(f.warnings) == 1


def test_depth_beyond_stickout_is_an_error() -> None:
    with pytest.raises(ConfigError, match="stickout 30 mm"):
        check_depth(35.0, 20.0, "--depth-mm", Findings(), stickout_mm=30.0)


def test_width_beyond_the_diameter_is_an_error() -> None:
    check_width(20.0, 20.0, "--engagement")  # a slot is a_e = D
    with pytest.raises(ConfigError, match=r"radial width 20.5 mm exceeds the tool diameter"):
        check_width(20.5, 20.0, "--engagement")


def test_feed_per_tooth_ranges() -> None:
    f = Findings()
    # F400 at 1000 rev/min, 2 teeth: f_z = 400 / (2 · 1000) = 0.2 mm: plausible
    check_cutting_moves([400.0], [1000.0], 2, 20.0, _label, f)
    assert f.warnings == []
    # F3000: 1.5 mm per tooth, above 0.5 mm: warning naming the line and the value
    check_cutting_moves([400.0, 3000.0, 3000.0], [1000.0] * 3, 2, 20.0, _label, f)
    assert f.warnings == ["p.nc:11: feed per tooth 1.5 mm is above 0.5 mm (implausibly coarse) "
                          "(2 cutting moves/steps)"]  # fmt: skip
    # F0.5: 0.25 µm per tooth: rubbing
    check_cutting_moves([0.5], [1000.0], 2, 20.0, _label, f)
    assert "0.00025 mm" in f.warnings[-1]
    # 1e9 mm/min: 5e5 mm per tooth, more than the 10 mm radius: impossible
    with pytest.raises(ConfigError, match=r"p.nc:10: .* 5e\+05 mm per tooth, more than the tool"):
        check_cutting_moves([1e9], [1000.0], 2, 20.0, _label, Findings())


def test_cutting_with_the_spindle_stopped_is_an_error() -> None:
    with pytest.raises(ProgramError, match=r"p.nc:11: the tool cuts with the spindle stopped"):
        check_cutting_moves(
            [400.0, 400.0], [1000.0, 0.0], 2, 20.0, _label, Findings(), error=ProgramError
        )


def test_spindle_above_the_machine_maximum_is_an_error() -> None:
    with pytest.raises(ConfigError, match="30000 rev/min exceeds the machine's max_rpm 24000"):
        check_cutting_moves([400.0], [30000.0], 2, 20.0, _label, Findings(), max_rpm=24000.0)


def test_feed_limit_machine_or_absolute() -> None:
    lim = MachineLimitsConfig(max_feed_mm_min=36000.0)
    check_feed_limit([np.nan, 36000.0], _label, lim)  # a rapid (NaN) and exactly the limit
    with pytest.raises(ConfigError, match=r"p.nc:11: feed 36001 mm/min exceeds 36000"):
        check_feed_limit([400.0, 36001.0], _label, lim)
    # no machine: 100 m/min
    check_feed_limit([99_999.0], _label, None)
    with pytest.raises(ConfigError, match="exceeds 100000 mm/min"):
        check_feed_limit([1e9], _label, None)


def test_modes_need_damping_and_stiffness() -> None:
    with pytest.raises(ConfigError, match=r"t.toml x\[1\]: damping_ratio = 0 must be > 0"):
        check_modes([900.0, 1200.0], [0.02, 0.0], [1e7, 1e7], "t.toml x", Findings())
    with pytest.raises(ConfigError, match=r"stiffness_n_m = 1e-09 must be ≥ 1000 N/m"):
        check_modes([900.0], [0.02], [1e-9], "t.toml x", Findings())
    f = Findings()
    check_modes([900.0], [1.5], [1e4], "t.toml y", f)
    assert len(f.warnings) == 2  # over-damped and soft


def test_limits_warn_on_force_and_power() -> None:
    lim = MachineLimitsConfig(spindle_power_kw=20.0, axis_force_n=9600.0)
    f = Findings()
    check_against_limits(lim, "p.nc:5", f, peak_force_n=9600.0, power_w=20e3)  # at the limits
    assert f.warnings == []
    check_against_limits(lim, "p.nc:5", f, peak_force_n=3e7, power_w=25e3)
    assert len(f.warnings) == 2 and "3e+07 N" in f.warnings[0] and "25 kW" in f.warnings[1]
    check_against_limits(None, "p.nc:5", f, peak_force_n=3e7)  # no machine: nothing
    assert len(f.warnings) == 2


def test_quaser_preset_has_limits() -> None:
    lim = simulator_machine("quaser-ux600").limits
    assert lim is not None
    # decision 0942: 20 N·m through a 12 mm lead at efficiency 0.92
    assert lim.axis_force_n == pytest.approx(20 * 2 * math.pi / 0.012 * 0.92, rel=0.01)
    assert lim.spindle_power_kw == 20.0 and lim.max_feed_mm_min == 36000.0


# ------------------------------------------------------------------ work ceilings


def test_plan_of_a_30_km_move_is_refused_before_allocating() -> None:
    tp = interpret("G21 G90\nS1000 M3\nG0 X0 Y0 Z0\nG1 X30000000 F400\nM30\n", source="big.nc")
    # 3e7 mm / 0.4 mm = 7.5e7 steps > 4e6
    with pytest.raises(ProgramError, match=r"big.nc: 3e\+04 m of path .* 7.5e\+07 steps.*line 4"):
        sample_path(tp, 0.4e-3)
    assert len(sample_path(interpret("G1 X1000 F400\nM30\n"), 0.4e-3)) == 2501  # 1 m: fine


def test_vertex_path_of_a_huge_arc_is_refused() -> None:
    # a full circle of 30 km radius at the 1 µm chord tolerance: 2π / (2·sqrt(2·1e-6/3e4))
    # ≈ 3.8e5 chords per turn; P20 turns ≈ 7.7e6 points > 4e6
    text = "G21 G90 G17\nS1000 M3\nG0 X0 Y0 Z0\nG2 X0 Y0 I30000000 J0 P20 F400\nM30\n"
    with pytest.raises(ProgramError, match=r"arc.nc: the path needs 7.\de\+06 points"):
        vertex_path(interpret(text, source="arc.nc"))


def test_signal_ceiling() -> None:
    budget.check_signal(budget.MAX_SIGNAL_S, "--duration-s", "shorter", ConfigError)
    with pytest.raises(ConfigError, match=r"--duration-s: 1e\+09 s of signal.*shorter"):
        budget.check_signal(1e9, "--duration-s", "shorter", ConfigError)


# ------------------------------------------------------------------ crash events

FEED = 0.1e-3 * 2 * 6000 / 60  # 0.1 mm/tooth at 6000 rev/min, 2 flutes: 20 mm/s
OMEGA = 6000 * 2 * math.pi / 60


def _sim(omega: float, limits: MachineLimitsConfig | None, duration: float) -> MachineSimulator:
    """A 2 mm slot from 1 mm along a straight move; at 6000 rev/min the spindle run-up and
    settling take 0.30 s before the feed starts."""
    m = simulator_machine("quaser-ux600")
    m = m.model_copy(
        update={"kinematics": "3-axis", "axes": {k: m.axes[k] for k in "xyz"}, "limits": limits}
    )
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    sched = EngagementSchedule.from_spec("slot", tool.diameter_m, 2e-3, start_m=0.001)
    process = ProcessCoupling(tool, coeffs, sched)
    job = Job.straight([0, 0, 0], [0.2, 0, 0], FEED, omega)
    return MachineSimulator(m, job, process, SimulatorOptions(seed=1), duration_s=duration)


def _run(sim: MachineSimulator) -> tuple[dict[str, np.ndarray], list]:  # type: ignore[type-arg]
    parts: dict[str, list[np.ndarray]] = {}
    events = []
    while (c := sim.read(700)) is not None:
        for k, v in c.data.items():
            parts.setdefault(k, []).append(v)
        events += sim.take_events()
    return {k: np.concatenate(v) for k, v in parts.items()}, events


def test_crash_when_the_tool_engages_with_the_spindle_stopped() -> None:
    data, events = _run(_sim(0.0, None, 0.25))
    assert [e.name for e in events] == ["spindle_stopped"]  # one event for a lasting crash
    ev = events[0]
    assert ev.kind is EventKind.CRASH and "spindle stopped" in ev.message
    # the event is at the first sample the recorded truth shows the tool in the stock
    first = int(np.argmax(data["truth/process/depth"] > 0)) / 10_000.0
    assert ev.time_s == pytest.approx(first, abs=1e-4)


def test_no_crash_in_a_plain_slot() -> None:
    # 2 mm slot at 0.1 mm/tooth: ~0.4 kN and ~1.5 kW, far below the UX600 limits
    _, events = _run(_sim(OMEGA, simulator_machine("quaser-ux600").limits, 0.55))
    assert events == []


def test_crash_beyond_the_axis_force_limit() -> None:
    data, events = _run(_sim(OMEGA, MachineLimitsConfig(axis_force_n=100.0), 0.55))
    assert [e.name for e in events] == ["axis_force"]
    ev = events[0]
    k = round(ev.time_s * 10_000.0)
    loads = np.abs(np.column_stack([data[f"truth/{a}/load"] for a in "xyz"]))
    # the event value is the recorded load at its time, and nothing before it exceeded 100 N
    assert loads[k].max() == pytest.approx(ev.value, rel=1e-12)
    assert ev.value > 100.0 and loads[: k - 30].max() <= 100.0


def test_crash_beyond_the_spindle_power_limit() -> None:
    sim = _sim(OMEGA, MachineLimitsConfig(spindle_power_kw=0.2), 0.55)
    data, events = _run(sim)
    assert [e.name for e in events] == ["spindle_power"]
    ev = events[0]
    k = round(ev.time_s * 10_000.0)
    # block mean of torque × speed from the recorded truth (block = sim.ratio samples)
    p = float(np.mean(data["truth/spindle/torque"][k : k + sim.ratio])) * OMEGA
    assert ev.value == pytest.approx(p, rel=0.02) and ev.value > 200.0


def test_zmap_beyond_the_cell_ceiling_is_refused() -> None:
    from millsense.plan.stock import ZMapStock

    # 100 × 80 mm at 1 µm: 1e5 × 8e4 = 8e9 cells > 2e8
    with pytest.raises(ConfigError, match=r"100000 × 80000 cells, beyond the ceiling of 2e\+08"):
        ZMapStock.from_box([0, 0, -0.03], [0.1, 0.08, 0], 1e-6)
