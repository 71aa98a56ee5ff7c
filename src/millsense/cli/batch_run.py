"""Many recordings through the pipeline on Dask, and the fleet's summary table
(issue 20, items 1 and 3; decision 2003).

:func:`run_batch` submits one :func:`~millsense.cli.batch_tasks.process_recording` task per
recording — or, for a recording longer than 1.5 × ``segment_s``, one
:func:`~millsense.cli.batch_tasks.process_part` task per segment and one for its wear sums
(decision 2005) — to a Dask ``distributed`` cluster — a local one (``workers`` processes, one
thread each) or an existing scheduler at ``scheduler`` — with retries, and collects the rows as
they finish. Recordings (and parts) whose row a previous batch already wrote (unchanged input)
are not run again. :func:`assess_wear` then judges every tool's runs in order
(:func:`~millsense.monitoring.wear.assess_tool`) and :func:`write_summary` writes the table as
one Parquet file (``OUT/summary.parquet``, queryable with duckdb, polars or pandas).
"""

from __future__ import annotations

import logging
import math
import os
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from millsense.cli.batch_tasks import (
    SEGMENT_WARMUP_S,
    STEPS,
    Part,
    fragment_path,
    merge_parts,
    part_dir,
    parts_of,
    process_part,
    process_recording,
    read_fragment,
    recording_parts,
    write_fragment,
)
from millsense.cli.batch_workers import start_worker_server
from millsense.core.errors import ConfigError, InputDataError

__all__ = [
    "BatchResult",
    "assess_wear",
    "find_recordings",
    "local_cluster",
    "parse_steps",
    "read_summary",
    "run_batch",
    "write_summary",
]

#: A task that raised (not a user error: those are rows) is retried this many times.
RETRIES = 2


@dataclass
class BatchResult:
    """Rows (one per recording), how many were run, reused from a previous batch, failed."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    ran: int = 0
    reused: int = 0
    workers: int = 0
    scheduler: str = ""
    #: the thread closing the client and the local cluster (join it before exiting; the
    #: interpreter does at exit, it is not a daemon)
    closing: threading.Thread | None = None


def find_recordings(spec: str) -> list[Path]:
    """The ``.h5`` recordings of a folder (recursively) or a glob pattern, sorted.

    Raises
    ------
    InputDataError
        Nothing matches (an empty folder, a pattern matching no recording).
    """
    import glob

    p = Path(spec)
    if p.is_dir():
        found = sorted(q for q in p.rglob("*.h5") if q.is_file())
    elif p.is_file():
        found = [p]
    else:
        found = sorted(Path(q) for q in glob.glob(spec, recursive=True) if Path(q).is_file())
    if not found:
        what = "folder" if p.is_dir() else "pattern"
        raise InputDataError(f"batch: {what} {spec} holds no recording (*.h5)")
    return found


def batch_inputs(spec: str, out_dir: Path) -> tuple[list[Path], int]:
    """The recordings of ``spec`` (:func:`find_recordings`) a batch into ``out_dir`` runs on,
    and how many found ones are outputs of a batch: the ``runs/`` files of ``out_dir`` and of
    any earlier batch output folder inside the input (a folder holding ``summary.parquet``;
    its ``runs/*/estimates.h5`` would be taken for recordings of the machine)."""
    out_abs = out_dir.resolve()
    found = find_recordings(spec)
    keep = [p for p in found if out_abs not in p.resolve().parents and not _batch_output(p)]
    return keep, len(found) - len(keep)


def _batch_output(path: Path) -> bool:
    """``path`` lies in the ``runs/`` folder of a batch's output (beside its summary)."""
    return any(
        d.name == "runs" and (d.parent / "summary.parquet").is_file()
        for d in path.resolve().parents
    )


def parse_steps(do: str) -> list[str]:
    """The steps of ``--do`` (one-line error naming an unknown one)."""
    steps = [s.strip() for s in do.split(",") if s.strip()]
    bad = [s for s in steps if s not in STEPS]
    if bad or not steps:
        raise ConfigError(f"--do: unknown step '{(bad or [do])[0]}' (any of {', '.join(STEPS)})")
    return steps


def run_batch(
    recordings: Sequence[Path],
    out_dir: Path,
    *,
    do: str = "estimate,monitor,wear,summary",
    machine: str | None = None,
    plan: str | None = None,
    workers: int = 2,
    scheduler: str | None = None,
    estimate_method: str = "spindle",
    monitor_methods: str = "chatter-comb",
    chunk: int = 2000,
    segment_s: float | None = 600.0,
    on_progress: Callable[[float, int], None] | None = None,
    on_waiting: Callable[[], None] | None = None,
) -> BatchResult:
    """Run every recording's task(s) on Dask and return the rows in the recordings' order.

    ``segment_s``: recordings longer than 1.5 × this many seconds run as segments (None: every
    recording as one task). ``on_progress(done, total)``: recordings done (a split recording
    counts by its finished parts) of the total. ``on_waiting()``: called once, when this process
    starts waiting for workers (its local cluster's start: the workers' fork server is still
    importing; or the tasks submitted to ``scheduler``): the caller can load what it needs after
    the batch then, on a core the workers do not use yet (decision 2008)."""
    from importlib.util import find_spec

    if find_spec("distributed") is None:  # imported where it is used (the cluster's thread)
        raise ConfigError(
            "batch: needs Dask's distributed scheduler: pip install 'dask[distributed]'"
        )

    if workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {workers}")
    floor = 2 * SEGMENT_WARMUP_S
    if segment_s is not None and not (segment_s >= floor and math.isfinite(segment_s)):
        raise ConfigError(f"--segment-s: must be ≥ {floor:g} s (twice the warm-up), got "
                          f"{segment_s:g}")  # fmt: skip
    options: dict[str, Any] = {
        "out_dir": str(out_dir.resolve()),
        "do": parse_steps(do),
        "machine": machine,
        "plan": plan,
        "estimate_method": estimate_method,
        "monitor_methods": monitor_methods,
        "chunk": chunk,
        "segment_s": segment_s,
    }
    res = BatchResult()
    # the local cluster starts (≈ 0.5 s, its workers forked from a server that imports the
    # tasks' modules meanwhile) while the rows of an earlier batch are read, unless every
    # recording has one already
    starting: dict[str, Any] = {}
    starter = None
    if scheduler is None and not all(fragment_path(out_dir, p).is_file() for p in recordings):
        # the workers' imports start first, on another core (decision 2008)
        start_worker_server()
        starter = threading.Thread(target=_start_local, args=(workers, starting, on_waiting),
                                   name="millsense-batch-start")  # fmt: skip
        starter.start()
    rows: dict[int, dict[str, Any]] = {}
    todo: list[int] = []
    for i, p in enumerate(recordings):
        old = read_fragment(out_dir, p)
        if old is not None and old.get("status") == "ok":
            rows[i] = old
            res.reused += 1
        else:
            todo.append(i)
    # a recording is split by its first task (the worker opens it, the client never does);
    # one that an earlier batch split keeps the parts it finished
    parts: dict[int, list[Part]] = {}
    finished: dict[int, dict[str, dict[str, Any]]] = {}
    for i in todo:
        if part_dir(out_dir, recordings[i]).is_dir():
            found = _parts(recordings[i], segment_s, options["do"])
            if found:
                parts[i] = found
                finished[i] = {}
                for pt in found:
                    old = read_fragment(out_dir, recordings[i], pt)
                    if old is not None and old.get("status") == "ok":
                        finished[i][pt.name] = old
    progress = _Progress(len(recordings), len(rows), parts, finished, on_progress)
    progress.report()
    if starter is not None:
        starter.join()
        if "error" in starting:
            raise starting["error"]
        if not todo:  # every row was there after all (a fragment of an unchanged input)
            _close(starting["client"], starting["cluster"])
    if todo:
        from dask.distributed import Client, as_completed

        cluster = None
        if scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except ValueError as exc:  # Dask's parse of the address: no port, unknown scheme
                raise ConfigError(f"--scheduler {scheduler!r}: {exc}") from None
            res.scheduler = scheduler
        else:
            if starter is None:
                _start_local(workers, starting, on_waiting)
                if "error" in starting:
                    raise starting["error"]
            cluster, client = starting["cluster"], starting["client"]
            res.scheduler = "local"
        try:
            res.workers = len(client.scheduler_info().get("workers", {}))
            futures: dict[Any, tuple[int, Part | None]] = {}

            def submit_parts(i: int) -> None:
                text = str(recordings[i].resolve())
                for pt in parts[i]:
                    if pt.name not in finished[i]:
                        key = f"millsense-batch-{i}-{pt.name}"
                        fut = client.submit(process_part, text, options, pt, retries=RETRIES,
                                            pure=False, key=key)  # fmt: skip
                        futures[fut] = (i, pt)
                        pending.add(fut)

            pending = as_completed([])
            for i in todo:
                if i in parts:
                    submit_parts(i)
                    continue
                text = str(recordings[i].resolve())
                fut = client.submit(process_recording, text, options, retries=RETRIES,
                                    pure=False, key=f"millsense-batch-{i}")  # fmt: skip
                futures[fut] = (i, None)
                pending.add(fut)
            if scheduler and on_waiting is not None:
                on_waiting()
            for i in [i for i in parts if len(finished[i]) == len(parts[i])]:
                rows[i] = _merged(out_dir, recordings[i], finished[i])  # all parts were done
                res.reused += 1
            for fut in pending:
                i, part = futures[fut]
                try:
                    row = fut.result()
                except Exception as exc:  # a task that failed RETRIES + 1 times, a killed worker
                    why = f"{type(exc).__name__}: {exc}"
                    row = {"run": recordings[i].stem, "path": str(recordings[i]),
                           "status": "error", "error": why}  # fmt: skip
                if part is None and row.get("status") == "split":
                    # a long recording: its parts run as tasks of their own
                    parts[i] = parts_of(int(row["n_samples"]), float(row["sample_rate_hz"]),
                                        segment_s, options["do"])  # fmt: skip
                    finished[i] = {}
                    submit_parts(i)
                elif part is None:
                    rows[i] = row
                    res.ran += 1
                    progress.whole()
                else:
                    row["part"] = part.name
                    finished[i][part.name] = row
                    if len(finished[i]) == len(parts[i]):
                        rows[i] = _merged(out_dir, recordings[i], finished[i])
                        res.ran += 1
                progress.report()
            # every task has ended: what a worker killed between writing and renaming left
            # (a hidden temporary) goes, so that runs/ holds the rows and nothing else
            from millsense.io.safe_output import remove_stale_temporaries

            remove_stale_temporaries(out_dir / "runs")
        finally:
            if cluster is not None:  # our own workers only, never a shared scheduler's
                try:
                    client.run(_leave_without_teardown, on_error="ignore")
                except Exception:  # a worker already gone: the close handles it
                    pass
            # the cluster shuts down while the caller assesses and reports
            res.closing = threading.Thread(target=_close, args=(client, cluster),
                                           name="millsense-batch-close")  # fmt: skip
            res.closing.start()
    res.rows = [rows[i] for i in range(len(recordings))]
    return res


def _start_local(
    workers: int, into: dict[str, Any], on_waiting: Callable[[], None] | None = None
) -> None:
    """Start the local cluster and its client into ``into`` (``cluster``, ``client``), or put
    the exception there (``error``); ``on_waiting()`` once Dask is imported (the cluster's own
    start is then about 0.1 s of this process's CPU, the rest is waiting for the workers)."""
    from dask.distributed import Client

    if on_waiting is not None:
        on_waiting()
    try:
        into["cluster"] = local_cluster(workers)
        into["client"] = Client(into["cluster"])
    except Exception as exc:  # re-raised by the caller's thread
        into["error"] = exc


def _leave_without_teardown() -> None:
    """Run on each worker of a local cluster once its batch is done (decision 2007): the worker
    process then ends at its first exit handler with ``os._exit(0)`` instead of tearing its
    modules down. That teardown (numba, scipy, pyarrow loaded) made the cluster's close take
    0.25 s, on the cores the client's fleet view needs; 0.02 s without it."""
    import atexit

    def leave() -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)

    atexit.register(leave)


def _close(client: Any, cluster: Any) -> None:
    client.close()
    if cluster is not None:
        cluster.close()


def local_cluster(workers: int) -> Any:
    """The local Dask cluster of a batch: ``workers`` processes of one thread each, on
    127.0.0.1 only (decision 2003).

    The worker processes are forked from a server that imported the tasks' modules while the
    cluster started (:func:`~millsense.cli.batch_workers.start_worker_server`, decision 2008;
    spawned where there is no fork server). Each runs one BLAS, one numba and one HDF5-codec
    thread (the workers are the parallelism: with the codec's default of a thread per core,
    two workers on two cores ran their tasks 13 % slower than one, and one worker was no
    faster for it) and no statistical profiler: Dask's samples the task's stack every 10 ms
    in a thread of its own, and with a worker per core that CPU comes out of the tasks
    (measured: tasks 15 % slower with two workers on two cores, 2.5 % with one). The
    event-loop tick, system and memory monitors poll every 1–5 s instead of 20–500 ms (the
    client process, which hosts the scheduler and the nannies, used about 0.1 core for them
    during a batch; half that now).
    """
    import dask
    from dask.distributed import LocalCluster

    from millsense.io.hdf5_chunks import IO_THREADS_ENV

    forked = start_worker_server()  # sets the workers' environment in any case
    quiet = {
        "distributed.worker.profile.enabled": False,
        # the cluster's own watchdogs poll less often: on two cores their CPU is the tasks'
        "distributed.admin.tick.interval": "1s",
        "distributed.admin.system-monitor.interval": "5s",
        "distributed.worker.memory.monitor-interval": "1s",
    }
    if forked:  # decision 2008 (a worker restarted after the start is spawned, as before)
        quiet["distributed.worker.multiprocessing-method"] = "forkserver"
    # this process's Dask logs at WARNING for good (decision 2009): LocalCluster silences them
    # on its handlers and restores INFO in its close while its comms are still closing, and a
    # "Batched Comm Closed" INFO line with its traceback reached the batch's stderr; the
    # logger's own level outlasts that (the workers keep the cluster's silencing)
    logging.getLogger("distributed").setLevel(logging.WARNING)
    with dask.config.set(quiet):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            host="127.0.0.1", dashboard_address="127.0.0.1:0",
                            env={IO_THREADS_ENV: os.environ.get(IO_THREADS_ENV, "1")})  # fmt: skip


def _parts(path: Path, segment_s: float | None, do: list[str]) -> list[Part]:
    """The parts of a long recording (none: one task; also for a file the client cannot open:
    its task reports why)."""
    from millsense.core.errors import UserError

    try:
        return recording_parts(path, segment_s, do)[2]
    except (UserError, OSError, ValueError, KeyError):
        return []


def _merged(out_dir: Path, path: Path, done: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The run's row from its parts, written as the run's fragment when every part is ok."""
    from millsense.streaming.event_log import read_event_log, write_event_log

    row = merge_parts(list(done.values()))
    if row.get("status") == "ok":
        run_dir = out_dir / "runs" / str(row["run"])
        logs = sorted(run_dir.glob("seg-*/events.parquet"))
        if logs:  # the segments' own events, one log for the run
            write_event_log(run_dir / "events.parquet",
                            [e for log in logs for e in read_event_log(log)],
                            recording=path)  # fmt: skip
        write_fragment(out_dir, path, row)
    return row


class _Progress:
    """Recordings done, a split recording counted by its finished parts."""

    def __init__(self, total: int, whole_done: int, parts: dict[int, list[Part]],
                 finished: dict[int, dict[str, dict[str, Any]]],
                 report: Callable[[float, int], None] | None) -> None:  # fmt: skip
        self.total = total
        self.parts = parts
        self.finished = finished
        self.whole_done = whole_done
        self._report = report

    def report(self) -> None:
        if self._report is None:
            return
        split = sum(len(self.finished[i]) / len(p) for i, p in self.parts.items())
        self._report(self.whole_done + split, self.total)

    def whole(self) -> None:
        self.whole_done += 1


def assess_wear(rows: list[dict[str, Any]], *, limit_mm: float = 0.3) -> list[dict[str, Any]]:
    """Add the wear columns to the rows that have wear sums: per tool (``tool_id``, else the
    tool's name, on each machine), in order of the tool's cutting time (``tool_cutting_time_s``)
    or, without it, of the rows: ``wear_vb_mm``, ``wear_worn``, ``wear_rate_mm_min``,
    ``wear_remaining_min``, ``tool_run_index``, ``tool_cutting_time_s``, ``wear_reference``,
    and the tool's reference fit (decision 1760): ``wear_shear_scale``, ``wear_edge_scale``
    (1: the plan's K_te kept), ``wear_reference_condition``, ``wear_edge_error``."""
    from millsense.monitoring.wear import ToolRun, WearSums, assess_tool

    fields = WearSums.__dataclass_fields__
    groups: dict[tuple[str, str], list[tuple[int, dict[str, Any]]]] = {}
    for i, r in enumerate(rows):
        if r.get("status") == "ok" and "wear_n" in r:
            key = (str(r.get("machine", "")), str(r.get("tool_id") or r.get("tool", "")))
            groups.setdefault(key, []).append((i, r))
    for members in groups.values():
        known = all(r.get("tool_cutting_time_s") is not None for _, r in members)
        runs = []
        for i, r in members:
            sums = WearSums(**{k: type(getattr(WearSums(), k))(r[f"wear_{k}"]) for k in fields})
            order = float(r["tool_cutting_time_s"]) if known else float(i)
            runs.append(ToolRun(str(i), order, float(r.get("cut_s", 0.0)), sums,
                                float(r["plan_kte_n_mm"]) * 1e3))  # fmt: skip
        try:
            assessed = assess_tool(runs, limit_m=limit_mm * 1e-3, cutting_time_known=known)
        except InputDataError as exc:
            for _, r in members:
                r["wear_note"] = str(exc)
            continue
        for a in assessed:
            r = rows[int(a.run)]
            remaining = a.remaining_s / 60 if math.isfinite(a.remaining_s) else None
            r.update(
                wear_vb_mm=a.vb_m * 1e3,
                wear_worn=a.worn,
                wear_reference=a.reference,
                wear_rate_mm_min=a.rate_m_s * 1e3 * 60 if math.isfinite(a.rate_m_s) else None,
                wear_remaining_min=remaining,
                tool_run_index=a.run_index,
                tool_cutting_time_s=a.cutting_time_s,
                wear_shear_scale=a.shear_scale,
                wear_edge_scale=a.edge_scale,
                wear_reference_condition=a.condition,
                wear_edge_error=a.edge_error,
            )
    return rows


def write_summary(rows: list[dict[str, Any]], out_dir: Path) -> Path:
    """The table as ``OUT/summary.parquet`` (atomically; columns: the union of the rows')."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from millsense.io.safe_output import atomic_path

    names: list[str] = []
    for r in rows:
        names += [k for k in r if k not in names]
    table = pa.Table.from_pylist([{k: r.get(k) for k in names} for r in rows])
    target = out_dir / "summary.parquet"
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp:
        pq.write_table(table, tmp)
    return target


def read_summary(path: Path) -> list[dict[str, Any]]:
    """The rows of a summary table written by :func:`write_summary`.

    Raises
    ------
    InputDataError
        Not a readable Parquet file, or not a batch's table (no ``run``/``status`` column):
        one line naming the file.
    """
    from millsense.core.parquet_read import read_parquet_table

    try:
        table = read_parquet_table(path)
    except (OSError, ValueError) as exc:
        why = str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__
        raise InputDataError(f"{path}: not a readable summary table ({why})") from None
    missing = [c for c in ("run", "status") if c not in table.column_names]
    if missing:
        raise InputDataError(
            f"{path}: not the summary table of a batch (no column {', '.join(missing)})"
        )
    return [dict(r) for r in table.to_pylist()]
