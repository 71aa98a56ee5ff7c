"""The flaws of real files, injected into clean columns on purpose (the example data set and
the tests of :mod:`millsense.io.quality`): every injection returns what it did, so a test can
check that the report finds exactly that.

Each function takes and returns a dict of column → float64 array (rows of one table; copies
are made) and the record of what was injected.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["add_drift", "add_hum", "clip", "drop_rows", "repeat_rows"]

Columns = dict[str, np.ndarray]


def _copy(columns: Mapping[str, np.ndarray]) -> Columns:
    return {k: np.array(v, dtype=np.float64, copy=True) for k, v in columns.items()}


def repeat_rows(
    columns: Mapping[str, np.ndarray], runs: Sequence[tuple[int, int]], keep: Sequence[str] = ()
) -> Columns:
    """Rows ``start+1 … start+length−1`` repeat row ``start`` in every column but ``keep``
    (e.g. the time column): up-sampling by hold. ``runs`` = (start, length) in rows."""
    out = _copy(columns)
    for s, n in runs:
        for k, v in out.items():
            if k not in keep:
                v[s + 1 : s + n] = v[s]
    return out


def clip(
    columns: Mapping[str, np.ndarray], column: str, rail: float
) -> tuple[Columns, list[tuple[int, int, float]]]:
    """Clip ``column`` at ``rail`` from above (an amplifier's rail).

    Returns the columns and the flat tops made: (start row, length, rail) for every run of
    two or more rows above the rail (a single sample at the rail looks like a natural
    maximum and is not a flat top)."""
    out = _copy(columns)
    x = out[column]
    rail = float(rail)
    above = np.concatenate([[False], x >= rail, [False]])
    edges = np.flatnonzero(np.diff(above.astype(np.int8)))
    runs = [
        (int(a), int(b - a), rail)
        for a, b in zip(edges[0::2], edges[1::2], strict=True)
        if b - a >= 2
    ]
    out[column] = np.minimum(x, rail)
    return out, runs


def drop_rows(columns: Mapping[str, np.ndarray], start: int, length: int) -> Columns:
    """Remove rows ``start … start+length−1`` (a gap in a file with a time column)."""
    return {
        k: np.delete(np.asarray(v, dtype=np.float64), np.s_[start : start + length])
        for k, v in columns.items()
    }


def add_drift(columns: Mapping[str, np.ndarray], column: str, per_row: float) -> Columns:
    """Add ``per_row × row`` to ``column`` (an offset drifting linearly)."""
    out = _copy(columns)
    out[column] = out[column] + per_row * np.arange(out[column].size)
    return out


def add_hum(
    columns: Mapping[str, np.ndarray], column: str, amplitude: float, freq_hz: float, fs: float
) -> Columns:
    """Add mains hum ``amplitude·sin(2π f k/fs)`` and a third harmonic at a third of it."""
    out = _copy(columns)
    t = np.arange(out[column].size) / fs
    out[column] = out[column] + amplitude * (
        np.sin(2 * np.pi * freq_hz * t) + np.sin(2 * np.pi * 3 * freq_hz * t) / 3.0
    )
    return out
