"""The event log (issue 15, item 5): one Parquet row per event, read back unchanged, readable
with pandas; bad files named."""

from __future__ import annotations

import math

import pytest

from millsense.core.errors import ConfigError
from millsense.streaming import Event, EventKind, Severity, read_event_log, write_event_log
from millsense.streaming.event_log import default_event_log_path, event_log_recording


def _events() -> list[Event]:
    return [
        Event(
            1.25,
            EventKind.ALARM,
            "chatter.comb",
            "chatter at 938 Hz",
            name="chatter",
            value=938.0,
            sample=12500,
            severity=Severity.WARNING,
            values={"energy_ratio": 2.4, "tooth_passing_hz": 400.0},
            nc_line=17,
            x_mm=12.5,
            y_mm=-3.0,
            z_mm=-2.0,
        ),
        Event(0.5, EventKind.NOTE, "plan", "segment entered", name="segment"),
        Event(
            2.0,
            EventKind.OVERRIDE,
            "afc",
            "feed hold",
            name="feed_hold",
            value=0.0,
            severity=Severity.CRITICAL,
            values={"nan_value": math.nan},
        ),
    ]


def test_round_trip_sorted_by_time(tmp_path):
    p = write_event_log(tmp_path / "run.events.parquet", _events())
    back = read_event_log(p)
    assert [e.time_s for e in back] == [0.5, 1.25, 2.0]  # sorted by time on writing
    chatter = back[1]
    assert chatter == Event(**{**_events()[0].__dict__})
    assert back[0].nc_line is None and back[0].x_mm is None and back[0].sample == -1
    assert back[2].severity is Severity.CRITICAL
    assert math.isnan(back[2].values["nan_value"])  # non-finite numbers stored as null


def test_plain_parquet_columns(tmp_path):
    """Any Parquet reader (pandas, duckdb, pyarrow) sees plain typed columns."""
    import pyarrow.parquet as pq

    p = write_event_log(tmp_path / "e.parquet", _events())
    t = pq.read_table(p).to_pydict()
    assert t["name"] == ["segment", "chatter", "feed_hold"]
    assert t["value"][1] == 938.0
    assert t["nc_line"] == [None, 17, None]
    assert pq.read_schema(p).metadata[b"millsense_event_log_schema_version"] == b"1"


def test_default_path_beside_recording(tmp_path):
    assert default_event_log_path(tmp_path / "run.h5") == tmp_path / "run.events.parquet"


def test_not_an_event_log_is_named(tmp_path):
    bad = tmp_path / "bad.parquet"
    bad.write_text("not parquet")
    with pytest.raises(ConfigError, match=r"bad\.parquet"):
        read_event_log(bad)


def test_the_log_names_its_recording(tmp_path):
    """A log says which recording it describes (its file name), also once moved away from it;
    a log written without one says nothing (None)."""
    p = write_event_log(tmp_path / "x.parquet", _events(), recording=tmp_path / "sub" / "run7.h5")
    assert event_log_recording(p) == "run7.h5"
    assert event_log_recording(write_event_log(tmp_path / "y.parquet", _events())) is None
    assert len(read_event_log(p)) == 3


def test_pandas_reads_nc_line_as_a_nullable_integer(tmp_path):
    """pandas' metadata in the file names ``nc_line`` a nullable ``Int64`` column, so that
    ``pd.read_parquet`` gives line 17 and <NA>, not 17.0 and NaN (its default for an integer
    column with nulls). pandas is not a dependency: the key is checked here as pyarrow's
    ``to_pandas`` reads it (its ``columns[].numpy_type``, an extension dtype name), and was
    checked with pandas 3.1.1 / pyarrow 26 by hand (dtypes Int64, the index a RangeIndex)."""
    import json

    import pyarrow.parquet as pq

    p = write_event_log(tmp_path / "e.parquet", _events())
    meta = json.loads(pq.read_schema(p).metadata[b"pandas"])
    assert meta["index_columns"] == []
    (col,) = meta["columns"]
    assert (col["name"], col["field_name"], col["numpy_type"]) == ("nc_line", "nc_line", "Int64")
    assert str(pq.read_schema(p).field("nc_line").type) == "int64"
