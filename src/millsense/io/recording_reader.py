"""Lazy reading of a recording file: windows of samples on demand, never the whole record.

:func:`~millsense.io.recording_file.read_recording` loads every channel into memory; a
shift-long recording (an hour at 10 kHz, 60 channels: 17 GB of float64) does not fit. A
:class:`RecordingReader` keeps the HDF5 file open and reads the samples ``[start, stop)`` of a
channel when asked (:meth:`RecordingReader.window`, h5py slicing through HDF5's own shuffle +
deflate filters and its chunk cache), so a replay holds one chunk of each channel at a time
(decision 0961 "Streaming with constant memory").

:func:`open_recording` returns a reader for a complete file; an interrupted recording (the
``<path>.partial/`` sidecar of a killed writer) is recovered in memory by
:func:`~millsense.io.recording_file.read_recording` as before: its segments are raw and its
length is what one run wrote before it died. Both answer the same questions
(``sample_rate_hz``, ``t0_s``, ``n_samples``, ``metadata``, ``channel_names``, ``info``,
``in``, ``stream``); :func:`channel_window` reads a window from either.

:class:`RecordingSegment` (``open_recording(path, segment=(start, stop))``) is samples
``[start, stop)`` of either, seen as a recording of its own: its ``t0_s`` is the time of its
first sample, its streams keep the rows of its time span. ``millsense batch`` runs the
segments of a long recording as separate tasks (issue 20, decision 2005).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from millsense.core.errors import RecordingError
from millsense.core.recording import ChannelInfo, Recording, Stream
from millsense.io.recording_file import (
    _attr_str,
    _check_format,
    _layout,
    _open_h5,
    _root_metadata,
    _root_times,
    _source_metadata,
    read_recording,
)

__all__ = ["RecordingReader", "RecordingSegment", "channel_window", "open_recording"]

#: HDF5 chunk cache per dataset, bytes: two of the writer's 512 KiB chunks, so that reading a
#: chunk's samples in several windows inflates it once.
_CHUNK_CACHE_BYTES = 2 * 1024 * 1024


class RecordingReader:
    """A complete recording file opened for windowed reads (see the module docstring).

    Parameters
    ----------
    path : the ``.h5`` file (complete; use :func:`open_recording` for any recording path).

    Raises
    ------
    RecordingError
        Missing, truncated or foreign file, damaged root attributes, channels of different
        lengths or not 1-D numbers: one line naming the file (and the channel).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._file = self._open(self.path)
        try:
            self._init()
        except BaseException:
            self._file.close()
            raise

    @staticmethod
    def _open(path: Path) -> h5py.File:
        if not path.is_file():
            return _open_h5(path)  # the one-line error for a missing file
        try:
            return h5py.File(path, "r", rdcc_nbytes=_CHUNK_CACHE_BYTES)
        except OSError:
            return _open_h5(path)  # raises the one-line "not a readable HDF5 file"

    def _init(self) -> None:
        f, path = self._file, self.path
        _check_format(path, f)
        try:
            meta = _root_metadata(path, f)
            layout = _layout(f)
            self.sample_rate_hz, self.t0_s = _root_times(path, f)
        except (KeyError, ValueError, TypeError) as exc:
            raise RecordingError(f"{path}: damaged root attributes ({exc})") from None
        self.metadata: dict[str, object] = _source_metadata(dict(meta), path)
        self._datasets: dict[str, h5py.Dataset] = {}
        self._info: dict[str, ChannelInfo] = {}
        n: int | None = None
        first = ""
        for name in layout["channels"]:
            try:
                ds = f[f"/channels/{name}"]
            except (KeyError, OSError) as exc:
                raise RecordingError(f"{path}: cannot read /channels/{name} ({exc})") from None
            if not isinstance(ds, h5py.Dataset) or ds.ndim != 1 or ds.dtype.kind not in "iuf":
                raise RecordingError(f"{path}: channel '{name}' is not a 1-D array of numbers")
            if n is None:
                n, first = int(ds.shape[0]), name
            elif int(ds.shape[0]) != n:
                raise RecordingError(
                    f"{path}: inconsistent recording (channel '{name}' has {ds.shape[0]} "
                    f"samples, '{first}' has {n})"
                )
            self._datasets[name] = ds
        self.n_samples = int(n or 0)
        self._streams: dict[str, list[str]] = dict(layout["streams"])

    # ------------------------------------------------------------------ Recording-like
    @property
    def channel_names(self) -> list[str]:
        return list(self._datasets)

    @property
    def stream_names(self) -> list[str]:
        return list(self._streams)

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.sample_rate_hz

    def __contains__(self, name: object) -> bool:
        return name in self._datasets

    def info(self, name: str) -> ChannelInfo:
        """Unit and description of a channel (read from the file when first asked: a replay
        reads a few of the channels, and the attributes of sixty cost ≈ 25 ms per opening)."""
        self._check(name)
        got = self._info.get(name)
        if got is None:
            ds = self._datasets[name]
            try:
                unit, text = _attr_str(ds, "unit"), _attr_str(ds, "description")
            except (OSError, KeyError, ValueError, RuntimeError) as exc:
                raise RecordingError(
                    f"{self.path}: cannot read the attributes of channel '{name}' ({exc})"
                ) from None
            got = self._info[name] = ChannelInfo(name, unit, text)
        return got

    def _check(self, name: str) -> None:
        if name not in self._datasets:
            raise RecordingError(
                f"{self.path}: unknown channel '{name}'; available: "
                f"{', '.join(self._datasets) or '(none)'}"
            )

    def window(self, name: str, start: int, stop: int) -> np.ndarray:
        """Samples ``[start, stop)`` of channel ``name`` (clipped to the recording), a new
        array in native byte order.

        Raises
        ------
        RecordingError
            Unknown channel, or a chunk that does not decode (one line naming the file, the
            channel and the samples).
        """
        self._check(name)
        a = max(0, min(int(start), self.n_samples))
        b = max(a, min(int(stop), self.n_samples))
        ds = self._datasets[name]
        try:
            arr = np.asarray(ds[a:b])
        except (OSError, ValueError, RuntimeError, zlib.error) as exc:
            raise RecordingError(
                f"{self.path}: cannot read channel '{name}' samples {a}-{b} "
                f"({str(exc).splitlines()[0][:120]}) - truncated or corrupt?"
            ) from None
        if not arr.dtype.isnative:
            arr = arr.astype(arr.dtype.newbyteorder("="))
        return arr

    def channel(self, name: str) -> np.ndarray:
        """The whole channel (reads every sample: the streaming paths use :meth:`window`)."""
        return self.window(name, 0, self.n_samples)

    def stream(self, name: str) -> Stream:
        """A stream read whole (streams are slow tables: the 333 Hz ``cnc`` rows of an hour
        are 9.6 MB per field)."""
        if name not in self._streams:
            raise RecordingError(
                f"{self.path}: unknown stream '{name}'; available: "
                f"{', '.join(self._streams) or '(none)'}"
            )
        cols: dict[str, np.ndarray] = {}
        infos: dict[str, ChannelInfo] = {}
        try:
            for k in ["time_s", *self._streams[name]]:
                ds = self._file[f"/streams/{name}/{k}"]
                cols[k] = np.asarray(ds[()])
                infos[k] = ChannelInfo(k, _attr_str(ds, "unit"), _attr_str(ds, "description"))
        except (KeyError, OSError, ValueError, RuntimeError) as exc:
            raise RecordingError(f"{self.path}: cannot read stream '{name}' ({exc})") from None
        time_s = cols.pop("time_s")
        infos.pop("time_s")
        return Stream(name, time_s, cols, infos)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        if self._file.id.valid:
            self._file.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"RecordingReader({str(self.path)!r}, {len(self._datasets)} channels, "
            f"{self.n_samples} samples at {self.sample_rate_hz:g} Hz)"
        )


class RecordingSegment:
    """Samples ``[start, stop)`` of a recording (a :class:`RecordingReader` or a
    :class:`Recording`) as a recording of its own (module docstring).

    Raises
    ------
    RecordingError
        An empty or reversed range, or one beyond the recording's samples.
    """

    def __init__(self, rec: RecordingReader | Recording, start: int, stop: int) -> None:
        n = int(rec.n_samples)
        if not (0 <= int(start) < int(stop) <= n):
            where = getattr(rec, "path", "recording")
            raise RecordingError(
                f"{where}: segment samples {start}-{stop} outside the recording's 0-{n}"
            )
        self.base = rec
        self.start = int(start)
        self.stop = int(stop)
        self.path = getattr(rec, "path", None)
        self.sample_rate_hz = float(rec.sample_rate_hz)
        self.t0_s = float(rec.t0_s) + self.start / self.sample_rate_hz
        self.n_samples = self.stop - self.start
        self.metadata: dict[str, object] = dict(rec.metadata)

    @property
    def channel_names(self) -> list[str]:
        return list(self.base.channel_names)

    @property
    def stream_names(self) -> list[str]:
        return list(self.base.stream_names)

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.sample_rate_hz

    def __contains__(self, name: object) -> bool:
        return name in self.base

    def info(self, name: str) -> ChannelInfo:
        return self.base.info(name)

    def window(self, name: str, start: int, stop: int) -> np.ndarray:
        """Samples ``[start, stop)`` of the segment (clipped to it)."""
        a = self.start + max(0, min(int(start), self.n_samples))
        b = self.start + max(0, min(int(stop), self.n_samples))
        return channel_window(self.base, name, a, max(a, b))

    def channel(self, name: str) -> np.ndarray:
        return self.window(name, 0, self.n_samples)

    def stream(self, name: str) -> Stream:
        """The stream's rows whose time lies in the segment's span."""
        return self.base.stream(name).slice_time(self.t0_s, self.t0_s + self.duration_s)

    def close(self) -> None:
        close = getattr(self.base, "close", None)
        if close is not None:
            close()

    def __repr__(self) -> str:
        return f"RecordingSegment({self.base!r}, samples {self.start}-{self.stop})"


def open_recording(
    path: str | Path, segment: tuple[int, int] | None = None
) -> RecordingReader | Recording | RecordingSegment:
    """A lazy :class:`RecordingReader` of a complete file; an interrupted recording (only its
    ``.partial/`` sidecar exists) recovered in memory as a :class:`Recording`; with
    ``segment=(start, stop)`` the :class:`RecordingSegment` of those samples.

    Raises
    ------
    RecordingError
        As :func:`~millsense.io.recording_file.read_recording`; a segment outside the samples.
    """
    p = Path(path)
    rec: RecordingReader | Recording = RecordingReader(p) if p.is_file() else read_recording(p)
    if segment is None:
        return rec
    try:
        return RecordingSegment(rec, *segment)
    except RecordingError:
        if isinstance(rec, RecordingReader):
            rec.close()
        raise


@contextmanager
def opened_recording(
    path: str | Path, segment: tuple[int, int] | None = None
) -> Iterator[RecordingReader | Recording | RecordingSegment]:
    """:func:`open_recording` as a context: the file is closed on leaving (a recovered
    in-memory recording has nothing to close)."""
    rec = open_recording(path, segment)
    try:
        yield rec
    finally:
        if isinstance(rec, RecordingReader | RecordingSegment):
            rec.close()


def channel_window(rec: Any, name: str, start: int, stop: int) -> np.ndarray:
    """Samples ``[start, stop)`` of ``name`` from a :class:`RecordingReader` (read from the
    file) or a :class:`Recording` (a view)."""
    window = getattr(rec, "window", None)
    if window is not None:
        return np.asarray(window(name, start, stop))
    return np.asarray(rec.channel(name)[max(0, start) : max(0, stop)])
