"""Decision 1733: the plan's expected torque follows the CNC's path feed, so a move that stops
in the material is a transient, not a broken flute.

Found by running the general breakage cuts (`validation/cases/monitoring_breakage_general.py`)
intact with other seeds of the virtual machine: every cut ends with `G1 X90` inside the block
and retracts. Over the last few tenths of a millimetre the path decelerates to the end point,
and the chip thins with it. The plan, at the programmed feed times the override, said steady.
With seeds 0-39, the flute pattern confirmed a break on the intact tool in 28 of the 240 runs
before decisions 1732 and 1733, in 14 with decision 1732 alone, and in none with both. Each
alarm came within 15 ms of the move's end.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from millsense.online._sync_kernels import plan_rows_kernel


def _rows(u: np.ndarray, feed: np.ndarray, feed_table: np.ndarray) -> np.ndarray:
    """``plan_rows_kernel`` over three rows matched at samples 0, 4 and 8 (rows 0, 1, 2) with
    shear torque 2.0 per row: returns the u it used (written in place) and checks the shear
    part follows it."""
    n = u.size
    at = np.array([0, 4, 8], dtype=np.int64)
    matched = np.array([0, 1, 2], dtype=np.int64)
    ones = np.ones(4, dtype=bool)
    table = np.array([0.3, 0.3, 0.3, 0.0])
    shear = np.array([2.0, 2.0, 2.0, 0.0])
    rows = np.empty(n, dtype=np.int64)
    values = np.empty((11, n))
    flags = np.empty((2, n), dtype=bool)
    plan_rows_kernel(at, matched, -1, u, feed, feed_table, ones, table, shear,
                     np.zeros(4, dtype=np.int64), ones, np.zeros(4), np.zeros(4), np.zeros(4),
                     rows, values, flags[0], flags[1])  # fmt: skip
    assert np.allclose(values[4], 2.0 * u, rtol=1e-12)
    return u


def test_u_is_the_path_feed_over_the_rows_programmed_feed() -> None:
    """Rows 0 and 1 programmed at 0.025 m/s (1500 mm/min), row 2 with none (a rapid): u is
    |path feed| / 0.025 on rows 0-1, the override where the row has no programmed feed, and the
    override everywhere without a path feed."""
    feed = np.array([0.025, 0.025, 0.0125, 0.0125, 0.005, -0.005, 0.0, 0.0, 0.3, 0.3])
    table = np.array([0.025, 0.025, 0.0, 0.0])
    u = _rows(np.full(10, 0.8), feed, table)
    assert np.allclose(u[:8], [1.0, 1.0, 0.5, 0.5, 0.2, 0.2, 0.0, 0.0], rtol=1e-12)
    assert np.allclose(u[8:], 0.8)
    assert np.allclose(_rows(np.full(10, 0.8), np.empty(0), table), 0.8)


#: The NC line of the cut's retract in :func:`~millsense.validation.cases.
#: monitoring_breakage_general._program` (the 8th line of the file: the G1 X90 cut is the 7th).
RETRACT_LINE = 8


def _false_alarms(seed: int, feed_channel: bool) -> tuple[list[float], float]:
    """Breakage alarms of `run`'s session on the intact 4-flute slot at 6000 rev/min (a general
    cut), virtual machine seed ``seed``, with or without the path feed in the plan sync, and
    the time the CNC left the cut's move for the retract (s)."""
    from millsense.core.config import ToolConfig
    from millsense.online import session
    from millsense.validation.cases._program_session import program_session
    from millsense.validation.cases.monitoring_breakage_general import _program

    left: list[float] = []

    def watch(chunk: Any, _out: Any, _events: Any) -> None:
        at = np.flatnonzero(np.asarray(chunk.data["cnc/nc_line"]) == RETRACT_LINE)
        if at.size and not left:
            left.append((chunk.start + int(at[0])) / chunk.sample_rate_hz)

    path = session.PATH_FEED
    try:
        if not feed_channel:
            session.PATH_FEED = "no/such/channel"
        with tempfile.TemporaryDirectory() as tmp:
            prog = Path(tmp) / "slot.nc"
            prog.write_text(_program(6000, "slot", 1500, 4.0))
            tool = ToolConfig(diameter_mm=12.0, flutes=4, helix_deg=35.0)
            res = program_session(prog, tool, seed=seed, observer=watch).result
    finally:
        session.PATH_FEED = path
    return [e.time_s for e in res.events if e.name == "breakage"], left[0]


#: Two of the finding's runs (the flute pattern at 11.05σ and 8.4σ, 0.03 s before the move's
#: end on an AMD EPYC host, where the path decelerated to X90). Which of them alarms again
#: without the path feed depends on the host's floating point (seed 36 gives none on an Intel
#: Xeon): the test needs one of them to.
FINDING_SEEDS = (24, 36)


def test_a_move_stopping_in_the_material_is_no_broken_flute() -> None:
    """Without the path feed the alarm comes back at the move's end in one of the finding's
    runs at least, and only there (from 0.1 s before the CNC leaves the move, the cut's last
    0.3 mm at 1500 mm/min and the deceleration, to 0.03 s after it); with it neither run
    alarms."""
    without = {seed: _false_alarms(seed, feed_channel=False) for seed in FINDING_SEEDS}
    assert any(times for times, _ in without.values()), without
    for times, end in without.values():
        assert all(end - 0.1 < t < end + 0.03 for t in times), without
    for seed in FINDING_SEEDS:
        assert _false_alarms(seed, feed_channel=True)[0] == [], seed
