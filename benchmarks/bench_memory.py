"""Peak resident memory of ``simulate`` and ``estimate`` for 60 s and 600 s runs (issue 21).

Each command runs in a fresh Python process (the CLI's ``main`` in ``python -c``) that reports
its own ``ru_maxrss`` when it ends, so each figure is that command's peak alone. ``simulate``
runs the 5-axis quaser-ux600 on a long zig-zag slot program (``--air-mm 6``: an air phase at
cutting feed before the stock) for ``--duration-s`` 60 and 600; ``estimate`` replays those
recordings with ``--method feed,raw --axes x,y --idle auto --plot --json``: the whole path
(idle air phase scan, streamed replay, estimate-vs-truth table, plot).

The property asked (decision 0961 "Streaming with constant memory"): peak memory independent
of the recording's length, the 600 s peak within 20 % of the 60 s peak; target ≤ 500 MB for
an hour at 10 kHz (here: the 600 s peak, the memory not growing with length).
``MILLSENSE_BENCH_MEMORY_S=SHORT,LONG`` changes the two durations (e.g. ``60,3600``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from _harness import Metric, benchmark

#: Peak memory target of the issue for an hour at 10 kHz, MB.
TARGET_MB = 500.0
#: Largest relative growth of the peak from the short to the long run.
#: The machine file a user makes by commissioning (README walkthrough; the preset is a nameplate)
COMMISSIONED = str(
    Path(__file__).resolve().parents[1]
    / "examples"
    / "walkthrough"
    / "quaser-ux600-commissioned.toml"
)
MAX_GROWTH = 0.20

_RSS = (
    "import resource, sys\n"
    "from millsense.cli.main import main\n"
    "code = 0\n"
    "try:\n"
    "    main(sys.argv[1:])\n"
    "except SystemExit as exc:\n"
    "    code = exc.code or 0\n"
    "print('PEAK_RSS_KB', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, code)\n"
)


def _durations() -> tuple[float, float]:
    text = os.environ.get("MILLSENSE_BENCH_MEMORY_S", "60,600")
    short, long = (float(x) for x in text.split(","))
    return short, long


def _program(path: Path, seconds: float) -> None:
    """Zig-zag slot passes in X at 1200 mm/min, 2 mm deep, long enough for ``seconds``."""
    pass_mm, feed = 500.0, 1200.0
    passes = int(seconds / (pass_mm / feed * 60.0)) + 2
    lines = ["%", "O1000", "G90 G94 G17 G21 G54", "T1 M6", "S6000 M3", "G0 X-15. Y0.", "G0 Z5."]
    lines.append("G1 Z-2. F1200.")
    for i in range(passes):
        lines.append(f"G1 X{pass_mm if i % 2 == 0 else -15.0:.1f} F{feed:.0f}.")
        lines.append(f"G1 Y{(i + 1) * 0.5:.1f}")
    lines += ["G0 Z5.", "M30", "%"]
    path.write_text("\n".join(lines) + "\n")


def peak_rss_mb(args: list[str]) -> tuple[float, float]:
    """(peak resident memory in MB, wall s) of ``millsense ARGS`` in a fresh process.

    Raises
    ------
    RuntimeError
        If the command fails (its stderr's last line).
    """
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _RSS, *args], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    lines = [x for x in proc.stdout.splitlines() if x.startswith("PEAK_RSS_KB ")]
    if proc.returncode or not lines or lines[-1].split()[2] != "0":
        tail = (proc.stderr.strip().splitlines() or ["?"])[-1]
        raise RuntimeError(f"millsense {' '.join(args[:2])} failed: {tail}")
    return int(lines[-1].split()[1]) / 1024.0, wall  # ru_maxrss: KiB on Linux


def _metrics(what: str, peaks: dict[float, tuple[float, float]]) -> list[Metric]:
    (short, (p_s, w_s)), (long, (p_l, w_l)) = sorted(peaks.items())
    growth = p_l / p_s - 1.0
    return [
        Metric(
            f"peak_rss_{short:g}s",
            p_s,
            "MB",
            note=f"{what} of {short:g} s at 10 kHz, {w_s:.0f} s wall",
        ),
        Metric(
            f"peak_rss_{long:g}s",
            p_l,
            "MB",
            TARGET_MB,
            higher_is_better=False,
            note=f"{what} of {long:g} s at 10 kHz, {w_l:.0f} s wall; target: an hour within 500 MB",
        ),
        Metric(
            "peak_growth",
            growth,
            "1",
            MAX_GROWTH,
            higher_is_better=False,
            baseline=f"peak_rss_{short:g}s",
            note=f"peak of {long:g} s / peak of {short:g} s - 1 (constant memory: < 20 %)",
        ),
    ]


_CACHE: dict[str, dict[float, tuple[float, float]]] = {}


def _run_all() -> dict[str, dict[float, tuple[float, float]]]:
    """Simulate both durations, then estimate both recordings (shared by the two cases).

    The two runs of a command go side by side (two processes): each reports its own peak,
    and on a shared machine the pair finishes sooner.
    """
    if _CACHE:
        return _CACHE
    with tempfile.TemporaryDirectory(prefix="millsense-mem-") as tmp:
        d = Path(tmp)
        durations = _durations()
        prog = d / "slot.nc"
        _program(prog, max(durations))
        sim_args = {
            s: [
                "simulate", "--machine", "quaser-ux600", "--program", str(prog),
                "--depth-mm", "2", "--air-mm", "6", "--duration-s", f"{s:g}",
                "--chunk", "10000", "-o", str(d / f"run{s:g}.h5"),
            ]
            for s in durations
        }  # fmt: skip
        est_args = {
            s: [
                "estimate", str(d / f"run{s:g}.h5"), "--machine", COMMISSIONED,
                "--method", "feed,raw", "--axes", "x,y", "--idle", "auto",
                "--chunk", "10000", "-o", str(d / f"est{s:g}.h5"),
                "--plot", str(d / f"est{s:g}.png"), "--json", str(d / f"est{s:g}.json"),
            ]
            for s in durations
        }  # fmt: skip
        with ThreadPoolExecutor(max_workers=len(durations)) as pool:
            sim = dict(zip(durations, pool.map(peak_rss_mb, sim_args.values()), strict=True))
            est = dict(zip(durations, pool.map(peak_rss_mb, est_args.values()), strict=True))
    _CACHE["simulate"], _CACHE["estimate"] = sim, est
    return _CACHE


@benchmark("cli.memory_simulate")
def _simulate() -> list[Metric]:
    return _metrics("simulate --program (5-axis)", _run_all()["simulate"])


@benchmark("cli.memory_estimate")
def _estimate() -> list[Metric]:
    return _metrics("estimate feed,raw x,y --idle auto --plot", _run_all()["estimate"])
