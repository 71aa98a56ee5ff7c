"""Contact detection and the Gauss–Newton circle fit (seed 004 ch. 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.monitoring.contact import detect_contact, fit_circle
from millsense.validation.cases.monitoring_contact import FS, PERIOD_S, TABLE_3_2, simulate_contact


def test_circle_fit_exact_and_table_3_2():
    th = np.radians([10.0, 50.0, 95.0, 170.0])
    f = fit_circle(3.0 + 31.0 * np.cos(th), -2.0 + 31.0 * np.sin(th))
    assert (f.x_c, f.y_c, f.diameter) == pytest.approx((3.0, -2.0, 62.0), abs=1e-9)
    pts = np.array(TABLE_3_2)
    g = fit_circle(pts[:, 0], pts[:, 1])
    # digest V5 refit: centre (−30.971, 1.235), D = 61.991 mm, residuals ≤ 1.2 µm
    assert g.x_c == pytest.approx(-30.971, abs=1e-3)
    assert g.y_c == pytest.approx(1.235, abs=1e-3)
    assert g.diameter == pytest.approx(61.991, abs=1e-3)
    assert np.max(np.abs(g.residuals)) < 1.3e-3
    with pytest.raises(InputDataError, match="collinear"):
        fit_circle(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    with pytest.raises(InputDataError, match="≥ 3"):
        fit_circle(np.array([0.0, 1.0]), np.array([0.0, 1.0]))


def test_contact_detected_within_a_few_micrometres():
    cut, air, pos = simulate_contact(3, surface_mm=0.25)
    c = detect_contact(cut, air, pos, FS, PERIOD_S)
    # the line through the rise crosses η a few µm from the true surface (0.25 mm)
    assert c.position == pytest.approx(0.25, abs=0.008)
    assert c.index_b < c.index_a and c.slope > 0 and math.isfinite(c.kappa)


def test_contact_bad_input():
    cut, air, pos = simulate_contact(4)
    with pytest.raises(InputDataError, match="no contact"):
        detect_contact(air, air, pos, FS, PERIOD_S)
    with pytest.raises(InputDataError, match="one length"):
        detect_contact(cut[:-1], air, pos, FS, PERIOD_S)
    with pytest.raises(InputDataError, match="reference revolution"):
        detect_contact(cut[:1000], air[:1000], pos[:1000], FS, PERIOD_S)


def test_contact_block_streams_like_the_batch_detector():
    from millsense.monitoring.contact import make_contact_block
    from millsense.streaming.block import Chunk

    cut, air, pos = simulate_contact(5)
    ref = detect_contact(cut, air, pos, FS, PERIOD_S)
    data = {"spindle/torque_cmd": cut, "x/position": pos}
    for chunk in (1000, 7777):
        block = make_contact_block(air_torque_nm=air, period_s=PERIOD_S)
        block.reset(FS)
        events = []
        for i in range(0, cut.size, chunk):
            out = block.process(Chunk(i, FS, 0.0, {k: v[i : i + chunk] for k, v in data.items()}))
            events += out.events
        assert len(events) == 1 and events[0].name == "contact"
        # the centred average near A is complete: the same contact as the whole record
        assert events[0].value == pytest.approx(ref.position, abs=1e-9)


def test_air_cut_is_a_separate_run_with_its_own_ripple():
    """Decision 1780: the air cut's ripple is the cut's shifted by its own start error and
    drifting by a few %, not a bit-identical copy; with no start error and no drift it is."""
    from millsense.validation.cases import monitoring_contact as mc

    ideal = {"start_jitter_s": 0.0, "c_return_rad": 0.0, "ripple_drift": 0.0}
    cut0, air0, _ = simulate_contact(6, **ideal)
    cut1, air1, _ = simulate_contact(6)
    # the contact torque and the noise are the same in both calls: the differences are the
    # ripple's alone, and each record's is its own
    d_cut, d_air = cut1 - cut0, air1 - air0
    assert np.any(d_cut != 0.0) and np.any(d_air != 0.0)
    assert not np.array_equal(d_cut, d_air)
    # what the subtraction leaves of the ripple: a few mN·m, within 3 RMS of each record's
    # drift and twice the largest start error (at each harmonic's order)
    resid = (cut1 - air1) - (cut0 - air0)
    shift = 2 * math.pi * mc.START_JITTER_S / PERIOD_S + 3 * mc.C_RETURN_RAD
    bound = sum(a * (2 * 3 * mc.RIPPLE_DRIFT + 2 * h * shift) for h, a in mc.RIPPLE_NM)
    assert 1e-4 < np.max(np.abs(resid)) < bound
