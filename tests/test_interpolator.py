"""Interpolator: trapezoidal profile, acceleration limit, override latency/quantisation, hold."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.simulator.interpolator import Interpolator, OverrideChannel, Upsampler

T = 3e-3


def _acc(out: dict[str, np.ndarray], v0: float = 0.0) -> np.ndarray:
    return np.diff(np.concatenate([[v0], out["v"]])) / T


def test_trapezoid_closed_form() -> None:
    length, feed, a = 0.1, 0.02, 0.5
    ip = Interpolator(np.array([[0, 0, 0], [length, 0, 0.0]]), feed, a)
    out = ip.advance(3000)
    t, v, s = out["t"], out["v"], out["s"]
    # closed form: reach the feed at F/a = 40 ms (discrete: ceil(F/(aT))·T = 42 ms)
    assert t[np.argmax(v >= feed - 1e-12)] == pytest.approx(feed / a, abs=T)
    # distance during the ramp = F²/(2a) = 0.4 mm (trapezoidal integration, exact for a ramp)
    k = int(np.argmax(v >= feed - 1e-12))
    assert s[k - 1] == pytest.approx(0.5 * a * t[k - 1] ** 2, rel=1e-9)
    # total time L/F + F/a = 5.04 s; the discrete look-ahead brakes at most a few periods early
    t_end = t[np.argmax(s >= length)]
    assert t_end == pytest.approx(length / feed + feed / a, abs=6 * T)
    assert ip.done and s[-1] == length and v[-1] == 0.0


def test_acceleration_never_exceeds_limit_with_feed_changes_and_overrides() -> None:
    rng = np.random.default_rng(3)
    pts = np.cumsum(rng.uniform(-0.01, 0.01, (40, 3)), axis=0)
    feeds = rng.uniform(0.002, 0.03, 39)
    a = 0.8
    ip = Interpolator(pts, feeds, a)
    outs = []
    for k in range(20):
        ip.set_override([1.0, 0.3, 1.5, 0.0, 0.8][k % 5])
        outs.append(ip.advance(150))
    v = np.concatenate([o["v"] for o in outs])
    acc = np.diff(np.concatenate([[0.0], v])) / T
    # the kernel clamps every step to ±a·T: only round-off above a
    assert np.abs(acc).max() <= a * (1 + 1e-9)
    # with a constant override the look-ahead holds each feed-change boundary: the speed in
    # the period that crosses boundary j is at most min(f_j, f_j+1) + a·T
    ip = Interpolator(pts, feeds, a)
    out = ip.advance(20000)
    assert ip.done
    for j in range(1, 39):
        k = int(np.searchsorted(out["s"], ip.cum[j]))
        assert out["v"][k - 1] <= min(feeds[j - 1], feeds[j]) + a * T + 1e-12


def test_chunked_equals_one_run() -> None:
    pts = np.array(
        [[0, 0, 0, 0, 0], [0.05, 0.02, 0, 0.1, 0.0], [0.05, 0.02, 0, 0.1, 0.5], [0.1, 0, 0, 0, 0.5]]
    )
    a1 = Interpolator(pts, [0.01, 0.2, 0.02], 0.3)
    a1.set_override(0.5, at_time_s=0.3)
    one = a1.advance(900)
    a2 = Interpolator(pts, [0.01, 0.2, 0.02], 0.3)
    parts = [a2.advance(100)]
    a2.set_override(0.5, at_time_s=0.3)  # same command time: same effect
    parts += [a2.advance(n) for n in (1, 299, 500)]
    for key in one:
        np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), one[key])


def test_override_latency_and_quantisation() -> None:
    path = np.array([[0, 0, 0], [1.0, 0, 0.0]])
    closed = Interpolator(path, 0.01, 1.0, channel=OverrideChannel.closed_cnc())
    closed.advance(100)  # t = 0.3 s
    closed.set_override(0.73)  # commanded at t = 0.3 s
    out = closed.advance(100)
    # Munasinghe §M9: 10 % steps (0.73 → 0.7), ≈ 120 ms latency: effective from 0.42 s
    changed = out["t"][np.argmax(out["override"] < 1.0)]
    # first period whose midpoint is after 0.42 s
    assert 0.42 < changed - T / 2 <= 0.42 + T
    assert out["override"][-1] == pytest.approx(0.7, abs=1e-12)
    # the speed then ramps down at a to 0.7·F (a·T = 3 mm/s ≫ 3 mm/s change: one step)
    assert out["v"][-1] == pytest.approx(0.007, rel=1e-12)
    open_ = Interpolator(path, 0.01, 1.0, channel=OverrideChannel.open_cnc())
    open_.advance(100)
    open_.set_override(0.73)
    out = open_.advance(10)
    # open CNC: 2.5 ms latency, continuous value (Munasinghe §M1)
    changed = out["t"][np.argmax(out["override"] < 1.0)]
    assert 0.3025 < changed - T / 2 <= 0.3025 + T
    assert out["override"][-1] == pytest.approx(0.73, abs=1e-12)


def test_feed_hold_stops_within_braking_distance() -> None:
    feed, a = 0.05, 0.4
    ip = Interpolator(np.array([[0, 0, 0], [1.0, 0, 0.0]]), feed, a)
    first = ip.advance(200)
    assert first["v"][-1] == pytest.approx(feed)
    s_hold = first["s"][-1]
    ip.set_override(0.0)
    out = ip.advance(300)
    assert out["v"][-1] == 0.0 and not ip.done
    # v²/(2a) = 3.125 mm, plus what is travelled during the 2.5 ms latency and the first
    # period (v·(latency + T)) of the discrete ramp
    bound = feed**2 / (2 * a) + feed * (2.5e-3 + T)
    travelled = out["s"][-1] - s_hold
    assert feed**2 / (2 * a) <= travelled <= bound
    # resuming after the hold reaches the end
    ip.set_override(1.0)
    ip.advance(7000)
    assert ip.done


def test_upsampler_linear_and_hermite() -> None:
    ip = Interpolator(np.array([[0, 0, 0], [0.01, 0.0, 0]]), 0.01, 0.5)
    out = ip.advance(400)
    lin = Upsampler(30, np.zeros(3))
    herm = Upsampler(30, np.zeros(3), method="hermite")
    fine_l = np.vstack(
        [lin(out["position"][a:b], out["velocity"][a:b], T) for a, b in [(0, 7), (7, 400)]]
    )
    fine_h = herm(out["position"], out["velocity"], T)
    assert fine_l.shape == (400 * 30, 3)
    # every 30th fine sample is the coarse sample (both methods interpolate)
    np.testing.assert_allclose(fine_l[29::30], out["position"], atol=1e-15)
    np.testing.assert_allclose(fine_h[29::30], out["position"], atol=1e-15)
    # Hermite vs linear differ by < a·T²/8 ≈ 0.6 µm (the curvature of a ramp within a period)
    assert np.abs(fine_h - fine_l).max() < 0.5 * T**2 / 8 * 1.01


def test_hermite_fine_interpolation_is_the_trapezoid() -> None:
    """On the interpolator's samples (``s⁺ − s = (v + v⁺)·T/2``) the Hermite cubic has no cubic
    term, so within every period the fine acceleration is the period's own (v⁺ − v)/T: constant,
    no step of the velocity at the samples and no 333 Hz line (decision 1682). Checked on the
    second differences inside each period through the ramp-up, the cruise and the look-ahead
    braking (the path end, where s is clamped, excluded), to 1e-6 of a (float round-off of
    positions ~0.05 m over dt² = 1e-8 s² is ~1e-8 m/s²)."""
    a, n = 2.0, 100
    ip = Interpolator(np.array([[0, 0, 0], [0.05, 0.0, 0]]), 0.3, a)
    out = ip.advance(n)
    assert not ip.done and out["v"].max() == pytest.approx(0.3)  # cruise reached, end not
    fine = Upsampler(30, np.zeros(3), method="hermite")(out["position"], out["velocity"], T)
    x = np.concatenate([[0.0], fine[:, 0]])
    per = np.column_stack([x[0:-1:30], x[1:].reshape(n, 30)])  # each period with its start
    dt = T / 30
    acc = np.diff(per, 2, axis=1) / dt**2  # (n, 29) second differences inside each period
    expected = np.diff(np.concatenate([[0.0], out["v"]])) / T
    np.testing.assert_allclose(acc, np.repeat(expected[:, None], 29, axis=1), atol=1e-6 * a)
    assert np.abs(expected).max() == pytest.approx(a)  # the ramps run at the limit


def test_bad_input_errors() -> None:
    with pytest.raises(InputDataError, match="path"):
        Interpolator(np.zeros((1, 3)), 0.01, 1.0)
    with pytest.raises(InputDataError, match="feed"):
        Interpolator(np.array([[0, 0, 0], [1.0, 0, 0]]), 0.0, 1.0)


def test_collinear_vertices_keep_the_feed_and_corners_slow_down() -> None:
    feed, a = 0.02, 2.0  # 20 mm/s, the simulator's 2 m/s²
    # a 40 mm line sampled every 0.4 mm (Aslan's virtual-file spacing), 100 segments
    pts = np.column_stack([np.linspace(0.0, 0.04, 101), np.zeros(101), np.zeros(101)])
    ip = Interpolator(pts, feed, a)
    out = ip.advance(3000)
    assert ip.done
    v, s = out["v"], out["s"]
    ramp = feed**2 / (2 * a) + 2 * feed * T  # ramp distance + the discrete look-ahead margin
    cruise = (s > ramp) & (s < 0.04 - ramp)
    # between the ramps the programmed feed exactly (requirement: within 0.1 %)
    assert cruise.sum() > 600
    assert np.min(v[cruise]) == pytest.approx(feed, rel=1e-3)
    # a gently curved path (R = 20 mm arc sampled at 0.4 mm, 1.15° per vertex): the corner
    # limit √(a·R_δ) ≈ 0.63 m/s is far above the feed, so the cruise is at the feed too
    ang = np.arange(0, 101) * 0.4e-3 / 0.02
    arc = np.column_stack([0.02 * np.sin(ang), 0.02 * (1 - np.cos(ang)), np.zeros(101)])
    ip = Interpolator(arc, feed, a)
    out = ip.advance(3000)
    s_arc = out["s"]
    cruise = (s_arc > ramp) & (s_arc < ip.length - ramp)
    assert np.min(out["v"][cruise]) == pytest.approx(feed, rel=1e-3)
    # a 90° corner in the middle of a 20 mm + 20 mm path still slows down: junction
    # deviation δ = 0.01 mm gives v = √(a·δ·s/(1 − s)), s = sin 45°: 6.95 mm/s; the
    # discrete profile reaches it within one acceleration step a·T = 6 mm/s
    corner = np.array([[0.0, 0, 0], [0.02, 0, 0], [0.02, 0.02, 0]])
    ip = Interpolator(corner, feed, a)
    out = ip.advance(3000)
    s45 = np.sin(np.pi / 4)
    v_corner = np.sqrt(a * 1e-5 * s45 / (1 - s45))
    assert v_corner == pytest.approx(6.95e-3, rel=1e-3)
    # the period that crosses the vertex starts at most a·T above the limit (as for feed
    # changes, test above) and the profile dips to the limit there
    k = int(np.searchsorted(out["s"], 0.02))
    assert out["v"][k - 1] <= v_corner + a * T + 1e-12
    assert np.min(out["v"][k - 2 : k + 2]) == pytest.approx(v_corner, rel=1e-9)


def test_rapids_ignore_the_feed_override_but_stop_on_hold() -> None:
    """Decision 1665: a G0 segment runs at its rapid rate whatever the feed override (a CNC's
    G0 answers the rapid override), a feed move at feed × override, and a feed hold stops
    both. Path: 200 mm rapid at 0.5 m/s, then 30 mm feed at 0.02 m/s, a = 5 m/s²."""
    path = np.array([[0, 0, 0], [0.2, 0, 0], [0.23, 0, 0.0]])
    feed = np.array([0.5, 0.02])
    rapid = np.array([True, False])
    for ovr in (0.5, 1.5):
        ip = Interpolator(path, feed, 5.0, initial_override=ovr, rapid=rapid)
        out = ip.advance(1500)
        on_rapid = out["s"] < 0.2
        # the rapid reaches its own rate, neither 50 % nor 150 % of it (exact: the cap)
        assert out["v"][on_rapid].max() == pytest.approx(0.5, rel=1e-12)
        # the feed move runs at feed × override, exactly, once it settles
        assert out["v"][out["s"] > 0.21].max() == pytest.approx(0.02 * ovr, rel=1e-12)
    # without the mask the override scales the rapid too (the former behaviour)
    out = Interpolator(path, feed, 5.0, initial_override=0.5).advance(200)
    assert out["v"].max() == pytest.approx(0.25, rel=1e-12)
    # a hold in the middle of the rapid stops it within v²/(2a) + v·T (25 mm + one period)
    ip = Interpolator(path, feed, 5.0, rapid=rapid)
    first = ip.advance(60)  # 0.18 s: at 0.5 m/s
    ip.set_override(0.0)
    rest = ip.advance(300)
    assert first["v"][-1] == pytest.approx(0.5, rel=1e-12)
    assert rest["v"][-1] == 0.0
    stop = rest["s"][-1] - first["s"][-1]
    assert stop <= 0.5**2 / (2 * 5.0) + 2 * 0.5 * T + 1e-12
    assert stop >= 0.5**2 / (2 * 5.0) - 0.5 * T
    with pytest.raises(InputDataError, match="rapid mask"):
        Interpolator(path, feed, 5.0, rapid=np.array([True]))
