"""Reading one Parquet file into a pyarrow table, without pyarrow's dataset layer.

``pyarrow.parquet.read_table`` goes through ``pyarrow.dataset`` (it accepts folders, filters
and partitions), whose first import is paid by every batch worker for its first plan and by
every command that reads a plan or an event log: a fleet plan's first read took 63 ms with
``read_table`` against 17 ms with ``ParquetFile.read`` in one process on the 2-core
development host (2026-11-28; the difference is ``pyarrow.dataset`` and ``pyarrow.compute``
loading). millsense's own tables (plans, event logs, batch rows and
summaries) are single files, for which ``ParquetFile.read`` gives the same table, schema
metadata included (checked in ``tests/test_parquet_read.py``).
"""

from __future__ import annotations

import os
from typing import Any


def read_parquet_table(path: str | os.PathLike[str]) -> Any:
    """The table in the Parquet *file* ``path`` (a ``pyarrow.Table``). Raises what
    ``pyarrow.parquet.ParquetFile`` raises: ``FileNotFoundError``, ``IsADirectoryError`` (an
    ``OSError``), ``pyarrow.ArrowInvalid`` (a ``ValueError``) for a file that is not Parquet."""
    import pyarrow.parquet as pq

    with pq.ParquetFile(path) as f:
        return f.read()
