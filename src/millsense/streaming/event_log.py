"""The event log: events of monitors, controllers and the simulator as one Parquet file.

One row per :class:`~millsense.streaming.block.Event`, written beside a recording
(``run.h5`` → ``run.events.parquet`` by default), readable with pandas
(``pd.read_parquet``) or duckdb (``SELECT * FROM 'run.events.parquet'``). The columns are the
event's fields; the free-form ``values`` mapping is stored as a JSON text column so that any
monitor may add named numbers without changing the schema, and the log's ``schema_version``
is kept in the file's metadata (issue 15, item 5), with the recording the events are of (its
file name, :func:`event_log_recording`) where the writer knows it.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from pathlib import Path

from millsense.core.errors import ConfigError
from millsense.io.safe_output import atomic_path
from millsense.streaming.block import Event, EventKind, Severity

SCHEMA_VERSION = 1

#: Column order of the log.
COLUMNS = (
    "time_s",
    "sample",
    "kind",
    "severity",
    "source",
    "name",
    "value",
    "nc_line",
    "x_mm",
    "y_mm",
    "z_mm",
    "message",
    "values_json",
)


def default_event_log_path(recording: str | os.PathLike[str]) -> Path:
    """``run.h5`` → ``run.events.parquet`` in the same folder."""
    p = Path(recording)
    return p.with_name(p.stem + ".events.parquet")


def _finite_or_none(v: float | None) -> float | None:
    if v is None:
        return None
    f = float(v)
    return f if math.isfinite(f) else None


#: The file-metadata key of the recording the events are of.
RECORDING_KEY = "millsense_recording"

#: pandas' own metadata key: ``pd.read_parquet`` reads the ``nc_line`` column (an integer
#: with gaps where an event has no NC line) as pandas' nullable ``Int64``, as it would have
#: written it, instead of its default for an integer column with nulls, float64 (line 12.0).
#: Only that column is described; the others convert as they do without the key.
PANDAS_KEY = "pandas"
PANDAS_METADATA = json.dumps(
    {
        "index_columns": [],
        "column_indexes": [],
        "columns": [
            {
                "name": "nc_line",
                "field_name": "nc_line",
                "pandas_type": "int64",
                "numpy_type": "Int64",
                "metadata": None,
            }
        ],
        "creator": {"library": "millsense"},
        "pandas_version": "1.0.0",
    }
)


def write_event_log(
    path: str | os.PathLike[str],
    events: Iterable[Event],
    recording: str | os.PathLike[str] | None = None,
) -> Path:
    """Write ``events`` (sorted by time, then sample) to ``path`` as Parquet, atomically;
    ``recording``: the recording they are of, whose file name the log's metadata keeps
    (:func:`event_log_recording`), so that a log moved away from it still says what it
    describes."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = sorted(events, key=lambda e: (e.time_s, e.sample))
    cols: dict[str, list[object]] = {c: [] for c in COLUMNS}
    for e in rows:
        cols["time_s"].append(float(e.time_s))
        cols["sample"].append(int(e.sample))
        cols["kind"].append(str(e.kind))
        cols["severity"].append(str(e.severity))
        cols["source"].append(e.source)
        cols["name"].append(e.name)
        cols["value"].append(_finite_or_none(e.value))
        cols["nc_line"].append(None if e.nc_line is None else int(e.nc_line))
        cols["x_mm"].append(_finite_or_none(e.x_mm))
        cols["y_mm"].append(_finite_or_none(e.y_mm))
        cols["z_mm"].append(_finite_or_none(e.z_mm))
        cols["message"].append(e.message)
        cols["values_json"].append(
            json.dumps({k: _finite_or_none(v) for k, v in e.values.items()}, sort_keys=True)
        )
    schema = pa.schema(
        [
            ("time_s", pa.float64()),
            ("sample", pa.int64()),
            ("kind", pa.string()),
            ("severity", pa.string()),
            ("source", pa.string()),
            ("name", pa.string()),
            ("value", pa.float64()),
            ("nc_line", pa.int64()),
            ("x_mm", pa.float64()),
            ("y_mm", pa.float64()),
            ("z_mm", pa.float64()),
            ("message", pa.string()),
            ("values_json", pa.string()),
        ],
        metadata={
            "millsense_event_log_schema_version": str(SCHEMA_VERSION),
            PANDAS_KEY: PANDAS_METADATA,
            **({} if recording is None else {RECORDING_KEY: Path(recording).name}),
        },
    )
    table = pa.table(cols, schema=schema)
    out = Path(path)
    with atomic_path(out) as tmp:
        pq.write_table(table, tmp)
    return out


def event_log_recording(path: str | os.PathLike[str]) -> str | None:
    """The file name of the recording an event log is of (None: not recorded in the log,
    e.g. a log written before it was kept)."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(Path(path)).metadata or {}
    value = meta.get(RECORDING_KEY.encode())
    return None if value is None else value.decode()


def read_event_log(path: str | os.PathLike[str]) -> list[Event]:
    """Read a log written by :func:`write_event_log` back into events.

    Raises :class:`~millsense.core.errors.ConfigError` naming the file when it is not a
    millsense event log.
    """
    from millsense.core.parquet_read import read_parquet_table

    p = Path(path)
    try:
        table = read_parquet_table(p)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{p}: not a readable Parquet event log ({exc})") from None
    missing = [c for c in COLUMNS if c not in table.column_names]
    if missing:
        raise ConfigError(f"{p}: not a millsense event log (missing columns {', '.join(missing)})")
    d = table.to_pydict()
    out: list[Event] = []
    for i in range(table.num_rows):
        values = json.loads(str(d["values_json"][i]))
        out.append(
            Event(
                time_s=float(d["time_s"][i]),
                kind=EventKind(d["kind"][i]),
                source=str(d["source"][i]),
                message=str(d["message"][i]),
                name=str(d["name"][i]),
                value=d["value"][i],
                sample=int(d["sample"][i]),
                severity=Severity(d["severity"][i]),
                values={k: (math.nan if v is None else float(v)) for k, v in values.items()},
                nc_line=d["nc_line"][i],
                x_mm=d["x_mm"][i],
                y_mm=d["y_mm"][i],
                z_mm=d["z_mm"][i],
            )
        )
    return out
