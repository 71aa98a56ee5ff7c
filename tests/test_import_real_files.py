"""Recordings as users bring them (QA of the "real data in" path): column names carrying their
unit after an underscore (``x_current_A``, ``time_ms``), missing values, constant channels,
a second file at another rate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.io.importers import import_files, load_map

MAP = """[[channels]]
column = "x_current_A"
channel = "x/current_cmd"
unit = "header"

[[channels]]
column = "spindle_speed_rpm"
channel = "spindle/speed"
unit = "header"
"""


def _write(tmp_path: Path, name: str, text: str, mapping: str = MAP) -> tuple[Path, Path]:
    (tmp_path / name).write_text(text)
    (tmp_path / "m.toml").write_text(mapping)
    return tmp_path / name, tmp_path / "m.toml"


@pytest.mark.parametrize(("tname", "factor"), [("time_ms", 1e-3), ("t_us", 1e-6), ("Zeit_s", 1.0)])
def test_time_and_units_after_an_underscore_in_the_column_names(
    tmp_path: Path, tname: str, factor: float
) -> None:
    """``time_ms`` was not taken for the time column ("no time column and no sample rate"),
    and ``unit = "header"`` found no unit in ``x_current_A``: the part after the last
    underscore is the column's unit when it is a known one. 200 rows 0.2 ms apart are
    5000 Hz (1e-9), rev/min converted to rad/s (3000 rev/min = 314.159 rad/s, 1e-12)."""
    step = 0.2e-3 / factor
    rows = "".join(f"{k * step:.6g},{np.sin(k / 10):.6f},3000\n" for k in range(200))
    csv, m = _write(tmp_path, "a.csv", f"{tname},x_current_A,spindle_speed_rpm\n" + rows)
    res = import_files([csv], load_map(m))
    rec = res.recording
    assert rec.sample_rate_hz == pytest.approx(5000.0, rel=1e-9)
    assert rec.info("x/current_cmd").unit == "A"
    assert rec.channel("spindle/speed")[0] == pytest.approx(3000 * 2 * np.pi / 60, rel=1e-12)


def test_a_name_ending_in_no_unit_still_asks_for_one(tmp_path: Path) -> None:
    """``coolant_on`` ends in no unit: ``unit = "header"`` is still refused naming the column
    (the suffix is a unit only when it is one of the map's units)."""
    from millsense.core.errors import InputDataError

    rows = "".join(f"{k * 0.2:.1f},1\n" for k in range(20))
    mapping = '[[channels]]\ncolumn = "coolant_on"\nchannel = "cnc/coolant"\nunit = "header"\n'
    csv, m = _write(tmp_path, "a.csv", "time_ms,coolant_on\n" + rows, mapping)
    with pytest.raises(InputDataError, match="column 'coolant_on' has no unit in the file"):
        import_files([csv], load_map(m))
