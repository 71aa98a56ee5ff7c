"""NI TDMS files (``npTDMS``). Columns are ``group/channel``; a channel's ``wf_increment``
property (s) states the rate, its ``unit_string`` the unit."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import InputDataError
from millsense.io.importers.table import RawTable

__all__ = ["read_tdms", "write_tdms"]


def _module(path: Path) -> Any:
    """The optional reader package, or a one-line error saying how to install it."""
    import importlib

    try:
        return importlib.import_module("nptdms")
    except ImportError:
        raise InputDataError(
            f"{path}: reading or writing {path.suffix} needs the npTDMS package: "
            "pip install 'millsense[import]'"
        ) from None


def read_tdms(path: Path, group: str | None = None) -> RawTable:
    """Read the numeric channels of a TDMS file (of ``group`` only when given).

    Raises
    ------
    InputDataError
        Not a TDMS file, no numeric channel, or channels of different lengths.
    """
    nptdms = _module(path)
    try:
        tdms = nptdms.TdmsFile.read(str(path))
    except Exception as exc:  # npTDMS raises ValueError/KeyError/struct.error on bad files
        raise InputDataError(f"{path}: not a readable TDMS file: {exc}") from None
    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    rate = None
    for g in tdms.groups():
        if group is not None and g.name != group:
            continue
        for ch in g.channels():
            data = np.asarray(ch[:])
            if data.dtype.kind not in "iuf" or data.size == 0:
                continue
            name = f"{g.name}/{ch.name}"
            columns[name] = data.astype(np.float64)
            units[name] = str(ch.properties.get("unit_string", ""))
            inc = ch.properties.get("wf_increment")
            if inc and rate is None:
                rate = 1.0 / float(inc)
    if not columns:
        raise InputDataError(f"{path}: no numeric channel")
    if len({v.size for v in columns.values()}) > 1:
        raise InputDataError(
            f'{path}: channels of different lengths; give [[files]] sheet = "GROUP" '
            "to read one group"
        )
    return RawTable(path=path, columns=columns, units=units, stated_rate_hz=rate)


def write_tdms(
    path: Path,
    columns: Mapping[str, np.ndarray],
    units: Mapping[str, str],
    rate_hz: float,
    group: str = "millsense",
) -> dict[str, str]:
    """Write the columns as channels of one group with ``wf_increment`` and ``unit_string``.
    Returns column → TDMS column name (``group/channel``, the channel's ``/`` as ``.``)."""
    nptdms = _module(path)
    ChannelObject, TdmsWriter = nptdms.ChannelObject, nptdms.TdmsWriter

    names = {c: c.replace("/", ".") for c in columns}
    with TdmsWriter(str(path)) as w:
        objs = [
            ChannelObject(
                group,
                names[c],
                np.asarray(v, dtype=np.float64),
                properties={"wf_increment": 1.0 / rate_hz, "unit_string": units.get(c, "")},
            )
            for c, v in columns.items()
        ]
        w.write_segment(objs)
    return {c: f"{group}/{n}" for c, n in names.items()}
