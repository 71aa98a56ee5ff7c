"""`check` judges the data, not what millsense computed from it (decision 1745): a session's
recording lists its block outputs (and the guard's fault channel) in ``computed_channels``,
which the data-quality checks skip; NaN there means "none" (no chatter frequency, no
threshold yet)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from millsense.core.recording import COMPUTED_CHANNELS, ChannelInfo, Recording
from millsense.io.quality import check_recording
from millsense.streaming.block import Block, BlockOutput, Chunk


def test_computed_channels_are_not_checked() -> None:
    """Two channels full of NaN and a third constant: the computed ones give no finding, the
    measured one its NaN finding, as before."""
    n = 2000
    rec = Recording(1000.0, 0.0, {COMPUTED_CHANNELS: ["chatter/chatter_hz", "guard/fault"]})
    rec.add_channel("x/current", np.sin(np.arange(n) * 0.01), "A")
    rec.add_channel("x/bad", np.where(np.arange(n) < 10, np.nan, np.cos(np.arange(n))), "A")
    rec.add_channel("chatter/chatter_hz", np.full(n, np.nan), "Hz")
    rec.add_channel("guard/fault", np.zeros(n), "1")
    found = {(f.kind, f.where) for f in check_recording(rec).findings}
    assert ("nan", "x/bad") in found
    assert not [w for _, w in found if w in ("chatter/chatter_hz", "guard/fault")]
    # without the list (an imported file, a recording of before) every channel is checked
    rec.metadata.pop(COMPUTED_CHANNELS)
    found = {(f.kind, f.where) for f in check_recording(rec).findings}
    assert ("nan", "chatter/chatter_hz") in found and ("constant", "guard/fault") in found


def test_a_sessions_recording_lists_its_computed_channels(tmp_path: Path) -> None:
    """``run_session`` writes the blocks' outputs and the guard's channel as computed; the
    source's channels are not."""
    from millsense.io.recording_reader import open_recording
    from millsense.online.guard import FAULT_CHANNEL
    from millsense.online.session import run_session
    from millsense.streaming.sources import RecordingSource

    class Nan(Block):
        name = "nan"
        inputs = ("x/position_cmd",)

        def output_channels(self) -> list[ChannelInfo]:
            return [ChannelInfo("nan/value", "1", "NaN: none")]

        def reset(self, sample_rate_hz: float) -> None:
            pass

        def process(self, chunk: Chunk) -> BlockOutput:
            return BlockOutput({"nan/value": np.full(chunk.n, np.nan)})

    rec = Recording(1000.0, 0.0, {})
    rec.add_channel("x/position_cmd", np.linspace(0.0, 0.01, 1000), "m")  # moving: no stall
    run_session(RecordingSource(rec), [Nan()], out=tmp_path / "run.h5", chunk_samples=100)
    with open_recording(tmp_path / "run.h5") as r:
        assert sorted(r.metadata[COMPUTED_CHANNELS]) == sorted([FAULT_CHANNEL, "nan/value"])
        assert "x/position_cmd" in r.channel_names
