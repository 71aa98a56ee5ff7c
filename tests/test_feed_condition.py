"""Feed estimator following the operating condition (estimation.feed_condition)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from millsense.estimation.feed.condition import (
    REST_MEAN_WINDOW_S,
    OperatingConditionFeedEstimator,
)
from millsense.estimation.feed.estimator import FeedAxisEstimator, FeedAxisModel
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine
from millsense.streaming.block import Chunk

FS = 10_000.0
LAG = 60


@pytest.fixture(scope="module")
def models() -> tuple[FeedAxisModel, FeedAxisModel, float]:
    cfg = simulator_machine("quaser-ux600").axis("y")
    moving = FeedAxisModel.from_config("y", cfg, sample_rate_hz=FS)
    # a different at-rest model (Φ_d's modes 3 % lower): enough to tell the two apart
    rest = replace(moving, disturbance=moving.disturbance.with_modes_scaled(0.97))
    return moving, rest, cfg.transmission_m_rad


def _block(models: tuple[FeedAxisModel, FeedAxisModel, float]) -> OperatingConditionFeedEstimator:
    moving, rest, rg = models
    b = OperatingConditionFeedEstimator(
        FeedAxisEstimator(moving, LAG),
        FeedAxisEstimator(replace(rest, condition="at_rest"), LAG),
        rg,
    )
    b.reset(FS)
    return b


def test_rest_weight_is_the_centred_window_at_the_estimated_sample(
    models: tuple[FeedAxisModel, FeedAxisModel, float],
) -> None:
    # rest for 1000 samples, then a move at 5 rad/s (motor): the at-rest weight of output k
    # is the fraction of rest commands over [k − L − h, k − L + h], h = 25 (5 ms window)
    b = _block(models)
    rg = models[2]
    n = 2000
    v = np.where(np.arange(n) < 1000, 0.0, 5.0)
    pos = np.cumsum(v) / FS * rg
    w = b.rest_weight(pos)
    rest = (np.arange(n) < 1000).astype(float)  # pos = cumsum(v): sample 1000 moves
    h = 25
    idx = np.arange(n) - LAG
    expect = np.array([np.mean(rest[np.clip(np.arange(i - h, i + h + 1), 0, n - 1)]) for i in idx])
    # before the stream the axis stood in its first condition (rest): clip at 0 is exact
    np.testing.assert_allclose(w, expect, atol=1e-12)
    assert w[1000 + LAG - h - 1] == 1.0 and w[1000 + LAG + h + 1] == 0.0


def test_blend_is_each_model_in_its_condition_and_streams_like_batch(
    models: tuple[FeedAxisModel, FeedAxisModel, float],
) -> None:
    moving, rest, rg = models
    cfg = simulator_machine("quaser-ux600").axis("y")
    n = 6000
    v = np.where(np.arange(n) < 3000, 0.0, 3.0)  # hold, then move at 3 rad/s
    pos = np.cumsum(v) / FS
    t = np.arange(n) / FS
    load = 300.0 * np.sin(2 * np.pi * 100.0 * t) + 200.0
    res = FeedDriveSim(FeedDriveParams.from_config(cfg), FS, seed=3).advance(pos, v, load)
    data = {
        "y/current_cmd": res["current_cmd"],
        "y/motor_speed": res["speed"],
        "y/position_cmd": pos * rg,
    }

    def run(block: object, step: int) -> np.ndarray:
        block.reset(FS)  # type: ignore[attr-defined]
        outs = [
            block.process(  # type: ignore[attr-defined]
                Chunk(s, FS, 0.0, {k: x[s : s + step] for k, x in data.items()})
            ).channels["y/load_est"]
            for s in range(0, n, step)
        ]
        return np.concatenate(outs)

    blend = run(_block(models), n)
    only_rest = run(FeedAxisEstimator(replace(rest, condition="at_rest"), LAG), n)
    only_moving = run(FeedAxisEstimator(moving, LAG), n)
    # holding: the moving estimate plus the at-rest one's deviation from the 0.1 s mean of the
    # difference (decision 0129; computed here with a convolution, d before the stream = d[0]);
    # moving (after the crossfade window): the moving one exactly
    d = only_rest - only_moving
    nw = round(REST_MEAN_WINDOW_S * FS)
    mean = np.convolve(np.concatenate([np.full(nw - 1, d[0]), d]), np.ones(nw) / nw, "valid")
    hold = slice(0, 3000 + LAG - 30)
    np.testing.assert_allclose(blend[hold], (only_moving + d - mean)[hold], atol=1e-9)
    np.testing.assert_allclose(blend[3000 + LAG + 30 :], only_moving[3000 + LAG + 30 :], atol=1e-9)
    assert np.max(np.abs(only_rest - only_moving)) > 1.0  # the two models do differ
    for step in (7, 100, 1001):
        np.testing.assert_allclose(run(_block(models), step), blend, rtol=0, atol=1e-9)


def test_a_holding_axis_takes_its_mean_from_the_moving_path_and_its_lines_from_the_at_rest_one(
    models: tuple[FeedAxisModel, FeedAxisModel, float],
) -> None:
    # decision 0129: a held axis under 200 N + 300 N at 100 Hz. Once the 0.1 s window is past,
    # the blend's mean over whole periods is the moving estimate's and its 100 Hz line (a
    # multiple of 1/T: the boxcar passes none of it) the at-rest estimate's, within 2 % of
    # what tells the two models apart (the estimates are not exactly periodic: the drive's
    # friction and noise)
    moving, _, rg = models
    # an at-rest path of 0.8 × the moving one: its static gain and its lines differ
    p = moving.disturbance
    rest = replace(moving, disturbance=replace(
        p, complex_residues=0.8 * p.complex_residues, real_residues=0.8 * p.real_residues,
        d=0.8 * p.d), condition="at_rest")  # fmt: skip
    cfg = simulator_machine("quaser-ux600").axis("y")
    n = 4000
    t = np.arange(n) / FS
    pos = np.zeros(n)
    load = 300.0 * np.sin(2 * np.pi * 100.0 * t) + 200.0
    res = FeedDriveSim(FeedDriveParams.from_config(cfg), FS, seed=3).advance(pos, pos, load)
    data = {"y/current_cmd": res["current_cmd"], "y/motor_speed": res["speed"],
            "y/position_cmd": pos}  # fmt: skip

    def run(block: object) -> np.ndarray:
        block.reset(FS)  # type: ignore[attr-defined]
        return np.asarray(block.process(Chunk(0, FS, 0.0, data)).channels["y/load_est"])  # type: ignore[attr-defined]

    blend = run(_block((moving, rest, rg)))
    only_rest = run(FeedAxisEstimator(rest, LAG))
    only_moving = run(FeedAxisEstimator(moving, LAG))
    w = slice(2000, 4000)  # 20 whole periods of 100 Hz, long after the window

    def line(x: np.ndarray) -> complex:
        return complex(np.fft.rfft(x[w])[20])

    apart_mean = abs(only_rest[w].mean() - only_moving[w].mean())
    apart_line = abs(line(only_rest) - line(only_moving))
    assert apart_mean > 1.0 and apart_line > 1e-3 * abs(line(only_rest))  # they do differ
    assert abs(blend[w].mean() - only_moving[w].mean()) < 0.02 * apart_mean
    assert abs(line(blend) - line(only_rest)) < 0.02 * apart_line
