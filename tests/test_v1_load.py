"""The V1 cut's realistic load (decision 1710): runout, the truth spindle's speed, the entry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.validation.cases._v1_load import V1_RUNOUT_M, entry_immersion, v1_feed, v1_load
from millsense.validation.cases.estimation_feed_drive import FS_HZ, _harmonic_error

#: 3000 rev/min, 2 flutes: 100 samples per tooth, 200 per revolution at 10 kHz
RPM = 3000.0
N_AIR, N_STEADY = 2000, 6000


def test_entry_arc_closed_form() -> None:
    r = 0.01
    assert entry_immersion(r, r) is None  # edge on the cutter's front: no contact yet
    assert entry_immersion(0.0, r) == pytest.approx((0.0, math.pi))  # half circle
    # edge R/2 ahead of the centre: R sin φ ≥ R/2 for φ in [π/6, 5π/6]
    assert entry_immersion(0.5 * r, r) == pytest.approx((math.pi / 6, 5 * math.pi / 6))
    assert entry_immersion(-0.003, r) == pytest.approx((0.0, math.pi))  # centre past the edge


def test_v1_runout_makes_the_force_periodic_per_revolution_not_per_tooth() -> None:
    # constant speed, full engagement: without runout the two teeth load the table alike (the
    # per-tooth means agree to rounding); with 37 µm (seed 000 Ch. 4.5: 35-40 µm on Aslan's
    # Ø20 mm 2-flute) the chips are 0.2 ± ~0.07 mm and the tooth means differ by hundreds of N,
    # while whole revolutions still repeat
    ideal = v1_load(RPM, N_AIR, N_STEADY, FS_HZ, runout_m=0.0, spindle=False, entry=False)
    real = v1_load(RPM, N_AIR, N_STEADY, FS_HZ, spindle=False, entry=False)
    assert V1_RUNOUT_M == pytest.approx(37e-6)
    for load, lo, hi in ((ideal, 0.0, 1e-6), (real, 100.0, 1e4)):
        fx = load.table_x[load.n_full : load.n_full + 40 * 100].reshape(40, 100)
        means = fx.mean(axis=1)
        assert lo <= abs(means[0] - means[1]) <= hi
        # whole revolutions (2 teeth) repeat to rounding in both
        np.testing.assert_allclose(means[::2], means[0], atol=1e-6)


def test_v1_spindle_speed_dips_at_the_entry_and_ripples_in_the_cut() -> None:
    load = v1_load(RPM, N_AIR, N_STEADY, FS_HZ)
    w = RPM * 2 * math.pi / 60
    s = load.tool_speed
    steady = s[load.n_full + 2000 :]
    # in air the truth spindle holds the command (its velocity PI, after the run-up)
    assert np.max(np.abs(s[: N_AIR - 10] / w - 1)) < 1e-3
    # in the cut the speed ripples (tooth torque through the structure and the velocity loop)
    # but the PI's integral keeps its mean: ripple > 0.01 %, mean within 0.1 %
    assert np.std(steady) / w > 1e-4
    assert abs(np.mean(steady) / w - 1) < 1e-3
    # the fixed point torque → angle → torque has converged to well below a newton
    assert load.pass_change < 0.5


def test_v1_entry_grows_over_r_over_the_feed() -> None:
    load = v1_load(RPM, N_AIR, N_STEADY, FS_HZ)
    n_entry = load.n_full - load.n_air
    # R / v_f: 10 mm at 0.2 mm/tooth × 2 × 50 rev/s = 20 mm/s → 0.5 s
    assert v1_feed(RPM) == pytest.approx(0.02)
    assert n_entry == round(0.01 / 0.02 * FS_HZ)
    assert np.all(load.table_x[: load.n_air] == 0.0)
    res = np.hypot(load.table_x, load.table_y)
    entry, steady = res[load.n_air : load.n_full], res[load.n_full :]
    tenth = n_entry // 10
    # the engaged arc grows from nothing to the half circle: the mean resultant of the entry's
    # first tenth (arc up to 2·acos(0.9) = 52° about the feed direction) is below 0.4 of the
    # steady slot's (measured 0.29), its last tenth above 0.8 (measured 0.92)
    assert np.mean(entry[:tenth]) < 0.4 * np.mean(steady)
    assert np.mean(entry[-tenth:]) > 0.8 * np.mean(steady)


def test_harmonic_error_on_whole_revolutions_ignores_the_spindle_orders() -> None:
    # 99 tooth periods (49.5 revolutions) of 100 Hz: a spindle-order line at 50 Hz (runout)
    # leaks onto the tooth lines of a whole-tooth-period window, not of a whole-revolution one
    f_t = 100.0
    t = np.arange(9950) / FS_HZ
    true = 300 * np.cos(2 * np.pi * f_t * t)
    est = true + 100 * np.cos(2 * np.pi * 0.5 * f_t * t + 0.3)
    assert _harmonic_error(est, true, f_t, teeth=2) == pytest.approx(0.0, abs=1e-9)
    assert _harmonic_error(est, true, f_t, teeth=1) > 1e-3
