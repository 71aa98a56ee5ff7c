"""Benchmark of the breakage and engagement monitors on a 10 kHz stream (issue 15).

The three breakage blocks (virtual threshold with an expected-torque channel, constant
threshold, dual residual on two force channels) and the per-revolution engagement monitor run
together on 60 s of a synthetic 10 kHz stream at 1000 rev/min (a 2-flute Ø20 mm cut's torque),
in 10 ms and in 0.1 s chunks, after compilation; the breakage blocks alone are reported too,
and the three in one compiled call (as ``millsense monitor`` runs them). The virtual threshold
runs at three phases of the tooth period (decision 1552); ``monitoring.breakage_phases`` times
that against the seed's single phase side by side.
"""

from __future__ import annotations

import numpy as np

from _harness import Metric, alternated, benchmark
from _monitoring_stream import _blocks, _stream, _time_blocks

FS = 10000.0


def _run(
    data: dict[str, np.ndarray], chunk: int, engagement: bool = True, grouped: bool = False
) -> float:
    return _time_blocks(_blocks(engagement, grouped), data, chunk)


@benchmark("monitoring.breakage_speed")
def _speed() -> list[Metric]:
    _run(_stream(1.0), 100)  # compile / load the numba cache
    seconds = 60.0
    data = _stream(seconds)
    out = []
    cases = ((True, False, "all"), (False, False, "breakage"), (False, True, "group"))
    for engagement, grouped, what in cases:
        for chunk, label in ((100, "10ms"), (1000, "100ms")):
            wall = _run(data, chunk, engagement, grouped)
            note = ("3 breakage detectors (virtual at three phases) in one compiled call"
                    if grouped else "3 breakage blocks (virtual at three phases)")
            note += " + engagement (1000 rev/min)" if engagement else ""
            out.append(
                Metric(
                    f"x_realtime_{what}_{label}",
                    seconds / wall,
                    "x",
                    target=500.0,
                    note=f"{note}, {seconds:.0f} s at 10 kHz, {label} chunks, one core, best of 3",
                )
            )
    return out


@benchmark("monitoring.breakage_phases")
def _phases() -> list[Metric]:
    """The three detectors with the virtual one at three phases (decision 1552) against the
    same with one phase (a plain ``BreakageGroup`` of the three), alternated, best of 3 each."""
    from millsense.monitoring.breakage import BreakageBlock, BreakageGroup
    from millsense.streaming.block import Block

    def single() -> list[Block]:
        return [BreakageGroup([BreakageBlock(2, "virtual", expected_channel="plan/torque"),
                               BreakageBlock(2, "constant"),
                               BreakageBlock(2, "dual", signal_channels=("force_x", "force_y"))])]

    _run(_stream(1.0), 100, False, True)
    _time_blocks(single(), _stream(1.0), 100, repeats=1)
    seconds = 60.0
    data = _stream(seconds)
    out = []
    for chunk, label in ((100, "10ms"), (1000, "100ms")):
        three, one = alternated(
            lambda c=chunk: _time_blocks(_blocks(False, True), data, c, repeats=1),
            lambda c=chunk: _time_blocks(single(), data, c, repeats=1),
            3,
        )
        note = (f"3 breakage detectors in one compiled call, {seconds:.0f} s at 10 kHz, {label} "
                "chunks, one core, best of 3 alternated")
        out += [
            Metric(f"x_realtime_single_phase_{label}", seconds / one, "x", note=note),
            Metric(f"x_realtime_three_phases_{label}", seconds / three, "x", note=note),
            Metric(f"time_ratio_three_to_single_{label}", three / one, "x",
                   higher_is_better=False, note=note + " (the phases' cost)"),
        ]
    return out
