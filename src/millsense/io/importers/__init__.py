"""Measurements made outside millsense into a :class:`~millsense.core.recording.Recording`.

One module per format (:mod:`.delimited` CSV/TSV and CNC trace exports, :mod:`.matlab` .mat
v5/v7.3, :mod:`.tdms` NI TDMS, :mod:`.audio` WAV/FLAC/MP3, :mod:`.parquet`), each reading a
file into a :class:`~.table.RawTable` and writing one (for ``millsense export`` and the round
trip); :mod:`.mapfile` is the map naming which column is which channel; :func:`import_files`
applies it: units to SI, time base and rate, gaps filled, the fastest file as channels and
slower ones as streams, with the data-quality report of :mod:`millsense.io.quality`
(decision 1701). :mod:`.export` writes a recording in every format with the map that imports
it back.
"""

from __future__ import annotations

import fnmatch
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import Recording
from millsense.io.importers.mapfile import (
    ChannelMap,
    FileOptions,
    ImportMap,
    check_channel_unit,
    load_map,
    si_factor,
    si_zero,
    time_factor,
)
from millsense.io.importers.table import RawTable
from millsense.io.quality import Finding, QualityReport, check_recording, nan_runs, rate_from_time

__all__ = ["FORMATS", "ImportResult", "import_files", "load_map", "read_table"]

#: File suffix → format name.
FORMATS = {
    ".csv": "csv",
    ".txt": "csv",
    ".tsv": "tsv",
    ".mat": "mat",
    ".tdms": "tdms",
    ".wav": "audio",
    ".flac": "audio",
    ".mp3": "audio",
    ".ogg": "audio",
    ".parquet": "parquet",
}
#: NaN runs up to this many samples are filled by linear interpolation; longer ones refused.
MAX_NAN_FILL = 10


def read_table(
    path: Path,
    options: FileOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RawTable:
    """Read one file with the reader of its suffix (``progress(done, total)``: a text file's
    characters read, after each chunk of its table).

    Raises
    ------
    InputDataError
        Missing file, unknown suffix, or the reader's one-line error.
    """
    opt = options or FileOptions()
    if not path.is_file():
        raise InputDataError(f"{path}: no such file")
    kind = FORMATS.get(path.suffix.lower())
    if kind in ("csv", "tsv"):
        from millsense.io.importers.delimited import read_delimited

        return read_delimited(path, opt.delimiter, opt.decimal, progress)
    if kind == "mat":
        from millsense.io.importers.matlab import read_mat

        return read_mat(path)
    if kind == "tdms":
        from millsense.io.importers.tdms import read_tdms

        return read_tdms(path, opt.sheet)
    if kind == "audio":
        from millsense.io.importers.audio import read_audio

        return read_audio(path)
    if kind == "parquet":
        from millsense.io.importers.parquet import read_parquet

        return read_parquet(path)
    raise InputDataError(
        f"{path}: unknown file type '{path.suffix}' (known: {', '.join(sorted(FORMATS))})"
    )


@dataclass
class ImportResult:
    """The recording and what was found on the way."""

    recording: Recording
    report: QualityReport


@dataclass
class _Timed:
    """One file on its time base: rate, first time, columns already on a uniform grid."""

    table: RawTable
    fs: float
    t0: float
    columns: dict[str, np.ndarray]
    stated: float | None
    has_time: bool
    filled: np.ndarray  # samples filled in gaps


def _file_of(ch: ChannelMap, tables: Sequence[RawTable], where: str) -> RawTable:
    cands = [t for t in tables if ch.file is None or fnmatch.fnmatch(t.path.name, ch.file)]
    if ch.file is not None and not cands:
        raise ConfigError(f"{where}: file = {ch.file!r} matches none of the files given")
    having = [t for t in cands if ch.column in t.columns]
    if not having:
        t = cands[0]
        skip = next((c for c in cands if ch.column in c.skipped), None)
        if skip is not None:
            size, why = skip.skipped[ch.column]
            raise InputDataError(
                f"{skip.path}: {ch.column!r} ({size}) is not a column for channel "
                f"'{ch.channel}': {why}"
            )
        shown = ", ".join(repr(c) for c in list(t.columns)[:12])
        hint = ""
        if len(t.columns) == 1 and FORMATS.get(t.path.suffix.lower()) in ("csv", "tsv"):
            hint = " (one column only: is the delimiter right?)"
        raise InputDataError(
            f"{t.path}: no column {ch.column!r} for channel '{ch.channel}'; columns: {shown}{hint}"
        )
    if len(having) > 1:
        raise ConfigError(
            f"{where}: column {ch.column!r} is in {having[0].path.name} and "
            f'{having[1].path.name}: say which with file = "..."'
        )
    return having[0]


def _on_grid(
    table: RawTable, opt: FileOptions, rate_hz: float | None, report: QualityReport
) -> _Timed:
    """The file's columns on a uniform time grid (gaps filled), its rate and first time."""
    where = str(table.path)
    stated = opt.sample_rate_hz or rate_hz or table.stated_rate_hz
    if stated is not None and not (math.isfinite(stated) and stated > 0):
        raise InputDataError(  # the map's and --rate-hz are checked: the file's own (.mat fs)
            f"{where}: the file states a sample rate of {stated:g} Hz (must be finite and > 0): "
            "give [[files]] sample_rate_hz in the map or --rate-hz"
        )
    tcol = table.time_column(opt.time_column)
    if tcol is not None and tcol not in table.columns:
        raise InputDataError(f"{where}: no time column {opt.time_column!r}")
    cols = {k: v for k, v in table.columns.items() if k != tcol}
    n = table.n_rows
    if tcol is None:
        if stated is None:
            raise InputDataError(
                f"{where}: no time column and no sample rate: give [[files]] sample_rate_hz "
                "in the map or --rate-hz"
            )
        report.rates[where] = (stated, stated)
        return _Timed(table, float(stated), 0.0, cols, stated, False, np.zeros(n, bool))
    # the map's time_unit, else the file's (units row, "Time [ms]"), else seconds
    unit = opt.time_unit or table.unit_of(tcol) or "s"
    factor = time_factor(unit, f"{where}: time column {tcol!r}")
    if tcol in table.clock_origin and factor != 1.0:
        raise ConfigError(
            f"{where}: time column {tcol!r} holds dates and times (read in s): time_unit = "
            f"{opt.time_unit!r} does not apply"
        )
    t = np.asarray(table.columns[tcol], dtype=np.float64) * factor
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputDataError(
            f"{where}: line {table.first_line + k}: time column {tcol!r} is empty or not finite"
        )
    fs, _, _ = rate_from_time(t, stated, where, report)
    bad = [f for f in report.refusals if f.where == where]
    if bad:
        row = bad[0].data.get("row")
        line = (
            f" (line {table.first_line + int(row)} of the file)" if row and table.first_line else ""
        )
        raise InputDataError(bad[0].message + line)
    pos = (t - t[0]) * fs
    k = np.rint(pos).astype(np.int64)
    m = int(k[-1]) + 1
    filled = np.ones(m, dtype=bool)
    if np.max(np.abs(pos - k)) < 0.25 and np.all(np.diff(k) > 0):
        filled[k] = False
        grid = {c: _fill_index(k, v, m) for c, v in cols.items()}
    else:
        report.add(
            Finding(
                "time",
                where,
                f"{where}: time steps jitter by up to "
                f"{np.max(np.abs(pos - k)):.2f} samples: resampled linearly on a "
                f"uniform {fs:.6g} Hz grid",
            )
        )
        filled[:] = False
        grid = {c: np.interp(np.arange(m), pos, v) for c, v in cols.items()}
    return _Timed(table, fs, float(t[0]), grid, stated, True, filled)


def _clock_start(tm: _Timed, opt: FileOptions) -> str | None:
    """The first wall-clock stamp of a file read on its clock column, else None."""
    tcol = tm.table.time_column(opt.time_column)
    return tm.table.clock_origin.get(tcol) if tm.has_time and tcol is not None else None


def _on_one_clock(
    timed: Mapping[Path, _Timed], fastest: _Timed, opts: Mapping[Path, FileOptions]
) -> None:
    """Files stamped with the wall clock start where their first stamps say, relative to the
    fastest file's first stamp (t = 0): each was read as seconds from its own first row, so a
    temperature log started 0.5 s before the drives' trace was laid 0.5 s late.

    Raises
    ------
    InputDataError
        Stamps with a zone offset in one file and without in another: no common clock.
    """
    from millsense.io.importers.delimited import stamp_ns

    ref = _clock_start(fastest, opts[fastest.table.path])
    if ref is None:
        return
    ref_ns, zoned = stamp_ns(ref)
    for path, tm in timed.items():
        start = _clock_start(tm, opts[path])
        if tm is fastest or start is None:
            continue
        start_ns, other = stamp_ns(start)
        if other != zoned:
            raise InputDataError(
                f"{path}: its first stamp {start!r} and {fastest.table.path}'s {ref!r}: one has "
                "a zone offset and the other not: no common clock"
            )
        tm.t0 = (start_ns - ref_ns) * 1e-9


def _sparse_to_stream(
    ch: ChannelMap,
    x: np.ndarray,
    si: str,
    timed: _Timed,
    streams: dict[str, tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]],
    report: QualityReport,
) -> bool:
    """A column holding a value every k-th row (k > :data:`MAX_NAN_FILL`), blank between: a
    slower channel merged into a DAQ's table (a temperature at 100 Hz among 10 kHz currents).
    It becomes a stream at rate / k (STREAM/FIELD from its channel name) instead of a long
    NaN run refused; True when so."""
    idx = np.flatnonzero(np.isfinite(x))
    if idx.size < 2:
        return False
    steps = np.diff(idx)
    k = int(steps[0])
    if k <= MAX_NAN_FILL or np.any(steps != k) or idx[0] >= k or x.size - idx[-1] > k:
        return False
    sname, _, fname = ch.channel.rpartition("/")
    sname = sname or timed.table.path.stem
    t = timed.t0 + idx / timed.fs
    old = streams.setdefault(sname, (t, {}, {}))
    if old[0].shape != t.shape or np.any(old[0] != t):
        raise InputDataError(
            f"{timed.table.path}: channel '{ch.channel}' holds a value every {k} rows, another "
            f"field of stream '{sname}' not on the same rows: name them in different streams"
        )
    old[1][fname], old[2][fname] = x[idx], si
    report.add(
        Finding(
            "nan",
            ch.channel,
            f"{timed.table.path}: channel '{ch.channel}' holds a value every {k} rows, blank "
            f"between: stored as field '{fname}' of stream '{sname}' at "
            f"{timed.fs / k:.6g} Hz ({idx.size} rows)",
            data={"every": k, "rows": int(idx.size)},
        )
    )
    return True


def _fill_index(k: np.ndarray, v: np.ndarray, m: int) -> np.ndarray:
    if k.size == m:
        return np.asarray(v, dtype=np.float64)
    return np.interp(np.arange(m), k, v)


def _convert(ch: ChannelMap, timed: _Timed, where: str) -> tuple[np.ndarray, str]:
    unit = ch.unit
    if unit == "header":
        unit = timed.table.unit_of(ch.column)
        if not unit:
            raise InputDataError(
                f"{timed.table.path}: column {ch.column!r} has no unit in the file: give "
                f"unit in {where}"
            )
    si, factor = si_factor(unit, where)
    check_channel_unit(ch.channel, unit, si, where)
    x = (timed.columns[ch.column] * ch.scale + ch.offset) * factor + si_zero(unit)
    return x, si


def _fill_nan(
    x: np.ndarray, name: str, where: str, first_line: int, report: QualityReport, fs: float
) -> np.ndarray:
    st, ln = nan_runs(x)
    if not st.size:
        return x
    long = np.flatnonzero(ln > MAX_NAN_FILL)
    if long.size or np.count_nonzero(np.isfinite(x)) < 2:
        i = int(st[long[0]]) if long.size else int(st[0])
        n = int(ln[long[0]]) if long.size else int(ln[0])
        line = f"line {first_line + i}" if first_line else f"sample {i}"
        raise InputDataError(
            f"{where}: {line}: channel '{name}' has {n} missing (NaN) samples in a row "
            f"(at most {MAX_NAN_FILL} are filled)"
        )
    ok = np.isfinite(x)
    k = np.arange(x.size)
    y = x.copy()
    y[~ok] = np.interp(k[~ok], k[ok], x[ok])
    report.add(
        Finding(
            "nan",
            name,
            f"{where}: channel '{name}': {int(ln.sum())} missing (NaN) "
            f"samples in {st.size} runs filled by linear interpolation, first at "
            f"t = {st[0] / fs:.6g} s",
            data={"starts": st.tolist(), "lengths": ln.tolist()},
        )
    )
    return y


#: Metadata of the cut that the monitors compute with (tooth frequency = flutes · rpm / 60).
_WHOLE_METADATA = ("flutes",)
_POSITIVE_METADATA = ("spindle_rpm", "feed_mm_min")


def _check_process_metadata(values: Mapping[str, object], where: str) -> None:
    """A one-line ConfigError for a number of teeth that is no whole number ≥ 1, or a spindle
    speed or feed that is not finite and > 0. ``where``: "--" (an option, named ``--key``) or
    the map's ``[metadata]``."""
    for key, value in values.items():
        if value is None or key not in _WHOLE_METADATA + _POSITIVE_METADATA:
            continue
        name = f"--{key.replace('_', '-')}" if where == "--" else f"{where} {key} ="
        shown = f"{value:g}" if isinstance(value, float) else repr(value)
        if key in _WHOLE_METADATA:
            ok = isinstance(value, int | float) and float(value).is_integer() and value >= 1
            if not ok:
                raise ConfigError(f"{name} {shown}: must be a whole number ≥ 1")
        elif not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise ConfigError(f"{name} {shown}: must be finite and > 0")


def import_files(
    paths: Sequence[Path],
    mapping: ImportMap,
    *,
    rate_hz: float | None = None,
    metadata: Mapping[str, object] | None = None,
    map_source: str = "map",
    source: str = "millsense import",
    progress: Callable[[Path, int, int], None] | None = None,
) -> ImportResult:
    """Read ``paths``, apply ``mapping`` and check the result.

    Parameters
    ----------
    paths : the files (CSV, TSV, MAT, TDMS, WAV, FLAC, MP3, Parquet).
    mapping : the map (:func:`~millsense.io.importers.mapfile.load_map`).
    rate_hz : the stated rate for files with neither a time column nor a map rate (CLI).
    metadata : added over the map's ``[metadata]`` (CLI options).
    map_source : how messages name the map (its path).
    source : how messages name the recording (``metadata['source']``, e.g. the output file).
    progress : ``progress(file, done, total)`` while a text file is read (characters).

    Returns
    -------
    ImportResult
        The recording (fastest file as channels at its measured rate, slower ones as streams,
        metadata with ``quality_json``) and the report.

    Raises
    ------
    InputDataError, ConfigError
        One line naming the file, line, column or map key; or a refusal of the data
        (time going backwards, NaN runs, more than 10 % missing).
    """
    report = QualityReport()
    _check_process_metadata(mapping.metadata, f"{map_source}: [metadata]")
    _check_process_metadata(metadata or {}, "--")
    opts = {p: mapping.options_for(p) for p in paths}
    tables = [
        read_table(p, opts[p], None if progress is None else functools.partial(progress, p))
        for p in paths
    ]
    users: dict[Path, list[ChannelMap]] = {t.path: [] for t in tables}
    for i, ch in enumerate(mapping.channels):
        where = f"{map_source}: channels[{i}] ({ch.channel})"
        users[_file_of(ch, tables, where).path].append(ch)
    used = [t for t in tables if users[t.path]]
    timed = {t.path: _on_grid(t, opts[t.path], rate_hz, report) for t in used}
    fastest = max(timed.values(), key=lambda tm: tm.fs)
    _on_one_clock(timed, fastest, opts)
    meta: dict[str, object] = {
        "source": source,
        "imported_from": [str(p) for p in paths],
        "import_map": map_source,
    }
    meta.update(mapping.metadata)
    meta.update({k: v for k, v in (metadata or {}).items() if v is not None})
    rec = Recording(fastest.fs, fastest.t0, meta)
    sparse: dict[str, tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]] = {}
    for ch in users[fastest.table.path]:
        where = f"{map_source}: channel '{ch.channel}'"
        x, si = _convert(ch, fastest, where)
        if _sparse_to_stream(ch, x, si, fastest, sparse, report):
            continue
        x = _fill_nan(
            x, ch.channel, str(fastest.table.path), fastest.table.first_line, report, fastest.fs
        )
        rec.add_channel(
            ch.channel, x, si, ch.description or f"{ch.column} of {fastest.table.path.name}"
        )
    for sname, (t_s, fields, units) in sparse.items():
        rec.add_stream(sname, t_s, fields, units)
    for tm in timed.values():
        if tm is fastest:
            continue
        streams: dict[str, tuple[dict[str, np.ndarray], dict[str, str]]] = {}
        for ch in users[tm.table.path]:
            x, si = _convert(ch, tm, f"{map_source}: channel '{ch.channel}'")
            sname, _, fname = ch.channel.rpartition("/")
            sname = sname or tm.table.path.stem
            fields, units = streams.setdefault(sname, ({}, {}))
            fields[fname], units[fname] = x, si
        n = next(iter(tm.columns.values())).size if tm.columns else 0
        t = tm.t0 + np.arange(n) / tm.fs
        for sname, (fields, units) in streams.items():
            rec.add_stream(sname, t, fields, units)
    stated = fastest.stated if not fastest.has_time else None
    check_recording(rec, report, stated_hz=stated)
    if not fastest.has_time:
        # no time column: the rate measured from angle/speed pairs wins over the stated one
        rate_fs = [f.data["measured_hz"] for f in report.of_kind("rate")]
        if rate_fs:
            rec = _with_rate(rec, float(np.median(rate_fs)))
    rec.metadata["stated_sample_rate_hz"] = fastest.stated
    tcol = fastest.table.time_column(opts[fastest.table.path].time_column)
    if fastest.has_time and tcol in fastest.table.clock_origin:
        # the wall-clock time of t = 0 s, as the file wrote it
        rec.metadata["time_origin"] = fastest.table.clock_origin[tcol]
    rec.metadata["quality_json"] = report.to_json()
    if report.refusals:
        raise InputDataError(report.refusals[0].message)
    return ImportResult(rec, report)


def _with_rate(rec: Recording, fs: float) -> Recording:
    """The same recording at another rate (channels shared, stream times kept)."""
    out = Recording(fs, rec.t0_s, rec.metadata)
    for c in rec.channel_names:
        i = rec.info(c)
        out.add_channel(c, rec.channel(c), i.unit, i.description)
    for s in rec.stream_names:
        st = rec.stream(s)
        out.add_stream(
            s,
            st.time_s,
            st.fields,
            {f: st.info[f].unit for f in st.fields},
            {f: st.info[f].description for f in st.fields},
        )
    return out
