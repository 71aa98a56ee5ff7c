"""Benchmark registry used by ``benchmarks/run.py``.

A benchmark module ``bench_<area>.py`` defines functions decorated with :func:`benchmark`; each
returns a list of :class:`Metric`. Figures are measured, never asserted from memory: the runner
prints one JSON object per metric with the machine it ran on, and can regenerate
``docs/performance.md``.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
from collections.abc import Callable
from dataclasses import dataclass

_BENCHMARKS: dict[str, Callable[[], list[Metric]]] = {}


@dataclass(frozen=True)
class Metric:
    """One measured figure.

    ``target`` is the figure the issue asks for, ``higher_is_better`` says which side passes.
    ``baseline`` optionally names what a ratio was taken against (run side by side).
    """

    metric: str
    value: float
    unit: str
    target: float | None = None
    higher_is_better: bool = True
    baseline: str = ""
    note: str = ""

    @property
    def passed(self) -> bool | None:
        if self.target is None:
            return None
        return self.value >= self.target if self.higher_is_better else self.value <= self.target


def benchmark(case: str) -> Callable[[Callable[[], list[Metric]]], Callable[[], list[Metric]]]:
    """Register a benchmark function under the dotted ``case`` name."""

    def register(func: Callable[[], list[Metric]]) -> Callable[[], list[Metric]]:
        if case in _BENCHMARKS:
            raise ValueError(f"benchmark {case} registered twice")
        _BENCHMARKS[case] = func
        return func

    return register


def alternated(
    new: Callable[[], float], old: Callable[[], float], repeats: int
) -> tuple[float, float]:
    """The best of ``repeats`` timings of ``new`` and of ``old``, run alternately (the shared
    host's load drifts; a ratio of two measurements taken side by side survives it)."""
    a, b = [], []
    for _ in range(repeats):
        a.append(new())
        b.append(old())
    return min(a), min(b)


def registered() -> dict[str, Callable[[], list[Metric]]]:
    return dict(_BENCHMARKS)


def machine_info() -> dict[str, object]:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "system": platform.system(),
        "date": _dt.date.today().isoformat(),
    }
