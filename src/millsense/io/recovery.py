"""Recover an interrupted recording into a plain HDF5 file (``millsense recover``, ``info``).

A :class:`~millsense.io.recording_file.RecordingWriter` that dies (``kill -9``, power cut)
leaves its checksummed segments in ``RUN.h5.partial/``. Only millsense can read that folder;
:func:`recover` turns it into an ordinary recording file (the layout of
:mod:`millsense.io.recording_file`: ``/channels/<name>`` datasets with ``unit`` attributes,
metadata as root attributes) that h5py, MATLAB and pandas (through h5py) open, with a note of
what was lost both printed and stored as the root attributes ``recovered`` (True) and
``recovery_lost`` (one line). Decision 0922.

What is lost, and how it is known:

* the samples the writer still held in memory: at most one flush interval (the schema's
  ``flush_every_samples``; 0.5 s in ``simulate`` and ``estimate``) after the last segment;
* a segment being written at the moment of death (a ``.seg-*.bin.tmp`` file: never renamed,
  so never known to be whole) — discarded;
* segments after a missing, damaged or out-of-order one — not used, and then the sidecar is
  kept so that nothing that might still be salvaged by hand is deleted.

The sidecar is removed only when the recovered file was written to the recording's own path,
reads back with every recovered sample, and no segment was left out.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from millsense.core.errors import RecordingError
from millsense.io.recording_file import (
    partial_dir,
    read_interrupted,
    read_recording,
    recording_status,
    write_recording,
    writer_alive,
)

__all__ = ["Recovered", "recover"]


@dataclass(frozen=True)
class Recovered:
    """The outcome of :func:`recover`.

    Attributes
    ----------
    output : Path
        The plain HDF5 file written.
    n_samples : int
        Samples per channel recovered.
    duration_s : float
        Their duration, s.
    lost : str
        One line: what could not be recovered.
    partial_removed : bool
        True if the ``.partial/`` folder was removed (all its data are in ``output``).
    """

    output: Path
    n_samples: int
    duration_s: float
    lost: str
    partial_removed: bool


def _lost_note(info: dict[str, object], fs: float, ends_at_s: float) -> str:
    schema = info["schema"]
    assert isinstance(schema, dict)
    flush = schema.get("flush_every_samples")
    if isinstance(flush, int) and flush > 0:
        tail = f"at most {flush / fs:.3g} s of signal the writer held unflushed after t = "
    else:
        tail = "the signal the writer held unflushed after t = "
    parts = [f"{tail}{ends_at_s:.6g} s"]
    unfinished = info["unfinished"]
    assert isinstance(unfinished, list)
    if unfinished:
        parts.append(f"{len(unfinished)} half-written segment(s) discarded")
    if info["note"]:
        parts.append(str(info["note"]))
    return "lost: " + "; ".join(parts)


def recover(path: str | Path, output: str | Path | None = None) -> Recovered:
    """Write the interrupted recording ``path`` (its ``.partial/`` folder) as a plain file.

    Parameters
    ----------
    path : str or Path
        The recording's file name (``RUN.h5``); its data are in ``RUN.h5.partial/``.
    output : str or Path, optional
        File to write; default ``path`` itself (which must not exist: a complete file there
        is an earlier recording and is never overwritten).

    Raises
    ------
    RecordingError
        Nothing to recover (no sidecar; or a complete file only), a writer still running,
        the default output already existing, or an unreadable sidecar. One line.
    """
    path = Path(path)
    partial = partial_dir(path)
    if not partial.is_dir():
        if path.is_file():
            try:
                recording_status(path)  # what the file is: corrupt and foreign files say so
            except RecordingError as exc:
                raise RecordingError(f"{exc}; no {partial.name} folder to recover from") from None
            raise RecordingError(f"{path}: a complete recording; nothing to recover")
        raise RecordingError(f"{path}: no such recording and no {partial.name} folder to recover")
    if writer_alive(path):
        raise RecordingError(
            f"{path}: still being written by a running process; recover it once that ends"
        )
    out = path if output is None else Path(output)
    if out == path and path.exists():
        raise RecordingError(
            f"{path}: an earlier complete recording is in the way of the interrupted one in "
            f"{partial.name}; give -o NEW.h5"
        )
    rec, info = read_interrupted(path)
    fs = rec.sample_rate_hz
    lost = _lost_note(info, fs, rec.t0_s + rec.n_samples / fs)
    rec.metadata["recovered"] = True
    rec.metadata["recovery_lost"] = lost
    rec.metadata.pop("source", None)  # the reader's own bookkeeping, not the recording's
    write_recording(out, rec)
    back = read_recording(out)
    removed = False
    if back.n_samples != rec.n_samples:  # pragma: no cover - a disk that lies
        raise RecordingError(
            f"{out}: read back {back.n_samples} samples, wrote {rec.n_samples}; {partial} kept"
        )
    if out.resolve() == path.resolve() and not info["note"]:
        shutil.rmtree(partial, ignore_errors=True)
        removed = True
    return Recovered(out, rec.n_samples, rec.n_samples / fs, lost, removed)
