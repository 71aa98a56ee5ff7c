"""Tests of the Aslan Ch. 4 accelerometer fusion estimator (estimation.fusion)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from millsense.estimation.accel.fusion import (
    AccelFusionBlock,
    DoubleIntegrator,
    DynamicsMap,
    MapNode,
    design_fusion,
    fusion_weights,
    run_fusion,
    weight_firs,
)
from millsense.ident.modal_fit import fit_modes
from millsense.streaming.block import Chunk
from millsense.validation.cases._accel_sim import ModeSet, simulate_foh

FS = 8192.0


def _fit(alpha: tuple[float, ...]):  # type: ignore[no-untyped-def]
    modes = ModeSet((620.0, 980.0, 1450.0), (0.03, 0.025, 0.03), alpha)
    f = np.arange(1.0, 2001.0)
    return modes, fit_modes((f, modes.receptance(f)), (200.0, 1800.0), n_modes=3)


@pytest.fixture(scope="module")
def two_sensors():  # type: ignore[no-untyped-def]
    return _fit((0.15, 0.6, 0.3)), _fit((0.05, 0.2, 0.8))


def test_double_integrator_matches_closed_form() -> None:
    # ideal double integration of a sinusoid: −a/ω² times the analog leak s²/(s + ω_hp)²;
    # Numerov's numerator keeps the discrete error under 1 % up to f_s/7 (1.17 kHz)
    di = DoubleIntegrator(FS, 150.0)
    f = 1000.0
    h = di.frf(np.array([f]))[0]
    s = 2j * np.pi * f
    wc = 2 * np.pi * 150.0
    ideal = 1.0 / (s + wc) ** 2
    # the leak is bilinear: its own warping at 1 kHz is (tan(πfΔt)/(πfΔt))-sized, < 1 % here
    assert abs(h / ideal - 1) < 0.02
    t = np.arange(8192) / FS
    y = di.process(np.sin(2 * np.pi * f * t))
    assert np.max(np.abs(y[4000:])) == pytest.approx(abs(h), rel=0.01)


def test_weights_sum_to_one_and_firs_to_a_delay(two_sensors) -> None:  # type: ignore[no-untyped-def]
    # Aslan Eq. 4.10: Σ_m w_m(ω) = 1; the linear FIR design then sums to a pure delay
    fits = [two_sensors[0][1], two_sensors[1][1]]
    w = fusion_weights(fits, np.linspace(0, 4000, 50))
    np.testing.assert_allclose(w.sum(axis=0), 1.0, atol=1e-12)
    h = weight_firs(fits, FS, 65)
    total = h.sum(axis=0)
    expect = np.zeros(65)
    expect[32] = 1.0
    np.testing.assert_allclose(total, expect, atol=1e-12)
    # sensor 2 dominates near 1450 Hz (α 0.8 vs 0.3)
    assert fusion_weights(fits, np.array([1450.0]))[1, 0] > 0.6


def test_map_selects_nearest_node(two_sensors) -> None:  # type: ignore[no-untyped-def]
    fit = two_sensors[0][1]
    nodes = tuple(
        MapNode(n, load, (fit,), fit) for n in (7500.0, 9000.0) for load in (0.0, 50.0, 100.0)
    )
    node = DynamicsMap(nodes).select(8900.0, 37.0)
    assert (node.speed_rpm, node.load_n) == (9000.0, 50.0)


def test_fusion_recovers_a_tooth_force_on_exact_models(two_sensors) -> None:  # type: ignore[no-untyped-def]
    # exact identified models, no noise: a force of harmonics at 300/600/900 Hz is recovered
    # within 3 % RMS of the force seen through the integrator's leak s²/(s + ω_hp)² (the only
    # other differences are the discrete filters)
    (m1, f1), (m2, f2) = two_sensors
    node = MapNode(9000.0, 0.0, (f1, f2), f1)
    filt = design_fusion(node, FS, 9000.0, [1e-16, 1e-16], highpass_hz=100.0)
    over = 4
    t = np.arange(round(0.5 * FS * over)) / (FS * over)
    force = sum(
        a * np.sin(2 * np.pi * f * t + p)
        for a, f, p in ((300, 300, 0.1), (150, 600, 1), (80, 900, 2))
    )
    acc = np.vstack(
        [simulate_foh(m.accelerance_ss(), force, 1 / (FS * over))[::over] for m in (m1, m2)]
    )
    res = run_fusion(filt, acc)
    d = res.delay_samples
    wc = 2 * np.pi * 100.0
    b_hp, a_hp = scipy.signal.bilinear([1.0, 0.0, 0.0], [1.0, 2 * wc, wc * wc], FS)
    ref = scipy.signal.lfilter(b_hp, a_hp, force[::over])
    est = res.force[d:]
    tail = slice(2000, est.size)
    err = np.sqrt(np.mean((est[tail] - ref[: est.size][tail]) ** 2)) / np.sqrt(
        np.mean(ref[tail] ** 2)
    )
    assert err < 0.03


def test_block_matches_record_run(two_sensors) -> None:  # type: ignore[no-untyped-def]
    (_m1, f1), (_m2, f2) = two_sensors
    filt = design_fusion(MapNode(9000.0, 0.0, (f1, f2), f1), FS, 9000.0, [1e-14, 1e-14])
    rng = np.random.default_rng(1)
    acc = rng.standard_normal((2, 3000))
    ref = run_fusion(filt, acc)
    blk = AccelFusionBlock("fus", ["a1", "a2"], filt)
    blk.reset(FS)
    out = []
    for s in range(0, 3000, 333):
        o = blk.process(Chunk(s, FS, 0.0, {"a1": acc[0, s : s + 333], "a2": acc[1, s : s + 333]}))
        out.append(o.channels["fusion_force"])
    np.testing.assert_allclose(
        np.concatenate(out), ref.force, rtol=1e-9, atol=1e-9 * np.abs(ref.force).max()
    )
    assert blk.delay_samples == 64 + 4
    assert math.isfinite(float(ref.displacement[-1]))
