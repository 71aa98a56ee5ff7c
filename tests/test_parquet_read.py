"""``core.parquet_read.read_parquet_table``: the table ``pyarrow.parquet.read_table`` gives for a
single file (schema metadata included), the errors the callers catch, and no import of
``pyarrow.dataset`` (the 0.1 s per process it exists to save)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from millsense.core.parquet_read import read_parquet_table


def _table() -> pa.Table:
    t = pa.table({"t_s": [0.0, 0.1, 0.2], "line": [1, 2, 3], "name": ["a", "b", "c"]})
    return t.replace_schema_metadata({b"millsense": b'{"format_version": 2}'})


def test_same_table_and_metadata_as_read_table(tmp_path: Path) -> None:
    p = tmp_path / "x.parquet"
    pq.write_table(_table(), p, compression="zstd")
    got = read_parquet_table(p)
    assert got.equals(pq.read_table(p))
    assert got.schema.metadata == pq.read_table(p).schema.metadata
    assert got.schema.metadata[b"millsense"] == b'{"format_version": 2}'


def test_errors_the_callers_catch(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_parquet_table(tmp_path / "missing.parquet")
    with pytest.raises(OSError):
        read_parquet_table(tmp_path)  # a folder
    bad = tmp_path / "bad.parquet"
    bad.write_text("not parquet")
    with pytest.raises(ValueError):  # pyarrow.ArrowInvalid
        read_parquet_table(bad)


def test_reading_does_not_load_the_dataset_layer(tmp_path: Path) -> None:
    p = tmp_path / "x.parquet"
    pq.write_table(_table(), p)
    code = (
        "import sys\n"
        "from millsense.core.parquet_read import read_parquet_table\n"
        f"read_parquet_table({str(p)!r})\n"
        "print('pyarrow.dataset' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
