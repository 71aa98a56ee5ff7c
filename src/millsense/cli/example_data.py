"""The example data set of ``millsense example-data`` (README "Your own measurements").

A slot on the virtual quaser-ux600 (Ø20 mm 2-flute, Al7050, 4 mm deep at 1200 mm/min and
3000 rev/min, 6 mm of air first) is recorded, then written the way a CNC trace export looks:
``;``-separated with a decimal comma, ``key: value`` lines first, names and a units row, field
units (ms, mm, deg, rev/min, mm/min), two dynamometer columns (the simulator's axis loads with
0.5 N of noise). The flaws of real files are added with :mod:`millsense.io.importers.quirks`
and written to ``quirks.json`` so that a test can check the report finds each of them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from millsense.core.errors import ConfigError
from millsense.io.importers import quirks
from millsense.io.importers.export import map_text

__all__ = ["STATED_RATE_HZ", "make_example"]

SLOT = """G21 G90 G94
G0 X-15 Y0 Z0
S3000 M3
G1 X60 F1200
M5
M30
"""
#: The rate the example's header states (the data are at 10 kHz: +1 %).
STATED_RATE_HZ = 10100.0
#: SI unit → (field unit written, factor SI → field).
_FIELD = {
    "m": ("mm", 1e3),
    "rad": ("deg", 180 / math.pi),
    "rad/s": ("rpm", 60 / (2 * math.pi)),
    "m/s": ("mm/min", 60e3),
    "A": ("A", 1.0),
    "1": ("1", 1.0),
    "N": ("N", 1.0),
}
_AXES = ("x", "y")


def _columns(rec: object) -> tuple[dict[str, np.ndarray], list[tuple[str, str, str]]]:
    """Field-unit columns and (column, channel, unit) of the map."""
    from millsense.core.recording import Recording

    assert isinstance(rec, Recording)
    cols: dict[str, np.ndarray] = {"Zeit": (rec.time_s - rec.t0_s) * 1e3}
    entries: list[tuple[str, str, str]] = []
    keep = [
        c for c in rec.measured_channel_names() if c.split("/")[0] in (*_AXES, "spindle", "cnc")
    ]
    for c in keep:
        si = rec.info(c).unit
        unit, k = _FIELD[si]
        col = c.replace("/", ".")
        cols[col] = np.asarray(rec.channel(c), dtype=np.float64) * k
        entries.append((col, c, unit))
    rng = np.random.default_rng(17)
    for a in _AXES:
        col = f"F{a}_dyn"
        cols[col] = np.asarray(rec.channel(f"truth/{a}/load")) + rng.normal(0, 0.5, rec.n_samples)
        entries.append((col, f"dynamometer/{a}/force", "N"))
    return cols, entries


def make_example(out: Path, duration_s: float = 1.3) -> list[Path]:
    """Write ``native.h5``, ``trace.csv``, ``map.toml``, ``quirks.json`` and ``slot.nc`` into
    ``out``; return the files written."""
    from millsense.cli.cmd_simulate import run_simulation
    from millsense.io import read_recording
    from millsense.io.importers.delimited import write_delimited
    from millsense.io.safe_output import atomic_path, write_text

    if not 0.9 <= duration_s <= 4.0:
        raise ConfigError(f"--duration-s {duration_s}: between 0.9 and 4 s")
    out.mkdir(parents=True, exist_ok=True)
    prog = out / "slot.nc"
    write_text(prog, SLOT)
    native = out / "native.h5"
    run_simulation(
        machine="quaser-ux600",
        program=prog,
        plan=None,
        tool=None,
        material=None,
        engagement="slot",
        depth_mm=4.0,
        out=native,
        air_mm=6.0,
        duration_s=duration_s,
        seed=0,
        cnc="open",
        break_at_s=None,
        break_flute=0,
        realism=None,
        accelerometer=False,
        microphone=False,
        chunk=1000,
    )
    rec = read_recording(native)
    fs = rec.sample_rate_hz
    cols, entries = _columns(rec)
    n = rec.n_samples
    cols = quirks.add_hum(cols, "x.current", 0.5, 60.0, fs)
    drift_per_s = 15.0
    cols = quirks.add_drift(cols, "Fy_dyn", drift_per_s / fs)
    # the rail: 90 % of the largest spindle current of the last half (in the cut)
    rail = 0.9 * float(np.max(cols["spindle.current"][n // 2 :]))
    cols, clipped = quirks.clip(cols, "spindle.current", rail)
    busy = np.zeros(n, dtype=bool)
    for s, ln, _ in clipped:
        busy[max(0, s - 2) : s + ln + 2] = True
    repeated: list[tuple[int, int]] = []
    for frac, ln in ((0.2, 4), (0.62, 3), (0.85, 6)):
        s = int(frac * n)
        while busy[s : s + ln + 1].any():
            s += 7
        repeated.append((s, ln))
    cols = quirks.repeat_rows(cols, repeated, keep=("Zeit",))
    gap_start, gap_len = int(0.3 * n), 30
    cols = quirks.drop_rows(cols, gap_start, gap_len)
    header = {
        "Trace": "millsense example (simulated slot, flaws added)",
        "Machine": "quaser-ux600 (virtual)",
        "Sample rate": f"{STATED_RATE_HZ:g} Hz",
    }
    csv = out / "trace.csv"
    with atomic_path(csv) as tmp:
        write_delimited(tmp, cols, {k: "ms" if k == "Zeit" else "" for k in cols}, ";", header)
        # the units row of a German-locale export: field units, decimal commas
        lines = tmp.read_text().splitlines()
        k = len(header) + 1
        units = {col: unit for col, _, unit in entries}
        lines[k] = ";".join(f"[{'ms' if c == 'Zeit' else units[c]}]" for c in cols)
        body = [ln.replace(".", ",") if i > k else ln for i, ln in enumerate(lines)]
        tmp.write_text("\n".join(body) + "\n")
    text = map_text(
        [(c, ch, "header", 1.0) for c, ch, _ in entries],
        metadata={
            "machine": "quaser-ux600",
            "tool": "aslan-d20-2flute",
            "material": "al7050",
            "flutes": 2,
            "spindle_rpm": 3000,
            "feed_mm_min": 1200,
        },
        match="trace.csv",
    )
    text = text.replace(
        'match = "trace.csv"',
        'match = "trace.csv"\ndelimiter = ";"\ndecimal = ","\n'
        'time_column = "Zeit"\ntime_unit = "ms"',
    )
    write_text(out / "map.toml", text)
    truth = {
        "true_rate_hz": fs,
        "stated_rate_hz": STATED_RATE_HZ,
        "repeated": repeated,
        "clipped": {"channel": "spindle/current", "runs": clipped},
        "gap": {
            "start_sample": gap_start,
            "missing": gap_len,
            "t_s": rec.t0_s + (gap_start - 1) / fs,
        },
        "drift": {"channel": "dynamometer/y/force", "per_s": drift_per_s},
        "hum": {"channel": "x/current", "hz": 60.0, "amplitude": 0.5},
    }
    write_text(out / "quirks.json", json.dumps(truth, indent=1) + "\n")
    return [prog, native, csv, out / "map.toml", out / "quirks.json"]
