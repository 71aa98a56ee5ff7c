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

import argparse
import pickle
import sys
from typing import Any

import numpy as np

from compare_online_outputs import Run, diff


def replay() -> dict[tuple[str, int], Run]:
    """Every output channel (concatenated) and event of each stream and chunk size."""
    from _monitoring_stream import OBSERVER_NOISE_NM, _stream
    from bench_monitoring_all import FS, _all_blocks
    from millsense.streaming.block import Chunk
    from millsense.streaming.engine import Pipeline

    res: dict[tuple[str, int], Run] = {}
    streams = (("clean", _stream(20.0)), ("sensorless", _stream(20.0, noise_nm=OBSERVER_NOISE_NM)))
    for label, data in streams:
        n = len(data["spindle/speed"])
        for chunk in (100, 1000, 73):
            pipe = Pipeline(_all_blocks())
            pipe.reset(FS)
            outs: dict[str, list[np.ndarray]] = {}
            events: list[dict[str, Any]] = []
            for a in range(0, n, chunk):
                c = Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in data.items()})
                o, e = pipe.process(c)
                for k, v in o.items():
                    outs.setdefault(k, []).append(np.array(v, copy=True))
                events += [ev.as_dict() for ev in e]
            res[(label, chunk)] = ({k: np.concatenate(v) for k, v in outs.items()}, events)
    return res


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("save")
    s.add_argument("file")
    d = sub.add_parser("diff")
    d.add_argument("before")
    d.add_argument("after")
    d.add_argument("--tol", type=float, default=1e-12)
    args = p.parse_args()
    if args.cmd == "save":
        with open(args.file, "wb") as f:
            pickle.dump(replay(), f)
        return 0
    with open(args.before, "rb") as fa, open(args.after, "rb") as fb:
        return 1 if diff(pickle.load(fa), pickle.load(fb), args.tol) else 0


if __name__ == "__main__":
    sys.exit(main())
