"""A recording's channels in another format, with the map that imports it back.

``millsense export`` writes the channels (streams are not exported) as

* ``csv`` / ``tsv``: a time column ``time`` (s), the channel names as column names, a units
  row, 17 significant digits (exact);
* ``mat`` (v5, scipy) / ``mat73`` (HDF5): one double vector per channel (``/`` → ``_``), ``fs``;
* ``tdms``: group ``millsense``, ``wf_increment`` and ``unit_string`` per channel;
* ``wav`` (64-bit float), ``flac`` (24-bit) and ``mp3``: channels scaled to full scale, the
  scale in the map;
* ``parquet``: float64 columns with their unit, and the rate, in the schema.

The map (TOML text returned by :func:`export_recording`) names each written column with its
channel, SI unit and scale, so ``millsense import FILE --map MAP`` gives the recording back
within the format's precision (exact for csv/tsv/mat/mat73/tdms/wav/parquet, 2⁻²³ of full
scale for FLAC, lossy for MP3).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import Recording

__all__ = ["EXPORT_FORMATS", "export_recording", "map_text"]

EXPORT_FORMATS = {
    "csv": ".csv",
    "tsv": ".tsv",
    "mat": ".mat",
    "mat73": ".mat",
    "tdms": ".tdms",
    "wav": ".wav",
    "flac": ".flac",
    "mp3": ".mp3",
    "parquet": ".parquet",
}


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    return json.dumps(str(v))


def map_text(
    entries: Sequence[tuple[str, str, str, float]],
    *,
    rate_hz: float | None = None,
    time_column: str | None = None,
    metadata: dict[str, object] | None = None,
    match: str = "*",
) -> str:
    """A map file: entries are (column, channel, unit, scale)."""
    lines = ["# written by millsense export: the map that imports the file back", ""]
    if metadata:
        lines.append("[metadata]")
        lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in metadata.items()]
        lines.append("")
    lines += ["[[files]]", f"match = {json.dumps(match)}"]
    if rate_hz is not None:
        lines.append(f"sample_rate_hz = {rate_hz!r}")
    if time_column is not None:
        lines += [f"time_column = {json.dumps(time_column)}", 'time_unit = "s"']
    lines.append("")
    for col, ch, unit, scale in entries:
        lines += [
            "[[channels]]",
            f"column = {json.dumps(col)}",
            f"channel = {json.dumps(ch)}",
            f"unit = {json.dumps(unit)}",
        ]
        if scale != 1.0:
            lines.append(f"scale = {scale!r}")
        lines.append("")
    return "\n".join(lines)


_META_KEYS = ("machine", "tool", "material", "flutes", "spindle_rpm", "feed_mm_min", "program")


def export_recording(
    rec: Recording,
    path: Path,
    fmt: str,
    channels: Sequence[str] | None = None,
    name: str | None = None,
) -> str:
    """Write the channels of ``rec`` to ``path`` in ``fmt``; return the map that reads it back.

    ``path`` is written as given (pass a temporary sibling for an atomic write and the final
    file name as ``name``, which the map's ``match`` names).

    Raises
    ------
    ConfigError
        Unknown format or channel.
    """
    if fmt not in EXPORT_FORMATS:
        raise ConfigError(f"--format {fmt!r}: one of {', '.join(EXPORT_FORMATS)}")
    # a channel asked for twice is written (and mapped) once: the map must import it back
    names = list(dict.fromkeys(channels)) if channels else rec.channel_names
    for c in names:
        if c not in rec:
            sname = c.rpartition("/")[0]
            if c in rec.stream_names or sname in rec.stream_names:
                raise ConfigError(
                    f"--channel {c!r}: a stream of {rec.source}; streams are not exported "
                    f"(only channels: {', '.join(rec.channel_names[:8])}...)"
                )
            raise ConfigError(f"--channel {c!r}: not in {rec.source}")
    cols = {c: np.asarray(rec.channel(c), dtype=np.float64) for c in names}
    units = {c: rec.info(c).unit for c in names}
    fs = rec.sample_rate_hz
    meta = {
        k: rec.metadata[k] for k in _META_KEYS if isinstance(rec.metadata.get(k), str | int | float)
    }
    match = name or path.name
    scale = dict.fromkeys(names, 1.0)
    colname = {c: c for c in names}
    time_column = None
    rate: float | None = fs
    if fmt in ("csv", "tsv"):
        from millsense.io.importers.delimited import write_delimited

        t = rec.t0_s + np.arange(rec.n_samples) / fs
        write_delimited(
            path,
            {"time": t, **cols},
            {"time": "s", **units},
            "," if fmt == "csv" else "\t",
            header={"exported by": "millsense export", "sample rate": f"{fs:.17g} Hz"},
        )
        time_column, rate = "time", None
    elif fmt == "mat":
        from millsense.io.importers.matlab import write_mat

        colname = write_mat(path, cols, units, fs)
    elif fmt == "mat73":
        from millsense.io.importers.matlab import write_mat73

        colname = write_mat73(path, cols, units, fs)
    elif fmt == "tdms":
        from millsense.io.importers.tdms import write_tdms

        colname = write_tdms(path, cols, units, fs)
    elif fmt in ("wav", "flac", "mp3"):
        from millsense.io.importers.audio import write_audio

        scale = write_audio(path, cols, fs)
        colname = {c: str(k) for k, c in enumerate(names)}
    else:
        from millsense.io.importers.parquet import write_parquet

        write_parquet(path, cols, units, fs)
    entries = [(colname[c], c, units[c], scale[c]) for c in names]
    return map_text(entries, rate_hz=rate, time_column=time_column, metadata=meta, match=match)
