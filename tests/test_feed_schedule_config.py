"""The position-scheduled feed estimator built from a machine file (disturbance_modes_at)."""

from __future__ import annotations

import numpy as np
import pydantic
import pytest

from millsense.core.config import FeedAxisConfig, MachineConfig
from millsense.core.errors import ConfigError
from millsense.estimation.feed.schedule import ScheduledFeedEstimator
from millsense.estimation.from_config import build_estimators, load_channel
from millsense.simulator.machine_file import simulator_machine
from millsense.streaming.block import Chunk

FS = 10_000.0


def _machine(tables: list[dict[str, object]]) -> MachineConfig:
    m = simulator_machine("quaser-ux600")
    x = m.axes["x"]
    # Q fixed so the members' designs do not depend on a tuning search
    x = FeedAxisConfig.model_validate(
        x.model_dump() | {"disturbance_modes_at": tables, "estimator": {"q_nm2_s": 2000.0}}
    )
    return m.model_copy(update={"axes": {**m.axes, "x": x}})


def _tables(scales: tuple[float, ...], positions_mm: tuple[float, ...]) -> list[dict[str, object]]:
    base = simulator_machine("quaser-ux600").axes["x"].disturbance_modes
    assert base is not None
    out = []
    for s, p in zip(scales, positions_mm, strict=True):
        d = base.model_dump()
        d["natural_frequency_hz"] = [f * s for f in d["natural_frequency_hz"]]
        d["alpha"] = [a * s * s for a in d["alpha"]]
        out.append(d | {"position_mm": p})
    return out


def _run(machine: MachineConfig, n: int = 6000) -> np.ndarray:
    built = build_estimators(machine, ["feed"], ["x"], FS)
    block = built.blocks[0]
    block.reset(FS)
    rng = np.random.default_rng(3)
    t = np.arange(n) / FS
    data = {
        "x/current_cmd": 0.5 * np.sin(2 * np.pi * 37.0 * t) + 0.05 * rng.standard_normal(n),
        "x/motor_speed": 20.0 + 0.3 * rng.standard_normal(n),
        # the table moves from -150 mm to +150 mm: it crosses the middle member's support
        "x/position_cmd": np.linspace(-0.15, 0.15, n),
    }
    outs = [
        block.process(Chunk(s, FS, 0.0, {k: v[s : s + 500] for k, v in data.items()})).channels[
            load_channel("feed", "x")
        ]
        for s in range(0, n, 500)
    ]
    return np.concatenate(outs)


def test_identical_tables_give_the_single_model_estimate() -> None:
    # three identical Φ_d tables at -200/0/+200 mm: any interpolation of identical estimators
    # is that estimator, so the scheduled output equals the one-model estimate (members
    # starting mid-run are warmed up by replaying 1 s of torque: bumpless to ~1e-8 of range)
    same = _machine(_tables((1.0, 1.0, 1.0), (-200.0, 0.0, 200.0)))
    single = simulator_machine("quaser-ux600")
    x1 = FeedAxisConfig.model_validate(
        single.axes["x"].model_dump() | {"estimator": {"q_nm2_s": 2000.0}}
    )
    single = single.model_copy(update={"axes": {**single.axes, "x": x1}})
    built = build_estimators(same, ["feed"], ["x"], FS)
    assert isinstance(built.blocks[0].inner, ScheduledFeedEstimator)
    assert built.blocks[0].inner.bank.positions == pytest.approx((-0.2, 0.0, 0.2))
    a, b = _run(same), _run(single)
    assert np.max(np.abs(a - b)) <= 1e-6 * np.max(np.abs(b))


def test_different_tables_change_the_estimate_between_positions() -> None:
    # modes 3 % apart at the ends: the scheduled estimate must differ from the centre model's
    # by more than round-off (the schedule is really used)
    sched = _run(_machine(_tables((0.97, 1.0, 1.03), (-200.0, 0.0, 200.0))))
    centre = _run(_machine(_tables((1.0, 1.0, 1.0), (-200.0, 0.0, 200.0))))
    assert np.max(np.abs(sched - centre)) > 1e-3 * np.max(np.abs(centre))


def test_bad_tables_are_refused_with_one_line() -> None:
    with pytest.raises(pydantic.ValidationError, match="strictly ascending"):
        _machine(_tables((1.0, 1.0), (100.0, -100.0)))
    with pytest.raises(ConfigError, match="disturbance_modes_at"):
        build_estimators(
            _machine(_tables((1.0, 1.0), (-100.0, 100.0))), ["feed"], ["x"], FS, harmonic_teeth=2
        )
