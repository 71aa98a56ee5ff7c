"""MATLAB .mat files: v5 (``scipy.io``) and v7.3 (HDF5, ``h5py``).

Every numeric vector variable (1-D, or N×1 / 1×N) is a column; the variables of a struct are
read as ``struct.field``. A scalar variable named like a sample rate (``fs``, ``Fs``,
``sample_rate_hz``, ``SampleRate``) states the rate. v7.3 files are HDF5 with a 512-byte
MATLAB header; their datasets are stored transposed (MATLAB is column-major), which for
vectors changes only the shape.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from millsense.core.errors import InputDataError
from millsense.io.importers.table import RawTable

__all__ = ["read_mat", "write_mat", "write_mat73"]

_RATE_NAMES = ("fs", "sample_rate_hz", "samplerate", "sample_rate", "srate")
_UNITS_VAR = "units"


def _vector(value: object) -> np.ndarray | None:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iufb" or arr.size == 0:
        return None
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.reshape(-1)
    if arr.ndim != 1:
        return None
    return arr.astype(np.float64)


def _is_v73(path: Path) -> bool:
    with open(path, "rb") as fh:
        head = fh.read(128)
    return b"MATLAB 7.3" in head or h5py.is_hdf5(path)


def read_mat(path: Path) -> RawTable:
    """Read the numeric vectors of a .mat file (v5 or v7.3) as columns.

    Raises
    ------
    InputDataError
        The file is not a MAT file, or holds no numeric vector.
    """
    try:
        flat = _read_v73(path) if _is_v73(path) else _read_v5(path)
    except (OSError, ValueError, NotImplementedError, TypeError) as exc:
        raise InputDataError(f"{path}: not a readable MAT file: {exc}") from None
    rate = None
    units: dict[str, str] = {}
    columns: dict[str, np.ndarray] = {}
    skipped: dict[str, tuple[str, str]] = {}
    for name, value in flat.items():
        if isinstance(value, str):
            continue
        arr = np.asarray(value)
        if arr.size == 1 and name.lower().rsplit(".", 1)[-1] in _RATE_NAMES:
            rate = float(arr.reshape(-1)[0])
            continue
        vec = _vector(value)
        if vec is not None and vec.size > 1:
            columns[name] = vec
        elif arr.dtype.kind in "iufb" and arr.ndim > 1:
            skipped[name] = ("×".join(map(str, arr.shape)), "a matrix, not a vector")
    for name, value in flat.items():
        if isinstance(value, str) and name.startswith(_UNITS_VAR + "."):
            units[name.removeprefix(_UNITS_VAR + ".")] = value
    if not columns:
        raise InputDataError(f"{path}: no numeric vector variable")
    lengths = {v.size for v in columns.values()}
    if len(lengths) > 1:
        longest = max(lengths)
        for k, v in columns.items():
            if v.size != longest:
                skipped[k] = (
                    f"{v.size} samples",
                    f"the columns of one file have one length ({longest}); save it in a file "
                    "of its own",
                )
        columns = {k: v for k, v in columns.items() if v.size == longest}
    return RawTable(path=path, columns=columns, units=units, stated_rate_hz=rate, skipped=skipped)


def _read_v5(path: Path) -> dict[str, object]:
    from scipy.io import loadmat

    data = loadmat(str(path), squeeze_me=True, struct_as_record=False, chars_as_strings=True)
    out: dict[str, object] = {}

    def walk(prefix: str, value: object) -> None:
        if hasattr(value, "_fieldnames"):
            for f in value._fieldnames:
                walk(f"{prefix}.{f}", getattr(value, f))
        elif isinstance(value, str):
            out[prefix] = value
        else:
            out[prefix] = value

    for k, v in data.items():
        if not k.startswith("__"):
            walk(k, v)
    return out


def _read_v73(path: Path) -> dict[str, object]:
    out: dict[str, object] = {}
    with h5py.File(path, "r") as f:

        def visit(name: str, obj: object) -> None:
            if not isinstance(obj, h5py.Dataset) or name.startswith("#refs#"):
                return
            key = name.replace("/", ".")
            if obj.attrs.get("MATLAB_class", b"") in (b"char", "char"):
                codes = np.asarray(obj[()]).reshape(-1)
                out[key] = "".join(chr(int(c)) for c in codes)
            else:
                out[key] = np.asarray(obj[()])

        f.visititems(visit)
    return out


def _matlab_names(columns: Mapping[str, np.ndarray]) -> dict[str, str]:
    """column → MATLAB variable name (``/`` → ``_``); a name the file's rate or units variable
    holds (``fs``, ``units``, …; the importer reads any of ``_RATE_NAMES`` as the rate) takes
    ``_channel`` (a channel named ``fs`` overwrote the rate); a clash is an error."""
    names = {c: "".join(ch if ch.isalnum() else "_" for ch in c) for c in columns}
    names = {c: (n if n[0].isalpha() else "v" + n) for c, n in names.items()}
    reserved = {*_RATE_NAMES, _UNITS_VAR}
    names = {c: (n + "_channel" if n.lower() in reserved else n) for c, n in names.items()}
    if len(set(names.values())) != len(names):
        raise InputDataError("MAT export: two channels map to one variable name")
    return names


def write_mat(
    path: Path, columns: Mapping[str, np.ndarray], units: Mapping[str, str], rate_hz: float
) -> dict[str, str]:
    """Write a v5 .mat file: one double vector per column, ``fs`` and a ``units`` struct.
    Returns column → variable name."""
    from scipy.io import savemat

    names = _matlab_names(columns)
    data: dict[str, object] = {
        names[c]: np.asarray(v, dtype=np.float64)[:, None] for c, v in columns.items()
    }
    data["fs"] = float(rate_hz)
    data[_UNITS_VAR] = {names[c]: units.get(c, "") or "1" for c in columns}
    savemat(str(path), data, do_compression=True, oned_as="column")
    return names


def write_mat73(
    path: Path, columns: Mapping[str, np.ndarray], units: Mapping[str, str], rate_hz: float
) -> dict[str, str]:
    """Write a v7.3 .mat file (HDF5 with the 512-byte MATLAB header, ``MATLAB_class``
    attributes) that MATLAB's ``load`` and h5py read. Returns column → variable name."""
    names = _matlab_names(columns)
    with h5py.File(path, "w", userblock_size=512) as f:
        for c, v in columns.items():
            ds = f.create_dataset(
                names[c],
                data=np.asarray(v, dtype=np.float64)[None, :],
                compression="gzip",
                shuffle=True,
            )
            ds.attrs["MATLAB_class"] = np.bytes_("double")
        f.create_dataset("fs", data=np.array([[float(rate_hz)]]))
        f["fs"].attrs["MATLAB_class"] = np.bytes_("double")
        g = f.create_group(_UNITS_VAR)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for c in columns:
            text = units.get(c, "") or "1"
            ds = g.create_dataset(
                names[c], data=np.array([[ord(ch)] for ch in text], dtype=np.uint16).T
            )
            ds.attrs["MATLAB_class"] = np.bytes_("char")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: millsense HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        block = header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
        fh.write(block.ljust(512, b"\x00"))
    return names
