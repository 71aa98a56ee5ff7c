"""CSV and TSV: plain tables with or without a time column, and the shapes of CNC trace exports.

Siemens Servo Trace and Heidenhain TNCscope export CSV files with lines of free text before
the table (``key: value`` or ``key;value``: trace name, sample time...), then a row of column
names, sometimes a row of units (``[s];[A];[mm]``) or units in the names (``I_x [A]``), then
the numbers, in German-locale exports with ``;`` as delimiter and a decimal comma. The reader
finds the table as the first run of lines that are all numbers, takes the row before it as the
units row when it is not numeric and the row before that holds names, and keeps the ``key:
value`` lines before as the header (a stated sample rate is read from it).

Data loggers and PC acquisition software stamp each row with the wall clock instead:
ISO-8601 dates and times (``2026-11-29T10:15:02.123456``, a space for the ``T``, with or
without a zone offset or ``Z``). Such a column is read as seconds from its first row (on UTC
when the stamps carry offsets, so a change of summer time is no jump), and the first stamp as
written is kept (:attr:`RawTable.clock_origin`).
"""

from __future__ import annotations

import io
import re
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from millsense.core.errors import InputDataError
from millsense.io.importers.table import RawTable, rate_from_header

__all__ = ["read_delimited", "write_delimited"]

_CANDIDATES = (";", "\t", ",", "|")
_UNIT_IN_NAME = re.compile(r"^(.*?)\s*[\[(]([^\])]*)[\])]\s*$")
_KEY_VALUE = re.compile(r"^\s*([^:=;\t,]+?)\s*[:=;\t,]\s*(.+?)\s*$")
#: An ISO-8601 date and time: ``T`` or a space, seconds and fraction optional, ``Z``/offset.
_DATETIME = re.compile(
    r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2}(?:[.,]\d+)?)?(?:Z|[+-]\d{2}:?\d{2})?$"
)
_ZONE = re.compile(r"(?:Z|[+-]\d{2}:?\d{2})$")


def _text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputDataError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        encs: tuple[str, ...] = ("utf-16",)  # Excel's "Unicode Text" export
    else:
        encs = ("utf-8-sig", "cp1252")
    for enc in encs:
        try:
            return raw.decode(enc)
        except UnicodeDecodeError:
            continue
    raise InputDataError(f"{path}: not a text file")  # pragma: no cover - cp1252 decodes all


def _is_datetime(field: str) -> bool:
    return _DATETIME.match(field.strip().strip('"')) is not None


def stamp_ns(stamp: str) -> tuple[int, bool]:
    """An ISO-8601 date and time as written (``T`` or a space, ``,`` or ``.`` before the
    fraction) → (ns since 1970, on UTC when it has a zone offset; whether it has one)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    text = stamp.strip()
    text = (text[:10] + "T" + text[11:]).replace(",", ".")
    zoned = _ZONE.search(text) is not None
    value = pc.cast(pa.array([text]), pa.timestamp("ns", tz="UTC" if zoned else None))
    return int(value.cast(pa.int64())[0].as_py()), zoned


def _is_cell(field: str, decimal: str) -> bool:
    """A number, an empty cell or an ISO-8601 date and time (a table's cell, not text)."""
    return _is_number(field, decimal) or _is_datetime(field)


def _is_number(field: str, decimal: str) -> bool:
    f = field.strip().strip('"')
    if f == "":
        return True  # an empty cell is a missing sample (NaN), not text
    if decimal == ",":
        f = f.replace(",", ".")
    try:
        float(f)
    except ValueError:
        return False
    return True


def _numeric_line(fields: list[str], decimal: str) -> bool:
    return any(f.strip() for f in fields) and all(_is_cell(f, decimal) for f in fields)


_DATA_LIKE = re.compile(r"^[\s\d.,;:|\t+\-eEnaNifINFTZ\"]*\d[\s\d.,;:|\t+\-eEnaNifINFTZ\"]*$")


def _sniff(lines: list[str], decimal: str = ".") -> str:
    """The delimiter splitting the last lines that look like numbers into the same number
    (> 1) of fields (``,`` is not a candidate with a decimal comma); else ``" "`` (runs of
    blanks) if those split them so (columns aligned with spaces)."""
    tail = [ln for ln in lines[-50:] if _DATA_LIKE.match(ln)]
    best, best_n = ("," if decimal == "." else ";"), 1
    for d in _CANDIDATES:
        if d == decimal:
            continue
        counts = {ln.count(d) for ln in tail}
        if len(counts) == 1 and (n := counts.pop()) + 1 > best_n:
            best, best_n = d, n + 1
    if best_n == 1 and tail and len(widths := {len(ln.split()) for ln in tail}) == 1:
        if widths.pop() > 1:
            return " "
    return best


#: A clock column's first stamp: its ns (None until parsed), zone offset or not, as written.
_Origin = tuple[int | None, bool, str]


class _LazySplit:
    """``lines[i].split(d)`` computed when asked for."""

    def __init__(self, lines: list[str], d: str) -> None:
        self.lines, self.d = lines, d

    def __getitem__(self, i: int) -> list[str]:
        return self.lines[i].split(self.d)


def _units_row(fields: list[str]) -> bool:
    """True if every field looks like a unit: empty, bracketed (``[mm]``) or a known unit."""
    from millsense.io.importers.mapfile import UNITS

    for f in fields:
        t = _name(f)
        if t and not (t[0] in "[(" or t in UNITS):
            return False
    return True


def _name(field: str) -> str:
    return field.strip().strip('"').strip()


#: Lines searched for the header and the table's start (a longer header: the whole file).
HEAD_LINES = 2000
#: Characters of the table parsed at a time: memory of the read stays near the file's text
#: plus its numbers (a 10-minute 10 kHz file of 290 MB: 2.8 GB read whole, 0.9 GB in
#: chunks), and progress is reported per chunk.
CHUNK_CHARS = 8_000_000


def _head(text: str, n: int) -> tuple[list[str], bool]:
    """The first ``n`` lines of ``text`` with their line ends, and whether there are more."""
    pos = 0
    for _ in range(n):
        k = text.find("\n", pos)
        if k < 0:
            return text.splitlines(keepends=True), False
        pos = k + 1
    return text[:pos].splitlines(keepends=True), pos < len(text)


def _table_start(lines: list[str], split: _LazySplit, decimal: str) -> int | None:
    """The first line from which three lines (or all remaining) are numbers."""
    for i in range(len(lines)):
        if _numeric_line(split[i], decimal):
            nxt = [j for j in range(i, min(i + 3, len(lines))) if lines[j].strip()]
            if all(_numeric_line(split[j], decimal) for j in nxt):
                return i
    return None


def read_delimited(
    path: Path,
    delimiter: str | None = None,
    decimal: str = ".",
    progress: Callable[[int, int], None] | None = None,
) -> RawTable:
    """Read a CSV/TSV table (see the module notes for the trace-export shapes).

    Parameters
    ----------
    path : the file.
    delimiter : ``,``, ``;``, tab... (None: sniffed from the last lines; ``.tsv`` → tab);
        ``" "``: any run of blanks (columns aligned with spaces).
    decimal : ``.`` or ``,`` (decimal comma).
    progress : ``progress(done, total)`` in characters of the file, after each chunk of the
        table (:data:`CHUNK_CHARS`).

    Raises
    ------
    InputDataError
        One line naming the file and the line/column: no table found, a row with another
        number of fields than the header, text in a numeric column.
    """
    text = _text(path)
    # only the lines down to the table are split here (the table is parsed by numpy, in
    # chunks of the text)
    raw, more = _head(text, HEAD_LINES)
    # the delimiter is sniffed on the last lines of the file
    tail = text[-200_000:].splitlines()[1:] if more else [ln.rstrip("\r\n") for ln in raw]
    if delimiter is None:
        delimiter = "\t" if path.suffix.lower() == ".tsv" else _sniff(tail, decimal)
    for _ in range(2):
        lines = [ln.rstrip("\r\n") for ln in raw]
        if delimiter == " ":
            # columns aligned with blanks: a run of them is one separator (no empty cells)
            lines = [" ".join(ln.split()) for ln in lines]
        split = _LazySplit(lines, delimiter)
        start = _table_start(lines, split, decimal)
        if start is not None or not more:
            break
        raw, more = text.splitlines(keepends=True), False  # a header longer than HEAD_LINES
    if start is None:
        other = _sniff(tail, decimal)
        hint = (
            f"; the lines split on {other!r}: is the delimiter right?" if other != delimiter else ""
        )
        raise InputDataError(
            f"{path}: no table of numbers found (delimiter {delimiter!r}, decimal {decimal!r})"
            f"{hint}"
        )
    width = len(split[start])
    _text_in_first_rows(path, lines, split, start, (delimiter, decimal))
    above = [i for i in range(start) if lines[i].strip()]
    names_row, units_row = None, None
    if above and len(split[above[-1]]) == width:
        names_row = above[-1]
        if len(above) > 1 and len(split[above[-2]]) == width and _units_row(split[above[-1]]):
            # two rows of the table's width: names then units (Servo Trace / TNCscope)
            units_row, names_row = above[-1], above[-2]
    if names_row is None:
        names = [f"col{k}" for k in range(width)]
    else:
        names = [_name(f) for f in split[names_row]]
    units = [""] * width
    if units_row is not None:
        units = [_name(f).strip("[]()") for f in split[units_row]]
    for k, nm in enumerate(names):
        m = _UNIT_IN_NAME.match(nm)
        if m and m.group(1):
            names[k] = m.group(1).strip()
            units[k] = units[k] or m.group(2).strip()
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise InputDataError(f"{path}: line {(names_row or 0) + 1}: column '{dup.pop()}' twice")
    header: dict[str, str] = {}
    for i in above:
        if i in (names_row, units_row):
            continue
        m = _KEY_VALUE.match(lines[i])
        if m:
            header[m.group(1).strip('"')] = m.group(2).strip('"')
    first_row = split[start]
    clock = [k for k, f in enumerate(first_row) if _is_datetime(f)]
    offset = sum(len(ln) for ln in raw[:start])
    del raw, lines, tail, split
    data = _parse_chunks(path, text, offset, (delimiter, decimal), names, start, clock, progress)
    columns = {nm: np.ascontiguousarray(data[:, k]) for k, nm in enumerate(names)}
    for k in clock:
        units[k] = "s"
    return RawTable(
        path=path,
        columns=columns,
        units=dict(zip(names, units, strict=True)),
        stated_rate_hz=rate_from_header(header),
        header=header,
        first_line=start + 1,
        clock_origin={names[k]: _name(first_row[k]) for k in clock},
    )


def _text_in_first_rows(
    path: Path, lines: list[str], split: _LazySplit, start: int, dialect: tuple[str, str]
) -> None:
    """The table's start is the first of three rows of numbers: a cell of text in one of the
    first data rows moved it below that row, taken for the names. Rows of the table's width
    holding numbers right above the start, under a row of text of that width (the names),
    are data rows: the first bad cell among them is named at its line (one line, raised)."""
    d, decimal = dialect
    width = len(split[start])
    walked: list[int] = []
    i = start - 1
    while i >= 0:
        f = split[i]
        if not lines[i].strip():
            i -= 1
            continue
        if len(f) != width:
            return
        if not any(f_.strip() and _is_cell(f_, decimal) for f_ in f):
            break  # a row of text: the names (or the units)
        walked.append(i)
        i -= 1
    if i < 0 or not walked:
        return
    names = [_name(f_) for f_ in split[i]]
    clock = [k for k, f_ in enumerate(split[start]) if _is_datetime(f_)]
    rows = sorted(walked)
    _locate_bad(path, [lines[r] for r in rows], d, decimal, width, names, rows[0], clock)


def _parse_chunks(
    path: Path,
    text: str,
    offset: int,
    dialect: tuple[str, str],
    names: list[str],
    start: int,
    clock: list[int],
    progress: Callable[[int, int], None] | None,
) -> np.ndarray:
    """The table from character ``offset`` of ``text`` (line ``start`` + 1), parsed in
    chunks of about :data:`CHUNK_CHARS` ending at a line end; blank lines at the end are
    dropped. Shape (rows, columns)."""
    d, decimal = dialect
    total = len(text)
    out = np.empty((text.count("\n", offset) + 1, len(names)))
    row, line, pos = 0, start, offset
    origin: dict[int, _Origin] = {}
    while pos < total:
        end = text.find("\n", min(pos + CHUNK_CHARS, total))
        end = total if end < 0 else end
        chunk = text[pos:end]
        body = chunk.splitlines()
        if end == total:
            while body and not body[-1].strip():
                body.pop()
        if d == " ":
            body = [" ".join(ln.split()) for ln in body]
        if body:
            block = _parse(path, body, d, decimal, len(names), names, line, clock, origin)
            out[row : row + len(block)] = block
            row += len(block)
        line += chunk.count("\n") + 1
        pos = end + 1
        if progress is not None:
            progress(min(pos, total), total)
    return out[:row]


def _parse(
    path: Path,
    body: list[str],
    d: str,
    decimal: str,
    width: int,
    names: list[str],
    start: int,
    clock: list[int],
    origin: dict[int, _Origin],
) -> np.ndarray:
    """The numbers of ``body`` (its first line is line ``start`` + 1 of the file), shape
    (rows, width); empty cells are NaN; the columns ``clock`` (ISO-8601 stamps) in seconds
    from the file's first stamp (``origin``: column → its ns and zone, set by the first
    chunk)."""
    text = "\n".join(body)
    if decimal == ",":
        text = text.replace(",", ".")
    text = text.replace('"', "")
    empty = d + d in text or text.startswith(d) or text.endswith(d)
    if empty or f"\n{d}" in text or f"{d}\n" in text:
        # empty cells (missing samples) become NaN; the regular expressions are run only
        # where there are any (they were half the time of a long file's read)
        e = re.escape(d)
        text = re.sub(rf"(?m)^(?={e})", "nan", text)
        text = re.sub(rf"(?m)(?<={e})$", "nan", text)
        for _ in range(2):
            text = re.sub(rf"{e}(?={e})", f"{d}nan", text)
    numeric = [k for k in range(width) if k not in clock]
    try:
        if clock:
            arr = np.full((len(body), width), np.nan)
            if numeric:
                arr[:, numeric] = np.loadtxt(
                    io.StringIO(text), delimiter=d, dtype=np.float64, ndmin=2, usecols=numeric
                )
            for k in clock:
                arr[:, k] = _clock_seconds(path, text, d, k, names[k], start, origin)
        else:
            arr = np.loadtxt(io.StringIO(text), delimiter=d, dtype=np.float64, ndmin=2)
    except ValueError:
        _locate_bad(path, body, d, decimal, width, names, start, clock)
        raise  # pragma: no cover - _locate_bad always raises
    if arr.shape[1] != width:  # pragma: no cover - loadtxt checks the widths
        raise InputDataError(f"{path}: {arr.shape[1]} columns, the header has {width}")
    return arr


def _clock_seconds(
    path: Path, text: str, d: str, k: int, name: str, start: int, origin: dict[int, _Origin]
) -> np.ndarray:
    """Column ``k`` of ``text`` (ISO-8601 stamps) as seconds after the file's first stamp
    (``origin[k]``: (its ns, whether it has a zone offset, as written), set from this text
    when missing): parsed by Arrow (C, no per-row Python), on UTC when the first stamp has a
    zone offset.

    Raises
    ------
    InputDataError
        One line naming the line and column: a stamp that is no date and time, or one with a
        zone offset among stamps without (or the reverse).
    ValueError
        Another number of fields on a line (located by the caller).
    """
    import pyarrow as pa
    import pyarrow.compute as pc
    from pyarrow import csv as pcsv

    try:
        col = pcsv.read_csv(
            io.BytesIO(text.encode()),
            read_options=pcsv.ReadOptions(autogenerate_column_names=True),
            parse_options=pcsv.ParseOptions(delimiter=d),
            convert_options=pcsv.ConvertOptions(
                include_columns=[f"f{k}"], column_types={f"f{k}": pa.string()}
            ),
        ).column(0)
    except pa.ArrowInvalid as exc:
        raise ValueError(str(exc)) from None
    col = pc.utf8_trim_whitespace(col.combine_chunks())
    col = pc.replace_substring_regex(col, pattern="^(.{10}) ", replacement="\\1T")
    col = pc.replace_substring_regex(col, pattern=",", replacement=".")
    if k not in origin:
        first = str(col[0])
        origin[k] = (None, _ZONE.search(first) is not None, first)
    ns0, zoned, first = origin[k]
    try:
        stamps = pc.cast(col, pa.timestamp("ns", tz="UTC" if zoned else None))
    except pa.ArrowInvalid:
        for i, v in enumerate(col.to_pylist()):  # error path only: find the line
            if not _is_datetime(v):
                raise InputDataError(
                    f"{path}: line {start + i + 1}, column {k + 1} ('{name}'): {v!r} is not "
                    "an ISO-8601 date and time"
                ) from None
            if (_ZONE.search(v) is not None) != zoned:
                has = "without" if zoned else "with"
                raise InputDataError(
                    f"{path}: line {start + i + 1}, column {k + 1} ('{name}'): {v!r} {has} a "
                    f"zone offset, the first stamp ({first!r}) {'with' if zoned else 'without'}"
                ) from None
        raise InputDataError(f"{path}: column {k + 1} ('{name}'): stamps not read") from None
    ns = stamps.cast(pa.int64()).to_numpy(zero_copy_only=False)
    if ns0 is None:
        ns0 = int(ns[0])
        origin[k] = (ns0, zoned, first)
    return (ns - ns0).astype(np.float64) * 1e-9


def _locate_bad(
    path: Path,
    body: list[str],
    d: str,
    decimal: str,
    width: int,
    names: list[str],
    start: int,
    clock: list[int],
) -> None:
    """Raise the one-line error naming the first bad line and column (error path only)."""
    for i, ln in enumerate(body):
        fields = ln.split(d)
        line = start + i + 1
        if not ln.strip():
            raise InputDataError(f"{path}: line {line}: empty line inside the table")
        if len(fields) != width:
            raise InputDataError(
                f"{path}: line {line}: {len(fields)} fields, the table has {width} "
                f"(delimiter {d!r})"
            )
        for k, f in enumerate(fields):
            if k in clock and not _is_datetime(f):
                raise InputDataError(
                    f"{path}: line {line}, column {k + 1} ('{names[k]}'): "
                    f"{f.strip()!r} is not an ISO-8601 date and time"
                )
            if k not in clock and not _is_number(f, decimal):
                raise InputDataError(
                    f"{path}: line {line}, column {k + 1} ('{names[k]}'): "
                    f"{f.strip()!r} is not a number"
                )
    raise InputDataError(f"{path}: the table cannot be read as numbers")


def write_delimited(
    path: Path,
    columns: Mapping[str, np.ndarray],
    units: Mapping[str, str],
    delimiter: str = ",",
    header: Mapping[str, str] | None = None,
) -> None:
    """Write ``columns`` as a table: optional ``key: value`` header lines, a names row, a units
    row (``[A]``), then every value with 17 significant digits (exact float64 round trip).

    ``path`` is written as given (callers pass a temporary sibling from
    :func:`~millsense.io.safe_output.atomic_path`).
    """
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=np.float64) for n in names])
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        for k, v in (header or {}).items():
            fh.write(f"{k}: {v}\n")
        fh.write(delimiter.join(names) + "\n")
        fh.write(delimiter.join(f"[{units.get(n, '')}]" for n in names) + "\n")
        np.savetxt(fh, data, delimiter=delimiter, fmt="%.17g")
