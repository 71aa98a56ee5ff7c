"""The streaming engine: chunk-size invariance, truth isolation, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo, Recording
from millsense.estimation.feed.rigid_body import DriveModel, RigidBodyForceEstimator
from millsense.models.friction import CoulombViscous
from millsense.streaming import Block, BlockOutput, Chunk, Event, EventKind, Pipeline, run
from millsense.streaming.sources import RecordingSource

FS = 10000.0


class ThresholdAlarm(Block):
    """Test block: an alarm event at every upward crossing of a level (stateful across chunks)."""

    def __init__(self, channel: str, level: float) -> None:
        self.name = f"alarm_{channel}"
        self.inputs = (channel,)
        self.level = level
        self._above = False

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(f"{self.inputs[0]}_above", "1", "1 while above the level")]

    def reset(self, sample_rate_hz: float) -> None:
        self._above = False

    def process(self, chunk: Chunk) -> BlockOutput:
        x = chunk.data[self.inputs[0]]
        above = x > self.level
        prev = np.concatenate([[self._above], above[:-1]])
        events = [
            Event(float(t), EventKind.ALARM, self.name, "above level", name="level")
            for t in chunk.time_s[above & ~prev]
        ]
        if len(x):
            self._above = bool(above[-1])
        return BlockOutput({f"{self.inputs[0]}_above": above.astype(float)}, events)


def make_recording(n: int = 3000, seed: int = 1) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    rec = Recording(FS, metadata={"source": "test.h5"})
    speed = 10.0 + 2.0 * np.sin(2 * np.pi * 30 * t) + 0.05 * rng.standard_normal(n)
    current = 1.0 + 0.5 * np.sin(2 * np.pi * 100 * t) + 0.1 * rng.standard_normal(n)
    rec.add_channel("x/current_cmd", current, "A")
    rec.add_channel("x/motor_speed", speed, "rad/s")
    rec.add_channel("truth/x/force", -100 * np.ones(n), "N")
    return rec


def model() -> DriveModel:
    return DriveModel(0.01366, 1.964, 0.012 / (2 * np.pi), 0.92, CoulombViscous(1.7, 1.8, 0.1, 0.1))


def pipeline() -> Pipeline:
    return Pipeline(
        [RigidBodyForceEstimator("x", model(), 300.0), ThresholdAlarm("x/force_est", 5.0)]
    )


def run_chunked(rec: Recording, chunk: int):
    return run(RecordingSource(rec), pipeline(), chunk)


def test_chunk_sizes_1_7_100_whole_give_identical_outputs() -> None:
    rec = make_recording()
    ref = run_chunked(rec, rec.n_samples)
    assert ref.n_samples == rec.n_samples
    assert len(ref.events) > 0  # the alarm block does fire on this signal
    for size in (1, 7, 100):
        res = run_chunked(rec, size)
        for name, values in ref.channels.items():
            np.testing.assert_allclose(res.channels[name], values, rtol=1e-12, atol=1e-9)
        assert [e.time_s for e in res.events] == [e.time_s for e in ref.events]


@settings(max_examples=25, deadline=None)
@given(sizes=st.lists(st.integers(min_value=1, max_value=400), min_size=1, max_size=30))
def test_chunk_size_invariance_random_chunkings(sizes: list[int]) -> None:
    rec = make_recording(n=1200)
    ref = run_chunked(rec, rec.n_samples)

    class Varying(RecordingSource):
        def __init__(self) -> None:
            super().__init__(rec)
            self.k = 0

        def read(self, max_samples: int) -> Chunk | None:
            n = sizes[self.k % len(sizes)]
            self.k += 1
            return super().read(n)

    res = run(Varying(), pipeline(), 1)
    for name, values in ref.channels.items():
        np.testing.assert_allclose(res.channels[name], values, rtol=1e-12, atol=1e-9)


def test_estimator_matches_independent_offline_computation() -> None:
    # Independent: whole-array inverse dynamics with scipy's sosfilt, Aslan Eq. 3.10-3.11.
    rec = make_recording()
    res = run_chunked(rec, 77)
    m = model()
    i, w = rec.channel("x/current_cmd"), rec.channel("x/motor_speed")
    acc = np.diff(w, prepend=w[0]) * FS
    tau = m.torque_constant * i - m.friction.torque(w) - m.inertia * acc
    sos = signal.butter(2, 300.0, fs=FS, output="sos")
    tau_f = signal.sosfilt(sos, tau, zi=signal.sosfilt_zi(sos) * tau[0])[0]
    expected = -m.efficiency * tau_f / m.transmission
    np.testing.assert_allclose(res.channels["x/force_est"], expected, rtol=1e-10, atol=1e-8)


def test_blocks_may_not_read_truth() -> None:
    class Cheater(ThresholdAlarm):
        pass

    with pytest.raises(ValueError, match="ground-truth"):
        Pipeline([Cheater("truth/x/force", 0.0)])


def test_nan_in_channel_named_with_time() -> None:
    rec = make_recording()
    bad = rec.channel("x/current_cmd").copy()
    bad[1234] = np.nan
    rec2 = Recording(FS, metadata={"source": "run.h5"})
    rec2.add_channel("x/current_cmd", bad, "A")
    rec2.add_channel("x/motor_speed", rec.channel("x/motor_speed"), "rad/s")
    with pytest.raises(InputDataError) as err:
        run(RecordingSource(rec2), pipeline(), 500)
    msg = str(err.value)
    assert "run.h5" in msg and "'x/current_cmd'" in msg and "sample 1234" in msg
    assert "t = 0.1234 s" in msg


def test_missing_channel_named() -> None:
    rec = Recording(FS, metadata={"source": "run.h5"})
    rec.add_channel("x/current_cmd", np.zeros(10), "A")
    with pytest.raises(InputDataError, match="needs channel 'x/motor_speed'"):
        run(RecordingSource(rec), pipeline(), 5)


def test_override_events_reach_the_source() -> None:
    class Override(ThresholdAlarm):
        def process(self, chunk: Chunk) -> BlockOutput:
            out = super().process(chunk)
            out.events = [
                Event(e.time_s, EventKind.OVERRIDE, self.name, "slow down", "feed_override", 80.0)
                for e in out.events
            ]
            return out

    rec = make_recording()
    src = RecordingSource(rec)
    res = run(
        src, Pipeline([RigidBodyForceEstimator("x", model()), Override("x/force_est", 5.0)]), 50
    )
    assert len(src.commands) == len(res.events) > 0
    assert all(c.value == 80.0 for c in src.commands)


def test_replay_stopped_early_is_the_prefix_of_the_whole() -> None:
    # a replay that ends at sample 1234 gives exactly the first 1234 outputs of the full replay
    # (the idle compensation runs its estimators over the air phase this way)
    rec = make_recording()
    whole = run(RecordingSource(rec), pipeline(), 100).channels
    part = run(RecordingSource(rec, stop_sample=1234), pipeline(), 100).channels
    for name, values in part.items():
        assert len(values) == 1234
        np.testing.assert_array_equal(values, whole[name][:1234])
