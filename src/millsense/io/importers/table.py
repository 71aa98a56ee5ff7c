"""What every format reader returns: the columns of one file, with what its header says."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["TIME_NAMES", "RawTable", "name_unit", "rate_from_header"]

#: Column names taken as the time column when the map names none (case-insensitive).
TIME_NAMES = ("time", "t", "time_s", "zeit", "timestamp", "time [s]")

_RATE_KEY = re.compile(r"(sampl\w*[ _-]?(rate|freq\w*)|abtastrate|abtastfrequenz|fs)\b", re.I)
_PERIOD_KEY = re.compile(r"(sampl\w*[ _-]?(time|period|interval)|abtastzeit|cycle|takt)", re.I)
_NUMBER_UNIT = re.compile(r"([-+]?\d+(?:[.,]\d+)?(?:[eE][-+]?\d+)?)\s*\[?\s*([a-zA-Zµ]*)")
_PERIOD_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "": 1.0}
_RATE_UNITS = {"hz": 1.0, "khz": 1e3, "": 1.0}


@dataclass
class RawTable:
    """The columns of one file as read, before the map is applied.

    Attributes
    ----------
    path : the file.
    columns : column name → float64 samples (all columns of one file have one length).
    units : column name → unit as written in the file ('' when it says none).
    stated_rate_hz : the sample rate the file itself states (header line, WAV/TDMS property),
        or None.
    header : key → value lines found before the table (free text of the export).
    first_line : 1-based line of the first data row in a text file (0 for binary formats), so
        that messages can name a row's line.
    skipped : variable name → (its size, why it is not a column): a .mat matrix, a vector of
        another length, so that a map naming it is told why.
    clock_origin : column of wall-clock stamps (ISO-8601 in a text file, read as seconds from
        its first row) → its first stamp as written.
    """

    path: Path
    columns: dict[str, np.ndarray]
    units: dict[str, str] = field(default_factory=dict)
    stated_rate_hz: float | None = None
    header: dict[str, str] = field(default_factory=dict)
    first_line: int = 0
    skipped: dict[str, tuple[str, str]] = field(default_factory=dict)
    clock_origin: dict[str, str] = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        """Rows of the table."""
        for v in self.columns.values():
            return int(v.shape[0])
        return 0

    def unit_of(self, column: str) -> str:
        """The unit the file gives ``column``: its units row or bracket (:attr:`units`), else
        a known unit after the name's last underscore (``x_current_A``, ``time_ms``), else
        ''."""
        return self.units.get(column, "") or (name_unit(column) or ("", ""))[1]

    def time_column(self, name: str | None) -> str | None:
        """The time column: ``name`` if given (``""``: none, the rate is stated), else one
        named like :data:`TIME_NAMES` (also with a time unit after an underscore:
        ``time_ms``), else the only column of wall-clock stamps."""
        if name is not None:
            return name or None
        for col in self.columns:
            if col.strip().lower() in TIME_NAMES:
                return col
        for col in self.columns:
            stem_unit = name_unit(col)
            if stem_unit and stem_unit[0].strip().lower() in TIME_NAMES:
                from millsense.io.importers.mapfile import UNITS

                if UNITS[stem_unit[1]][0] == "s":
                    return col
        if len(self.clock_origin) == 1:
            return next(iter(self.clock_origin))
        return None


def name_unit(column: str) -> tuple[str, str] | None:
    """(stem, unit) of a column name ending in ``_UNIT`` with a known unit (the map's
    :data:`~millsense.io.importers.mapfile.UNITS`: ``x_current_A`` → ("x_current", "A"),
    ``spindle_speed_rpm``, ``time_ms``), else None (``coolant_on``, ``x_current_cmd``)."""
    from millsense.io.importers.mapfile import UNITS

    stem, sep, unit = column.strip().rpartition("_")
    if sep and stem and unit in UNITS:
        return stem, unit
    return None


def rate_from_header(header: dict[str, str]) -> float | None:
    """A sample rate (Hz) stated by a header line: ``Sample rate: 10 kHz``,
    ``Abtastzeit; 0,1 ms``, ``sampling period = 100 us``... None when no line states one."""
    for key, value in header.items():
        m = _NUMBER_UNIT.search(value)
        if m is None:
            continue
        number = float(m.group(1).replace(",", "."))
        unit = m.group(2).lower()
        if _RATE_KEY.search(key) and unit in _RATE_UNITS and number > 0:
            return number * _RATE_UNITS[unit]
        if _PERIOD_KEY.search(key) and unit in _PERIOD_UNITS and number > 0:
            return 1.0 / (number * _PERIOD_UNITS[unit])
    return None
