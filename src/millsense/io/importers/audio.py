"""Sound files through libsndfile (``soundfile``): WAV, FLAC, and MP3 where the installed
libsndfile reads it (1.1 and later). Columns are the channels ``"0"``, ``"1"``...; the file's
rate is the stated rate. Samples are read as float64 (integer PCM scaled to ±1, as every
audio tool does): the map's ``scale`` turns them into pascals or volts."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import InputDataError
from millsense.io.importers.table import RawTable

__all__ = ["AUDIO_SUFFIXES", "read_audio", "write_audio"]

AUDIO_SUFFIXES = (".wav", ".flac", ".mp3", ".ogg")
#: The sampling rates of MPEG-1, -2 and -2.5 audio (ISO/IEC 11172-3, 13818-3), the only ones
#: an MP3 file can hold [Hz].
MP3_RATES_HZ = (8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000)


def _module(path: Path) -> Any:
    """The optional reader package, or a one-line error saying how to install it."""
    import importlib

    try:
        return importlib.import_module("soundfile")
    except ImportError:
        raise InputDataError(
            f"{path}: reading or writing {path.suffix} needs the soundfile package: "
            "pip install 'millsense[import]'"
        ) from None


def read_audio(path: Path) -> RawTable:
    """Read every channel of a sound file.

    Raises
    ------
    InputDataError
        libsndfile cannot read the file (not audio, or a format this build lacks).
    """
    sf = _module(path)

    try:
        data, rate = sf.read(str(path), dtype="float64", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, TypeError) as exc:
        raise InputDataError(f"{path}: not a sound file libsndfile reads: {exc}") from None
    columns = {str(k): np.ascontiguousarray(data[:, k]) for k in range(data.shape[1])}
    return RawTable(path=path, columns=columns, stated_rate_hz=float(rate))


def write_audio(path: Path, columns: Mapping[str, np.ndarray], rate_hz: float) -> dict[str, float]:
    """Write the columns as channels of a sound file, each scaled to its peak (±1 full
    scale, 24-bit FLAC, 64-bit float WAV). Returns column → scale (the value of full scale),
    which the exported map gives back as ``scale``."""
    sf = _module(path)

    rate = round(rate_hz)
    if abs(rate - rate_hz) > 1e-9 * rate_hz:
        raise InputDataError(f"{path}: sound files need an integer rate, got {rate_hz} Hz")
    if path.suffix.lower() == ".mp3" and rate not in MP3_RATES_HZ:
        raise InputDataError(
            f"{path}: MP3 holds only the MPEG rates {', '.join(map(str, MP3_RATES_HZ))} Hz, "
            f"the recording is at {rate_hz:g} Hz: export wav or flac (any integer rate)"
        )
    limit = {".flac": 8, ".mp3": 2}.get(path.suffix.lower())
    if limit is not None and len(columns) > limit:
        raise InputDataError(
            f"{path}: {path.suffix.lstrip('.').upper()} holds at most {limit} channels, "
            f"{len(columns)} given (choose them with --channel)"
        )
    scales: dict[str, float] = {}
    cols = []
    for c, v in columns.items():
        x = np.asarray(v, dtype=np.float64)
        peak = float(np.max(np.abs(x))) if x.size else 0.0
        scales[c] = peak if peak > 0 else 1.0
        cols.append(x / scales[c])
    data = np.column_stack(cols)
    try:
        if path.suffix.lower() == ".flac":
            sf.write(str(path), np.clip(data, -1.0, 1.0 - 2.0**-23), rate, subtype="PCM_24")
        elif path.suffix.lower() == ".mp3":
            sf.write(str(path), data, rate, format="MP3", subtype="MPEG_LAYER_III")
        else:
            sf.write(str(path), data, rate, subtype="DOUBLE")
    except (sf.LibsndfileError, RuntimeError, TypeError, ValueError) as exc:
        # libsndfile's own limits (FLAC at most 655 350 Hz...): its message, without the
        # "Error opening '<path>':" prefix that repeats the file
        why = str(exc).split("Error : ", 1)[-1]
        raise InputDataError(f"{path}: libsndfile cannot write it: {why}") from None
    return scales
