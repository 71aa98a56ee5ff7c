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
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import UserError

__all__ = [
    "STEPS",
    "fragment_path",
    "machine_ref",
    "process_recording",
    "read_fragment",
    "run_name",
]

STEPS = ("estimate", "monitor", "wear", "summary")


def run_name(path: Path) -> str:
    """The run's name in the table: the file name without ``.h5``."""
    return path.name[:-3] if path.name.endswith(".h5") else path.stem


def fragment_path(out_dir: Path, path: Path) -> Path:
    """Where the worker writes the run's row."""
    return out_dir / "runs" / f"{run_name(path)}.parquet"


def _stamp(path: Path) -> str:
    st = path.stat()
    return f"{st.st_size}:{st.st_mtime_ns}"


def read_fragment(out_dir: Path, path: Path) -> dict[str, Any] | None:
    """The row a previous batch wrote for ``path``, if the file is unchanged since (else None)."""
    import pyarrow.parquet as pq

    frag = fragment_path(out_dir, path)
    if not frag.is_file():
        return None
    try:
        rows = pq.read_table(frag).to_pylist()
    except Exception:  # a fragment cut short by a killed worker: redo the run
        return None
    if len(rows) != 1 or rows[0].get("input_stamp") != _stamp(path):
        return None
    return dict(rows[0])


def _write_fragment(out_dir: Path, path: Path, row: dict[str, Any]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from millsense.io.safe_output import atomic_path

    frag = fragment_path(out_dir, path)
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


def _stats(prefix: str, values: np.ndarray) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {}
    a = np.abs(v)
    return {
        f"{prefix}_mean": float(v.mean()),
        f"{prefix}_rms": float(np.sqrt(np.mean(v * v))),
        f"{prefix}_p99abs": float(np.quantile(a, 0.99)),
        f"{prefix}_maxabs": float(a.max()),
    }


def _column(name: str) -> str:
    return name.replace("/", "_").replace("-", "_")


def process_recording(path_text: str, options: dict[str, Any]) -> dict[str, Any]:
    """Run the steps on one recording and return (and write) its row (module docstring).

    ``options``: ``out_dir`` (str), ``do`` (list of steps), ``machine`` (file or preset, None:
    the recording's commissioned machine), ``plan`` (None: the recording's), ``estimate_method``,
    ``monitor_methods``, ``chunk``.
    """
    path = Path(path_text)
    out_dir = Path(options["out_dir"])
    t0 = time.perf_counter()
    row: dict[str, Any] = {"run": run_name(path), "path": str(path), "status": "ok", "error": ""}
    try:
        row["input_stamp"] = _stamp(path)
        _steps(path, out_dir, options, row)
    except UserError as exc:
        row.update(status="error", error=str(exc))
    except (OSError, ValueError, KeyError) as exc:  # corrupt beyond the reader's own checks
        row.update(status="error", error=f"{path}: {type(exc).__name__}: {exc}")
    row["wall_s"] = time.perf_counter() - t0
    row["worker_pid"] = os.getpid()
    _write_fragment(out_dir, path, row)
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


def _steps(path: Path, out_dir: Path, options: dict[str, Any], row: dict[str, Any]) -> None:
    from millsense.io.recording_reader import opened_recording

    do = list(options.get("do", STEPS))
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
            for name in ("spindle/speed", "spindle/current"):
                if name in rec.channel_names:
                    row.update(_stats(_column(name), rec.channel(name)))
        if "wear" in do:
            _wear(rec, path, meta, options, row)
    run_dir = out_dir / "runs" / row["run"]
    if "estimate" in do:
        _estimate(path, meta, run_dir, options, row)
    if "monitor" in do:
        _monitor(path, run_dir, options, row)


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
    chunk = int(options.get("chunk", 2000))
    sums = recording_wear_sums(rec, vp, _machine(options, meta), chunk=chunk, where=str(path))
    row.update({f"wear_{k}": v for k, v in sums.as_dict().items()})
    row["wear_ratio"] = sums.ratio
    row["raw_torque_nm"] = sums.raw_torque_nm
    row["cut_s"] = sums.raw_n / float(rec.sample_rate_hz)
    row["plan_kte_n_mm"] = coefficients_from_metadata(vp.metadata, str(plan)).kte * 1e-3


def _estimate(path: Path, meta: dict[str, Any], run_dir: Path, options: dict[str, Any],
              row: dict[str, Any]) -> None:  # fmt: skip
    from millsense.cli.cmd_estimate import run_estimate
    from millsense.io.recording_reader import opened_recording

    run_dir.mkdir(parents=True, exist_ok=True)
    out = run_dir / "estimates.h5"
    out.unlink(missing_ok=True)
    machine = machine_ref(options, meta)
    summary = run_estimate(recording=path, machine=str(machine),
                           method=str(options.get("estimate_method", "spindle")), axes=None,
                           out=out, chunk=int(options.get("chunk", 2000)))  # fmt: skip
    row["estimates"] = len(summary["estimates"])
    with opened_recording(out) as est:
        for name in est.channel_names:
            if name.startswith("est/"):
                row.update(_stats(_column(name), est.channel(name)))


def _monitor(path: Path, run_dir: Path, options: dict[str, Any], row: dict[str, Any]) -> None:
    from millsense.cli.cmd_monitor import run_monitor

    run_dir.mkdir(parents=True, exist_ok=True)
    out = run_dir / "events.parquet"
    out.unlink(missing_ok=True)
    res = run_monitor(recording=path, out=out, methods=str(options.get("monitor_methods",
                      "chatter-comb")), chunk=int(options.get("chunk", 2000)))  # fmt: skip
    events = list(res["events"])
    alarms = [e for e in events if str(e.kind) == "alarm"]
    row["events"] = len(events)
    row["alarms"] = len(alarms)
    row["chatter_alarms"] = sum(1 for e in alarms if "chatter" in e.name)
    row["breakage_alarms"] = sum(1 for e in alarms if "break" in e.name)
    row["first_alarm_s"] = min((e.time_s for e in alarms), default=math.nan)
