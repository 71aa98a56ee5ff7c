"""The map file of ``millsense import``: which column of which file is which millsense channel.

A TOML file (pydantic model, one-line errors naming the file and key, like
:mod:`millsense.core.config`)::

    [metadata]                 # free keys copied into the recording's metadata
    machine = "quaser-ux600"
    spindle_rpm = 3000         # field units in key names, also stored converted
    feed_mm_min = 1200
    flutes = 2

    [[files]]                  # optional: how to read files whose name matches ``match``
    match = "trace*.csv"       # glob on the file name (default "*": every file)
    sample_rate_hz = 10000     # stated rate when the file has no time column (or a header)
    time_column = "Time"       # a time column (its unit: time_unit) instead of a stated rate
                               # ("": none, although one is named like one: the rate is stated)
    time_unit = "ms"           # default: the file's (units row, "Time [ms]"), else s
    delimiter = ";"            # csv/tsv: default sniffed among , ; tab
    decimal = ","              # csv/tsv: decimal comma (Siemens exports in German locale)

    [[channels]]
    column = "I_x"             # column / variable / TDMS "group/channel" / audio "0", "1"...
    channel = "x/current_cmd"  # millsense channel name (as the simulator names it)
    unit = "A"                 # the file's unit; converted to SI (see UNITS)
    scale = 1.0                # optional: value = (raw * scale + offset) in ``unit``
    offset = 0.0
    file = "trace*.csv"        # optional glob: which file holds the column

``unit = "header"`` takes the unit from the file's unit row (Servo Trace / TNCscope exports), a
bracket in the name (``I_x [A]``) or a known unit after the name's last underscore (``x_current_A``,
``time_ms``: also a time column).
Counts (encoder positions): give the unit one count is expressed in and the count size as
``scale`` (``unit = "um"``, ``scale = 0.5`` for 0.5 µm per count).
"""

from __future__ import annotations

import fnmatch
import math
import re
from pathlib import Path
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from millsense.core import units as u
from millsense.core.config import parse_config, read_toml
from millsense.core.errors import ConfigError
from millsense.core.recording import check_name

__all__ = [
    "CHANNEL_SI",
    "UNITS",
    "ChannelMap",
    "FileOptions",
    "ImportMap",
    "check_channel_unit",
    "load_map",
    "si_factor",
    "si_zero",
    "time_factor",
]

#: Field unit → (SI unit, factor to SI). Spellings of one unit are listed separately; a unit
#: string is matched after removing spaces and brackets (``[mm]`` → ``mm``).
UNITS: dict[str, tuple[str, float]] = {
    "A": ("A", 1.0),
    "mA": ("A", 1e-3),
    "kA": ("A", 1e3),
    "V": ("V", 1.0),
    "mV": ("V", 1e-3),
    "m": ("m", 1.0),
    "mm": ("m", u.MM),
    "um": ("m", u.UM),
    "µm": ("m", u.UM),
    "μm": ("m", u.UM),
    "nm": ("m", 1e-9),
    "in": ("m", 0.0254),
    "rad": ("rad", 1.0),
    "deg": ("rad", u.DEG),
    "°": ("rad", u.DEG),
    "rev": ("rad", 2.0 * math.pi),
    "rad/s": ("rad/s", 1.0),
    "deg/s": ("rad/s", u.DEG),
    "rev/min": ("rad/s", u.RPM),
    "rpm": ("rad/s", u.RPM),
    "1/min": ("rad/s", u.RPM),
    "m/s": ("m/s", 1.0),
    "mm/s": ("m/s", u.MM),
    "mm/min": ("m/s", u.MM_PER_MIN),
    "m/min": ("m/s", 1.0 / 60.0),
    "N": ("N", 1.0),
    "kN": ("N", 1e3),
    "N*m": ("N*m", 1.0),
    "Nm": ("N*m", 1.0),
    "N·m": ("N*m", 1.0),
    "m/s^2": ("m/s^2", 1.0),
    "m/s²": ("m/s^2", 1.0),
    "g": ("m/s^2", 9.80665),
    "Pa": ("Pa", 1.0),
    "W": ("W", 1.0),
    "kW": ("W", 1e3),
    "s": ("s", 1.0),
    "ms": ("s", 1e-3),
    "us": ("s", 1e-6),
    "µs": ("s", 1e-6),
    "1": ("1", 1.0),
    "%": ("1", u.PERCENT),
    # temperatures (a drive's motor or a spindle's bearing, as CNC traces hold them): kelvin
    # inside; Celsius and Fahrenheit are affine, their zero in UNIT_ZERO_K
    "K": ("K", 1.0),
    "degC": ("K", 1.0),
    "°C": ("K", 1.0),
    "℃": ("K", 1.0),
    "degF": ("K", 5.0 / 9.0),
    "°F": ("K", 5.0 / 9.0),
    "℉": ("K", 5.0 / 9.0),
}

#: Field units whose zero is not SI's: value_SI = value · factor + UNIT_ZERO_K[unit] (Celsius:
#: 0 °C = 273.15 K; Fahrenheit: 0 °F = 459.67 · 5/9 K = 255.372 K). Every other unit: 0.
UNIT_ZERO_K: dict[str, float] = {
    "degC": 273.15,
    "°C": 273.15,
    "℃": 273.15,
    "degF": 459.67 * 5.0 / 9.0,
    "°F": 459.67 * 5.0 / 9.0,
    "℉": 459.67 * 5.0 / 9.0,
}


#: SI unit(s) of the channels every command reads by name, by the last part of the name (the
#: simulator's names: ``x/current_cmd``, ``spindle/speed``, ``dynamometer/y/force``...);
#: other names (``mic/pressure``, ``acc/x``...) take any unit (decision 1668).
CHANNEL_SI: dict[str, tuple[str, ...]] = {
    "current": ("A",),
    "current_cmd": ("A",),
    "motor_angle": ("rad",),
    "angle": ("rad",),
    "motor_speed": ("rad/s",),
    "position_cmd": ("m", "rad"),
    "speed": ("rad/s",),
    "speed_cmd": ("rad/s",),
    "force": ("N",),
    "torque": ("N*m",),
    "feed": ("m/s",),
    "feed_override": ("1",),
    "spindle_override": ("1",),
    "nc_line": ("1",),
    "temperature": ("K",),
}


def check_channel_unit(channel: str, unit: str, si: str, where: str) -> None:
    """A ConfigError (one line) when ``unit`` (SI ``si``) is not a unit of the quantity
    ``channel`` holds (:data:`CHANNEL_SI`): a current mapped in mm would be read as amperes."""
    want = CHANNEL_SI.get(channel.rpartition("/")[2])
    if want is not None and si not in want:
        raise ConfigError(
            f"{where}: unit {unit!r} is {si}, but channel '{channel}' holds "
            f"{' or '.join(want)}: give the column's unit (scale/offset to convert)"
        )


def _clean_unit(text: str) -> str:
    return re.sub(r"[\s\[\]()]", "", text)


def si_factor(unit: str, where: str) -> tuple[str, float]:
    """(SI unit, factor) of a field unit; an unknown unit is a one-line ConfigError."""
    key = _clean_unit(unit)
    if key in UNITS:
        return UNITS[key]
    if key.lower() in ("counts", "count", "inc", "incr"):
        raise ConfigError(
            f"{where}: unit '{unit}': give the unit one count is in and the count size as "
            "'scale' (e.g. unit = \"um\", scale = 0.5)"
        )
    raise ConfigError(f"{where}: unknown unit '{unit}' (known: {', '.join(UNITS)})")


def si_zero(unit: str) -> float:
    """The SI value of ``unit``'s zero (:data:`UNIT_ZERO_K`; 0 for a unit that is a pure
    factor of SI's). Call after :func:`si_factor` has accepted the unit."""
    return UNIT_ZERO_K.get(_clean_unit(unit), 0.0)


def time_factor(unit: str, where: str) -> float:
    """Seconds per ``unit`` of a time column; a unit of another quantity (a column of mm or
    amperes is no clock) is a one-line ConfigError."""
    si, factor = si_factor(unit, where)
    if si != "s":
        raise ConfigError(f"{where}: unit {unit!r} is not a time unit (s, ms, us)")
    return factor


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class FileOptions(_Model):
    """How to read the files whose name matches ``match``."""

    match: str = "*"
    sample_rate_hz: Annotated[float, Field(gt=0, le=10e6)] | None = None
    time_column: str | None = None
    time_unit: str | None = None
    """Unit of the time column; None: the file's (units row or name), else seconds."""
    delimiter: str | None = None
    decimal: str = "."
    sheet: str | None = None
    """TDMS group or .mat struct holding the columns (default: all)."""

    @model_validator(mode="after")
    def _options(self) -> FileOptions:
        if self.delimiter is not None and self.delimiter not in (",", ";", "\t", " ", "|"):
            raise ValueError(f"delimiter {self.delimiter!r}: one of ',', ';', '\\t', ' ', '|'")
        if self.decimal not in (".", ","):
            raise ValueError(f"decimal {self.decimal!r}: '.' or ','")
        if self.decimal == "," and self.delimiter == ",":
            raise ValueError("decimal ',' needs another delimiter (';' or tab)")
        return self


class ChannelMap(_Model):
    """One column of a file → one millsense channel."""

    column: str
    channel: str
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    description: str = ""
    file: str | None = None

    @model_validator(mode="after")
    def _finite(self) -> ChannelMap:
        if not (math.isfinite(self.scale) and math.isfinite(self.offset)) or self.scale == 0:
            raise ValueError("scale must be finite and non-zero, offset finite")
        return self


class ImportMap(_Model):
    """The whole map file."""

    metadata: dict[str, Any] = Field(default_factory=dict)
    files: list[FileOptions] = Field(default_factory=list)
    channels: list[ChannelMap] = Field(min_length=1)

    def options_for(self, path: Path) -> FileOptions:
        """The first ``[[files]]`` entry matching ``path``'s name, else the defaults."""
        for opt in self.files:
            if fnmatch.fnmatch(path.name, opt.match):
                return opt
        return FileOptions()


def load_map(path: str | Path) -> ImportMap:
    """Read and check a map file.

    Raises
    ------
    ConfigError
        One line naming the file and key: a malformed key, a channel named twice, a malformed
        channel name, an unknown unit.
    """
    source = str(path)
    m = parse_config(ImportMap, read_toml(path), source)
    seen: dict[str, int] = {}
    for i, ch in enumerate(m.channels):
        where = f"{source}: channels[{i}] ({ch.column!r})"
        try:
            check_name(ch.channel)
        except Exception as exc:  # InputDataError: rephrase with the map's position
            raise ConfigError(f"{where}: {exc}") from None
        if ch.channel in seen:
            raise ConfigError(
                f"{source}: channel '{ch.channel}' is named twice "
                f"(channels[{seen[ch.channel]}] and channels[{i}])"
            )
        seen[ch.channel] = i
        if ch.unit != "header":
            si, _ = si_factor(ch.unit, where)
            check_channel_unit(ch.channel, ch.unit, si, where)
    for i, f in enumerate(m.files):
        if f.time_unit is not None:
            time_factor(f.time_unit, f"{source}: files[{i}].time_unit")
    return m
