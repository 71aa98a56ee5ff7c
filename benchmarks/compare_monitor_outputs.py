"""Replay the monitoring.all_speed streams and compare every output channel and event of two
versions.

Used to check that a speed-up of the process monitors leaves their outputs alone (issue 15's
speed work): ``save`` runs the blocks of :mod:`bench_monitoring_all` (the chatter group, the
grouped breakage detectors, the engagement monitor) in a :class:`~millsense.streaming.engine.
Pipeline` on 20 s of its clean stream and of the same cut with the sensorless estimate's noise,
in 10 ms, 0.1 s and 73-sample chunks, and pickles every output channel and event; ``diff``
compares two such files as :mod:`compare_online_outputs` does (``--tol``: relative, per
sample).

    cd benchmarks
    PYTHONPATH=../src python compare_monitor_outputs.py save /tmp/before.pkl
    ... change the code ...
    PYTHONPATH=../src python compare_monitor_outputs.py save /tmp/after.pkl
    PYTHONPATH=../src python compare_monitor_outputs.py diff /tmp/before.pkl /tmp/after.pkl
"""

from __future__ import annotations

import sys

from compare_online_outputs import Run, cli, replay_pipeline


def replay() -> dict[tuple[str, int], Run]:
    """Every output channel (concatenated) and event of each stream and chunk size."""
    from _monitoring_stream import OBSERVER_NOISE_NM, _stream
    from bench_monitoring_all import _all_blocks

    res: dict[tuple[str, int], Run] = {}
    streams = (("clean", _stream(20.0)), ("sensorless", _stream(20.0, noise_nm=OBSERVER_NOISE_NM)))
    for label, data in streams:
        for chunk in (100, 1000, 73):
            res[(label, chunk)] = replay_pipeline(_all_blocks(), data, chunk)
    return res


if __name__ == "__main__":
    sys.exit(cli(replay))
