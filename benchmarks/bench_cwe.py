"""Benchmarks of the z-map stock and the cutter–workpiece engagement (issue 4 performance).

Each case runs in a child process (``python bench_cwe.py --child N``) so that its peak
resident memory (``ru_maxrss`` of the child, which includes the interpreter, numpy and numba)
is measured alone. The child first runs a 10-step path to load the compiled kernels (numba
cache), then times removal + engagement of the synthetic path in one call.

Synthetic path on a 300 × 300 × 50 mm block, 0.1 mm grid (9 M cells), Ø20 mm 2-flute end
mill with 30° helix, 0.4 mm steps: full-width slots along y, then zig-zag pocket rows along x
with a 10 mm step-over, layer after layer 3 mm deeper, with plunges between layers.
"""

from __future__ import annotations

import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from _harness import Metric, benchmark  # noqa: E402

STEP_M = 0.4e-3
TOP_M = 0.05


def synthetic_path(n_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tool-tip polyline sampled every 0.4 mm, cut to ``n_steps`` steps."""
    verts: list[tuple[float, float, float]] = []
    layer = 0
    total = 0.0
    while True:
        z = TOP_M - 3e-3 * (layer + 1)
        # slots along y at x = 20 and 280 mm, entering from outside the block
        for xs in (0.02, 0.28):
            verts += [(xs, -0.015, z), (xs, 0.315, z)]
        # zig-zag pocket rows along x, 10 mm step-over
        for i, y in enumerate(np.arange(0.03, 0.271, 0.01)):
            a, b = (0.03, 0.27) if i % 2 == 0 else (0.27, 0.03)
            verts += [(a, float(y), z), (b, float(y), z)]
        layer += 1
        v = np.asarray(verts)
        total = float(np.sum(np.linalg.norm(np.diff(v, axis=0), axis=1)))
        if total >= n_steps * STEP_M or layer >= 15:
            break
    v = np.asarray(verts)
    seg = np.linalg.norm(np.diff(v, axis=0), axis=1)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    si = np.arange(0.0, s[-1], STEP_M)[:n_steps]
    return tuple(np.interp(si, s, v[:, i]) for i in range(3))  # type: ignore[return-value]


def _child(n_steps: int) -> None:
    from millsense.plan.cwe import compute_engagement
    from millsense.plan.stock import ZMapStock
    from millsense.process.geometry import EndMill

    tool = EndMill(20e-3, 2, helix_rad=math.radians(30.0))
    warm = ZMapStock.from_box((0, 0, 0), (0.02, 0.02, 0.01), 1e-4)
    wx = np.linspace(0.0, 0.02, 10)
    compute_engagement(warm, tool, wx, np.full(10, 0.01), np.full(10, 0.008))
    x, y, z = synthetic_path(n_steps)
    t0 = time.perf_counter()
    stock = ZMapStock.from_box((0, 0, 0), (0.3, 0.3, TOP_M), 1e-4)
    res = compute_engagement(stock, tool, x, y, z)
    wall = time.perf_counter() - t0
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        json.dumps(
            {
                "wall": wall,
                "rss_mb": rss_mb,
                "steps": int(x.size),
                "in_cut": int(res.in_cut.sum()),
                "max_gain_mm": float(res.gain_cwe_mm.max()),
            }
        )
    )


def _run_child(n_steps: int) -> dict[str, float]:
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", str(n_steps)],
        capture_output=True,
        text=True,
        check=True,
    )
    data: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    data["process"] = time.perf_counter() - t0
    return data


def _metrics(n_steps: int, wall_target: float) -> list[Metric]:
    d = _run_child(n_steps)
    desc = (
        f"{int(d['steps'])} steps ({int(d['in_cut'])} in cut) on a 300×300 mm block at "
        "0.1 mm (9 M cells), Ø20 2-flute, 10 layers, 0.5° bins, slots + zig-zag pocket"
    )
    return [
        Metric(
            "wall_time",
            d["wall"],
            "s",
            target=wall_target,
            higher_is_better=False,
            note=f"stock creation + removal + engagement + Gain_CWE, after compilation; {desc}",
        ),
        Metric(
            "process_time",
            d["process"],
            "s",
            higher_is_better=False,
            note="whole child process: interpreter, imports, numba cache load, warm-up, run",
        ),
        Metric(
            "peak_rss_mb",
            d["rss_mb"],
            "MB",
            target=2000.0,
            higher_is_better=False,
            note="ru_maxrss of the child process (interpreter and libraries included)",
        ),
    ]


@benchmark("virtual.cwe_5000_steps")
def _b5000() -> list[Metric]:
    return _metrics(5000, 5.0)


@benchmark("virtual.cwe_100k_steps")
def _b100k() -> list[Metric]:
    return _metrics(100_000, 120.0)


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] == "--child":
    _child(int(sys.argv[2]))
