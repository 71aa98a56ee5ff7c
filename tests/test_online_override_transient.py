"""Decision 1714: a feed-override change is a transient of the plan's expected torque until the
feed has followed it, so the breakage monitor does not read the plant's lag as a broken flute.

Found on the plainest cut: `millsense run` on a 3 mm slot with the default tool at 3000 rev/min
raised a breakage alarm and a feed hold on the intact tool at 1.936 s, 25 ms after the adaptive
feed stepped the override from 50 % (held through the entry) to 93.5 %: the expected torque
jumped with the CNC's override at once, the torque followed one to two tooth periods later, and
the flute pattern (decision 1684) read the lag's drop and the overshoot's rise as a broken
flute at 7.55σ.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core.config import FeedAxisConfig
from millsense.core.presets import commissioned_machine
from millsense.online._sync_kernels import OVERRIDE_STATE, override_transient_kernel
from millsense.online.plan_sync import (
    DEFAULT_FEED_TIME_CONSTANT_S,
    OVERRIDE_TRANSIENT_TOL,
    feed_time_constant_s,
)

FS = 10000.0


def _run_kernel(u: np.ndarray, tau_s: float, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """Steady rows of edge 0.3 and shear 1.0 × u through the kernel in ``chunk``-sample pieces:
    the steady flags and the floor (edge + shear part) after it."""
    n = u.size
    steady = np.ones(n, dtype=bool)
    values = np.zeros((11, n))
    values[3] = 0.3
    values[4] = 1.0 * u
    state = np.zeros(OVERRIDE_STATE)
    alpha = -math.expm1(-1.0 / (FS * tau_s))
    for a in range(0, n, chunk):
        b = min(a + chunk, n)
        s_part, v_part = steady[a:b].copy(), values[:, a:b].copy()
        override_transient_kernel(u[a:b], alpha, OVERRIDE_TRANSIENT_TOL, state, s_part, v_part)
        steady[a:b], values[:, a:b] = s_part, v_part
    return steady, values[8] + values[9]


@pytest.mark.parametrize("chunk", [1, 100, 777, 4000])
def test_an_override_step_is_a_transient_for_as_long_as_the_lag_says(chunk: int) -> None:
    """0.5 → 0.935 at sample 1000 (the adaptive feed's step of the finding): the lag
    u_f = u − δ(1 − α)^m after m samples (α = 1 − e^(−Δt/τ)) stays more than 10 % below u for
    m < (τ/Δt)·ln(δ/(0.1·u)) = 614.95 at τ = 40 ms (m = 1 at the step's sample): samples
    1000-1613 are a transient,
    whatever the chunking, with the floor the edge plus the shear part at the lag's override;
    before and after, steady."""
    u = np.full(4000, 0.5)
    u[1000:] = 0.935
    steady, floor = _run_kernel(u, DEFAULT_FEED_TIME_CONSTANT_S, chunk)
    m = DEFAULT_FEED_TIME_CONSTANT_S * FS * math.log(0.435 / (OVERRIDE_TRANSIENT_TOL * 0.935))
    assert m == pytest.approx(614.95, abs=0.01)
    transient = np.flatnonzero(~steady)
    assert transient[0] == 1000 and transient[-1] == 999 + math.floor(m)
    assert transient.size == math.floor(m)
    alpha = -math.expm1(-1.0 / (FS * DEFAULT_FEED_TIME_CONSTANT_S))
    k = np.arange(1000, 1000 + transient.size)
    lag = 0.935 - 0.435 * (1.0 - alpha) ** (k - 999)
    assert np.allclose(floor[transient], 0.3 + lag, rtol=1e-12)


def test_an_override_cut_is_judged_against_the_lower_override_and_small_moves_are_not() -> None:
    """A step down 1.0 → 0.6: the floor is the edge plus the shear part at the new, lower
    override at once (the plant comes down to it); the adaptive feed's moves inside its dead
    band (±5 %) never differ from their lag by 10 %: no transient."""
    u = np.full(3000, 1.0)
    u[500:] = 0.6
    steady, floor = _run_kernel(u, DEFAULT_FEED_TIME_CONSTANT_S, 100)
    assert not steady[500] and np.allclose(floor[~steady], 0.3 + 0.6)
    small = 1.0 + 0.05 * np.sign(np.sin(2 * np.pi * np.arange(3000) / 600.0))
    steady2, _ = _run_kernel(small, DEFAULT_FEED_TIME_CONSTANT_S, 100)
    assert steady2.all()


def test_a_feed_hold_is_no_transient() -> None:
    """An override falling to 0 (a feed hold) starts no transient: the plan then expects the
    edge torque alone, and the tooth period that straddles the hold is judged as before (a
    broken flute's pair completes there: `tests/test_online_session.py::
    test_run_and_replay_on_a_short_slot`); a resumption from 0 is a transient."""
    u = np.full(3000, 0.9)
    u[1000:2000] = 0.0
    steady, _ = _run_kernel(u, DEFAULT_FEED_TIME_CONSTANT_S, 100)
    assert steady[:2000].all()
    assert not steady[2000] and steady[2900:].all()


def test_the_feed_time_constant_is_twice_the_slowest_linear_position_loop() -> None:
    """The shipped commissioned quaser-ux600: K_v 62.8/s on X, Y and Z (the rotary A and C,
    47.1/s, are not the path's feed): 2/62.832 = 31.8 ms. Without a gain the drive's design
    from the velocity bandwidth, a quarter of its angular frequency, is the gain."""
    shipped = commissioned_machine("quaser-ux600")
    assert shipped is not None
    machine = shipped[0]
    assert feed_time_constant_s(machine) == pytest.approx(2.0 / 62.832, rel=1e-4)
    assert feed_time_constant_s(None) == DEFAULT_FEED_TIME_CONSTANT_S
    axis = next(a for a in machine.axes.values() if a.kind == "linear")
    bare = FeedAxisConfig.model_validate(
        {**axis.model_dump(), "position_gain_1_s": None, "velocity_bandwidth_hz": 40.0}
    )
    assert bare.position_gain() == pytest.approx(2 * math.pi * 40.0 / 4.0, rel=1e-12)


def test_the_slot_of_the_finding_runs_without_a_breakage_alarm(tmp_path: Path) -> None:
    """The finding's reproduction, to 2.5 s (past the override step at 1.91 s and the false
    alarm at 1.936 s): no breakage alarm and no feed hold on the intact tool."""
    from millsense.cli.main import main

    prog = tmp_path / "slot.nc"
    prog.write_text("G21 G90 G17\nT1 M6\nS3000 M3\nG0 X-12 Y40 Z5\nG0 Z-3\nG1 X60 F600\n"
                    "G0 Z20\nM30\n")  # fmt: skip
    stock = Path(__file__).resolve().parents[1] / "examples/demo_part/stock.toml"
    out = tmp_path / "slot.h5"
    try:
        main(["run", "--program", str(prog), "--stock", str(stock), "--tool",
              "aslan-d20-2flute", "--material", "al7050", "--duration-s", "2.5", "-o",
              str(out)])  # fmt: skip
    except SystemExit as exc:
        assert not exc.code
    import pyarrow.parquet as pq

    events = pq.read_table(out.with_suffix(".events.parquet")).to_pylist()
    names = [e["name"] for e in events]
    assert "feed_override" in names  # the adaptive feed's step is there
    assert "breakage" not in names and "feed_hold" not in names
