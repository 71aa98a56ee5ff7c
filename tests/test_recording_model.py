"""In-memory recording model: channels, streams, slicing, truth separation, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millsense.core.errors import InputDataError, RecordingError
from millsense.core.recording import ChannelInfo, Recording


def _rec() -> Recording:
    rec = Recording(1000.0, t0_s=2.0, metadata={"source": "demo.h5", "machine": "m1"})
    k = np.arange(50)
    rec.add_channel("x/current_cmd", np.sin(0.1 * k), "A", "q-axis current command")
    rec.add_channel("spindle/speed", np.full(50, 314.0), "rad/s")
    rec.add_channel("truth/x/force", k * 2.0, "N", "simulated cutting force")
    rec.add_stream(
        "tcp", [2.0, 2.003, 2.006, 2.04], {"x": [0.0, 1e-3, 2e-3, 3e-3]}, {"x": "m"}, {"x": "pos"}
    )
    return rec


def test_basic_properties() -> None:
    rec = _rec()
    # 50 samples at 1 kHz: duration N/fs = 0.05 s; sample k at t0 + k/fs.
    assert rec.n_samples == 50
    assert rec.duration_s == pytest.approx(0.05, abs=1e-15)
    assert rec.time_s[10] == pytest.approx(2.0 + 10 / 1000.0, abs=1e-12)
    assert rec.channel_names == ["x/current_cmd", "spindle/speed", "truth/x/force"]
    assert rec.info("x/current_cmd") == ChannelInfo("x/current_cmd", "A", "q-axis current command")
    assert rec["truth/x/force"][3] == 6.0  # k * 2 at k = 3, exact in float64
    assert "spindle/speed" in rec and "nope" not in rec
    assert len(rec.stream("tcp")) == 4
    assert rec.stream("tcp").info["x"].unit == "m"


def test_truth_separated_from_measured() -> None:
    rec = _rec()
    # Estimators read measured channels only (ARCHITECTURE rule 2).
    assert rec.measured_channel_names() == ["x/current_cmd", "spindle/speed"]
    assert rec.truth_channel_names() == ["truth/x/force"]


def test_channels_are_read_only_copies() -> None:
    data = np.zeros(5)
    rec = Recording(10.0)
    rec.add_channel("a", data, "1")
    data[0] = 7.0  # the caller's later change must not alter the record
    assert rec["a"][0] == 0.0
    with pytest.raises(ValueError):
        rec["a"][0] = 1.0


def test_list_input_is_float64_and_bool_is_uint8() -> None:
    rec = Recording(10.0)
    rec.add_channel("a", [1, 2, 3], "1")
    rec.add_channel("flag", np.array([True, False, True]), "1")
    assert rec["a"].dtype == np.float64  # lists never become int (no silent truncation later)
    assert rec["flag"].dtype == np.uint8 and rec["flag"].tolist() == [1, 0, 1]


def test_unknown_channel_message_lists_available() -> None:
    rec = _rec()
    with pytest.raises(RecordingError) as err:
        rec.channel("foo")
    msg = str(err.value)
    assert msg == (
        "demo.h5: unknown channel 'foo'; available: x/current_cmd, spindle/speed, truth/x/force"
    )
    with pytest.raises(RecordingError, match="recording: unknown channel 'b'"):
        Recording(10.0)["b"]  # no source -> "recording"
    with pytest.raises(RecordingError, match="unknown stream 'nc'"):
        rec.stream("nc")


def test_length_mismatch_names_channel() -> None:
    rec = _rec()
    with pytest.raises(InputDataError, match="channel 'y/current_cmd' has 49 samples") as err:
        rec.add_channel("y/current_cmd", np.zeros(49), "A")
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("name", "data", "pattern"),
    [
        ("x/current_cmd", np.zeros(50), "already exists"),
        ("x", np.zeros(50), "collides with channel 'x/current_cmd'"),
        ("x/current_cmd/hi", np.zeros(50), "collides"),
        ("/abs", np.zeros(50), "malformed"),
        ("a//b", np.zeros(50), "malformed"),
        ("a/../b", np.zeros(50), "malformed"),
        ("m", np.zeros((50, 2)), "expected a 1-D array"),
        ("s", np.array(["a"] * 50), "expected numbers"),
        ("a\x00b", np.zeros(50), "malformed"),
        ("a\ud800", np.zeros(50), "malformed"),
    ],
)
def test_bad_channels(name: str, data: np.ndarray, pattern: str) -> None:
    rec = _rec()
    with pytest.raises(InputDataError, match=pattern) as err:
        rec.add_channel(name, data, "1")
    assert "\n" not in str(err.value)


def test_nul_in_unit_or_description_refused() -> None:
    # HDF5 variable-length strings cannot hold NUL: refused at the door, not at write time.
    rec = Recording(10.0)
    with pytest.raises(InputDataError, match="channel 'a': description contains a NUL"):
        rec.add_channel("a", [1.0], "A", "x\x00y")
    with pytest.raises(InputDataError, match="field 'f': unit contains a NUL"):
        rec.add_stream("s", [0.0], {"f": [1.0]}, {"f": "m\x00"})


def test_bad_streams() -> None:
    rec = Recording(10.0)
    with pytest.raises(InputDataError, match="field 'y' has no unit"):
        rec.add_stream("s", [0.0, 1.0], {"y": [1, 2]}, {})
    with pytest.raises(InputDataError, match="field 'y' has 3 rows, time_s has 2"):
        rec.add_stream("s", [0.0, 1.0], {"y": [1, 2, 3]}, {"y": "m"})
    with pytest.raises(InputDataError, match="time_s decreases at row 2"):
        rec.add_stream("s", [0.0, 1.0, 0.5], {"y": [1, 2, 3]}, {"y": "m"})


def test_require_finite_names_channel_sample_and_time() -> None:
    rec = Recording(10000.0, metadata={"source": "run7.h5"})
    x = np.zeros(2000)
    x[1234] = np.nan
    rec.add_channel("x/current_cmd", x, "A")
    rec.add_channel("ok", np.ones(2000), "A")
    rec.require_finite(["ok"])  # finite: no error
    with pytest.raises(InputDataError) as err:
        rec.require_finite(["ok", "x/current_cmd"])
    # sample 1234 at 10 kHz is t = 0.1234 s
    assert (
        str(err.value)
        == "run7.h5: channel 'x/current_cmd' has NaN/inf at sample 1234 (t = 0.1234 s)"
    )
    x2 = np.zeros(2000)
    x2[5] = -np.inf
    rec.add_channel("y", x2, "A")
    with pytest.raises(InputDataError, match="'y' has NaN/inf at sample 5"):
        rec.require_finite(["y"])


def test_slice_time_channels_streams_metadata() -> None:
    rec = _rec()
    part = rec.slice_time(2.003, 2.010)
    # samples with 2.003 <= t < 2.010: k = 3..9 (sample exactly at 2.003 included)
    assert part.n_samples == 7
    assert part.t0_s == pytest.approx(2.003, abs=1e-12)
    np.testing.assert_array_equal(part["truth/x/force"], np.arange(3, 10) * 2.0)
    assert part.stream("tcp").time_s.tolist() == [2.003, 2.006]
    assert part.metadata["sliced_from"] == [2.003, 2.010]
    assert part.metadata["machine"] == "m1"
    assert "sliced_from" not in rec.metadata
    # outside the recording: clipped, empty
    assert rec.slice_time(10.0, 11.0).n_samples == 0
    with pytest.raises(InputDataError, match="invalid time slice"):
        rec.slice_time(2.01, 2.0)


def test_metadata_must_be_json() -> None:
    meta = {"n": np.int64(3), "arr": np.arange(2), "f": np.float32(0.5)}
    rec = Recording(1.0, metadata=meta)
    assert rec.metadata == {"n": 3, "arr": [0, 1], "f": 0.5}  # numpy values made plain
    with pytest.raises(InputDataError, match="metadata key 'bad'"):
        Recording(1.0, metadata={"bad": object()})
    with pytest.raises(InputDataError, match="sample_rate_hz"):
        Recording(0.0)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 300),
    fs=st.sampled_from([1.0, 333.0, 1000.0, 10000.0]),
    t0=st.floats(-5, 5, allow_nan=False),
    i=st.integers(0, 300),
    j=st.integers(0, 300),
)
def test_slice_matches_numpy_slicing(n: int, fs: float, t0: float, i: int, j: int) -> None:
    data = np.random.default_rng(n).standard_normal(n)
    rec = Recording(fs, t0_s=t0)
    rec.add_channel("a", data, "1")
    i, j = sorted((min(i, n), min(j, n)))
    t = t0 + np.arange(n + 1) / fs
    part = rec.slice_time(t[i], t[j])  # times of samples i and j: expect data[i:j]
    np.testing.assert_array_equal(part["a"], data[i:j])
    assert part.t0_s == pytest.approx(t0 + i / fs, abs=1e-9)
    # A boundary strictly between samples selects the same as a numpy time mask.
    a, b = t[i] + 0.5 / fs, t[j] + 0.5 / fs
    mask = (rec.time_s >= a) & (rec.time_s < b)
    np.testing.assert_array_equal(rec.slice_time(a, b)["a"], data[mask])
