"""Depth of cut, runout and K_t from torque harmonics (seed 004 ch. 2): the harmonic model
against the process model, exact recovery, the N = 2 system, streaming and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.monitoring.engagement import EngagementBlock, make_engagement_block
from millsense.monitoring.torque_spectrum import (
    SpectrumIdentifier,
    ToolGeometry,
    runout_harmonic,
    solve_runout,
    static_harmonics,
)
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.validation.cases.monitoring_breakage import run_block

R = 3e-3
BETA = math.radians(35.0)
C = 25e-6


def _torque(n, dr, da, rho=0.0, lam=0.7, kte=0.0, m=1000, n_discs=200):
    tool = EndMill(2 * R, n, helix_rad=BETA, runout_offset_m=rho, runout_angle_rad=lam)
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=kte)
    phi = 2 * np.pi * np.arange(m) / m
    f = milling_forces(tool, co, Engagement.radial(dr, 2 * R, "down"), C, da, phi, n_discs)
    return np.fft.fft(f.torque_nm) / m


def test_harmonic_model_matches_the_process_model():
    """Lee Eqs. 2.11-2.13 with errata V1 (height r/tanβ, factor N) and V2 (sign) restored
    agree with the sliced process model of the simulator."""
    x = _torque(4, 1.5e-3, 1.5e-3, rho=0.3e-6)
    g = ToolGeometry(4, R, BETA)
    st = math.acos(1.5e-3 / R - 1)
    k = 4 * np.arange(1, 4, dtype=float)
    mod = static_harmonics(k, 1.5e-3, st, math.pi, g, 758e6, C)
    np.testing.assert_allclose(x[k.astype(int)], mod, rtol=2e-3)
    t1 = runout_harmonic(0.3e-6 * np.exp(-0.7j), 1.5e-3, st, math.pi, g, 758e6)
    assert abs(x[1] - t1) / abs(t1) < 0.03


@pytest.mark.parametrize(
    ("n", "dr", "da"), [(4, 1.5e-3, 1.5e-3), (4, 0.5e-3, 3e-3), (1, 1e-3, 2e-3), (2, 3e-3, 1e-3)]
)
def test_exact_recovery_without_noise(n, dr, da):
    """Digest V4/[S]: noiseless data → d_a, d_r to a few µm, K_t and K_e to 1 %."""
    x = _torque(n, dr, da, kte=25e3)
    ident = SpectrumIdentifier(ToolGeometry(n, R, BETA), 60 // n)
    e = ident.identify(x[n * np.arange(1, 60 // n + 1)], complex(x[1]), C)
    assert e.axial_depth_m == pytest.approx(da, abs=5e-6)
    assert e.radial_depth_m == pytest.approx(dr, abs=5e-6)
    assert e.kt_n_m2 == pytest.approx(758e6, rel=0.01)
    assert e.edge_n_m == pytest.approx(25e3, rel=0.01)
    assert e.reliability > 0.99


def test_runout_four_flutes_and_two_flutes():
    """Eq. 2.18 (N ≥ 3, constant ω_n²/2 per V1) and the re-derived N = 2 system (V3)."""
    x = _torque(4, 1e-3, 0.5e-3, rho=1.5e-6)
    ident = SpectrumIdentifier(ToolGeometry(4, R, BETA), 15)
    e = ident.identify(x[4 * np.arange(1, 16)], complex(x[1]), C)
    assert e.runout_m == pytest.approx(1.5e-6, abs=0.1e-6)
    assert e.runout_angle_rad == pytest.approx(0.7, abs=0.05)
    # N = 2: the forward model inverted exactly where the system is well conditioned
    g = ToolGeometry(2, R, BETA)
    w = 4.4e-6 * np.exp(-0.7j)
    t1 = runout_harmonic(w, 5e-3, 2.0, math.pi, g, 758e6)
    assert solve_runout(t1, 5e-3, 2.0, math.pi, g, 758e6) == pytest.approx(w, abs=1e-9)


def test_block_per_revolution_and_chunk_invariance():
    fs, rpm = 10000.0, 1200.0
    omega = rpm * 2 * math.pi / 60
    t = np.arange(int(0.3 * fs)) / fs
    tool = EndMill(2 * R, 4, helix_rad=BETA, runout_offset_m=1.5e-6, runout_angle_rad=0.7)
    co = CuttingCoefficients(ktc=758e6, krc=379e6)
    eng = Engagement.radial(3e-3, 2 * R, "down")
    f = milling_forces(tool, co, eng, C, 0.5e-3, omega * t, n_discs=60)
    data = {"spindle/torque_est": f.torque_nm, "spindle/speed": np.full(t.size, omega)}

    def run(chunk):
        b = EngagementBlock(4, 6.0, 35.0, feed_per_tooth_mm=0.025, n_harmonics=15)
        _, ch = run_block(b, data, chunk)
        return b, ch

    b, ch = run(t.size)
    assert len(b.estimates) == 5  # 6 revolutions of 50 ms; the last is not complete
    e = b.estimates[-1][1]
    assert e is not None
    assert e.axial_depth_m == pytest.approx(0.5e-3, rel=0.03)
    assert e.radial_depth_m == pytest.approx(3e-3, rel=0.03)
    assert e.runout_m == pytest.approx(1.5e-6, abs=0.3e-6)
    assert np.isnan(ch["engagement/axial_depth"][0])  # nothing before the first revolution
    for chunk in (7, 100):
        _, ch2 = run(chunk)
        for k in ch:
            np.testing.assert_allclose(ch2[k], ch[k], rtol=1e-9, equal_nan=True)


def test_bad_options():
    with pytest.raises(ConfigError, match="helix_deg"):
        EngagementBlock(4, 6.0, 0.0, feed_per_tooth_mm=0.025)
    with pytest.raises(ConfigError, match="feed"):
        make_engagement_block(n_flutes=4, diameter_mm=6.0, helix_deg=35.0)
    with pytest.raises(ConfigError, match="n_flutes"):
        EngagementBlock(0, 6.0, 35.0, feed_per_tooth_mm=0.025)
