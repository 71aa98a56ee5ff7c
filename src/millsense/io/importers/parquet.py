"""Parquet tables (pyarrow): one numeric column per channel; units and the rate in the
schema's key-value metadata (``unit`` per field, ``sample_rate_hz``) when written by millsense."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from millsense.core.errors import InputDataError
from millsense.io.importers.table import RawTable

__all__ = ["read_parquet", "write_parquet"]


def read_parquet(path: Path) -> RawTable:
    """Read the numeric columns of a Parquet file.

    Raises
    ------
    InputDataError
        The file is not Parquet or has no numeric column.
    """
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowInvalid) as exc:
        raise InputDataError(f"{path}: not a readable Parquet file: {exc}") from None
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    skipped: dict[str, tuple[str, str]] = {}
    for fld in table.schema:
        if not (
            pa.types.is_integer(fld.type)
            or pa.types.is_floating(fld.type)
            or pa.types.is_boolean(fld.type)
        ):
            skipped[fld.name] = (str(fld.type), "not numbers")
            continue
        col = table.column(fld.name)
        columns[fld.name] = col.to_numpy(zero_copy_only=False).astype(np.float64)
        if fld.metadata and b"unit" in fld.metadata:
            units[fld.name] = fld.metadata[b"unit"].decode()
    if not columns:
        raise InputDataError(f"{path}: no numeric column")
    meta = table.schema.metadata or {}
    rate = float(meta[b"sample_rate_hz"]) if b"sample_rate_hz" in meta else None
    return RawTable(path=path, columns=columns, units=units, stated_rate_hz=rate, skipped=skipped)


def write_parquet(
    path: Path, columns: Mapping[str, np.ndarray], units: Mapping[str, str], rate_hz: float
) -> None:
    """Write one float64 column per channel with its unit, and the rate, in the schema."""
    fields = [pa.field(c, pa.float64(), metadata={"unit": units.get(c, "")}) for c in columns]
    schema = pa.schema(fields, metadata={"sample_rate_hz": repr(float(rate_hz))})
    arrays = [pa.array(np.asarray(v, dtype=np.float64)) for v in columns.values()]
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), path)
