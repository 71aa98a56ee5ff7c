"""Recordings in memory: named channels at one sample rate, slower timestamped streams, metadata.

A :class:`Recording` is what every estimator, monitor and identification routine consumes,
whether the data came from a live CNC, a file or the virtual machine tool. It holds

* **channels**: 1-D arrays sampled at ``sample_rate_hz`` starting at ``t0_s`` (sample ``k`` is
  at ``t0_s + k / sample_rate_hz``), each with an SI unit (:class:`ChannelInfo`);
* **streams**: slower tables with their own time column (:class:`Stream`), e.g. the tool-centre
  point at 333 Hz or the active NC line;
* **metadata**: a JSON-serialisable dictionary (machine, tool, program, units, created,
  software_version, source, ...).

Simulated recordings carry ground truth under the ``truth/`` prefix (``truth/x/force``);
estimators read only :meth:`Recording.measured_channel_names`. Channel names may contain ``/``
(they become HDF5 groups in a file, see :mod:`millsense.io.recording_file`).

Arrays handed out by :meth:`Recording.channel` are read-only views: a recording is a record,
so a consumer that wants to modify a signal takes a copy first.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from millsense.core.errors import InputDataError, RecordingError

__all__ = ["TRUTH_PREFIX", "ChannelInfo", "Recording", "Stream", "check_name", "check_text"]

#: Prefix of ground-truth channels of a simulation; estimators never read these.
TRUTH_PREFIX = "truth/"
#: Metadata key of a recording: the channels millsense computed from the data (a session's
#: block outputs), which data-quality checks skip (decision 1745).
COMPUTED_CHANNELS = "computed_channels"

#: Tolerance, in samples, when converting a time to a sample index (absorbs float rounding of
#: ``t0 + k / fs`` so that slicing at exactly a sample's time includes that sample).
_INDEX_TOL = 1e-6


@dataclass(frozen=True)
class ChannelInfo:
    """Name, SI unit and description of a channel or stream field.

    Parameters
    ----------
    name : str
        Channel name, ``/``-separated path such as ``"x/current_cmd"`` or ``"truth/x/force"``.
    unit : str
        SI unit string: ``"A"``, ``"N"``, ``"m"``, ``"rad/s"``, ``"rad"``, ``"N*m"``, ``"1"``.
    description : str
        Free text.
    """

    name: str
    unit: str
    description: str = ""


def check_name(name: object, what: str = "channel") -> str:
    """Validate a channel/stream name and return it.

    A name is one or more non-empty parts separated by ``/``; no part may be ``.`` or ``..``
    (HDF5 reserves them) and the name may not start or end with ``/``.

    Raises
    ------
    InputDataError
        If the name is not a string or is malformed.
    """
    if not isinstance(name, str) or not name:
        raise InputDataError(f"{what} name must be a non-empty string, got {name!r}")
    parts = name.split("/")
    bad_text = "\x00" in name or not _utf8(name)
    if any(p in ("", ".", "..") for p in parts) or name != name.strip() or bad_text:
        raise InputDataError(
            f"{what} name {name!r} is malformed: use non-empty '/'-separated parts, "
            "no leading/trailing '/' or spaces, no '.' or '..' parts, no NUL"
        )
    return name


def check_text(value: object, what: str) -> str:
    """Validate a unit or description: a string without NUL (HDF5 strings cannot hold it)."""
    if not isinstance(value, str):
        raise InputDataError(f"{what} must be a string, got {type(value).__name__}")
    if "\x00" in value:
        raise InputDataError(f"{what} contains a NUL character")
    if not _utf8(value):
        raise InputDataError(f"{what} is not valid Unicode text (lone surrogate)")
    return value


def _utf8(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _conflicts(name: str, existing: Iterable[str]) -> str | None:
    """Return an existing name that is a path-prefix of ``name`` or has ``name`` as one."""
    for other in existing:
        if other.startswith(name + "/") or name.startswith(other + "/"):
            return other
    return None


def as_channel_array(data: ArrayLike, name: str, what: str = "channel") -> np.ndarray:
    """Convert ``data`` to a 1-D numeric array in native byte order.

    Python sequences become float64; numpy arrays keep their integer or float dtype; booleans
    are stored as uint8 (0/1) so that every reader (MATLAB included) sees a plain number.

    Raises
    ------
    InputDataError
        If the data are not 1-D or not numeric; the message names the channel.
    """
    arr = np.asarray(data) if isinstance(data, np.ndarray) else np.asarray(data, dtype=float)
    if arr.ndim != 1:
        raise InputDataError(f"{what} '{name}': expected a 1-D array, got shape {arr.shape}")
    if arr.dtype.kind == "b":
        arr = arr.astype(np.uint8)
    if arr.dtype.kind not in "iuf":
        raise InputDataError(
            f"{what} '{name}': expected numbers (int, unsigned or float), got dtype {arr.dtype}"
        )
    if not arr.dtype.isnative:
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return arr


def _frozen(arr: np.ndarray) -> np.ndarray:
    view = arr.view()
    view.flags.writeable = False
    return view


def _jsonable(value: object, key: str) -> Any:
    """Return ``value`` as plain JSON types (numpy scalars/arrays converted) or raise."""
    if isinstance(value, np.generic):
        value = value.item()
    elif isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, f"{key}.{k}") for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v, key) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        raise InputDataError(f"metadata key '{key}': {value} is not representable in JSON")
    if value is None or isinstance(value, str | int | float | bool):
        return value
    raise InputDataError(
        f"metadata key '{key}': value of type {type(value).__name__} is not JSON-serialisable"
    )


def normalise_metadata(metadata: Mapping[str, object] | None) -> dict[str, object]:
    """Copy ``metadata`` into a dict of plain JSON values (numpy scalars converted).

    Raises
    ------
    InputDataError
        Naming the first key whose value cannot be stored as JSON.
    """
    if metadata is None:
        return {}
    out = {str(k): _jsonable(v, str(k)) for k, v in metadata.items()}
    json.dumps(out)  # cannot fail after _jsonable; keeps the guarantee explicit
    return out


class Stream:
    """A slower timestamped table, e.g. the tool-centre point at 333 Hz or the NC line.

    Parameters
    ----------
    name : str
        Stream name (``/``-separated path allowed).
    time_s : array_like
        Row times in s, non-decreasing, float64.
    fields : mapping of str to array_like
        Columns, each 1-D with one value per row.
    info : mapping of str to ChannelInfo
        Unit and description of every field.

    Raises
    ------
    InputDataError
        If a field has the wrong length, no unit, a malformed name, or time decreases.
    """

    def __init__(
        self,
        name: str,
        time_s: ArrayLike,
        fields: Mapping[str, ArrayLike],
        info: Mapping[str, ChannelInfo],
    ) -> None:
        self.name = check_name(name, "stream")
        t = np.asarray(time_s, dtype=np.float64)
        if t.ndim != 1:
            raise InputDataError(f"stream '{name}': time_s must be 1-D, got shape {t.shape}")
        if t.size and not np.all(np.isfinite(t)):
            bad = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputDataError(f"stream '{name}': time_s has NaN/inf at row {bad}")
        if t.size > 1 and np.any(np.diff(t) < 0):
            bad = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
            raise InputDataError(f"stream '{name}': time_s decreases at row {bad}")
        self.time_s: np.ndarray = _frozen(t)
        self.fields: dict[str, np.ndarray] = {}
        self.info: dict[str, ChannelInfo] = {}
        for field, values in fields.items():
            if not isinstance(field, str) or not field or "/" in field or field == "time_s":
                raise InputDataError(
                    f"stream '{name}': field name {field!r} is invalid "
                    "(non-empty, no '/', not 'time_s')"
                )
            arr = as_channel_array(values, f"{name}.{field}", "stream field")
            if arr.shape[0] != t.shape[0]:
                raise InputDataError(
                    f"stream '{name}': field '{field}' has {arr.shape[0]} rows, "
                    f"time_s has {t.shape[0]}"
                )
            if field not in info:
                raise InputDataError(f"stream '{name}': field '{field}' has no unit")
            self.fields[field] = _frozen(arr)
            i = info[field]
            check_text(i.unit, f"stream '{name}': field '{field}': unit")
            check_text(i.description, f"stream '{name}': field '{field}': description")
            self.info[field] = ChannelInfo(field, i.unit, i.description)

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    def __getitem__(self, field: str) -> np.ndarray:
        try:
            return self.fields[field]
        except KeyError:
            raise RecordingError(
                f"stream '{self.name}': unknown field '{field}'; "
                f"available: {', '.join(self.fields) or '(none)'}"
            ) from None

    def slice_time(self, t0: float, t1: float) -> Stream:
        """Rows with ``t0 <= time_s < t1`` (s), as a new stream."""
        lo = int(np.searchsorted(self.time_s, t0, side="left"))
        hi = int(np.searchsorted(self.time_s, t1, side="left"))
        hi = max(hi, lo)
        return Stream(
            self.name,
            self.time_s[lo:hi],
            {k: v[lo:hi] for k, v in self.fields.items()},
            self.info,
        )

    def __repr__(self) -> str:
        return f"Stream({self.name!r}, rows={len(self)}, fields={list(self.fields)})"


class Recording:
    """Named channels at a common sample rate, slower streams and metadata.

    Parameters
    ----------
    sample_rate_hz : float
        Sample rate of every channel, Hz (> 0).
    t0_s : float
        Time of sample 0, s.
    metadata : mapping, optional
        JSON-serialisable values. Keys in use: ``machine``, ``tool``, ``program``, ``units``,
        ``created`` (ISO 8601 time), ``software_version``, ``source`` (used in error
        messages), plus free keys.

    Notes
    -----
    Sample ``k`` of every channel is at :math:`t_k = t_0 + k / f_s`. ``duration_s`` is
    :math:`N / f_s`, the span covered by ``N`` samples of one period each.
    """

    def __init__(
        self,
        sample_rate_hz: float,
        t0_s: float = 0.0,
        metadata: Mapping[str, object] | None = None,
    ) -> None:
        fs = float(sample_rate_hz)
        if not math.isfinite(fs) or fs <= 0:
            raise InputDataError(f"sample_rate_hz must be finite and > 0, got {sample_rate_hz}")
        t0 = float(t0_s)
        if not math.isfinite(t0):
            raise InputDataError(f"t0_s must be finite, got {t0_s}")
        self.sample_rate_hz: float = fs
        self.t0_s: float = t0
        self.metadata: dict[str, object] = normalise_metadata(metadata)
        self._channels: dict[str, np.ndarray] = {}
        self._info: dict[str, ChannelInfo] = {}
        self._streams: dict[str, Stream] = {}

    # ------------------------------------------------------------------ building
    @property
    def source(self) -> str:
        """``metadata['source']`` or ``"recording"``: how error messages name this recording."""
        src = self.metadata.get("source")
        return str(src) if src else "recording"

    def add_channel(self, name: str, data: ArrayLike, unit: str, description: str = "") -> None:
        """Add a 1-D channel sampled at ``sample_rate_hz``.

        Parameters
        ----------
        name : str
            ``/``-separated name, e.g. ``"x/current_cmd"``; ground truth under ``truth/``.
        data : array_like
            Samples (copied). Lists become float64; numpy int/float dtypes are kept.
        unit : str
            SI unit string.
        description : str
            Free text.

        Raises
        ------
        InputDataError
            If the name exists or collides with a group, or the length differs from the
            existing channels; the message names the channel.
        """
        arr = as_channel_array(data, check_name(name))
        self._insert_channel(name, np.array(arr, copy=True), unit, description)

    def _insert_channel(self, name: str, arr: np.ndarray, unit: str, description: str) -> None:
        """Add ``arr`` without copying (used by readers that own freshly read arrays)."""
        if arr.ndim != 1 or arr.dtype.kind not in "iuf":  # a file written by another tool
            arr = as_channel_array(arr, name)
        if name in self._channels:
            raise InputDataError(f"{self.source}: channel '{name}' already exists")
        other = _conflicts(name, self._channels)
        if other is not None:
            raise InputDataError(
                f"{self.source}: channel '{name}' collides with channel '{other}' "
                "(one name is a group of the other)"
            )
        check_text(unit, f"{self.source}: channel '{name}': unit")
        check_text(description, f"{self.source}: channel '{name}': description")
        if self._channels and arr.shape[0] != self.n_samples:
            raise InputDataError(
                f"{self.source}: channel '{name}' has {arr.shape[0]} samples, "
                f"existing channels have {self.n_samples}"
            )
        self._channels[name] = _frozen(arr)
        self._info[name] = ChannelInfo(name, unit, description)

    def add_stream(
        self,
        name: str,
        time_s: ArrayLike,
        fields: Mapping[str, ArrayLike],
        units: Mapping[str, str],
        descriptions: Mapping[str, str] | None = None,
    ) -> None:
        """Add a slower timestamped table.

        Parameters
        ----------
        name : str
            Stream name.
        time_s : array_like
            Row times, s, non-decreasing.
        fields : mapping of str to array_like
            Columns, one value per row.
        units : mapping of str to str
            SI unit of every field.
        descriptions : mapping of str to str, optional
            Free text per field.

        Raises
        ------
        InputDataError
            If the stream exists, or a field has no unit or the wrong length.
        """
        check_name(name, "stream")
        if name in self._streams:
            raise InputDataError(f"{self.source}: stream '{name}' already exists")
        other = _conflicts(name, self._streams)
        if other is not None:
            raise InputDataError(f"{self.source}: stream '{name}' collides with stream '{other}'")
        desc = descriptions or {}
        missing = [f for f in fields if f not in units]
        if missing:
            raise InputDataError(
                f"{self.source}: stream '{name}': field '{missing[0]}' has no unit"
            )
        info = {f: ChannelInfo(f, units[f], desc.get(f, "")) for f in fields}
        self._streams[name] = Stream(name, np.array(time_s, dtype=np.float64), fields, info)

    def _insert_stream(self, stream: Stream) -> None:
        self._streams[stream.name] = stream

    # ------------------------------------------------------------------ access
    @property
    def channel_names(self) -> list[str]:
        """Channel names in insertion order."""
        return list(self._channels)

    @property
    def stream_names(self) -> list[str]:
        """Stream names in insertion order."""
        return list(self._streams)

    def info(self, name: str) -> ChannelInfo:
        """Unit and description of channel ``name`` (RecordingError if unknown)."""
        self._check_channel(name)
        return self._info[name]

    def _check_channel(self, name: str) -> None:
        if name not in self._channels:
            raise RecordingError(
                f"{self.source}: unknown channel '{name}'; "
                f"available: {', '.join(self._channels) or '(none)'}"
            )

    def channel(self, name: str) -> np.ndarray:
        """Samples of channel ``name`` (read-only array, unit in :meth:`info`).

        Raises
        ------
        RecordingError
            ``"<source>: unknown channel 'foo'; available: a, b, ..."``.
        """
        self._check_channel(name)
        return self._channels[name]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.channel(name)

    def __contains__(self, name: object) -> bool:
        return name in self._channels

    def __iter__(self) -> Iterator[str]:
        return iter(self._channels)

    def stream(self, name: str) -> Stream:
        """Stream ``name`` (RecordingError if unknown)."""
        try:
            return self._streams[name]
        except KeyError:
            raise RecordingError(
                f"{self.source}: unknown stream '{name}'; "
                f"available: {', '.join(self._streams) or '(none)'}"
            ) from None

    @property
    def n_samples(self) -> int:
        """Number of samples per channel (0 if there are no channels)."""
        for arr in self._channels.values():
            return int(arr.shape[0])
        return 0

    @property
    def duration_s(self) -> float:
        """``n_samples / sample_rate_hz``, s."""
        return self.n_samples / self.sample_rate_hz

    @property
    def time_s(self) -> np.ndarray:
        """Sample times ``t0_s + k / sample_rate_hz``, s."""
        return self.t0_s + np.arange(self.n_samples, dtype=np.float64) / self.sample_rate_hz

    def to_dict_of_arrays(self) -> dict[str, np.ndarray]:
        """Channels as ``{name: read-only array}`` in insertion order (no copy)."""
        return dict(self._channels)

    def measured_channel_names(self) -> list[str]:
        """Every channel not under ``truth/``: what a real CNC provides."""
        return [n for n in self._channels if not n.startswith(TRUTH_PREFIX)]

    def truth_channel_names(self) -> list[str]:
        """Ground-truth channels of a simulation (under ``truth/``)."""
        return [n for n in self._channels if n.startswith(TRUTH_PREFIX)]

    def require_finite(self, names: Iterable[str]) -> None:
        """Raise if any of the channels ``names`` holds NaN or inf.

        Raises
        ------
        InputDataError
            ``"<source>: channel 'x/current_cmd' has NaN/inf at sample 1234 (t = 0.1234 s)"``
            for the first bad sample of the first bad channel.
        RecordingError
            If a channel is unknown.
        """
        for name in names:
            arr = self.channel(name)
            if arr.dtype.kind != "f":
                continue
            finite = np.isfinite(arr)
            if not finite.all():
                k = int(np.argmin(finite))
                t = self.t0_s + k / self.sample_rate_hz
                raise InputDataError(
                    f"{self.source}: channel '{name}' has NaN/inf at sample {k} (t = {t:.6g} s)"
                )

    # ------------------------------------------------------------------ slicing
    def index_at(self, t_s: float) -> int:
        """First sample index whose time is ``>= t_s`` (clipped to ``[0, n_samples]``)."""
        k = math.ceil((float(t_s) - self.t0_s) * self.sample_rate_hz - _INDEX_TOL)
        return min(max(k, 0), self.n_samples)

    def slice_time(self, t_start_s: float, t_end_s: float) -> Recording:
        """Samples with ``t_start_s <= t < t_end_s`` as a new recording.

        Channels are cut by sample index ``[start, end)``, streams by their own time, the
        metadata is copied with ``sliced_from = [t_start_s, t_end_s]`` added and ``t0_s`` is
        the time of the first kept sample.

        Raises
        ------
        InputDataError
            If ``t_end_s < t_start_s`` or either is not finite.
        """
        a, b = float(t_start_s), float(t_end_s)
        if not (math.isfinite(a) and math.isfinite(b)) or b < a:
            raise InputDataError(
                f"{self.source}: invalid time slice [{t_start_s}, {t_end_s}) s "
                "(need finite t_start_s <= t_end_s)"
            )
        start, end = self.index_at(a), self.index_at(b)
        meta = dict(self.metadata)
        meta["sliced_from"] = [a, b]
        out = Recording(self.sample_rate_hz, self.t0_s + start / self.sample_rate_hz, meta)
        for name, arr in self._channels.items():
            info = self._info[name]
            out._insert_channel(name, arr[start:end], info.unit, info.description)
        for stream in self._streams.values():
            out._insert_stream(stream.slice_time(a, b))
        return out

    def __repr__(self) -> str:
        return (
            f"Recording({self.source!r}, fs={self.sample_rate_hz:g} Hz, "
            f"n_samples={self.n_samples}, channels={len(self._channels)}, "
            f"streams={len(self._streams)})"
        )
