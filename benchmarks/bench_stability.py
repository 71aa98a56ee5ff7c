"""Stability lobe diagrams: wall time for 200 spindle speeds at 0.5 % accuracy.

The robust search of issue 14 (:mod:`millsense.stability.robust`) is timed next to the
earlier continuation search (``compute_lobes(..., robust=False)``); ``robust_cost_ratio`` is
the ratio of the two, run side by side on the same machine.

Steps per period: m = 20, raised to at least 10 steps per chatter cycle, with Richardson
extrapolation from m and 2m steps (first-order SDM
converges as O(m⁻²), benchmarks.md §1). The accuracy metric is the largest relative deviation,
at 10 of the 200 speeds, from depths extrapolated from 100 and 200 steps (converged to
< 0.01 %, see validation case stability.insperger.slot_15870).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from _harness import Metric, benchmark
from millsense.stability.cases import MillingStabilityCase, compute_lobes, load_case

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "stability"


@contextmanager
def _one_blas_thread() -> Iterator[None]:
    """BLAS on one thread while timing, as ``millsense lobes`` runs it (decisions 0907, 2004).

    On a shared two-core host a two-thread OpenBLAS made the robust 2-DOF chart 4.2x the
    continuation search instead of 2.8x (decision 0911); the earlier count is restored
    afterwards for the other benchmarks (``run.py`` already sets the thread variables).
    """
    from millsense.core.blas import limit_blas_threads

    before = limit_blas_threads(None)
    limit_blas_threads(1)
    try:
        yield
    finally:
        if before is not None:
            limit_blas_threads(before)


def _timed(func: Callable[[], Any]) -> tuple[Any, float, float]:
    """(result, wall time, CPU time of the process) of ``func()`` [s]."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = func()
    return out, time.perf_counter() - t0, time.process_time() - c0


def _run(case: MillingStabilityCase, target_s: float) -> list[Metric]:
    rpm = np.linspace(5000.0, 25000.0, 200)
    compute_lobes(case, rpm=rpm[:2])  # compile the numba kernels outside the timing
    compute_lobes(case, rpm=rpm[:2], robust=False)
    with _one_blas_thread():
        res, wall, cpu = _timed(lambda: compute_lobes(case, rpm=rpm, refine_minima=False))
        # the earlier continuation search (issue 14's "today"), run side by side
        _, wall_old, cpu_old = _timed(lambda: compute_lobes(case, rpm=rpm, robust=False))
    idx = np.arange(5, 200, 20)
    ref = compute_lobes(case, rpm=rpm[idx], steps_per_period=100, extrapolate=True, robust=False)
    err = float(np.max(np.abs(res.critical_depth_m[idx] / ref.critical_depth_m - 1.0)))
    note = (
        f"robust depth scan (ratio 1.1 from the small-gain depth, islands to 3x the limit), "
        f"SDM m=20 per tooth period (>=10 per chatter cycle), adaptive Richardson to 1 %; "
        f"grid min depth {res.min_depth_m * 1e3:.4f} mm at {res.min_depth_rpm:.0f} rev/min"
    )
    return [
        Metric("wall_time", wall, "s", target=target_s, higher_is_better=False, note=note),
        Metric(
            "cpu_time",
            cpu,
            "s",
            target=target_s,
            higher_is_better=False,
            note="CPU time of the process for the same chart (BLAS on one thread)",
        ),
        Metric(
            "robust_cost_ratio",
            wall / wall_old,
            "x",
            baseline="continuation search (sdm_lobes, before issue 14), same speeds",
            note=(
                f"robust {wall:.2f} s / continuation {wall_old:.2f} s wall, "
                f"{cpu:.2f} s / {cpu_old:.2f} s CPU ({cpu / cpu_old:.2f}x), run side by side"
            ),
        ),
        Metric(
            "max_depth_error",
            err,
            "-",
            target=0.005,
            higher_is_better=False,
            note="vs 100/200-step extrapolated depths at 10 of the speeds",
        ),
    ]


@benchmark("stability.lobes_1dof_200")
def _lobes_1dof() -> list[Metric]:
    return _run(load_case(EXAMPLES / "insperger_1dof_slot.toml"), 2.0)


@benchmark("stability.lobes_2dof_3modes_200")
def _lobes_2dof() -> list[Metric]:
    return _run(load_case(EXAMPLES / "two_dof_3modes_half_down.toml"), 10.0)


@benchmark("stability.lobes_1dof_200_refined")
def _lobes_1dof_refined() -> list[Metric]:
    """The same chart with every local minimum refined to 1 rev/min (what the CLI runs)."""
    case = load_case(EXAMPLES / "insperger_1dof_slot.toml")
    rpm = np.linspace(5000.0, 25000.0, 200)
    compute_lobes(case, rpm=rpm[:2])
    with _one_blas_thread():
        res, wall, _ = _timed(lambda: compute_lobes(case, rpm=rpm))
    note = (
        f"{len(res.minima)} local minima refined to 1 rev/min; "
        f"min {res.min_depth_m * 1e3:.4f} mm at {res.min_depth_rpm:.0f} rev/min"
    )
    return [Metric("wall_time", wall, "s", higher_is_better=False, note=note)]
