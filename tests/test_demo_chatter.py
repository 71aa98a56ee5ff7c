"""The demo's chatter-prone pass (issue 16 item 6; decision 1660): seed 000's T1 face mill
slotting Al7050 1.2 mm deep at 4500 rev/min, between two lobes, through the on-line session
with and without the chatter avoidance."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from millsense.demo_chatter import DEPTH_MM, quiet_after, run_chatter_demo, tool_modes_file


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("chatter-demo")
    return out, run_chatter_demo(out)


def _model():
    from millsense.control.chatter_avoidance import StabilityModel
    from millsense.stability.cases import load_case

    with resources.as_file(tool_modes_file()) as path:
        return StabilityModel(load_case(path), DEPTH_MM)


def test_open_pass_chatters(demo: tuple[Path, dict]) -> None:
    # the pass is chatter-prone: 4500 rev/min lies between lobes (the SDM limit of the tool
    # file is below the 1.2 mm cut), and with nothing sent the truth chatters in most of the
    # cut and the monitor alarms
    assert float(_model().lowest_unstable_depth_mm(np.array([4500.0]))[0]) < DEPTH_MM
    r = demo[1]["runs"]["open"]
    assert r["truth_chatter_share"] > 0.8
    assert r["alarm_s"] is not None
    assert abs(r["last_rpm"] - 4500.0) < 0.01 * 4500.0  # nothing reached the spindle


def test_controlled_pass_one_change_to_a_stable_speed_and_quiet_within_1_s(
    demo: tuple[Path, dict],
) -> None:
    ctl, opn = demo[1]["runs"]["controlled"], demo[1]["runs"]["open"]
    # the same signal up to the first alarm: the same alarm time in both runs
    assert ctl["alarm_s"] == pytest.approx(opn["alarm_s"], abs=1e-9)
    # seed 000 C13 / issue 16: one speed change, to a speed the lobes call stable at the
    # pass's depth (an SDM check independent of the pocket search), and the truth's chatter
    # gone within 1 s of it
    assert ctl["speed_commands"] == 1
    limit = float(_model().lowest_unstable_depth_mm(np.array([ctl["last_rpm"]]))[0])
    assert limit > DEPTH_MM
    assert ctl["stopped"] is True
    assert ctl["quiet_after_command_s"] <= 1.0
    assert ctl["truth_chatter_share"] < 0.5 * opn["truth_chatter_share"]


def test_outputs_written(demo: tuple[Path, dict]) -> None:
    out, summary = demo
    for name in ("online_chatter.nc", "online_chatter.h5", "online_chatter.events.parquet",
                 "online_chatter_open.events.parquet", "online_chatter.png"):  # fmt: skip
        assert (out / name).stat().st_size > 0, name
    on_disk = json.loads((out / "online_chatter_summary.json").read_text())
    assert on_disk["runs"]["controlled"]["speed_commands"] == summary["runs"]["controlled"][
        "speed_commands"
    ]


def test_quiet_after() -> None:
    # 1 s windows at 10 Hz: chatter until sample 12, then quiet; from sample 5 the first quiet
    # second starts at sample 13 → 0.8 s; never quiet → inf
    flag = np.zeros(40, dtype=bool)
    flag[:13] = True
    assert quiet_after(flag, 5, 10.0) == pytest.approx(0.8)
    assert quiet_after(np.ones(40, dtype=bool), 0, 10.0) == float("inf")


@pytest.mark.parametrize("seed", [0, 3])
def test_demo_seed_reaches_every_part(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """`millsense demo --seed S`: the on-line part's virtual machine runs seed S and the
    chatter pass's CHATTER_SEED + S (before, both ignored the option and always ran 0 and 11).
    The simulator is stopped at its construction, its options recorded."""
    from millsense import demo_chatter, demo_online
    from millsense.simulator import machine

    seen: list[int] = []

    class Stop(Exception):
        pass

    def fake_init(self: object, cfg: object, job: object, proc: object, opts: object) -> None:
        seen.append(int(opts.seed))  # type: ignore[attr-defined]
        raise Stop

    monkeypatch.setattr(machine.MachineSimulator, "__init__", fake_init)
    for part in (demo_online, demo_chatter):  # stopped before the plan is read
        with pytest.raises(Stop):
            part._run(None, part._plant_plan(), True, None, None, None, seed=seed)  # type: ignore[arg-type]
    assert seen == [seed, demo_chatter.CHATTER_SEED + seed]
