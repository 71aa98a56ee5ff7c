"""One recording through the pipeline: the task ``millsense batch`` runs on every worker
(issue 20, item 1).

:func:`process_recording` is a plain, picklable function of a path and a dictionary of options
(what a Dask worker receives). It runs the steps asked for — ``estimate`` (the estimators of
the machine file, :func:`~millsense.cli.cmd_estimate.run_estimate`), ``monitor`` (the monitors,
:func:`~millsense.cli.cmd_monitor.run_monitor`), ``wear`` (the wear sums at engagement matched
by the recording's virtual plan, :func:`~millsense.online.wear_run.recording_wear_sums`) and
``summary`` (duration, spindle statistics) — and returns **one row** of the summary table.
A recording that cannot be used (corrupt, truncated, without the channels a step needs) gives
a row with ``status = "error"`` and the one-line reason, never an exception: the batch goes on.
The row is also written to ``OUT/runs/<run>.parquet`` by the worker (atomically), so a batch
that is killed keeps every finished recording, and a rerun skips them (decision 2003).

A long recording is split into **parts** (:func:`parts_of`, decision 2005): segments of
``segment_s`` seconds, each run by :func:`process_part` from a warm-up of
:data:`SEGMENT_WARMUP_S` before its start (the estimators and monitors settle there; what they
give in the warm-up is dropped), and one ``wear`` part over the whole recording (the wear sums
need the plan synchronised and calibrated from the run's start). Each part's row is written to
``OUT/runs/<run>.parts/`` as it finishes; :func:`merge_parts` makes the run's row from them
(sums, counts and extremes exactly; the mean and RMS exactly from the segments' sums; the 99th
percentile as the largest of the segments', an upper bound of the run's).
"""

from __future__ import annotations

import itertools
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import UserError

__all__ = [
    "SEGMENT_WARMUP_S",
    "STEPS",
    "TASK_MODULES",
    "Part",
    "fragment_path",
    "machine_ref",
    "merge_parts",
    "part_dir",
    "part_fragment_path",
    "parts_of",
    "process_part",
    "process_recording",
    "read_fragment",
    "recording_parts",
    "run_name",
    "write_fragment",
]

STEPS = ("estimate", "monitor", "wear", "summary")
#: Seconds before a segment's first sample that its part also runs (and drops): the estimators'
#: transients (ms), the chatter monitor's 4096-sample spectrum (0.41 s at 10 kHz) and the
#: breakage monitor's first five revolutions (0.3 s at 1000 rev/min) fit in it.
SEGMENT_WARMUP_S = 2.0
#: The modules a task imports where its steps use them (and the libraries those import): the
#: worker processes of ``batch``'s local cluster are forked from a server that imported them
#: once, while the cluster starts (decision 2008). A step that imports another module lazily
#: adds it here (``tests/test_batch_start.py`` fails otherwise).
TASK_MODULES = (
    "millsense.cli.cmd_estimate",
    "millsense.cli.cmd_monitor",
    "millsense.core.config",
    "millsense.core.memory",
    "millsense.core.parquet_read",
    "millsense.core.plausibility",
    "millsense.core.presets",
    "millsense.data",
    "millsense.estimation.feed.commanded",
    "millsense.estimation.feed.idle_compensation",
    "millsense.estimation.from_config",
    "millsense.estimation.spindle_observer",
    "millsense.ident.idle_table",
    "millsense.io.recording_reader",
    "millsense.io.safe_output",
    "millsense.monitoring.chatter",
    "millsense.monitoring.registry",
    "millsense.monitoring.wear",
    "millsense.online.wear_run",
    "millsense.plan.virtual_plan",
    "millsense.streaming.event_log",
    "pyarrow.parquet",
)
#: Statistics kept per channel (:func:`_stats`); a segment returns the sums they come from.
_STAT_SUFFIXES = ("_mean", "_rms", "_p99abs", "_maxabs")


def run_name(path: Path) -> str:
    """The run's name in the table: the file name without ``.h5``."""
    return path.name[:-3] if path.name.endswith(".h5") else path.stem


@dataclass(frozen=True)
class Part:
    """A part of a long recording: ``kind`` ``segment`` (samples ``[start, stop)``, run from
    ``warm``) or ``wear`` (the whole recording, the wear step alone)."""

    kind: str
    index: int = 0
    warm: int = 0
    start: int = 0
    stop: int = 0

    @property
    def name(self) -> str:
        return "wear" if self.kind == "wear" else f"seg-{self.index:03d}"

    @property
    def segment(self) -> tuple[int, int]:
        """The samples the part reads (warm-up included)."""
        return (self.warm, self.stop)


def parts_of(
    n_samples: int, sample_rate_hz: float, segment_s: float | None, do: list[str]
) -> list[Part]:
    """The parts of a recording of ``n_samples`` (module docstring): none (one task) when
    ``segment_s`` is None or the recording is shorter than 1.5 segments; else segments of
    equal length (about ``segment_s`` each) and, when ``wear`` is asked for, the wear part."""
    if segment_s is None or n_samples < 1.5 * segment_s * sample_rate_hz:
        return []
    k = max(2, round(n_samples / (segment_s * sample_rate_hz)))
    edges = np.linspace(0, n_samples, k + 1).round().astype(int)
    warm = round(SEGMENT_WARMUP_S * sample_rate_hz)
    parts = [Part("segment", i, max(0, int(a) - warm), int(a), int(b))
             for i, (a, b) in enumerate(itertools.pairwise(edges.tolist()))]  # fmt: skip
    if "wear" in do:
        parts.append(Part("wear"))
    return parts


def fragment_path(out_dir: Path, path: Path) -> Path:
    """Where the worker writes the run's row."""
    return out_dir / "runs" / f"{run_name(path)}.parquet"


def _stamp(path: Path) -> str:
    st = path.stat()
    return f"{st.st_size}:{st.st_mtime_ns}"


def part_dir(out_dir: Path, path: Path) -> Path:
    """The folder of a split recording's part rows."""
    return out_dir / "runs" / f"{run_name(path)}.parts"


def part_fragment_path(out_dir: Path, path: Path, part: Part) -> Path:
    """Where the worker writes a part's row."""
    return part_dir(out_dir, path) / f"{part.name}.parquet"


def read_fragment(out_dir: Path, path: Path, part: Part | None = None) -> dict[str, Any] | None:
    """The row a previous batch wrote for ``path`` (or for its ``part``), if the file is
    unchanged since (else None)."""
    from millsense.core.parquet_read import read_parquet_table

    frag = fragment_path(out_dir, path) if part is None else part_fragment_path(out_dir, path, part)
    if not frag.is_file():
        return None
    try:
        rows = read_parquet_table(frag).to_pylist()
    except Exception:  # a fragment cut short by a killed worker: redo the run
        return None
    if len(rows) != 1 or rows[0].get("input_stamp") != _stamp(path):
        return None
    return dict(rows[0])


def write_fragment(
    out_dir: Path, path: Path, row: dict[str, Any], part: Part | None = None
) -> None:
    """Write a run's (or a part's) row atomically beside the others."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from millsense.io.safe_output import atomic_path

    frag = fragment_path(out_dir, path) if part is None else part_fragment_path(out_dir, path, part)
    frag.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(frag) as tmp:
        pq.write_table(pa.Table.from_pylist([row]), tmp)


def _plan_path(meta: dict[str, Any], recording: Path, plan: str | None) -> Path | None:
    """The run's virtual plan: ``--plan``, else the recording's ``plan`` metadata (as written,
    or beside the recording)."""
    if plan:
        return Path(plan)
    text = str(meta.get("plan", "") or "")
    if not text:
        return None
    p = Path(text)
    if p.is_file():
        return p
    beside = recording.parent / p.name
    return beside if beside.is_file() else None


def _stats(prefix: str, values: np.ndarray, sums: bool = False) -> dict[str, float]:
    """Mean, RMS, 99th percentile and maximum of |v| of the finite samples; with ``sums`` also
    the count, sum and sum of squares they come from (a segment's, merged by
    :func:`merge_parts`)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {}
    a = np.abs(v)
    out = {
        f"{prefix}_mean": float(v.mean()),
        f"{prefix}_rms": float(np.sqrt(np.mean(v * v))),
        f"{prefix}_p99abs": float(np.quantile(a, 0.99)),
        f"{prefix}_maxabs": float(a.max()),
    }
    if sums:
        out.update({f"{prefix}_n": float(v.size), f"{prefix}_sum": float(v.sum()),
                    f"{prefix}_sumsq": float(np.dot(v, v))})  # fmt: skip
    return out


def _column(name: str) -> str:
    return name.replace("/", "_").replace("-", "_")


def process_recording(path_text: str, options: dict[str, Any]) -> dict[str, Any]:
    """Run the steps on one recording and return (and write) its row (module docstring).

    ``options``: ``out_dir`` (str), ``do`` (list of steps), ``machine`` (file or preset, None:
    the recording's commissioned machine), ``plan`` (None: the recording's), ``estimate_method``,
    ``monitor_methods``, ``chunk``, ``segment_s`` (None: never split). A recording that
    :func:`parts_of` splits is not processed: the row says ``status = "split"`` with its
    ``n_samples`` and ``sample_rate_hz``, and the client runs its parts.
    """
    from millsense.core.memory import keep_freed_memory

    keep_freed_memory()  # the worker reuses the arrays it freed (no page faults per pass)
    path = Path(path_text)
    out_dir = Path(options["out_dir"])
    t0 = time.perf_counter()
    row: dict[str, Any] = {"run": run_name(path), "path": str(path), "status": "ok", "error": ""}
    try:
        row["input_stamp"] = _stamp(path)
        split = _long(path, options)
        if split is not None:
            return split  # the client submits its parts (nothing written)
        _steps(path, out_dir, options, row)
    except UserError as exc:
        row.update(status="error", error=str(exc))
    except (OSError, ValueError, KeyError) as exc:  # corrupt beyond the reader's own checks
        row.update(status="error", error=f"{path}: {type(exc).__name__}: {exc}")
    row["wall_s"] = time.perf_counter() - t0
    row["worker_pid"] = os.getpid()
    write_fragment(out_dir, path, row)
    return row


def recording_parts(
    path: Path, segment_s: float | None, do: list[str]
) -> tuple[int, float, list[Part]]:
    """(samples, sample rate, parts) of a recording: its parts by :func:`parts_of` (none: one
    task; ``segment_s`` None: never split, the file is not opened).

    Raises
    ------
    RecordingError
        The file does not open as a recording.
    """
    from millsense.io.recording_reader import opened_recording

    if segment_s is None:
        return 0, 0.0, []
    with opened_recording(path) as rec:
        n, fs = int(rec.n_samples), float(rec.sample_rate_hz)
    return n, fs, parts_of(n, fs, float(segment_s), do)


def _long(path: Path, options: dict[str, Any]) -> dict[str, Any] | None:
    """The ``split`` row of a recording that runs as parts, or None."""
    n, fs, parts = recording_parts(path, options.get("segment_s"), list(options.get("do", STEPS)))
    if not parts:
        return None
    return {"run": run_name(path), "path": str(path), "status": "split", "error": "",
            "n_samples": n, "sample_rate_hz": fs}  # fmt: skip


def process_part(path_text: str, options: dict[str, Any], part: Part) -> dict[str, Any]:
    """Run one part of a long recording (module docstring) and return (and write) its row;
    errors are rows, as in :func:`process_recording`."""
    from millsense.core.memory import keep_freed_memory

    keep_freed_memory()
    path = Path(path_text)
    out_dir = Path(options["out_dir"])
    t0 = time.perf_counter()
    row: dict[str, Any] = {"run": run_name(path), "path": str(path), "status": "ok", "error": "",
                           "part": part.name}  # fmt: skip
    try:
        row["input_stamp"] = _stamp(path)
        _steps(path, out_dir, options, row, part)
    except UserError as exc:
        row.update(status="error", error=str(exc))
    except (OSError, ValueError, KeyError) as exc:
        row.update(status="error", error=f"{path}: {type(exc).__name__}: {exc}")
    row["wall_s"] = time.perf_counter() - t0
    row["worker_pid"] = os.getpid()
    write_fragment(out_dir, path, row, part)
    return row


def merge_parts(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """The run's row from its parts' rows (module docstring): the header of the first part,
    the wear columns of the wear part, event counts summed, the first alarm the earliest,
    per channel mean and RMS from the segments' sums, 99th percentile and maximum the largest;
    ``segments`` the number of segments, ``wall_s`` the parts' total."""
    segs = sorted((p for p in parts if p.get("part") != "wear"), key=lambda p: str(p["part"]))
    bad = [p for p in parts if p.get("status") != "ok"]
    first = segs[0] if segs else parts[0]
    prefixes = {k[: -len("_sumsq")] for p in segs for k in p if k.endswith("_sumsq")}
    stat_keys = {pre + end for pre in prefixes
                 for end in ("_n", "_sum", "_sumsq", *_STAT_SUFFIXES)}  # fmt: skip
    row = {k: v for k, v in first.items() if k not in stat_keys}
    for key in ("part", "segment_start_s", "segment_stop_s"):
        row.pop(key, None)
    row["segments"] = len(segs)
    row["wall_s"] = float(sum(float(p.get("wall_s", 0.0)) for p in parts))
    if bad:
        row.update(status="error", error=str(bad[0].get("error", "")))
        return row
    for p in parts:
        if p.get("part") == "wear":
            row.update({k: v for k, v in p.items() if k.startswith("wear_")
                        or k in ("raw_torque_nm", "cut_s", "plan_kte_n_mm")})  # fmt: skip
    for key in ("events", "alarms", "chatter_alarms", "breakage_alarms"):
        if any(key in p for p in segs):
            row[key] = int(sum(int(p.get(key, 0)) for p in segs))
    if any("first_alarm_s" in p for p in segs):
        row["first_alarm_s"] = min((float(p["first_alarm_s"]) for p in segs
                                    if math.isfinite(float(p.get("first_alarm_s", math.nan)))),
                                   default=math.nan)  # fmt: skip
    for pre in sorted(prefixes):
        have = [p for p in segs if f"{pre}_n" in p]
        n = sum(float(p[f"{pre}_n"]) for p in have)
        row[f"{pre}_mean"] = sum(float(p[f"{pre}_sum"]) for p in have) / n
        row[f"{pre}_rms"] = math.sqrt(sum(float(p[f"{pre}_sumsq"]) for p in have) / n)
        row[f"{pre}_p99abs"] = max(float(p[f"{pre}_p99abs"]) for p in have)
        row[f"{pre}_maxabs"] = max(float(p[f"{pre}_maxabs"]) for p in have)
    return row


def machine_ref(options: dict[str, Any], meta: dict[str, Any]) -> str:
    """The machine file the steps use: ``--machine``, else the commissioned file shipped for
    the recording's machine (:func:`~millsense.core.presets.commissioned_machine`)."""
    from importlib import resources

    from millsense.core.errors import ConfigError

    if options.get("machine"):
        return str(options["machine"])
    name = str(meta.get("machine", ""))
    entry = resources.files("millsense.data").joinpath("commissioned", f"{name}.toml")
    if not name or not entry.is_file():
        raise ConfigError(
            f"no commissioned machine file for machine '{name or '?'}': give --machine"
        )
    return str(entry)


def _machine(options: dict[str, Any], meta: dict[str, Any]) -> Any:
    from millsense.core.config import MachineConfig
    from millsense.core.presets import load_preset

    return load_preset(MachineConfig, machine_ref(options, meta))


def _steps(path: Path, out_dir: Path, options: dict[str, Any], row: dict[str, Any],
           part: Part | None = None) -> None:  # fmt: skip
    from millsense.io.recording_reader import channel_window, opened_recording

    do = list(options.get("do", STEPS))
    if part is not None:
        # a segment runs everything but the wear step; the wear part only the wear step
        do = ["wear"] if part.kind == "wear" else [s for s in do if s != "wear"]
    seg = part if part is not None and part.kind == "segment" else None
    with opened_recording(path) as rec:
        meta = dict(rec.metadata)
        fs = float(rec.sample_rate_hz)
        row.update(
            machine=str(meta.get("machine", "")),
            tool=str(meta.get("tool", "")),
            program=str(meta.get("program", "")),
            plan=str(meta.get("plan", "")),
            sample_rate_hz=fs,
            n_samples=int(rec.n_samples),
            duration_s=float(rec.n_samples / fs),
            created=str(meta.get("created", "")),
        )
        if "tool_id" in meta:
            row["tool_id"] = str(meta["tool_id"])
        counter = meta.get("tool_cutting_time_s")
        if isinstance(counter, int | float):
            row["tool_cutting_time_s"] = float(counter)
        # ground truth of a simulation, for evaluation only (never read by a step)
        for key, value in meta.items():
            if key.startswith("truth_") and isinstance(value, int | float):
                row[key] = float(value)
        if "summary" in do:
            a, b = (seg.start, seg.stop) if seg is not None else (0, int(rec.n_samples))
            for name in ("spindle/speed", "spindle/current"):
                if name in rec.channel_names:
                    v = channel_window(rec, name, a, b)
                    row.update(_stats(_column(name), v, sums=seg is not None))
        if "wear" in do:
            _wear(rec, path, meta, options, row)
        t0 = float(rec.t0_s)
    run_dir = out_dir / "runs" / row["run"]
    if seg is not None:
        # the segment's span in the recording's time (the events' time base)
        run_dir = run_dir / seg.name
        row["segment_start_s"] = t0 + seg.start / fs
        row["segment_stop_s"] = t0 + seg.stop / fs
    if "estimate" in do:
        _estimate(path, meta, run_dir, options, row, seg)
    if "monitor" in do:
        _monitor(path, run_dir, options, row, seg)


def _wear(rec: Any, path: Path, meta: dict[str, Any], options: dict[str, Any],
          row: dict[str, Any]) -> None:  # fmt: skip
    from millsense.core.errors import InputDataError
    from millsense.online.wear_run import recording_wear_sums
    from millsense.plan.virtual_plan import VirtualPlan, coefficients_from_metadata

    plan = _plan_path(meta, path, options.get("plan"))
    if plan is None:
        raise InputDataError(
            f"{path}: wear needs the run's virtual plan (metadata 'plan' or --plan)"
        )
    vp = VirtualPlan.read(plan)
    if options.get("plan"):  # --plan for every run: of this run's program? (as monitor)
        from millsense.cli.plan_match import check_plan_matches

        check_plan_matches(vp, plan, rec, "the run")  # the row's message names the file
    chunk = int(options.get("chunk", 2000))
    sums = recording_wear_sums(rec, vp, _machine(options, meta), chunk=chunk, where=str(path))
    row.update({f"wear_{k}": v for k, v in sums.as_dict().items()})
    row["wear_ratio"] = sums.ratio
    row["raw_torque_nm"] = sums.raw_torque_nm
    row["cut_s"] = sums.raw_n / float(rec.sample_rate_hz)
    row["plan_kte_n_mm"] = coefficients_from_metadata(vp.metadata, str(plan)).kte * 1e-3


def _estimate(path: Path, meta: dict[str, Any], run_dir: Path, options: dict[str, Any],
              row: dict[str, Any], seg: Part | None = None) -> None:  # fmt: skip
    from millsense.cli.cmd_estimate import run_estimate
    from millsense.io.recording_reader import opened_recording

    run_dir.mkdir(parents=True, exist_ok=True)
    out = run_dir / "estimates.h5"
    out.unlink(missing_ok=True)
    machine = machine_ref(options, meta)
    summary = run_estimate(recording=path, machine=str(machine),
                           method=str(options.get("estimate_method", "spindle")), axes=None,
                           out=out, chunk=int(options.get("chunk", 2000)),
                           segment=None if seg is None else seg.segment)  # fmt: skip
    row["estimates"] = len(summary["estimates"])
    skip = 0 if seg is None else seg.start - seg.warm  # the warm-up's estimates are dropped
    with opened_recording(out) as est:
        for name in est.channel_names:
            if name.startswith("est/"):
                v = est.window(name, skip, est.n_samples) if hasattr(est, "window") else (
                    est.channel(name)[skip:])  # fmt: skip
                row.update(_stats(_column(name), v, sums=seg is not None))


def _monitor(path: Path, run_dir: Path, options: dict[str, Any], row: dict[str, Any],
             seg: Part | None = None) -> None:  # fmt: skip
    from millsense.cli.cmd_monitor import run_monitor

    run_dir.mkdir(parents=True, exist_ok=True)
    out = run_dir / "events.parquet"
    out.unlink(missing_ok=True)
    res = run_monitor(recording=path, out=out, methods=str(options.get("monitor_methods",
                      "chatter-comb")), chunk=int(options.get("chunk", 2000)),
                      segment=None if seg is None else seg.segment)  # fmt: skip
    events = list(res["events"])
    if seg is not None:
        # the warm-up's events are the previous segment's; the log keeps the segment's own
        from millsense.streaming.event_log import write_event_log

        t_start = float(row["segment_start_s"])
        events = [e for e in events if e.time_s >= t_start - 1e-9]
        write_event_log(out, events, recording=path)
    alarms = [e for e in events if str(e.kind) == "alarm"]
    row["events"] = len(events)
    row["alarms"] = len(alarms)
    row["chatter_alarms"] = sum(1 for e in alarms if "chatter" in e.name)
    row["breakage_alarms"] = sum(1 for e in alarms if "break" in e.name)
    row["first_alarm_s"] = min((e.time_s for e in alarms), default=math.nan)
