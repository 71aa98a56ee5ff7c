"""Idle table per direction of motion and its streamed subtraction (``estimate --idle``)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.feed.idle_compensation import IdleCompensatedBlock
from millsense.ident.idle_table import build_direction_idle
from millsense.streaming.block import Block, BlockOutput, Chunk

FS = 10_000.0


def test_direction_means_and_variances_are_the_sample_statistics() -> None:
    rng = np.random.default_rng(1)
    v = np.concatenate([np.full(400, -0.02), np.zeros(300), np.full(500, 0.02)])
    noise = rng.standard_normal(len(v))
    y = np.where(v > 0, 130.0, np.where(v < 0, -120.0, 4.0)) + noise
    t = build_direction_idle(v, y, deadband=1e-5, unit="N")
    # closed form: the sample mean and (population) variance of each direction's samples
    for k, sel in enumerate((v < 0, v == 0, v > 0)):
        assert t.value[k] == pytest.approx(float(y[sel].mean()), rel=1e-12)
        assert t.variance[k] == pytest.approx(float(y[sel].var()), rel=1e-12)
    assert t.samples == (400, 300, 500)
    # compensation leaves only the noise
    np.testing.assert_allclose(t.compensate(v, y), noise - np.where(
        v > 0, noise[v > 0].mean(), np.where(v < 0, noise[v < 0].mean(), noise[v == 0].mean())
    ), atol=1e-9)  # fmt: skip


def test_unseen_direction_is_not_compensated() -> None:
    v = np.full(200, 0.01)
    t = build_direction_idle(v, np.full(200, 7.0), deadband=1e-5)
    assert np.isnan(t.value[0]) and np.isnan(t.value[1]) and t.seen() == ["positive"]
    # at rest and backwards: untouched (0 subtracted); forwards: 7 N removed (exact)
    np.testing.assert_array_equal(t.compensate(np.array([-0.01, 0.0, 0.01]), np.ones(3)),
                                  [1.0, 1.0, -6.0])  # fmt: skip
    with pytest.raises(InputDataError):
        build_direction_idle(v, np.full(199, 7.0), deadband=1e-5)


class _Delay(Block):
    """Test estimator: the channel ``est`` delayed by ``d`` samples (state across chunks)."""

    def __init__(self, d: int) -> None:
        self.name = "delay"
        self.inputs = ("est_in",)
        self.d = d
        self._buf = np.zeros(d)

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo("est", "N", "delayed")]

    def reset(self, sample_rate_hz: float) -> None:
        self._buf = np.zeros(self.d)

    def process(self, chunk: Chunk) -> BlockOutput:
        x = np.concatenate([self._buf, np.asarray(chunk.data["est_in"], dtype=float)])
        n = len(chunk.data["est_in"])
        self._buf = x[n:]
        return BlockOutput({"est": x[:n]})


@pytest.mark.parametrize("chunk", [1, 7, 1000])
def test_streamed_compensation_follows_the_delayed_velocity(chunk: int) -> None:
    n, d = 600, 13
    pos = np.concatenate([np.zeros(200), 1e-4 * np.arange(1, 201), 0.02 - 1e-4 * np.arange(200)])
    est_in = np.linspace(0.0, 1.0, n)
    t = build_direction_idle(
        np.array([-0.1] * 100 + [0.0] * 100 + [0.1] * 100),
        np.array([-5.0] * 100 + [2.0] * 100 + [9.0] * 100),
        deadband=1e-5,
    )
    block = IdleCompensatedBlock(_Delay(d), "x", "est", t, delay_samples=d)
    assert block.inputs == ("est_in", "x/position_cmd")
    block.reset(FS)
    out = []
    for a in range(0, n, chunk):
        c = Chunk(
            a, FS, 0.0, {"est_in": est_in[a : a + chunk], "x/position_cmd": pos[a : a + chunk]}
        )
        out.append(block.process(c).channels["est"])
    got = np.concatenate(out)
    # independent: velocity = backward difference × f_s (first sample 0), delayed by d samples
    v = np.diff(pos, prepend=pos[0]) * FS
    v_d = np.concatenate([np.zeros(d), v[:-d]])
    idle = np.where(v_d > 1e-5, 9.0, np.where(v_d < -1e-5, -5.0, 2.0))
    expect = np.concatenate([np.zeros(d), est_in[:-d]]) - idle
    np.testing.assert_allclose(got, expect, atol=1e-12)
