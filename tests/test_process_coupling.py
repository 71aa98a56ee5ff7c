"""Process coupling: per-sample chip load forces, engagement schedules, injected events."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.simulator.process_coupling import (
    AirCut,
    DepthStep,
    EngagementSchedule,
    EngagementSegment,
    ProcessCoupling,
    StaticForceModel,
    ToothBreak,
    block_forces,
)

TOOL = EndMill(20e-3, 2, helix_rad=0.5, runout_offset_m=10e-6)
K = CuttingCoefficients(ktc=758e6, krc=379e6, kac=100e6, kte=25e3, kre=35e3, kae=5e3)


def test_static_kernel_equals_milling_forces_at_constant_feed() -> None:
    # independent computation: the package's vectorised force model
    ang = np.linspace(0.0, 20.0, 700)
    eng = Engagement.radial(5e-3, 20e-3)
    ref = milling_forces(TOOL, K, eng, 0.1e-3, 4e-3, ang, n_discs=10)
    out = StaticForceModel(TOOL, K, 10).forces(
        0, eng, 4e-3, ang, np.full(700, 0.1e-3), np.zeros((700, 2))
    )
    scale = np.abs(ref.fx_n).max()
    assert np.allclose(out[:, 0], ref.fx_n, atol=1e-10 * scale)
    assert np.allclose(out[:, 1], ref.fy_n, atol=1e-10 * scale)
    assert np.allclose(out[:, 2], ref.fz_n, atol=1e-10 * scale)
    assert np.allclose(out[:, 3], ref.torque_nm, atol=1e-10 * np.abs(ref.torque_nm).max())


def test_per_sample_feed_matches_sample_wise_reference() -> None:
    # each sample with its own c equals milling_forces evaluated at that c alone
    ang = np.array([0.3, 1.1, 2.0, 2.7])
    c = np.array([0.05e-3, 0.1e-3, 0.15e-3, 0.2e-3])
    fx, _fy, _fz, tq = block_forces(TOOL, K, Engagement.slot(), c, 3e-3, ang, None, 10)
    for i in range(4):
        r = milling_forces(TOOL, K, Engagement.slot(), c[i], 3e-3, ang[i : i + 1], n_discs=10)
        assert fx[i] == pytest.approx(r.fx_n[0], rel=1e-12, abs=1e-9)
        assert tq[i] == pytest.approx(r.torque_nm[0], rel=1e-12, abs=1e-12)


def test_broken_tooth_mean_torque_closed_form() -> None:
    # slot, straight flutes, no runout: mean torque per revolution
    # T = R·a·(N·Ktc·c/π + N·Kte/2); one flute gone: the other cuts 2c, T = R·a·(2Ktc·c/π + Kte/2)
    tool = EndMill(20e-3, 2)
    k = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    ang = np.linspace(0, 2 * math.pi, 4000, endpoint=False)
    c, a, r = 0.1e-3, 2e-3, 10e-3
    loss = np.zeros((4000, 2))
    _, _, _, t_ok = block_forces(tool, k, Engagement.slot(), np.full(4000, c), a, ang, loss, 4)
    loss[:, 0] = r + 1e-3
    _, _, _, t_br = block_forces(tool, k, Engagement.slot(), np.full(4000, c), a, ang, loss, 4)
    assert t_ok.mean() == pytest.approx(r * a * (2 * k.ktc * c / math.pi + k.kte), rel=1e-3)
    assert t_br.mean() == pytest.approx(r * a * (2 * k.ktc * c / math.pi + k.kte / 2), rel=1e-3)


def test_schedule_events_and_errors() -> None:
    sched = EngagementSchedule.from_spec("ae_mm=5,up", 20e-3, 2e-3, start_m=0.01)
    idx, depth = sched.at(np.array([0.0, 0.02]))
    assert list(idx) == [0, 0] and list(depth) == [0.0, 2e-3]  # air before the start
    proc = ProcessCoupling(
        TOOL, K, sched, events=[DepthStep(1.0, 4e-3), AirCut(2.0, 3.0), ToothBreak(0.5, 1)]
    )
    t = np.array([0.5, 1.5, 2.5, 3.5])
    idx, depth = proc.engagement_at(np.full(4, 0.05), t)
    assert list(depth) == [2e-3, 4e-3, 0.0, 4e-3]
    assert list(idx) == [0, 0, -1, 0]
    assert proc.radius_loss(t)[:, 1].min() > TOOL.radius_m  # broken: the flute is gone
    assert proc.breakage_time_s == 0.5
    with pytest.raises(ConfigError, match="--engagement"):
        EngagementSchedule.from_spec("half", 20e-3, 2e-3)
    with pytest.raises(ConfigError, match="flute 3"):
        ProcessCoupling(TOOL, K, sched, events=[ToothBreak(0.1, 3)])


def test_schedule_lookup_equals_searchsorted() -> None:
    """The compiled segment lookup of :meth:`EngagementSchedule.at` (speed work, issue 12)
    against its NumPy definition — the last segment with start ≤ s, the air entry before the
    first — on random arc lengths and on the segment starts themselves (equal starts: the
    later segment wins)."""
    sch = EngagementSchedule(
        (Engagement.slot(), Engagement.radial(5e-3, 20e-3)),
        (
            EngagementSegment(0.001, 0, 2e-3),
            EngagementSegment(0.005, 1, 3e-3),
            EngagementSegment(0.005, 0, 0.0),
            EngagementSegment(0.01, 1, 1e-3),
        ),
    )
    rng = np.random.default_rng(2)
    s = np.concatenate([rng.uniform(-0.002, 0.02, 500), [0.001, 0.005, 0.01, -1.0, 1.0]])
    k = np.searchsorted(np.array([0.001, 0.005, 0.005, 0.01]), s, side="right") - 1
    k[k < 0] = 4
    idx, depth = sch.at(s)
    assert np.array_equal(idx, np.array([0, 1, 0, 1, 0])[k])
    assert np.array_equal(depth, np.array([2e-3, 3e-3, 0.0, 1e-3, 0.0])[k])
