"""Benchmarks of the virtual plan (issue 4 items 5–6 performance).

Each case runs in a child process (``python bench_plan.py --child CASE``) so that its peak
resident memory (``ru_maxrss``, interpreter and libraries included) is its own. The child
plans once on a tiny program to load the compiled kernels (numba cache), then times
interpretation + sampling + stock + engagement + prediction + Parquet write.

- ``virtual.plan_demo_part``: examples/demo_part (Al7050 100 × 80 × 30 mm, 0.1 mm grid).
- ``virtual.plan_100k_steps``: a generated program on a 300 × 300 × 50 mm block (0.1 mm grid,
  9 M cells), Ø20 2-flute: full-width slots, then zig-zag pocket rows with a 10 mm step-over,
  3 mm deeper per layer, ≥ 100 000 steps of 0.4 mm.
- ``virtual.look_ahead``: the look-ahead verdict (seed 000 §2.10: 0.5 s ahead) from every row
  of the demo part's plan, in process: what the adaptive feed asks once or twice a revolution.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from _harness import Metric, benchmark  # noqa: E402

DEMO = ROOT / "examples" / "demo_part"


def synthetic_program(min_steps: int) -> str:
    """G-code with at least ``min_steps`` steps of 0.4 mm (slots + zig-zag pocket rows)."""
    lines = ["%", "O9000", "G90 G94 G17 G21", "T1 M6", "S1000 M3", "G0 X20. Y-15. Z5."]
    length = 0.0
    layer = 0
    while length < min_steps * 0.4 + 1000:
        z = -3.0 * (layer + 1)
        for xs in (20.0, 280.0):
            lines += [f"G0 X{xs:.1f} Y-15.", f"G1 Z{z:.1f} F400.", "Y315.", "G0 Z5."]
            length += 330.0 + 5.0 - z
        lines += ["G0 X30. Y30.", f"G1 Z{z:.1f} F400."]
        for i, y in enumerate(range(30, 271, 10)):
            a, b = (30.0, 270.0) if i % 2 == 0 else (270.0, 30.0)
            lines += [f"G1 X{a:.1f} Y{y:.1f}", f"X{b:.1f}"]
            length += 250.0
        lines.append("G0 Z5.")
        layer += 1
    lines += ["M5", "M30", "%"]
    return "\n".join(lines) + "\n"


def _child(which: str) -> None:
    import numpy as np

    from millsense.core.config import MaterialConfig, StockConfig, ToolConfig, load_config
    from millsense.plan.gcode import interpret, interpret_file
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    tool = EndMill.from_config(load_config(ToolConfig, DEMO / "tool.toml"))
    coeffs = CuttingCoefficients.from_config(load_config(MaterialConfig, DEMO / "material.toml"))
    warm = interpret("G21 G90 S1000 M3\nG0 X-15 Y10 Z-2\nG1 X20 F400\nM30\n")
    plan_program(warm, ZMapStock.from_box((0, 0, -0.01), (0.02, 0.02, 0), 1e-4), tool, coeffs)
    out = Path(tempfile.mkdtemp()) / "plan.parquet"
    t0 = time.perf_counter()
    if which == "demo":
        prog = interpret_file(DEMO / "program.nc")
        sc = load_config(StockConfig, DEMO / "stock.toml")
        assert sc.min_mm is not None and sc.max_mm is not None
        stock = ZMapStock.from_box(np.asarray(sc.min_mm) * 1e-3, np.asarray(sc.max_mm) * 1e-3)
    else:
        prog = interpret(synthetic_program(100_000), source="synthetic")
        stock = ZMapStock.from_box((0, 0, -0.05), (0.3, 0.3, 0.0))
    plan = plan_program(prog, stock, tool, coeffs)
    plan.write(out)
    wall = time.perf_counter() - t0
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        json.dumps(
            {
                "wall": wall,
                "rss_mb": rss_mb,
                "steps": len(plan),
                "in_cut": int(plan["in_cut"].sum()),
                "signatures": int(plan.metadata["signatures"]),
            }
        )
    )


def _run_child(which: str) -> dict[str, float]:
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", which],
        capture_output=True,
        text=True,
        check=True,
    )
    data: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    data["process"] = time.perf_counter() - t0
    return data


def _metrics(which: str, wall_target: float, min_steps: int) -> list[Metric]:
    d = _run_child(which)
    desc = (
        f"{int(d['steps'])} steps ({int(d['in_cut'])} in cut, {int(d['signatures'])} unique "
        "engagement signatures), 0.1 mm grid, Ø20 2-flute 30° helix, 720 angles/rev"
    )
    return [
        Metric(
            "wall_time",
            d["wall"],
            "s",
            target=wall_target,
            higher_is_better=False,
            note=f"interpret + sample + stock + CWE + prediction + Parquet, compiled; {desc}",
        ),
        Metric("steps", d["steps"], "steps", target=float(min_steps), note=desc),
        Metric(
            "peak_rss_mb",
            d["rss_mb"],
            "MB",
            target=2000.0,
            higher_is_better=False,
            note="ru_maxrss of the child process (interpreter and libraries included)",
        ),
        Metric(
            "process_time",
            d["process"],
            "s",
            higher_is_better=False,
            note="whole child process: imports, numba cache load, warm-up, run",
        ),
    ]


@benchmark("virtual.plan_demo_part")
def _demo() -> list[Metric]:
    return _metrics("demo", 10.0, 5000)


@benchmark("virtual.plan_100k_steps")
def _b100k() -> list[Metric]:
    return _metrics("100k", 120.0, 100_000)


@benchmark("virtual.look_ahead")
def _look_ahead() -> list[Metric]:
    from millsense.core.config import MaterialConfig, StockConfig, ToolConfig, load_config
    from millsense.plan.gcode import interpret_file
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    tool = EndMill.from_config(load_config(ToolConfig, DEMO / "tool.toml"))
    coeffs = CuttingCoefficients.from_config(load_config(MaterialConfig, DEMO / "material.toml"))
    sc = load_config(StockConfig, DEMO / "stock.toml")
    assert sc.min_mm is not None and sc.max_mm is not None
    lo, hi = (tuple(v * 1e-3 for v in c) for c in (sc.min_mm, sc.max_mm))
    stock = ZMapStock.from_box(lo, hi)
    plan = plan_program(interpret_file(DEMO / "program.nc"), stock, tool, coeffs)
    rows = range(len(plan) - 1)
    plan.look_ahead(0, 0.5)  # compiled and the columns converted once
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for r in rows:
            plan.look_ahead(r, 0.5, 1.0, 0.15)
        best = min(best, (time.perf_counter() - t0) / len(rows))
    return [
        Metric("us_per_call", 1e6 * best, "us", higher_is_better=False,
               note=f"the 0.5 s verdict from each of the demo part's {len(plan)} rows, 100 % "
               "override, best of 3 passes, one core"),
    ]  # fmt: skip


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] == "--child":
    _child(sys.argv[2])
