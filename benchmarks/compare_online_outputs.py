"""Replay the online.stack stream and compare every output channel and event of two versions.

Used to check that a speed-up of the on-line stack leaves its outputs alone (issue 16's latency
work): ``save`` replays the V8 stream of :mod:`bench_online` through the full and the default
stacks in 10 ms, 0.1 s and 73-sample chunks and pickles every output channel and event;
``diff`` compares two such files, channel by channel and event by event, and fails when a
value differs by more than ``--tol`` (relative, per sample) or an event differs otherwise.

    cd benchmarks
    PYTHONPATH=../src python compare_online_outputs.py save /tmp/before.pkl
    ... change the code ...
    PYTHONPATH=../src python compare_online_outputs.py save /tmp/after.pkl
    PYTHONPATH=../src python compare_online_outputs.py diff /tmp/before.pkl /tmp/after.pkl
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

Run = tuple[dict[str, np.ndarray], list[dict[str, Any]]]


def replay_pipeline(blocks: list[Any], data: dict[str, np.ndarray], chunk: int) -> Run:
    """Every output channel (concatenated) and event of ``blocks`` in a Pipeline fed ``data``
    in chunks of ``chunk`` samples."""
    from bench_online import FS
    from millsense.streaming.block import Chunk
    from millsense.streaming.engine import Pipeline

    pipe = Pipeline(blocks)
    pipe.reset(FS)
    n = len(next(iter(data.values())))
    outs: dict[str, list[np.ndarray]] = {}
    events: list[dict[str, Any]] = []
    for a in range(0, n, chunk):
        o, e = pipe.process(Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in data.items()}))
        for k, v in o.items():
            outs.setdefault(k, []).append(np.array(v, copy=True))
        events += [ev.as_dict() for ev in e]
    return {k: np.concatenate(v) for k, v in outs.items()}, events


def replay() -> dict[tuple[str, int], Run]:
    """Every output channel (concatenated) and event of each stack and chunk size."""
    from bench_online import _stream, stack_blocks

    data, _ = _stream()
    res: dict[tuple[str, int], Run] = {}
    for stack in ("full", "default"):
        for chunk in (100, 1000, 73):
            built: Any = stack_blocks(stack)
            res[(stack, chunk)] = replay_pipeline(built.blocks, data, chunk)
    return res


def _close(u: object, v: object, tol: float) -> bool:
    if isinstance(u, float) and isinstance(v, float):
        both_nan = math.isnan(u) and math.isnan(v)
        return u == v or both_nan or abs(u - v) <= tol * max(abs(u), abs(v))
    if isinstance(u, dict) and isinstance(v, dict):
        return u.keys() == v.keys() and all(_close(u[k], v[k], tol) for k in u)
    return u == v


def diff(a: dict[tuple[str, int], Run], b: dict[tuple[str, int], Run], tol: float) -> int:
    """Print the differences; the number beyond ``tol``."""
    bad = exact = near = ev_exact = ev_near = 0
    worst = 0.0
    for key, (oa, ea) in a.items():
        ob, eb = b[key]
        if set(oa) != set(ob):
            print(key, "channels differ:", sorted(set(oa) ^ set(ob)))
            bad += 1
        for ch in sorted(set(oa) & set(ob)):
            x, y = oa[ch], ob[ch]
            if x.shape == y.shape and np.array_equal(x, y, equal_nan=True):
                exact += 1
                continue
            if x.shape != y.shape or not np.array_equal(np.isnan(x), np.isnan(y)):
                print(key, ch, "shape or NaNs differ")
                bad += 1
                continue
            ok = ~np.isnan(x)
            rel = float(np.max(np.abs(x[ok] - y[ok]) / np.maximum(np.abs(x[ok]), 1e-300)))
            worst = max(worst, rel)
            near += 1
            print(key, ch, f"max relative difference {rel:.3g}")
            bad += rel > tol
        if len(ea) != len(eb):
            print(key, f"{len(ea)} events against {len(eb)}")
            bad += 1
            continue
        for u, v in zip(ea, eb, strict=True):
            if u == v:
                ev_exact += 1
            elif _close(u, v, tol):
                ev_near += 1
            else:
                print(key, "event differs:\n ", u, "\n ", v)
                bad += 1
    print(
        f"channels: {exact} bit-identical, {near} within rounding (worst {worst:.3g}); "
        f"events: {ev_exact} identical, {ev_near} within {tol:g}; {bad} beyond"
    )
    return bad


def cli(replay_fn: Callable[[], dict[tuple[str, int], Run]]) -> int:
    """``save FILE`` (pickle ``replay_fn()``) or ``diff BEFORE AFTER [--tol]``."""
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
            pickle.dump(replay_fn(), f)
        return 0
    with open(args.before, "rb") as fa, open(args.after, "rb") as fb:
        return 1 if diff(pickle.load(fa), pickle.load(fb), args.tol) else 0


if __name__ == "__main__":
    sys.exit(cli(replay))
