"""G-code interpretation throughput: a 1 000 000-line program like CAM output.

The program is generated to a temporary file (not timed) and interpreted with
:func:`millsense.plan.gcode.interpret_file` (timed: read, tokenise, interpret, build the
arrays). The mix imitates a 3-axis finishing post: header, tool change, then blocks of
modal G1 moves (``X.. Y..``, ``G1 X.. Y.. Z..`` with F) and G2/G3 IJK arcs with N numbers,
about 25 % arcs. Best of two runs (the machine is shared).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

from _harness import Metric, benchmark

N_LINES = 1_000_000


def write_program(path: Path, n_lines: int = N_LINES) -> int:
    """Write an ``n_lines``-line CAM-like program (mm) to ``path``; returns the line count."""
    head = [
        "%",
        "O1001 (BENCH)",
        "(T1 D=10. CR=0. - ZMIN=-5. - FLAT END MILL)",
        "G90 G94 G17 G40 G49 G80",
        "G21",
        "T1 M6",
        "S8000 M3",
        "G54",
        "G0 X0. Y0.",
        "G43 Z15. H1",
        "G1 Z-1. F500.",
    ]
    tail = ["G0 Z15.", "M5", "M30", "%"]
    out = list(head)
    body = n_lines - len(head) - len(tail)
    x, y = 0.0, 0.0
    n = 10
    k = 0
    r = 2.5
    while k < body:
        phase = k % 16
        n += 5
        if phase < 11:
            # feed line; after the arcs G1 is restated, then modal (most CAM lines)
            x += 0.731 if (k // 16) % 2 == 0 else -0.731
            y += 0.0173
            g = "G1 " if phase == 0 else ""
            out.append(f"N{n} {g}X{x:.3f} Y{y:.3f}")
        elif phase == 11:
            out.append(f"N{n} G1 X{x:.3f} Y{y:.3f} Z-1. F{400 + (k % 7) * 25}.")
        elif phase in (12, 14):
            # quarter arc CCW then back CW: end on the circle, IJK to the centre
            cx, cy = x, y + r
            ex, ey = cx + r * math.sin(0.6), cy - r * math.cos(0.6)
            out.append(f"N{n} G3 X{ex:.4f} Y{ey:.4f} I{cx - x:.4f} J{cy - y:.4f}")
            x, y = ex, ey
            r = 2.5 if r != 2.5 else 3.0
        else:
            cx, cy = x + 1.0, y
            ex, ey = cx - math.cos(0.5), cy + math.sin(0.5)
            out.append(f"N{n} G2 X{ex:.4f} Y{ey:.4f} I{cx - x:.4f} J{cy - y:.4f}")
            x, y = ex, ey
        k += 1
    out.extend(tail)
    path.write_text("\n".join(out) + "\n")
    return len(out)


@benchmark("virtual.gcode_1M_lines")
def _gcode_1m() -> list[Metric]:
    from millsense.plan.gcode import interpret_file

    with tempfile.TemporaryDirectory() as tmp:
        prog = Path(tmp) / "bench_1M.nc"
        n = write_program(prog)
        best = cpu = math.inf
        moves = 0
        for _ in range(2):
            t0, c0 = time.perf_counter(), time.process_time()
            tp = interpret_file(prog)
            best = min(best, time.perf_counter() - t0)
            cpu = min(cpu, time.process_time() - c0)
            moves = len(tp)
    note = f"{n} lines, {moves} moves (~25 % G2/G3 IJK arcs), best of 2"
    return [
        Metric("wall_time", best, "s", target=20.0, higher_is_better=False, note=note),
        Metric("lines_per_s", n / best, "1/s", target=N_LINES / 20.0, note=note),
        Metric("cpu_time", cpu, "s", higher_is_better=False, note="process CPU time, " + note),
    ]
