"""Recording files: round trip, HDF5 layout readable by stock readers, writer, bad input."""

from __future__ import annotations

import json
import mmap
import tempfile
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from millsense.core.errors import InputDataError, RecordingError
from millsense.core.recording import ChannelInfo, Recording
from millsense.io import (
    RecordingWriter,
    hdf5_chunks,
    read_recording,
    recording_status,
    write_recording,
)
from millsense.io.recording_file import partial_dir

META = {"machine": "dmu", "tool": "T3", "created": "2026-01-01T00:00:00+00:00"}


def _sample_recording(n: int = 1000, fs: float = 1000.0) -> Recording:
    rng = np.random.default_rng(4)
    rec = Recording(fs, t0_s=0.5, metadata={**META, "source": "sim", "nested": {"a": [1, 2]}})
    rec.add_channel("x/current_cmd", rng.standard_normal(n), "A", "current command")
    rec.add_channel("spindle/speed", np.full(n, 314.159), "rad/s")
    rec.add_channel("truth/x/force", rng.standard_normal(n) * 100, "N", "true force")
    rec.add_channel("count", np.arange(n, dtype=np.int32), "1")
    rec.add_stream(
        "tcp",
        np.arange(n // 3) * 0.003 + 0.5,
        {"x": rng.standard_normal(n // 3), "line": np.arange(n // 3, dtype=np.int64)},
        {"x": "m", "line": "1"},
        {"x": "tool-centre point"},
    )
    return rec


def _assert_same(a: Recording, b: Recording) -> None:
    assert a.sample_rate_hz == b.sample_rate_hz and a.t0_s == b.t0_s
    assert a.channel_names == b.channel_names
    for name in a.channel_names:
        assert a.info(name) == b.info(name)
        assert a[name].dtype == b[name].dtype
        np.testing.assert_array_equal(a[name], b[name])  # lossless: exact equality
    assert a.stream_names == b.stream_names
    for s in a.stream_names:
        sa, sb = a.stream(s), b.stream(s)
        np.testing.assert_array_equal(sa.time_s, sb.time_s)
        assert sa.info == sb.info
        for f in sa.fields:
            np.testing.assert_array_equal(sa.fields[f], sb.fields[f])


def test_round_trip_and_hdf5_layout(tmp_path: Path) -> None:
    rec = _sample_recording()
    path = tmp_path / "run.h5"
    write_recording(path, rec)
    back = read_recording(path)
    _assert_same(rec, back)
    # source names the file in error messages; the stored one is kept
    assert back.metadata["source"] == str(path)
    assert back.metadata["original_source"] == "sim"
    assert back.metadata["nested"] == {"a": [1, 2]}
    assert back.metadata["software_version"] == "0.1.0"

    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "millsense-recording"
        assert f.attrs["format_version"] == 1
        assert f.attrs["sample_rate_hz"] == 1000.0 and f.attrs["t0_s"] == 0.5
        assert json.loads(f.attrs["metadata_json"])["tool"] == "T3"
        assert f.attrs["machine"] == "dmu"  # scalar metadata also as own attr
        ds = f["/channels/truth/x/force"]  # "/" in a name -> HDF5 groups
        assert ds.attrs["unit"] == "N" and ds.attrs["description"] == "true force"
        assert ds.compression == "gzip" and ds.shuffle and ds.chunks is not None
        # HDF5's own filter pipeline (what MATLAB h5read uses) decodes our direct chunks
        np.testing.assert_array_equal(ds[()], rec["truth/x/force"])
        np.testing.assert_array_equal(f["/channels/count"][()], np.arange(1000))
        assert f["/channels/count"].dtype == np.int32
        assert f["/streams/tcp/x"].attrs["unit"] == "m"
        assert f["/streams/tcp/time_s"].attrs["unit"] == "s"
        np.testing.assert_array_equal(f["/streams/tcp/line"][()], np.arange(333))
    st_ = recording_status(path)
    assert st_.complete and st_.n_samples == 1000 and st_.recovered_from is None
    assert st_.ends_at_s == pytest.approx(1.5, abs=1e-12)  # t0 + N/fs = 0.5 + 1.0


def test_chunk_codec_matches_hdf5_filters(tmp_path: Path) -> None:
    # Our shuffle+deflate encoder, decoded by HDF5's filters, and HDF5's encoder decoded by ours.
    rng = np.random.default_rng(1)
    for dtype in (np.float64, np.float32, np.int16, np.uint8):
        a = (rng.standard_normal(70001) * 1000).astype(dtype)
        with h5py.File(tmp_path / "c.h5", "w") as f:
            hdf5_chunks.write_array(f, "ours", a)
            f.create_dataset("lib", data=a, chunks=(4096,), compression="gzip", shuffle=True)
        with h5py.File(tmp_path / "c.h5", "r") as f, open(tmp_path / "c.h5", "rb") as fh:
            np.testing.assert_array_equal(f["ours"][()], a)
            np.testing.assert_array_equal(hdf5_chunks.read_array(f["lib"]), a)
            np.testing.assert_array_equal(hdf5_chunks.read_array(f["ours"]), a)
            with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
                view = memoryview(mm)  # zero-copy path: chunks located by HDF5's index
                np.testing.assert_array_equal(hdf5_chunks.read_array(f["lib"], None, view), a)
                np.testing.assert_array_equal(hdf5_chunks.read_array(f["ours"], None, view), a)
                view.release()


def test_incompressible_planes_are_stored_and_others_deflated() -> None:
    # Noisy float64: the 6 low mantissa bytes are random and stored; sign/exponent planes
    # are deflated. The chunk must still be one standard zlib stream of the shuffled bytes.
    rng = np.random.default_rng(3)
    t = np.arange(65536) / 1e4
    x = 3 * np.sin(2 * np.pi * 50 * t) + 0.05 * rng.standard_normal(t.size)
    raw = hdf5_chunks.encode_chunk(x, 65536)
    shuffled = x.view(np.uint8).reshape(-1, 8).T.tobytes()
    assert zlib.decompress(raw) == shuffled  # any inflate reads it
    assert 0.80 < len(raw) / x.nbytes < 0.88  # 6 stored planes + 2 compressed ones (measured 0.84)
    const = np.full(65536, 2.5)
    assert len(hdf5_chunks.encode_chunk(const, 65536)) < 2000  # all planes deflated


_part = st.text("abcxyz_019", min_size=1, max_size=4)
_names = st.lists(
    st.lists(_part, min_size=1, max_size=3).map("/".join), min_size=0, max_size=5, unique=True
)


def _drop_conflicts(names: list[str]) -> list[str]:
    kept: list[str] = []
    for n in names:
        if not any(k.startswith(n + "/") or n.startswith(k + "/") for k in kept):
            kept.append(n)
    return kept


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    names=_names,
    n=st.integers(0, 400),
    fs=st.floats(1.0, 50000.0),
    t0=st.floats(-100.0, 100.0),
    dtype=st.sampled_from(["float64", "float32", "int16", "int64"]),
    n_rows=st.integers(0, 50),
    unit=st.sampled_from(["A", "N*m", "rad/s", "1", "N/m²"]),
    desc=st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=20),
    meta_value=st.one_of(st.integers(-(2**40), 2**40), st.text(max_size=10), st.booleans()),
    # (NUL and lone surrogates are refused in descriptions; metadata keeps them in JSON)
)
def test_round_trip_property(
    names: list[str],
    n: int,
    fs: float,
    t0: float,
    dtype: str,
    n_rows: int,
    unit: str,
    desc: str,
    meta_value: object,
) -> None:
    rng = np.random.default_rng(n)
    rec = Recording(fs, t0, {**META, "free": meta_value, "program": "O100"})
    for i, name in enumerate(_drop_conflicts(names)):
        data = (rng.standard_normal(n) * 1000).astype(dtype if i % 2 else "float64")
        rec.add_channel(name, data, unit, desc)
    rec.add_stream(
        "nc/line",
        np.sort(rng.uniform(0, 1, n_rows)),
        {"line": np.arange(n_rows), "feed": rng.standard_normal(n_rows)},
        {"line": "1", "feed": "m/s"},
        {"feed": desc},
    )
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "r.h5"
        write_recording(path, rec)
        back = read_recording(path)
    _assert_same(rec, back)
    expected = {**rec.metadata, "software_version": "0.1.0", "source": str(path)}
    assert back.metadata == expected


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    sizes=st.lists(st.integers(0, 300), min_size=1, max_size=12),  # dtype fixed by 1st append
    flush_s=st.sampled_from([0.001, 0.05, 0.3, 10.0]),
    stream_every=st.integers(1, 4),
)
def test_writer_chunks_equal_whole(sizes: list[int], flush_s: float, stream_every: int) -> None:
    n = sum(sizes)
    rng = np.random.default_rng(n)
    fs = 1000.0
    a = rng.standard_normal(n)
    b = np.arange(n, dtype=np.int16)
    t_stream = np.arange(n // 10) * 0.01
    x_stream = rng.standard_normal(n // 10)
    rec = Recording(fs, 1.0, META)
    rec.add_channel("x/a", a, "A", "alpha")
    rec.add_channel("b", b, "1")
    rec.add_stream("tcp", t_stream, {"x": x_stream}, {"x": "m"}, {"x": "pos"})
    chans = [ChannelInfo("x/a", "A", "alpha"), ChannelInfo("b", "1")]
    with tempfile.TemporaryDirectory() as d:
        whole, chunked = Path(d) / "whole.h5", Path(d) / "chunked.h5"
        write_recording(whole, rec)
        with RecordingWriter(
            chunked, fs, chans, META, {"tcp": [ChannelInfo("x", "m", "pos")]}, flush_s, 1.0
        ) as w:
            s = 0
            rows = np.array_split(np.arange(n // 10), max(1, len(sizes) // stream_every))
            for i, m in enumerate(sizes):
                w.append({"x/a": a[s : s + m], "b": b[s : s + m]})
                s += m
                if i % stream_every == 0 and rows:
                    r = rows.pop(0)
                    w.append_stream("tcp", t_stream[r], {"x": x_stream[r]})
            for r in rows:
                w.append_stream("tcp", t_stream[r], {"x": x_stream[r]})
            assert w.samples_appended == n
        assert not partial_dir(chunked).exists()  # sidecar removed on close
        r_whole, r_chunked = read_recording(whole), read_recording(chunked)
    _assert_same(r_whole, r_chunked)
    assert {k: v for k, v in r_chunked.metadata.items() if k != "source"} == {
        k: v for k, v in r_whole.metadata.items() if k != "source"
    }


def test_writer_flushes_every_flush_every_s_and_reader_sees_flushed(tmp_path: Path) -> None:
    path = tmp_path / "live.h5"
    w = RecordingWriter(path, 100.0, [ChannelInfo("a", "A")], flush_every_s=0.5)
    w.append({"a": np.arange(30.0)})
    assert w.samples_written == 0  # 0.3 s buffered < 0.5 s
    w.append({"a": np.arange(30.0, 60.0)})
    assert w.samples_written == 60  # 0.6 s >= 0.5 s: flushed automatically
    w.append({"a": np.arange(60.0, 70.0)})
    live = read_recording(path)  # while the writer runs: every flushed sample
    np.testing.assert_array_equal(live["a"], np.arange(60.0))
    assert live.metadata["recovered"] is True
    status = recording_status(path)
    assert not status.complete and status.n_samples == 60
    w.flush()
    assert w.samples_written == 70
    assert read_recording(path).n_samples == 70
    w.close()
    done = read_recording(path)
    np.testing.assert_array_equal(done["a"], np.arange(70.0))
    assert "recovered" not in done.metadata
    assert recording_status(path).complete


def test_writer_close_on_exception_keeps_data(tmp_path: Path) -> None:
    path = tmp_path / "fail.h5"
    with pytest.raises(ZeroDivisionError):
        with RecordingWriter(path, 10.0, [ChannelInfo("a", "A")]) as w:
            w.append({"a": [1.0, 2.0]})
            _ = 1 / 0
    np.testing.assert_array_equal(read_recording(path)["a"], [1.0, 2.0])


# ------------------------------------------------------------------------------- bad input
def _one_line(err: pytest.ExceptionInfo[BaseException], *needles: str) -> None:
    msg = str(err.value)
    assert "\n" not in msg
    for needle in needles:
        assert needle in msg, msg


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.h5"
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    _one_line(err, str(path), "no such recording file")
    with pytest.raises(RecordingError) as err:
        recording_status(path)
    _one_line(err, str(path))


def test_truncated_file(tmp_path: Path) -> None:
    path = tmp_path / "cut.h5"
    write_recording(path, _sample_recording(20000))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    _one_line(err, str(path), "truncated or corrupt")
    with pytest.raises(RecordingError):
        recording_status(path)


def test_corrupt_chunk_data(tmp_path: Path) -> None:
    path = tmp_path / "bad.h5"
    write_recording(path, _sample_recording(20000))
    blob = bytearray(path.read_bytes())
    mid = len(blob) // 2
    blob[mid : mid + 4096] = bytes(4096)  # zero 4 KiB inside compressed chunk data
    path.write_bytes(bytes(blob))
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    _one_line(err, str(path), "corrupt")


def test_not_hdf5_and_foreign_hdf5(tmp_path: Path) -> None:
    text = tmp_path / "notes.h5"
    text.write_text("hello\n")
    with pytest.raises(RecordingError) as err:
        read_recording(text)
    _one_line(err, str(text), "not a readable HDF5 file")
    foreign = tmp_path / "other.h5"
    with h5py.File(foreign, "w") as f:
        f["data"] = np.arange(3)
    with pytest.raises(RecordingError) as err:
        read_recording(foreign)
    _one_line(err, str(foreign), "not a millsense recording")


def test_unknown_channel_and_nan_in_read_recording_name_file(tmp_path: Path) -> None:
    rec = Recording(100.0)
    x = np.zeros(10)
    x[7] = np.nan
    rec.add_channel("x/current_cmd", x, "A")
    path = tmp_path / "nan.h5"
    write_recording(path, rec)
    back = read_recording(path)
    with pytest.raises(RecordingError) as err:
        back.channel("foo")
    _one_line(err, str(path), "unknown channel 'foo'", "available: x/current_cmd")
    with pytest.raises(InputDataError) as err:
        back.require_finite(back.measured_channel_names())
    # sample 7 at 100 Hz: t = 0.07 s
    _one_line(err, str(path), "channel 'x/current_cmd' has NaN/inf at sample 7 (t = 0.07 s)")


def test_writer_rejects_bad_chunks(tmp_path: Path) -> None:
    path = tmp_path / "w.h5"
    chans = [ChannelInfo("x/current_cmd", "A"), ChannelInfo("y/current_cmd", "A")]
    w = RecordingWriter(path, 1000.0, chans, streams={"tcp": [ChannelInfo("x", "m")]})
    with pytest.raises(InputDataError) as err:
        w.append({"x/current_cmd": np.zeros(5), "y/current_cmd": np.zeros(4)})
    _one_line(err, str(path), "channel 'y/current_cmd' has 4 samples", "'x/current_cmd' has 5")
    with pytest.raises(InputDataError) as err:
        w.append({"x/current_cmd": np.zeros(5), "y/current_cmd": np.zeros(5), "z": np.zeros(5)})
    _one_line(err, str(path), "channel 'z' was not declared")
    with pytest.raises(InputDataError) as err:
        w.append({"x/current_cmd": np.zeros(5)})
    _one_line(err, str(path), "lacks declared channel 'y/current_cmd'")
    w.append({"x/current_cmd": np.zeros(5), "y/current_cmd": np.zeros(5)})
    assert w.samples_appended == 5  # the rejected chunks added nothing
    with pytest.raises(InputDataError) as err:
        w.append({"x/current_cmd": np.zeros((5, 2)), "y/current_cmd": np.zeros(5)})
    _one_line(err, "x/current_cmd", "1-D")
    with pytest.raises(InputDataError) as err:
        w.append_stream("nc", [0.0], {"x": [1.0]})
    _one_line(err, str(path), "stream 'nc' was not declared")
    w.append_stream("tcp", [1.0], {"x": [1.0]})
    with pytest.raises(InputDataError) as err:
        w.append_stream("tcp", [0.5], {"x": [1.0]})
    _one_line(err, str(path), "goes back")
    w.close()
    assert read_recording(path).n_samples == 5
    with pytest.raises(RecordingError, match="writer is closed"):
        w.append({"x/current_cmd": np.zeros(5), "y/current_cmd": np.zeros(5)})


def test_chunk_dtypes_follow_first_chunk(tmp_path: Path) -> None:
    # same_kind casting: int -> float64 keeps the values, float -> int would truncate.
    with RecordingWriter(tmp_path / "c.h5", 10.0, [ChannelInfo("a", "1")]) as w:
        w.append({"a": [0.5, 1.5]})
        w.append({"a": np.array([2, 3])})
    np.testing.assert_array_equal(read_recording(tmp_path / "c.h5")["a"], [0.5, 1.5, 2.0, 3.0])
    path = tmp_path / "i.h5"
    with RecordingWriter(path, 10.0, [ChannelInfo("n", "1")]) as w:
        w.append({"n": np.array([1, 2], dtype=np.int32)})
        with pytest.raises(InputDataError) as err:
            w.append({"n": np.array([2.5])})
        _one_line(err, str(path), "channel 'n': got dtype float64", "stores int32")
    back = read_recording(path)["n"]
    assert back.dtype == np.int32 and back.tolist() == [1, 2]


def test_writer_overwrites_files_but_never_an_interrupted_recording(tmp_path: Path) -> None:
    path = tmp_path / "r.h5"
    write_recording(path, _sample_recording(10))
    with pytest.raises(RecordingError) as err:
        RecordingWriter(path, 10.0, [ChannelInfo("a", "A")], overwrite=False)
    _one_line(err, str(path), "file exists")
    w = RecordingWriter(path, 10.0, [ChannelInfo("a", "A")])  # default: replace, like a rerun
    w.append({"a": [1.0]})
    w.flush()
    assert read_recording(path).channel_names == ["a"]  # readers see the new one at once
    with pytest.raises(RecordingError) as err:  # its sidecar is not overwritten
        RecordingWriter(path, 10.0, [ChannelInfo("a", "A")])
    _one_line(err, str(path), "interrupted recording")
    with pytest.raises(RecordingError) as err:
        RecordingWriter(tmp_path / "no" / "dir.h5", 10.0, [ChannelInfo("a", "A")])
    _one_line(err, "dir.h5", "does not exist")


def test_partial_without_schema(tmp_path: Path) -> None:
    path = tmp_path / "x.h5"
    partial_dir(path).mkdir()
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    _one_line(err, str(path), "nothing to recover")


def test_damaged_segment_stops_recovery_there(tmp_path: Path) -> None:
    path = tmp_path / "seg.h5"
    w = RecordingWriter(path, 10.0, [ChannelInfo("a", "A")])
    for i in range(3):
        w.append({"a": np.full(4, float(i))})
        w.flush()
    seg2 = partial_dir(path) / "seg-000002.bin"
    blob = bytearray(seg2.read_bytes())
    blob[-10] ^= 0xFF  # one flipped byte in the samples: CRC-32 must catch it
    seg2.write_bytes(bytes(blob))
    rec = read_recording(path)
    np.testing.assert_array_equal(rec["a"], np.zeros(4))  # segment 1 only
    assert "seg-000002.bin damaged (checksum mismatch)" in rec.metadata["recovery_note"]
    assert recording_status(path).n_samples == 4  # status verifies the same way
    w.close()  # the writer still holds every sample: closing makes the complete file
    np.testing.assert_array_equal(read_recording(path)["a"], np.repeat([0.0, 1.0, 2.0], 4))


def test_metadata_edited_after_construction_is_checked_on_write(tmp_path: Path) -> None:
    rec = _sample_recording(10)
    rec.metadata["spindle_rev_min"] = np.int64(12000)  # numpy scalar: converted, stored
    write_recording(tmp_path / "ok.h5", rec)
    assert read_recording(tmp_path / "ok.h5").metadata["spindle_rev_min"] == 12000
    rec.metadata["bad"] = {1, 2}  # a set has no JSON form
    path = tmp_path / "bad.h5"
    with pytest.raises(InputDataError) as err:
        write_recording(path, rec)
    _one_line(err, str(path), "metadata key 'bad'")
    assert not path.exists()


def test_strided_views_are_written(tmp_path: Path) -> None:
    """A channel or stream given as a strided view (``t[::2]``: every other sample of a
    faster clock) failed to write with numpy's "the last axis must be contiguous" traceback
    when it filled one chunk; it is written and read back exactly."""
    from millsense.core.recording import Recording
    from millsense.io.recording_file import read_recording, write_recording

    t = np.arange(400) / 1000.0
    rec = Recording(500.0)
    rec.add_channel("x/position_cmd", t[::2], "m")
    rec.add_stream("axes", t[::4], {"a_position": t[1::4]}, {"a_position": "rad"})
    write_recording(tmp_path / "r.h5", rec)
    back = read_recording(tmp_path / "r.h5")
    np.testing.assert_array_equal(back.channel("x/position_cmd"), t[::2])
    np.testing.assert_array_equal(back.stream("axes")["a_position"], t[1::4])
    np.testing.assert_array_equal(back.stream("axes").time_s, t[::4])
