"""Recording files: plain HDF5 that h5py, MATLAB and pandas open, written crash-safely.

Layout of a complete file (``format = "millsense-recording"``, ``format_version = 1``)::

    /                      attrs: format, format_version, sample_rate_hz, t0_s, n_samples,
                                  metadata_json, layout_json, one attr per scalar metadata key
    /channels/<name>       1-D dataset per channel ("x/current_cmd" -> /channels/x/current_cmd),
                           attrs unit, description; chunked, shuffle + deflate
    /streams/<name>/time_s and /streams/<name>/<field>, attrs unit, description

While a :class:`RecordingWriter` runs, the file does not exist yet; the data live in the
sidecar directory ``<path>.partial/``:

* ``recording.json`` – schema (rate, t0, channels, streams, metadata), written before data;
* ``seg-000001.bin``, ``seg-000002.bin``, ... – one checksummed raw segment per flush
  (:mod:`millsense.io.recording_segments`), written under a temporary name and renamed
  (``os.replace`` is atomic), so a segment is either whole or absent whatever moment the
  writer dies;
* ``consolidating.h5.tmp`` – the final file being built (compressed chunk by chunk as data
  arrive); never read, because it is only valid once closed.

``close()`` finishes the final file, renames it to ``<path>`` and removes the sidecar. If the
writer was killed, :func:`read_recording` of ``<path>`` rebuilds the recording from the
complete segments and marks it ``metadata['recovered'] = True``; :func:`recording_status`
says where the data end. Why not HDF5 SWMR: see
``docs/decisions/0018-recording-files-crash-safety-by-atomic-segments-not-hdf5.md``.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import mmap
import os
import re
import shutil
import zlib
from collections.abc import Mapping, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike

import millsense
from millsense.core.errors import InputDataError, RecordingError
from millsense.core.recording import (
    ChannelInfo,
    Recording,
    Stream,
    _conflicts,
    _utf8,
    as_channel_array,
    check_name,
    check_text,
    normalise_metadata,
)
from millsense.io import hdf5_chunks
from millsense.io.recording_segments import Segment, SegmentError, read_segment, write_segment

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "RecordingStatus",
    "RecordingWriter",
    "partial_dir",
    "read_interrupted",
    "read_recording",
    "recording_status",
    "write_recording",
    "writer_alive",
]

FORMAT = "millsense-recording"
FORMAT_VERSION = 1
_PARTIAL_SUFFIX = ".partial"
_SCHEMA = "recording.json"
_INPROGRESS = "consolidating.h5.tmp"
_SEG_RE = re.compile(r"^seg-(\d{6,})\.bin$")
_RESERVED_ATTRS = {
    "format",
    "format_version",
    "sample_rate_hz",
    "t0_s",
    "n_samples",
    "metadata_json",
    "layout_json",
}


def partial_dir(path: str | Path) -> Path:
    """The sidecar directory ``<path>.partial`` used while a recording is being written."""
    p = Path(path)
    return p.with_name(p.name + _PARTIAL_SUFFIX)


def _now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _file_metadata(metadata: Mapping[str, object]) -> dict[str, object]:
    meta = dict(metadata)
    meta.setdefault("created", _now_iso())
    meta.setdefault("software_version", millsense.__version__)
    return meta


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_file(path: Path) -> None:
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())


def _atomic_json(path: Path, obj: object, fsync: bool) -> None:
    tmp = path.with_name("." + path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(obj, fh, indent=1)
        if fsync:
            fh.flush()
            os.fsync(fh.fileno())
    os.replace(tmp, path)


_LOCK = "writer.lock"


def _hold_writer_lock(partial: Path) -> Any:
    """Open ``partial/writer.lock`` and hold an exclusive lock on it while the writer lives.

    The operating system drops the lock when the process dies (``kill -9`` included), so
    :func:`writer_alive` tells a running writer from an interrupted one.
    """
    fh = open(partial / _LOCK, "w")
    try:
        import fcntl

        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (ImportError, OSError):  # no flock (Windows, some network file systems)
        pass
    return fh


def writer_alive(path: str | Path) -> bool:
    """True if a live process is still writing the recording ``path`` (holds its lock)."""
    lock = partial_dir(path) / _LOCK
    if not lock.is_file():
        return False
    try:
        import fcntl
    except ImportError:  # pragma: no cover - no flock: cannot tell, assume interrupted
        return False
    with open(lock) as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
    return False


def _check_parent(path: Path) -> None:
    if not path.parent.is_dir():
        raise RecordingError(f"{path}: directory {path.parent} does not exist")


# ---------------------------------------------------------------------------- writing
def _write_root(
    f: h5py.File,
    sample_rate_hz: float,
    t0_s: float,
    n_samples: int,
    metadata: Mapping[str, object],
    layout: Mapping[str, object],
) -> None:
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = FORMAT_VERSION
    f.attrs["sample_rate_hz"] = float(sample_rate_hz)
    f.attrs["t0_s"] = float(t0_s)
    f.attrs["n_samples"] = int(n_samples)
    f.attrs["metadata_json"] = json.dumps(metadata)
    f.attrs["layout_json"] = json.dumps(layout)
    for key, value in metadata.items():
        if key in _RESERVED_ATTRS or "/" in key or key in (".", ""):
            continue
        if isinstance(value, str) and ("\x00" in value or not _utf8(value)):
            continue  # HDF5 strings cannot hold these; the value is in metadata_json
        if isinstance(value, str | bool | int | float) and not (
            isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 2**63
        ):
            f.attrs[key] = value


def _set_info(ds: h5py.Dataset, info: ChannelInfo) -> None:
    ds.attrs["unit"] = info.unit
    ds.attrs["description"] = info.description


def _write_stream(f: h5py.File, stream: Stream) -> None:
    group = f.require_group("streams").create_group(stream.name)
    ds = hdf5_chunks.write_array(group, "time_s", np.asarray(stream.time_s))
    _set_info(ds, ChannelInfo("time_s", "s", "row time"))
    for field, values in stream.fields.items():
        ds = hdf5_chunks.write_array(group, field, np.asarray(values))
        _set_info(ds, stream.info[field])


def write_recording(path: str | Path, rec: Recording, *, fsync: bool = False) -> None:
    """Write ``rec`` to ``path`` atomically (temporary file, then ``os.replace``).

    Parameters
    ----------
    path : str or Path
        Destination ``.h5`` file; an existing file is replaced only once the new one is whole.
    rec : Recording
        Recording to store. ``created`` and ``software_version`` are added to the stored
        metadata if absent.
    fsync : bool
        Also flush the file to the disk before renaming (survives power loss, costs the time
        to write the file to the device).

    Raises
    ------
    RecordingError
        If the directory does not exist or the file cannot be written.
    """
    path = Path(path)
    _check_parent(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:  # metadata may have been edited after construction: check it again
        meta = _file_metadata(normalise_metadata(rec.metadata))
    except InputDataError as exc:
        raise InputDataError(f"{path}: {exc}") from None
    layout = {
        "channels": rec.channel_names,
        "streams": {s: list(rec.stream(s).fields) for s in rec.stream_names},
    }
    try:
        with h5py.File(tmp, "w") as f:
            _write_root(f, rec.sample_rate_hz, rec.t0_s, rec.n_samples, meta, layout)
            channels = f.create_group("channels")
            for name in rec.channel_names:
                ds = hdf5_chunks.write_array(channels, name, np.asarray(rec.channel(name)))
                _set_info(ds, rec.info(name))
            f.create_group("streams")
            for sname in rec.stream_names:
                _write_stream(f, rec.stream(sname))
        if fsync:
            _fsync_file(tmp)
        os.replace(tmp, path)
        if fsync:
            _fsync_dir(path.parent)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise RecordingError(f"{path}: cannot write recording: {exc}") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class RecordingWriter:
    """Append channels chunk by chunk; what was flushed survives the writer being killed.

    Parameters
    ----------
    path : str or Path
        Final ``.h5`` file, created by :meth:`close`. The sidecar ``<path>.partial/`` holds the
        data meanwhile.
    sample_rate_hz : float
        Sample rate of every channel, Hz.
    channels : sequence of ChannelInfo
        Declared channels; every :meth:`append` must give all of them.
    metadata : mapping, optional
        JSON-serialisable metadata (``created``/``software_version`` added if absent).
    streams : mapping of str to sequence of ChannelInfo, optional
        Declared streams and their fields (``time_s`` is implicit).
    flush_every_s : float
        Flush automatically once this much signal time is buffered, s.
    t0_s : float
        Time of sample 0, s.
    fsync : bool
        Also ``fsync`` each segment (survives power loss, about 8 ms per flush measured on an
        ext4 virtual disk); SIGKILL-safety does not need it.
    overwrite : bool
        Replace an existing complete file at ``path`` (default, like :func:`write_recording`);
        it stays whole until :meth:`close` renames the new file onto it (``os.replace``), so
        a writer killed meanwhile leaves it intact (decision 0921). While this writer lives,
        :func:`read_recording` returns the new recording in progress. With
        ``overwrite=False`` an existing file is an error.

    Raises
    ------
    RecordingError
        If ``<path>.partial/`` already exists (an interrupted recording: read or remove it),
        ``path`` exists and ``overwrite`` is false, or the directory is missing. An interrupted
        recording is never overwritten: it may hold the only copy of its data.
    InputDataError
        For malformed declarations.

    Notes
    -----
    Dtypes are fixed by the first :meth:`append`: numpy arrays keep their int/float dtype,
    lists become float64; later chunks must cast safely (``same_kind``) to that dtype.
    """

    def __init__(
        self,
        path: str | Path,
        sample_rate_hz: float,
        channels: Sequence[ChannelInfo],
        metadata: Mapping[str, object] | None = None,
        streams: Mapping[str, Sequence[ChannelInfo]] | None = None,
        flush_every_s: float = 1.0,
        t0_s: float = 0.0,
        *,
        fsync: bool = False,
        overwrite: bool = True,
    ) -> None:
        self.path = Path(path)
        _check_parent(self.path)
        # Validates rate, t0, metadata and channel names exactly as a Recording would.
        try:
            meta = _file_metadata(normalise_metadata(metadata))
        except InputDataError as exc:
            raise InputDataError(f"{self.path}: {exc}") from None
        self._proto = Recording(sample_rate_hz, t0_s, meta)
        if not math.isfinite(flush_every_s) or flush_every_s <= 0:
            raise InputDataError(f"{self.path}: flush_every_s must be > 0, got {flush_every_s}")
        self.sample_rate_hz = self._proto.sample_rate_hz
        self.t0_s = self._proto.t0_s
        self._flush_samples = max(1, math.ceil(flush_every_s * self.sample_rate_hz))
        self._fsync = fsync
        self._channels: dict[str, ChannelInfo] = {}
        for info in channels:
            name = check_name(info.name)
            check_text(info.unit, f"{self.path}: channel '{name}': unit")
            check_text(info.description, f"{self.path}: channel '{name}': description")
            if name in self._channels or _conflicts(name, self._channels) is not None:
                raise InputDataError(f"{self.path}: channel '{name}' declared twice or collides")
            self._channels[name] = info
        self._streams: dict[str, dict[str, ChannelInfo]] = {}
        for sname, fields in (streams or {}).items():
            check_name(sname, "stream")
            if _conflicts(sname, self._streams) is not None:
                raise InputDataError(f"{self.path}: stream '{sname}' collides with another")
            fmap: dict[str, ChannelInfo] = {}
            for fi in fields:
                if not fi.name or "/" in fi.name or fi.name == "time_s" or fi.name in fmap:
                    raise InputDataError(f"{self.path}: stream '{sname}': bad field '{fi.name}'")
                check_text(fi.unit, f"{self.path}: stream '{sname}' field '{fi.name}': unit")
                check_text(fi.description, f"{self.path}: stream '{sname}': description")
                fmap[fi.name] = fi
            self._streams[sname] = fmap

        self._partial = partial_dir(self.path)
        if self._partial.exists():
            raise RecordingError(
                f"{self.path}: {self._partial} exists (an interrupted recording); "
                f"recover it with 'millsense recover {self.path}' or remove that folder"
            )
        if self.path.exists():
            if not overwrite:
                raise RecordingError(f"{self.path}: file exists (overwrite=False)")
            if not self.path.is_file():
                raise RecordingError(f"{self.path}: exists and is not a file")
            # kept until close() renames the new file onto it: a run killed meanwhile leaves
            # the previous recording whole (decision 0921)
        try:
            self._partial.mkdir()
        except OSError as exc:
            raise RecordingError(f"{self.path}: cannot create {self._partial}: {exc}") from exc
        self._lock = _hold_writer_lock(self._partial)
        schema = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "sample_rate_hz": self.sample_rate_hz,
            "t0_s": self.t0_s,
            "flush_every_samples": self._flush_samples,
            "channels": [[c.name, c.unit, c.description] for c in self._channels.values()],
            "streams": {
                s: [[fi.name, fi.unit, fi.description] for fi in f.values()]
                for s, f in self._streams.items()
            },
            "metadata": self._proto.metadata,
        }
        _atomic_json(self._partial / _SCHEMA, schema, fsync)
        if fsync:
            _fsync_dir(self.path.parent)

        self._dtypes: dict[str, np.dtype] = {}
        self._pending: dict[str, list[np.ndarray]] = {n: [] for n in self._channels}
        self._pending_n = 0
        self._stream_dtypes: dict[str, dict[str, np.dtype]] = {s: {} for s in self._streams}
        self._stream_pending: dict[str, list[dict[str, np.ndarray]]] = {
            s: [] for s in self._streams
        }
        self._stream_last_t: dict[str, float] = {s: -math.inf for s in self._streams}
        self._flushed = 0
        self._appended = 0
        self._segment = 0
        self._closed = False
        self._final = h5py.File(self._partial / _INPROGRESS, "w")
        self._final.create_group("channels")
        self._appenders: dict[str, hdf5_chunks.ChunkAppender] = {}
        self._stream_appenders: dict[tuple[str, str], hdf5_chunks.ChunkAppender] = {}

    # ------------------------------------------------------------------ properties
    @property
    def samples_written(self) -> int:
        """Samples per channel flushed to segments (these survive a SIGKILL)."""
        return self._flushed

    @property
    def samples_appended(self) -> int:
        """Samples per channel appended so far (flushed or still buffered)."""
        return self._appended

    def update_metadata(self, metadata: Mapping[str, object]) -> None:
        """Add or replace metadata keys of the final file (written at :meth:`close`), e.g. the
        warnings and crash events a run raised; the sidecar of a killed run keeps the
        metadata given at construction."""
        self._check_open()
        try:
            extra = normalise_metadata(metadata)
        except InputDataError as exc:
            raise InputDataError(f"{self.path}: {exc}") from None
        self._proto.metadata.update(extra)

    # ------------------------------------------------------------------ appending
    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"{self.path}: writer is closed")

    def _coerce(
        self, key: str, values: ArrayLike, dtypes: Mapping[str, np.dtype], what: str
    ) -> np.ndarray:
        """Copy ``values`` as a 1-D array of the dtype fixed for ``key`` (first chunk's)."""
        dtype = dtypes.get(key)
        if (
            dtype is not None
            and type(values) is np.ndarray
            and values.ndim == 1
            and values.dtype == dtype
        ):
            return values.copy()  # the usual chunk: nothing to check or convert
        arr = as_channel_array(values, key, what)
        if dtype is None:
            return np.array(arr, copy=True)
        if not np.can_cast(arr.dtype, dtype, "same_kind"):
            raise InputDataError(
                f"{self.path}: {what} '{key}': got dtype {arr.dtype}, "
                f"the recording stores {dtype} (fixed by the first chunk)"
            )
        return np.array(arr, dtype=dtype, copy=True)

    def append(self, data: Mapping[str, ArrayLike]) -> None:
        """Append a chunk of any length holding every declared channel.

        Raises
        ------
        InputDataError
            A declared channel is missing, an undeclared one is given, or lengths differ; the
            message names the channel and the file.
        """
        self._check_open()
        extra = [k for k in data if k not in self._channels]
        if extra:
            raise InputDataError(
                f"{self.path}: channel '{extra[0]}' was not declared; declared: "
                f"{', '.join(self._channels)}"
            )
        missing = [k for k in self._channels if k not in data]
        if missing:
            raise InputDataError(f"{self.path}: chunk lacks declared channel '{missing[0]}'")
        chunk: dict[str, np.ndarray] = {}
        length: int | None = None
        first = ""
        for name in self._channels:
            arr = self._coerce(name, data[name], self._dtypes, "channel")
            if length is None:
                length, first = arr.shape[0], name
            elif arr.shape[0] != length:
                raise InputDataError(
                    f"{self.path}: channel '{name}' has {arr.shape[0]} samples in this chunk, "
                    f"channel '{first}' has {length}"
                )
            chunk[name] = arr
        for name, arr in chunk.items():  # only a valid chunk fixes the dtypes
            self._dtypes.setdefault(name, arr.dtype)
        if not length:
            return
        for name, arr in chunk.items():
            self._pending[name].append(arr)
        self._pending_n += length
        self._appended += length
        if self._pending_n >= self._flush_samples:
            self.flush()

    def append_stream(self, name: str, time_s: ArrayLike, fields: Mapping[str, ArrayLike]) -> None:
        """Append rows to a declared stream (written with the next flush).

        Raises
        ------
        InputDataError
            Undeclared stream or field, missing field, wrong length, or time going backwards.
        """
        self._check_open()
        if name not in self._streams:
            raise InputDataError(
                f"{self.path}: stream '{name}' was not declared; declared: "
                f"{', '.join(self._streams) or '(none)'}"
            )
        declared = self._streams[name]
        extra = [k for k in fields if k not in declared]
        if extra:
            raise InputDataError(f"{self.path}: stream '{name}': field '{extra[0]}' not declared")
        missing = [k for k in declared if k not in fields]
        if missing:
            raise InputDataError(f"{self.path}: stream '{name}': chunk lacks field '{missing[0]}'")
        t = np.array(time_s, dtype=np.float64)
        try:
            Stream(name, t, {k: fields[k] for k in declared}, declared)
        except InputDataError as exc:
            raise InputDataError(f"{self.path}: {exc}") from None
        if t.size and t[0] < self._stream_last_t[name]:
            raise InputDataError(
                f"{self.path}: stream '{name}': time_s {t[0]} s goes back before the previous "
                f"row at {self._stream_last_t[name]} s"
            )
        if t.size == 0:
            return
        rows = {"time_s": t}
        dtypes = self._stream_dtypes[name]
        for k in declared:
            rows[k] = self._coerce(k, fields[k], dtypes, f"stream '{name}' field")
        for k in declared:
            dtypes.setdefault(k, rows[k].dtype)
        self._stream_last_t[name] = float(t[-1])
        self._stream_pending[name].append(rows)

    # ------------------------------------------------------------------ flushing
    def flush(self) -> None:
        """Write everything appended so far as one segment; it then survives SIGKILL."""
        self._check_open()
        has_streams = any(self._stream_pending.values())
        if not self._pending_n and not has_streams:
            return
        block = {
            n: (np.concatenate(parts) if len(parts) > 1 else parts[0])
            for n, parts in self._pending.items()
            if parts
        }
        stream_block = {
            s: {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
            for s, rows in self._stream_pending.items()
            if rows
        }
        self._segment += 1
        seg = self._partial / f"seg-{self._segment:06d}.bin"
        tmp = self._partial / f".seg-{self._segment:06d}.bin.tmp"
        try:
            write_segment(tmp, self._flushed, self._pending_n, block, stream_block, self._fsync)
            os.replace(tmp, seg)
            if self._fsync:
                _fsync_dir(self._partial)
        except OSError as exc:
            self._segment -= 1
            tmp.unlink(missing_ok=True)
            raise RecordingError(f"{self.path}: cannot write segment {seg.name}: {exc}") from exc
        self._flushed += self._pending_n
        self._pending = {n: [] for n in self._channels}
        self._pending_n = 0
        for sname in stream_block:
            self._stream_pending[sname] = []
        self._consolidate(block)
        self._consolidate_streams(stream_block)

    def _consolidate(self, block: Mapping[str, np.ndarray]) -> None:
        """Feed flushed samples to the final file being built (compressed in the pool)."""
        channels = self._final["channels"]
        for name, arr in block.items():
            appender = self._appenders.get(name)
            if appender is None:
                ds = hdf5_chunks.create_chunked(
                    channels, name, self._dtypes[name], hdf5_chunks.CHUNK_SAMPLES
                )
                _set_info(ds, self._channels[name])
                appender = self._appenders[name] = hdf5_chunks.ChunkAppender(ds)
            appender.append(arr)

    def _stream_appender(
        self, sname: str, field: str, dtype: np.dtype, info: ChannelInfo
    ) -> hdf5_chunks.ChunkAppender:
        key = (sname, field)
        appender = self._stream_appenders.get(key)
        if appender is None:
            group = self._final.require_group("streams").require_group(sname)
            ds = hdf5_chunks.create_chunked(group, field, dtype, hdf5_chunks.CHUNK_SAMPLES)
            _set_info(ds, info)
            appender = self._stream_appenders[key] = hdf5_chunks.ChunkAppender(ds)
        return appender

    def _consolidate_streams(self, stream_block: Mapping[str, Mapping[str, np.ndarray]]) -> None:
        """Feed flushed stream rows to the final file as they come (not kept until close:
        a shift of 333 Hz rows would otherwise grow the writer's memory, decision 0961)."""
        for sname, cols in stream_block.items():
            for k, arr in cols.items():
                info = self._streams[sname].get(k) or ChannelInfo("time_s", "s", "row time")
                self._stream_appender(sname, k, arr.dtype, info).append(arr)

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Flush, finish the final file, rename it to ``path`` and remove the sidecar.

        If this fails the sidecar stays, so :func:`read_recording` still recovers the data.
        """
        if self._closed:
            return
        self.flush()
        self._closed = True
        f = self._final
        try:
            for name, info in self._channels.items():
                if name not in self._appenders:  # no sample ever appended
                    dtype = self._dtypes.get(name, np.dtype(np.float64))
                    ds = hdf5_chunks.create_chunked(f["channels"], name, dtype, 1)
                    _set_info(ds, info)
                else:
                    self._appenders[name].finish()
            f.require_group("streams")
            for sname, fields in self._streams.items():
                infos = {"time_s": ChannelInfo("time_s", "s", "row time"), **fields}
                for k, info in infos.items():
                    if (sname, k) in self._stream_appenders:
                        self._stream_appenders[(sname, k)].finish()
                    else:  # no row ever appended
                        dtype = self._stream_dtypes[sname].get(k, np.dtype(np.float64))
                        group = f["streams"].require_group(sname)
                        _set_info(hdf5_chunks.create_chunked(group, k, dtype, 1), info)
            layout = {
                "channels": list(self._channels),
                "streams": {s: list(fl) for s, fl in self._streams.items()},
            }
            _write_root(
                f, self.sample_rate_hz, self.t0_s, self._flushed, self._proto.metadata, layout
            )
            f.close()
            inprogress = self._partial / _INPROGRESS
            if self._fsync:
                _fsync_file(inprogress)
            os.replace(inprogress, self.path)
            if self._fsync:
                _fsync_dir(self.path.parent)
        except OSError as exc:
            raise RecordingError(
                f"{self.path}: cannot finish recording ({exc}); data kept in {self._partial}"
            ) from exc
        finally:
            if f.id.valid:
                f.close()
        shutil.rmtree(self._partial, ignore_errors=True)
        self._lock.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc is None:
            self.close()
            return
        # The caller failed mid-recording: keep what was appended; never mask its error.
        try:
            self.close()
        except Exception:  # the sidecar stays; read_recording recovers it
            pass


# ---------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class RecordingStatus:
    """What a recording path holds, without reading the samples.

    Attributes
    ----------
    complete : bool
        True if the final file exists (the writer closed).
    n_samples : int
        Samples per channel available.
    duration_s : float
        ``n_samples / sample_rate_hz``, s.
    recovered_from : str or None
        None for a complete file, else a description of what recovery uses.
    ends_at_s : float
        Time just after the last available sample, ``t0_s + n_samples / fs``, s.
    message : str
        One line for people.
    """

    complete: bool
    n_samples: int
    duration_s: float
    recovered_from: str | None
    ends_at_s: float
    message: str


def _open_h5(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such recording file") from None
    except OSError as exc:
        text = str(exc)  # e.g. "Unable to ... open file (truncated file: eof = 7, ...)"
        inner = text.split("(", 1)[1] if "(" in text else text
        reason = inner.split(":")[0].split(")")[0].strip() or type(exc).__name__
        size = path.stat().st_size if path.exists() else 0
        raise RecordingError(
            f"{path}: not a readable HDF5 file ({reason}; {size} bytes) - truncated or corrupt?"
        ) from None


def _root_metadata(path: Path, f: h5py.File) -> dict[str, Any]:
    """The file's metadata_json as a mapping, or a RecordingError naming the file."""
    meta = json.loads(_attr_str(f, "metadata_json") or "{}")
    if not isinstance(meta, dict):
        raise RecordingError(
            f"{path}: damaged root attribute metadata_json (a {type(meta).__name__}, not a table)"
        )
    return meta


def _root_times(path: Path, f: h5py.File) -> tuple[float, float]:
    """The file's sample rate (finite, > 0) and start time (finite), or a RecordingError
    naming the file (a damaged attribute must not surface as an unnamed error later)."""
    fs = float(f.attrs["sample_rate_hz"])
    t0 = float(f.attrs["t0_s"])
    if not (math.isfinite(fs) and fs > 0):
        raise RecordingError(f"{path}: damaged root attribute sample_rate_hz = {fs!r}")
    if not math.isfinite(t0):
        raise RecordingError(f"{path}: damaged root attribute t0_s = {t0!r}")
    return fs, t0


def _check_format(path: Path, f: h5py.File) -> None:
    fmt = f.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode()
    if fmt != FORMAT:
        raise RecordingError(
            f"{path}: HDF5 file but not a millsense recording (root attribute format="
            f"{fmt!r}, expected {FORMAT!r})"
        )
    version = int(f.attrs.get("format_version", -1))
    if version != FORMAT_VERSION:
        raise RecordingError(
            f"{path}: recording format_version {version} is not supported "
            f"(this millsense reads {FORMAT_VERSION})"
        )


def _attr_str(obj: h5py.HLObject, key: str) -> str:
    value = obj.attrs.get(key, "")
    return value.decode() if isinstance(value, bytes) else str(value)


def _walk_datasets(group: h5py.Group) -> list[str]:
    names: list[str] = []
    group.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
    return names


def _layout(f: h5py.File) -> dict[str, Any]:
    if "layout_json" in f.attrs:
        layout: dict[str, Any] = json.loads(_attr_str(f, "layout_json"))
        return layout
    channels = _walk_datasets(f["channels"]) if "channels" in f else []
    streams: dict[str, list[str]] = {}
    if "streams" in f:
        for ds_name in _walk_datasets(f["streams"]):
            sname, _, field = ds_name.rpartition("/")
            if field != "time_s":
                streams.setdefault(sname, []).append(field)
    return {"channels": channels, "streams": streams}


def _source_metadata(meta: dict[str, object], path: Path) -> dict[str, object]:
    """Make error messages name the file: ``source`` becomes the path (old one kept)."""
    old = meta.get("source")
    if old is not None and str(old) != str(path):
        meta.setdefault("original_source", old)
    meta["source"] = str(path)
    return meta


def _map_file(path: Path) -> tuple[mmap.mmap | None, memoryview | None]:
    """Memory-map ``path`` read-only for zero-copy chunk reads (None if it cannot be)."""
    try:
        with open(path, "rb") as fh:
            mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):
        return None, None
    return mm, memoryview(mm)


def _read_complete(path: Path) -> Recording:
    mm, mapped = _map_file(path)
    try:
        return _read_complete_h5(path, mapped)
    finally:
        if mapped is not None:
            mapped.release()
        if mm is not None:
            try:
                mm.close()
            except BufferError:  # a slice is still referenced; closed when collected
                pass


def _read_complete_h5(path: Path, mapped: memoryview | None) -> Recording:
    f = _open_h5(path)
    try:
        with f:
            _check_format(path, f)
            try:
                meta = _root_metadata(path, f)
                layout = _layout(f)
                fs, t0 = _root_times(path, f)
            except (KeyError, ValueError, TypeError) as exc:
                raise RecordingError(f"{path}: damaged root attributes ({exc})") from None
            rec = Recording(fs, t0, _source_metadata(meta, path))
            pending: list[Future[None]] = []
            arrays: list[tuple[str, np.ndarray, h5py.Dataset]] = []
            where = ""
            try:
                for name in layout["channels"]:
                    where = f"/channels/{name}"
                    ds = f[where]
                    arrays.append((name, hdf5_chunks.read_array(ds, pending, mapped), ds))
                streams: list[tuple[str, dict[str, np.ndarray], dict[str, ChannelInfo]]] = []
                for sname, fields in layout["streams"].items():
                    cols: dict[str, np.ndarray] = {}
                    infos: dict[str, ChannelInfo] = {}
                    for k in ["time_s", *fields]:
                        where = f"/streams/{sname}/{k}"
                        ds = f[where]
                        cols[k] = hdf5_chunks.read_array(ds, pending, mapped)
                        infos[k] = ChannelInfo(
                            k, _attr_str(ds, "unit"), _attr_str(ds, "description")
                        )
                    streams.append((sname, cols, infos))
                where = "chunk data"
                hdf5_chunks.wait_all(pending)
            except (KeyError, OSError, ValueError, RuntimeError, zlib.error) as exc:
                hdf5_chunks.wait_all_quietly(pending)
                raise RecordingError(
                    f"{path}: cannot read {where} ({str(exc).splitlines()[0][:120]}) - "
                    "truncated or corrupt?"
                ) from None
            for name, arr, ds in arrays:
                rec._insert_channel(name, arr, _attr_str(ds, "unit"), _attr_str(ds, "description"))
            for sname, cols, infos in streams:
                time_s = cols.pop("time_s")
                infos.pop("time_s")
                rec._insert_stream(Stream(sname, time_s, cols, infos))
            return rec
    except InputDataError as exc:
        raise RecordingError(f"{path}: inconsistent recording ({exc})") from None


@dataclass
class _Segments:
    """Complete segments of an interrupted recording, in order."""

    schema: dict[str, Any]
    files: list[Path]
    n_samples: int
    note: str  # why reading stopped early, or ""


def _load_schema(path: Path, partial: Path) -> dict[str, Any]:
    try:
        with open(partial / _SCHEMA, encoding="utf-8") as fh:
            schema: dict[str, Any] = json.load(fh)
    except FileNotFoundError:
        raise RecordingError(
            f"{path}: interrupted recording {partial} has no {_SCHEMA}; nothing to recover"
        ) from None
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{path}: cannot read {partial / _SCHEMA} ({exc})") from None
    if schema.get("format") != FORMAT:
        raise RecordingError(f"{path}: {partial / _SCHEMA} is not a millsense recording schema")
    return schema


def _scan_segments(path: Path, partial: Path, keep: bool) -> tuple[_Segments, list[Segment]]:
    """List complete, verified, contiguous segments; with ``keep`` also return their samples."""
    schema = _load_schema(path, partial)
    numbered = []
    for p in partial.iterdir():
        m = _SEG_RE.match(p.name)
        if m:
            numbered.append((int(m.group(1)), p))
    numbered.sort()
    files: list[Path] = []
    loaded: list[Segment] = []
    n = 0
    note = ""
    for expect, (index, p) in enumerate(numbered, start=1):
        if index != expect:
            note = f"segment {expect} missing; later segments ignored"
            break
        try:
            seg = read_segment(p)
        except SegmentError as exc:
            note = f"segment {p.name} damaged ({exc}); it and later segments ignored"
            break
        if seg.start_sample != n:
            note = f"segment {p.name} starts at sample {seg.start_sample}, expected {n}; ignored"
            break
        n += seg.n_samples
        files.append(p)
        if keep:
            loaded.append(seg)
    return _Segments(schema, files, n, note), loaded


def _recovery_message(segs: _Segments) -> str:
    fs = float(segs.schema["sample_rate_hz"])
    t0 = float(segs.schema["t0_s"])
    dur = segs.n_samples / fs
    msg = (
        f"incomplete: writer did not close; recovered {dur:.6g} s ({segs.n_samples} samples) "
        f"from {len(segs.files)} segments; data ends at t = {t0 + dur:.6g} s"
    )
    return msg + (f"; {segs.note}" if segs.note else "")


def _read_partial(path: Path, partial: Path, found: list[_Segments] | None = None) -> Recording:
    segs, loaded = _scan_segments(path, partial, keep=True)
    if found is not None:
        found.append(segs)
    schema = segs.schema
    try:
        meta = dict(schema.get("metadata", {}))
        meta["recovered"] = True
        meta["recovery_note"] = _recovery_message(segs)
        rec = Recording(
            float(schema["sample_rate_hz"]), float(schema["t0_s"]), _source_metadata(meta, path)
        )
        for name, unit, desc in schema["channels"]:
            parts = [s.channels[name] for s in loaded if name in s.channels]
            arr = np.concatenate(parts) if parts else np.zeros(0)
            rec._insert_channel(name, arr, unit, desc)
        for sname, fields in schema["streams"].items():
            keys = ["time_s", *(x[0] for x in fields)]
            cols = {k: [s.streams[sname][k] for s in loaded if sname in s.streams] for k in keys}
            arrays = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in cols.items()}
            infos = {x[0]: ChannelInfo(x[0], x[1], x[2]) for x in fields}
            time_s = arrays.pop("time_s")
            rec._insert_stream(Stream(sname, time_s, arrays, infos))
        return rec
    except (KeyError, ValueError, TypeError, InputDataError) as exc:
        raise RecordingError(f"{path}: cannot recover from {partial} ({exc})") from None


def read_interrupted(path: str | Path) -> tuple[Recording, dict[str, Any]]:
    """The recording in ``<path>.partial/`` even when a complete ``path`` exists beside it.

    Returns the recording (as :func:`read_recording` recovers it) and what recovery knows
    about the loss: ``schema`` (dict), ``segments`` (int), ``note`` (why reading stopped
    early, or ""), ``unfinished`` (names of half-written segment files, discarded).
    """
    path = Path(path)
    partial = partial_dir(path)
    if not partial.is_dir():
        raise RecordingError(f"{path}: no interrupted recording ({partial} does not exist)")
    found: list[_Segments] = []
    rec = _read_partial(path, partial, found)
    segs = found[0]
    unfinished = sorted(p.name for p in partial.iterdir() if p.name.endswith(".bin.tmp"))
    return rec, {
        "schema": segs.schema,
        "segments": len(segs.files),
        "note": segs.note,
        "unfinished": unfinished,
    }


def read_recording(path: str | Path) -> Recording:
    """Read a recording file, or recover an interrupted one from ``<path>.partial/``.

    Parameters
    ----------
    path : str or Path
        The ``.h5`` file given to :func:`write_recording` or :class:`RecordingWriter`.

    Returns
    -------
    Recording
        ``metadata['source']`` is the path (a stored source is kept as ``original_source``).
        A recovered recording has ``metadata['recovered'] = True`` and a ``recovery_note``.
        While a writer is still running this returns every sample flushed so far.

    Raises
    ------
    RecordingError
        Missing file, truncated/corrupt HDF5, an HDF5 file that is not a millsense recording,
        or an interrupted recording without a schema. One line naming the file.
    """
    path = Path(path)
    partial = partial_dir(path)
    for _ in range(3):
        if path.is_file() and not (partial.is_dir() and writer_alive(path)):
            return _read_complete(path)
        if partial.is_dir():
            try:
                return _read_partial(path, partial)
            except (OSError, RecordingError) as exc:
                if path.is_file() or not partial.is_dir():
                    continue  # the writer closed while we read: read the final file
                if isinstance(exc, RecordingError):
                    raise
                raise RecordingError(f"{path}: cannot read {partial} ({exc})") from None
        elif path.exists():
            raise RecordingError(f"{path}: not a file")
        else:
            break
    raise RecordingError(f"{path}: no such recording file")


def recording_status(path: str | Path) -> RecordingStatus:
    """Say whether ``path`` is complete or recoverable, how long, and where its data end.

    Raises
    ------
    RecordingError
        As :func:`read_recording` for missing, corrupt or foreign files.
    """
    path = Path(path)
    partial = partial_dir(path)
    if path.is_file() and not (partial.is_dir() and writer_alive(path)):
        with _open_h5(path) as f:
            _check_format(path, f)
            try:
                fs, t0 = _root_times(path, f)
                layout = _layout(f)
                if layout["channels"]:
                    n = int(f["channels"][layout["channels"][0]].shape[0])
                else:
                    n = int(f.attrs.get("n_samples", 0))
            except (KeyError, ValueError, TypeError, OSError, RuntimeError) as exc:
                raise RecordingError(f"{path}: damaged recording structure ({exc})") from None
        dur = n / fs
        msg = (
            f"complete: {dur:.6g} s ({n} samples), {len(layout['channels'])} channels, "
            f"{len(layout['streams'])} streams; data ends at t = {t0 + dur:.6g} s"
        )
        return RecordingStatus(True, n, dur, None, t0 + dur, msg)
    if partial.is_dir():
        try:
            segs, _ = _scan_segments(path, partial, keep=False)
        except OSError as exc:
            if path.is_file() or not partial.is_dir():
                return recording_status(path)  # the writer closed meanwhile
            raise RecordingError(f"{path}: cannot read {partial} ({exc})") from None
        fs = float(segs.schema["sample_rate_hz"])
        t0 = float(segs.schema["t0_s"])
        dur = segs.n_samples / fs
        return RecordingStatus(
            False,
            segs.n_samples,
            dur,
            f"{len(segs.files)} segments in {partial}",
            t0 + dur,
            _recovery_message(segs),
        )
    raise RecordingError(f"{path}: no such recording file")
