"""Position-scheduled feed estimator: weights, streaming, switching, shift measurement."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.estimation.feed.estimator import FeedAxisEstimator, FeedAxisModel
from millsense.estimation.feed.path_fit import SweepResult
from millsense.estimation.feed.schedule import (
    FeedModelBank,
    ScheduledFeedEstimator,
    interval_worst_db,
    relative_shift,
)
from millsense.ident.frf import FrfEstimate
from millsense.simulator.machine_file import simulator_machine
from millsense.streaming.block import Chunk

FS = 10_000.0


@cache
def _model() -> FeedAxisModel:
    ax = simulator_machine("quaser-ux600").axis("x")
    return FeedAxisModel.from_config("x", ax, sample_rate_hz=FS)


@cache
def _bank(crossfade: float = 1.0) -> FeedModelBank:
    m = _model()
    models = tuple(
        replace(m, disturbance=m.disturbance.with_modes_scaled(k), q=m.q * k)
        for k in (0.99, 1.0, 1.01)
    )
    return FeedModelBank((-0.1, 0.0, 0.1), models, (0.005,) * 3, crossfade)


def test_weights_closed_form() -> None:
    # nearest member, linear cross-fade over crossfade × spacing around the midpoint
    b = FeedModelBank(_bank().positions, _bank().models, _bank().half_shifts, 0.5)
    w = b.weights([-0.2, -0.1, -0.07, -0.05, -0.03, 0.0, 0.06, 0.5])
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(w[0], [1, 0, 0])  # beyond the low end: end member
    np.testing.assert_allclose(w[1], [1, 0, 0])
    # u = 0.3: (0.3 − 0.5)/0.5 + 0.5 = 0.1 to the upper member
    np.testing.assert_allclose(w[2], [0.9, 0.1, 0], atol=1e-12)
    np.testing.assert_allclose(w[3], [0.5, 0.5, 0], atol=1e-12)  # midpoint
    np.testing.assert_allclose(w[4], [0.1, 0.9, 0], atol=1e-12)
    np.testing.assert_allclose(w[5], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(w[6], [0, 0.3, 0.7], atol=1e-12)  # u = 0.6: 0.1/0.5 + 0.5
    np.testing.assert_allclose(w[7], [0, 0, 1])
    # crossfade 1: plain linear interpolation between neighbours
    np.testing.assert_allclose(_bank().weights([-0.07])[0], [0.7, 0.3, 0.0], atol=1e-12)


def test_bank_rejects_bad_positions() -> None:
    b = _bank()
    with pytest.raises(ConfigError, match="ascending"):
        FeedModelBank((0.0, 0.0, 0.1), b.models, b.half_shifts)
    with pytest.raises(ConfigError, match="crossfade"):
        FeedModelBank(b.positions, b.models, b.half_shifts, 0.0)


def _signals(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(4)
    t = np.arange(n) / FS
    cur = 1.0 + 0.5 * np.sin(2 * np.pi * 37 * t) + 0.1 * rng.standard_normal(n)
    spd = 10.0 + 0.01 * np.round(rng.standard_normal(n) * 10)
    pos = -0.15 + 0.3 * t / t[-1]  # crosses every interval and both ends
    return cur, spd, pos


def _run(
    est: ScheduledFeedEstimator, cur: np.ndarray, spd: np.ndarray, pos: np.ndarray, cuts: list[int]
) -> np.ndarray:
    est.reset(FS)
    out = []
    for a, b in zip([0, *cuts], [*cuts, len(cur)], strict=True):
        data = {"x/current_cmd": cur[a:b], "x/motor_speed": spd[a:b], "x/position_cmd": pos[a:b]}
        out.append(est.process(Chunk(a, FS, a / FS, data)).channels["x/load_est"])
    return np.concatenate(out)


def test_streaming_equals_batch() -> None:
    # all member states and the delayed-position line are carried across chunks
    cur, spd, pos = _signals(3000)
    est = ScheduledFeedEstimator(_bank())
    whole = _run(est, cur, spd, pos, [])
    chunked = _run(est, cur, spd, pos, [1, 59, 61, 777, 1500, 2999])
    np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-12 * np.max(np.abs(whole)))


def test_output_is_the_weighted_members_with_the_delayed_command() -> None:
    # independent computation: each member run alone as a FeedAxisEstimator, weighted by the
    # bank weights at the commanded position delayed by the smoother lag (60 samples)
    cur, spd, _ = _signals(2000)
    pos = np.where(np.arange(2000) < 900, -0.1, 0.05)  # a step: member 0 → half members 1, 2
    est = ScheduledFeedEstimator(_bank())
    got = _run(est, cur, spd, pos, [500, 1300])
    lag = est.lag
    delayed = np.concatenate([np.full(lag, pos[0]), pos[:-lag]])
    w = _bank().weights(delayed)
    ref = np.zeros(2000)
    gain = _model().drive.efficiency / _model().drive.transmission
    for j, m in enumerate(_bank().models):
        single = FeedAxisEstimator(m, lag)
        single.reset(FS)
        ref += w[:, j] * gain * single.torque(cur, spd)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))
    # the switch happens lag samples after the command step, not before
    assert np.allclose(w[900 + lag - 1], [1, 0, 0]) and np.allclose(w[900 + lag], [0, 0.5, 0.5])


def test_relative_shift_recovers_a_known_scale() -> None:
    # noiseless "sweep" of the model with every mode × 1.013: the fit finds 0.013 (to 1e-5)
    fit = _model().disturbance
    f = np.arange(3.0, 261.0, 1.0)
    h = fit.with_modes_scaled(1.013).continuous_frf(f)
    ones = np.ones_like(f)
    sweep = SweepResult(FrfEstimate(f, h, h, ones, 1, "multisine"), fit)
    assert relative_shift(fit, sweep, (3.0, 260.0)) == pytest.approx(0.013, abs=1e-5)


def test_interval_figure_without_shift_is_the_nominal_design() -> None:
    # half shift → 0: both members and all plants are the same model, so the interval's worst,
    # the midpoint and the hard switch coincide and the LTI limit is 0 dB
    r = interval_worst_db(_model(), 1e-7, design="nominal", n_positions=3)
    assert r["worst_db"] == pytest.approx(r["hard_switch_db"], abs=1e-3)
    assert r["midpoint_db"] == pytest.approx(r["hard_switch_db"], abs=1e-3)
    assert r["lti_bound_db"] < 1e-3


def test_active_set_and_warm_up_are_bumpless() -> None:
    # a ramp across the bank: member 2 starts running only when the delayed command passes
    # −0.01 m (10 % of the spacing before its weight support), at sample ~14 700 of 30 000,
    # after the 1 s history (10 000 samples) it replays; member 0 stops likewise. Its state
    # after the replay differs from the always-running member's by the decay of the slowest
    # filter pole over the replay (< 1 % of the initial error, asserted), and it enters at zero
    # weight, so the output equals running every member all the time to 1e-7 of its range;
    # without the replay (cold start) the difference is larger (the replay does the work)
    n = 30000
    cur, spd, _ = _signals(n)
    pos = np.linspace(-0.15, 0.15, n)
    bank = _bank()
    lazy = ScheduledFeedEstimator(bank)
    cold = ScheduledFeedEstimator(bank, warmup_s=0.0)
    full = ScheduledFeedEstimator(bank, all_members=True)
    slowest = max(
        float(np.max(np.abs(np.linalg.eigvals(m.design().closed_loop)))) for m in bank.models
    )
    assert slowest**lazy.warmup < 0.01
    ref = _run(full, cur, spd, pos, [])
    act = bank.active(pos, lazy.margin)
    k_on = int(np.argmax(act[:, 2]))
    assert k_on > lazy.warmup and act[-1, 2] and not act[-1, 0]  # members really switched
    err = np.max(np.abs(_run(lazy, cur, spd, pos, [3000, 17000]) - ref)) / np.ptp(ref)
    err_cold = np.max(np.abs(_run(cold, cur, spd, pos, []) - ref)) / np.ptp(ref)
    assert err < 1e-7  # measured 5.6e-9
    assert err_cold > 100 * err  # measured 6.9e-6
