"""Position-dependent disturbance modes in the feed-drive simulator (issue 7)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim
from millsense.simulator.machine_file import simulator_machine

FS = 10_000.0


def _axis(**kw: object) -> FeedAxisConfig:
    ax = simulator_machine("quaser-ux600").axis("z")
    return ax.model_copy(update=kw)


def test_config_key_converted_to_si() -> None:
    # 0.889 %/100 mm (±2 % over a 450 mm stroke) = 0.0889 per metre; reference 25 mm = 0.025 m
    p = FeedDriveParams.from_config(_axis(mode_shift_pct_per_100mm=0.889, mode_reference_mm=25.0))
    assert p.mode_shift_per_m == pytest.approx(0.0889, rel=1e-12)
    assert p.mode_reference_position == pytest.approx(0.025, rel=1e-12)
    # default: no position dependence
    assert FeedDriveParams.from_config(_axis()).mode_shift_per_m == 0.0


def test_rotary_axis_rejects_the_linear_key() -> None:
    ax = simulator_machine("quaser-ux600").axis("a")
    with pytest.raises(ValueError, match="mode_shift_pct_per_100mm"):
        FeedAxisConfig.model_validate({**ax.model_dump(), "mode_shift_pct_per_100mm": 1.0})


def test_modes_at_closed_form() -> None:
    # f_k(x) = f_k0·(1 + κ(x − x_ref)): κ = 0.1/m, x = 0.2 m, x_ref = 0 → every frequency × 1.02,
    # static gain Φ(0) = D + Σ α/ω² unchanged (α × λ²), Φ(s; λ) = Φ_0(s/λ)
    p = replace(FeedDriveParams.from_config(_axis()), mode_shift_per_m=0.1)
    m0, m = p.modes, p.modes_at(0.2)
    assert m0 is not None and m is not None
    np.testing.assert_allclose(m.frequency_hz, 1.02 * m0.frequency_hz, rtol=1e-14)
    assert m.static_gain() == pytest.approx(m0.static_gain(), rel=1e-12)
    f = np.array([10.0, 100.0, 183.3])
    np.testing.assert_allclose(m.frf_modal(1.02 * f), m0.frf_modal(f), rtol=1e-12)


def _held_run(p: FeedDriveParams, x: float, load: np.ndarray, chunks: list[int]) -> np.ndarray:
    sim = FeedDriveSim(p, FS, seed=3, initial_angle_rad=x / p.transmission)
    n = len(load)
    ref = np.full(n, x / p.transmission)
    parts = []
    for a, b in zip([0, *chunks], [*chunks, n], strict=True):
        parts.append(sim.advance(ref[a:b], np.zeros(b - a), load[a:b])["load_torque_motor"])
    return np.concatenate(parts)


def test_simulated_modes_follow_the_position() -> None:
    # axis held at x = 0.15 m with κ = 0.2/m (λ = 1.03): the motor-side load torque τ_c of the
    # kernel (closed-form block re-discretisation every 1 ms) equals an independent per-substep
    # simulation of modes_at(x) discretised by scipy expm; the held axis trembles by µm, so λ
    # differs from 1.03 by < 1e-6 and the responses agree to 1e-4 of their range
    p = replace(FeedDriveParams.from_config(_axis(current_noise_a=0.0)), mode_shift_per_m=0.2)
    x = 0.15
    n = 400
    rng = np.random.default_rng(0)
    load = rng.standard_normal(n) * 300.0
    tau_c = _held_run(p, x, load, [])
    m = p.modes_at(x)
    assert m is not None
    sub = 10
    ad, bd = m.discretise(1.0 / FS / sub)
    xd = np.zeros((m.a.shape[0], 2))
    ref = np.empty(n)
    lg = p.transmission / p.efficiency
    for k in range(n):
        ta = lg * load[k]
        for _ in range(sub):
            tc = m.d * ta + float(np.sum(m.c * xd))
            xd = np.einsum("kij,kj->ki", ad, xd) + bd * ta
        ref[k] = tc
    np.testing.assert_allclose(tau_c, ref, atol=1e-4 * np.ptp(ref))
    # and it is not the reference-position response (the shift is visible: > 1 % of the range)
    m_ref = p.modes_at(0.0)
    assert m_ref is not None
    assert not np.allclose(m_ref.frequency_hz, m.frequency_hz, rtol=0.02)


def test_position_dependence_is_chunking_invariant() -> None:
    # mode updates are counted in absolute samples: any chunking gives bit-identical output
    p = replace(FeedDriveParams.from_config(_axis()), mode_shift_per_m=0.5)
    n = 2500
    load = 200.0 * np.sin(2 * math.pi * 90.0 * np.arange(n) / FS)
    whole = _held_run(p, 0.1, load, [])
    np.testing.assert_array_equal(_held_run(p, 0.1, load, [1, 7, 13, 1001, 1999]), whole)


def test_overdamped_modes_rejected() -> None:
    from millsense.models.modal_ss import ModalStateSpace

    p = replace(
        FeedDriveParams.from_config(_axis()),
        modes=ModalStateSpace.from_modes([50.0], [1.5], [1e4], [0.0]),
        mode_shift_per_m=0.1,
    )
    with pytest.raises(ConfigError, match="underdamped"):
        FeedDriveSim(p, FS)
