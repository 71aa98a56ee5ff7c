"""Compile the on-line system's kernels once, before the first live session (decision 1549).

The streaming blocks run their per-sample work in numba kernels compiled on first use and kept
in numba's on-disk cache (``__pycache__`` beside the sources). On a fresh installation the
cache is empty and the first session compiles them as their code paths are first reached:
measured on the demo's session from a cold cache, 0.3-3 s at the first chunk of each block
(the spindle observer, its speed gate, the plan synchronisation, the monitors, the adaptive
feed) and 4-11 s later, when the first cut reaches the chatter avoidance and the adaptive
feed's RLS and GPC, about 20 s in all. A session paced by a machine falls behind real time
by that much, and its alarms and feed holds with it. With the cache filled, the same first
chunks take 5-36 ms.

:func:`warm_up` fills the cache: it runs the first seconds of the two demo sessions on the
virtual machine (:data:`ONLINE_S` of the demo part with the adaptive feed, the monitors and
the supervisor, and :data:`FORCE_S` of it with the feed-drive estimators regulating the peak
force; :data:`CHATTER_S` of the chatter-prone pass, through its detection and speed change),
and each chatter method on a synthetic cut entry (the parts of windows judged at an
entry, which the sessions reach only later), and the engagement monitor of ``millsense
monitor`` on two synthetic cuts. After it, the two whole demo sessions compile
nothing (measured from an empty cache). ``make`` runs it after installing
(``millsense warm-up``); a pip installation runs the command once. A warm cache makes it a
few seconds of planning and simulation that compile nothing.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from millsense.streaming.block import Chunk
from millsense.streaming.sources import Source, SourceWrapper

#: Seconds of the demo part's session the warm-up runs: its first cut (the adaptive feed, its
#: RLS and GPC, the look-ahead), the monitors and the supervisor.
ONLINE_S = 3.5
#: Seconds of the demo part's session regulating the peak force from the feed-drive
#: estimators (``--quantity force``): the estimators' kernels, all reached within 1.5 s (6 s
#: compiled nothing more, measured).
FORCE_S = 1.5
#: Seconds of the chatter-prone pass: its detection (found at 2.1 s) and speed change.
CHATTER_S = 3.5


class FirstSeconds(SourceWrapper):
    """The inner source's first ``seconds`` (its chunks cut to end there), then the end."""

    def __init__(self, inner: Source, seconds: float) -> None:
        super().__init__(inner)
        self._left = max(0, round(seconds * inner.sample_rate_hz))

    def read(self, max_samples: int) -> Chunk | None:
        if self._left <= 0:
            return None
        chunk = self.inner.read(min(max_samples, self._left))
        if chunk is not None:
            self._left -= chunk.n
        return chunk


def _feed(block: Any, data: dict[str, Any], fs: float, chunk: int = 100) -> None:
    """Reset ``block`` and feed it ``data`` (channel -> samples) in chunks of ``chunk``."""
    block.reset(fs)
    n = len(next(iter(data.values())))
    for k in range(0, n, chunk):
        block.process(Chunk(k, fs, 0.0, {c: v[k : k + chunk] for c, v in data.items()}))


def _chatter_entries(fs: float = 10000.0) -> None:
    """Each chatter method on a cut entry at a steady speed after a learned air cut: the parts
    of windows the monitor judges at an entry (decision 1539), which the demo sessions reach
    only after 6-10 s (a 4-flute tool at 6000 rev/min: 2 s of air, then 2 s of cut with its
    tooth-passing harmonics)."""
    import math

    import numpy as np

    from millsense.monitoring.chatter import METHODS, ChatterMonitor, ChatterSettings

    n = round(4.0 * fs)
    t = np.arange(n) / fs
    angle = 2 * math.pi * 100.0 * t
    cut = sum(np.cos(k * angle) / k for k in range(1, 17)) * (t >= 2.0)
    noise = 0.01 * np.random.default_rng(0).standard_normal(n)
    data = {"s": 1.0 + cut + noise, "spindle/speed": np.full(n, 2 * math.pi * 100.0)}
    for method in METHODS:
        _feed(ChatterMonitor(ChatterSettings(method=method, signal="s", n_flutes=4)), data, fs)


def _engagement_cuts(fs: float = 10000.0) -> None:
    """The engagement monitor (seed 004 ch. 2; ``millsense monitor --methods engagement``) on
    a 2-flute cut with its air torque given and on a 4-flute cut after air revolutions it learns
    the air torque from (decision 1806): the paths of its per-revolution fit, whose compile
    took about 50 s of a first ``monitor`` run (Ø20 mm, 30° helix, 1000 rev/min, down milling
    5 mm radial, 2 mm axial, 0.1 mm/tooth; 0.15 s of air, then 1.35 s of cut)."""
    import math

    import numpy as np

    from millsense.monitoring.engagement import EngagementBlock
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    n = round(1.5 * fs)
    t = np.arange(n) / fs
    omega = 2 * math.pi * 1000.0 / 60.0
    phi = 2 * math.pi * np.arange(600) / 600
    coefficients = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    noise = 0.01 * np.random.default_rng(0).standard_normal(n)
    for flutes, air in ((2, 0.0), (4, None)):
        tool = EndMill(20e-3, flutes, helix_rad=math.radians(30))
        rev = milling_forces(tool, coefficients, Engagement.radial(5e-3, 20e-3, "down"), 0.1e-3,
                             2e-3, phi).torque_nm  # fmt: skip
        cut = np.interp(np.mod(omega * t, 2 * math.pi), phi, rev, period=2 * math.pi)
        data = {"spindle/torque_est": (cut + noise) * (t >= 0.15),
                "spindle/speed": np.full(n, omega)}  # fmt: skip
        _feed(EngagementBlock(flutes, 20.0, 30.0, feed_per_tooth_mm=0.1, air_torque_nm=air),
              data, fs)  # fmt: skip


@dataclass(frozen=True)
class WarmUp:
    """What a warm-up did: wall time, s, and the kernels it compiled (0 with a warm cache)."""

    seconds: float
    compiled: tuple[str, ...]


@contextmanager
def compiled_kernels(package: str = "millsense") -> Iterator[list[str]]:
    """The names of the numba kernels of ``package`` compiled inside the ``with`` block
    (numba's event API, ``numba:compile``; a kernel loaded from the cache is not compiled)."""
    import numba  # noqa: F401  (numba before its submodule: importing numba.core first is circular)
    from numba.core import event

    names: list[str] = []

    class _Listener(event.Listener):
        def on_start(self, ev: Any) -> None:
            pass

        def on_end(self, ev: Any) -> None:
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            if func is not None and func.__module__.startswith(package):
                names.append(f"{func.__module__}.{func.__qualname__}")

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        yield names
    finally:
        event.unregister("numba:compile", listener)


def warm_up(
    online_s: float = ONLINE_S,
    chatter_s: float = CHATTER_S,
    on_progress: Callable[[float], None] | None = None,
) -> WarmUp:
    """Run the first ``online_s`` seconds of the demo part's session (as the demo runs it, and
    :data:`FORCE_S` of it regulating the peak force from the feed-drive estimators) and
    ``chatter_s`` of the chatter-prone pass's on the virtual machine, and each chatter method
    on a synthetic cut entry, so that the kernels the on-line system needs are compiled into
    numba's cache (decision 1549)."""
    from millsense import demo_chatter, demo_online
    from millsense.online.session import SessionOptions

    t0 = time.perf_counter()
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if on_progress is not None:
            on_progress(done / 4)

    with compiled_kernels() as names, tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        plan, plant = demo_online._plan(out), demo_online._plant_plan()
        for i, (seconds, opts) in enumerate(
            # the second regulates the force from the feed-drive estimators
            ((online_s, None), (FORCE_S, SessionOptions(quantity="force")))
        ):
            demo_online._run(plan, plant, True, out / f"online{i}.h5",
                             out / f"online{i}.events.parquet", None,
                             wrap=partial(FirstSeconds, seconds=seconds), options=opts)  # fmt: skip
            step()
        plan, plant = demo_chatter._plan(out), demo_chatter._plant_plan()
        demo_chatter._run(plan, plant, True, out / "chatter.h5", out / "chatter.events.parquet",
                          None, wrap=partial(FirstSeconds, seconds=chatter_s))  # fmt: skip
        step()
        _chatter_entries()
        _engagement_cuts()
        step()
    return WarmUp(time.perf_counter() - t0, tuple(dict.fromkeys(names)))
