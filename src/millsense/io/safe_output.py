"""Outputs that can never destroy an input: the one rule every millsense writer follows.

Two guarantees (issue 21, decision 0921):

1. **An output is never one of the command's inputs.** :func:`check_outputs` compares every
   output path with every input path *before anything is computed*: the same path after
   following symbolic links (``os.path.realpath``), or the same file by another name (a hard
   link, ``os.path.samefile``). A clash is a :class:`~millsense.core.errors.ConfigError` (one
   line, exit status 2) naming the option and the input.
2. **An existing output is replaced only whole.** Every writer writes to a temporary file in
   the target's own folder (same file system, so the rename is atomic) and renames it into
   place with ``os.replace``: a writer killed or failing mid-write leaves the previous output
   untouched and at most a hidden ``.NAME.PID.tmp.EXT`` file behind. The temporary name
   keeps the target's extension, so that writers choosing a format by extension (matplotlib,
   pyarrow) write the right one.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TypeAlias

from millsense.core.errors import ConfigError, UserError

__all__ = ["atomic_path", "check_outputs", "temporary_sibling", "write_bytes", "write_text"]

_PathLike: TypeAlias = "str | os.PathLike[str] | None"
#: description or option → path (None is skipped), as a mapping or as (name, path) pairs
Named: TypeAlias = "Mapping[str, _PathLike] | Iterable[tuple[str, _PathLike]]"


def _pairs(named: Named) -> list[tuple[str, str | os.PathLike[str] | None]]:
    return list(named.items()) if isinstance(named, Mapping) else list(named)


def _same(a: Path, b: Path) -> bool:
    """True if ``a`` and ``b`` name the same file (symbolic or hard links followed)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


#: What an output option's file holds, by the option's name, where every command writes one
#: kind (every ``--plot`` writes a PNG): its file name must say so.
OUTPUT_SUFFIXES = {"--plot": ".png"}
_KINDS = {".png": "PNG", ".html": "an HTML page", ".h5": "a recording (HDF5)", ".toml": "TOML",
          ".parquet": "Parquet"}  # fmt: skip
#: The suffixes of the on-line commands' outputs (``run``, ``replay``, ``record``): a recording,
#: its event log, the plan made from the program and the HTML report.
SESSION_SUFFIXES = {"-o": ".h5", "--events": ".parquet", "--plan-out": ".parquet",
                    "--report": ".html"}  # fmt: skip


def check_outputs(
    inputs: Named, outputs: Named, suffixes: Mapping[str, str] | None = None
) -> None:
    """Refuse an output that is one of the inputs, or two outputs that are the same file, or
    an output whose name does not end as what it holds (:data:`OUTPUT_SUFFIXES`, and the
    command's own ``suffixes``: option name → suffix, e.g. ``{"-o": ".html"}``).

    Parameters
    ----------
    inputs : mapping of description to path, or (description, path) pairs
        The files the command reads, described for the message (``"the recording"``,
        ``"the machine file"``, ``"one of the fragments"``). Entries that are None or
        that name no existing file or folder (a preset name such as ``quaser-ux600``) are
        ignored, except that a recording still being recovered from ``NAME.partial/``
        counts as ``NAME``.
    outputs : mapping of name to path
        The files the command writes (``-o``, ``--plot``, ``--json``); None and ``-``
        (standard output) are ignored.
    suffixes : mapping of output name to the suffix its file must have (lower case), or None.

    Raises
    ------
    ConfigError
        One line naming the output option, its path and the input it would overwrite.
    """
    ins: list[tuple[str, Path]] = []
    for name, p in _pairs(inputs):
        if p is None:
            continue
        path = Path(p)
        if path.exists() or path.with_name(path.name + ".partial").is_dir():
            ins.append((name, path))
    outs = [(n, Path(p)) for n, p in _pairs(outputs) if p is not None and str(p) != "-"]
    for oname, out in outs:
        for iname, inp in ins:
            if _same(out, inp):
                raise ConfigError(
                    f"{oname} {out}: is {iname} ({inp}), an input, which is never "
                    "overwritten: write to another file"
                )
    for i, (a_name, a) in enumerate(outs):
        for b_name, b in outs[i + 1 :]:
            if _same(a, b):
                raise ConfigError(f"{a_name} and {b_name} name the same file {a}: give two files")
    need = {**OUTPUT_SUFFIXES, **(suffixes or {})}
    for oname, out in outs:
        want = need.get(oname)
        if want is not None and out.suffix.lower() != want:
            raise ConfigError(
                f"{oname} {out}: the file is written as {_KINDS.get(want, want)}; give a "
                f"{want} file name"
            )


def temporary_sibling(path: str | os.PathLike[str]) -> Path:
    """A hidden temporary name beside ``path`` with the same extension (same file system)."""
    p = Path(path)
    return p.with_name(f".{p.stem}.{os.getpid()}.tmp{p.suffix}")


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the hidden temporaries of :func:`temporary_sibling` left below ``folder`` by a
    writer killed between writing and renaming (a batch worker killed mid-task: decision
    2003), and return them. Call it only when no writer can still be busy there: a live
    writer's temporary would be removed under it."""
    removed = []
    for p in sorted(Path(folder).rglob(".*.tmp*")):
        if p.is_file() and _TEMPORARY.fullmatch(p.name):
            with contextlib.suppress(OSError):
                p.unlink()
                removed.append(p)
    return removed


#: The names :func:`temporary_sibling` makes: ``.STEM.PID.tmpSUFFIX``.
_TEMPORARY = re.compile(r"\..+\.\d+\.tmp(\.[^.]*)?")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success rename it onto ``path``, else remove it.

    ``with atomic_path(out) as tmp: writer(tmp)``: ``out`` is either its old content or the
    whole new one, whatever happens to the process in between.
    """
    p = Path(path)
    tmp = temporary_sibling(p)
    try:
        yield tmp
        if not tmp.exists():
            return  # the writer chose to write nothing
        os.replace(tmp, p)
    except OSError as exc:
        if exc.filename is not None and Path(exc.filename) == tmp:
            # name the file the user asked for, not the temporary one
            raise OSError(exc.errno, exc.strerror, str(p)) from None
        raise
    except UserError as exc:
        if str(tmp) in str(exc):  # a writer's one-line error, naming the file it was given
            raise type(exc)(str(exc).replace(str(tmp), str(p))) from None
        raise
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data)


def write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`)."""
    write_bytes(path, text.encode(encoding))
