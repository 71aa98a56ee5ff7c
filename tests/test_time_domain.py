"""Time-domain regenerative milling simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.process.closed_forms import slot_average_forces
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import chip_thickness, milling_forces
from millsense.process.geometry import EndMill
from millsense.stability.time_domain import DirectionModes, TimeDomainMillingSim

# benchmarks.md §1 (Insperger et al. 2003): 1-DOF slotting, critical depth 0.3174 mm at
# 15 870 rev/min, chatter ≈ 932 Hz.
K_INS = CuttingCoefficients(ktc=6e8, krc=2e8)
MODE_X = DirectionModes.from_arrays([922.0], [0.011], [1.34005e6])
OMEGA = 15870.0 * 2 * math.pi / 60
A_CRIT = 0.3174e-3


def _insperger(depth_m: float) -> TimeDomainMillingSim:
    return TimeDomainMillingSim(
        EndMill(10e-3, 2),
        K_INS,
        Engagement.slot(),
        0.05e-3,
        depth_m,
        OMEGA,
        MODE_X,
        DirectionModes.rigid(),
        n_discs=1,
        steps_per_rev=100,
    )


def test_stable_slot_converges_to_static_forces() -> None:
    # At 0.3 × critical depth the cut is stable; in the periodic steady state
    # x(t) − x(t − τ) = 0, so the chip and the forces equal the static (rigid) model at the
    # same angles (0.5 % of the peak), and the mean equals the closed form (benchmarks.md §3).
    k = CuttingCoefficients(ktc=6e8, krc=2e8, kac=1e8, kte=2e4, kre=1.5e4, kae=5e3)
    tool = EndMill(10e-3, 2, helix_rad=0.3)
    sim = TimeDomainMillingSim(
        tool,
        k,
        Engagement.slot(),
        0.05e-3,
        0.3 * A_CRIT,
        OMEGA,
        MODE_X,
        DirectionModes.from_arrays([1200.0], [0.02], [3e6]),
        n_discs=10,
        steps_per_rev=100,
    )
    sim.run_revolutions(200)
    last = sim.run_revolutions(1)
    static = milling_forces(
        tool, k, Engagement.slot(), 0.05e-3, 0.3 * A_CRIT, last.spindle_angle_rad, n_discs=10
    )
    peak = np.abs(static.fy_n).max()
    assert np.max(np.abs(last.fx_n - static.fx_n)) < 5e-3 * peak
    assert np.max(np.abs(last.fy_n - static.fy_n)) < 5e-3 * peak
    ref = slot_average_forces(2, 0.3 * A_CRIT, 0.05e-3, k)
    assert np.mean(last.fx_n) == pytest.approx(float(ref[0]), rel=5e-3)
    assert np.mean(last.fy_n) == pytest.approx(float(ref[1]), rel=5e-3)
    assert np.mean(last.fz_n) == pytest.approx(float(ref[2]), rel=5e-3)
    assert sim.verdict().stable


def test_insperger_unstable_at_1p2_with_chatter_near_932hz() -> None:
    # 1.2 × critical depth: chatter (Hopf) at ≈ 932 Hz (benchmarks.md §1), within 1 %.
    sim = _insperger(1.2 * A_CRIT)
    out = sim.run_revolutions(150)
    v = sim.verdict()
    assert not v.stable
    assert sim.chatter_frequency_hz(out.x_m[-60 * 100 :]) == pytest.approx(932.0, rel=0.01)
    # The tool leaves the cut on the limit cycle: some flute passes have zero chip.
    assert np.mean(out.chip_m[-100:] == 0.0) > 0.3


def test_insperger_stable_at_0p8() -> None:
    # 0.8 × critical depth is stable (benchmarks.md §1): the Poincaré steps decay.
    sim = _insperger(0.8 * A_CRIT)
    sim.run_revolutions(150)
    v = sim.verdict()
    assert v.stable and v.multiplier_per_rev < 0.99


def _general(feed: float = 0.08e-3) -> TimeDomainMillingSim:
    tool = EndMill(
        12e-3,
        4,
        pitch_angles_rad=tuple(np.radians([80.0, 100.0, 80.0, 100.0])),
        helix_rad=0.5,
        runout_offset_m=10e-6,
        runout_angle_rad=0.4,
    )
    k = CuttingCoefficients(ktc=7e8, krc=2.5e8, kac=1e8, kte=2e4, kre=1.5e4, kae=5e3)
    return TimeDomainMillingSim(
        tool,
        k,
        Engagement.radial(4e-3, 12e-3, "down"),
        feed,
        2e-3,
        9000 * 2 * math.pi / 60,
        DirectionModes.from_arrays([700.0, 1500.0], [0.03, 0.02], [2e7, 4e7]),
        DirectionModes.from_arrays([800.0], [0.03], [2.5e7]),
        n_discs=6,
        steps_per_rev=360,
    )


def test_resume_equals_one_run() -> None:
    # State is carried exactly: two chunks give bit-identical outputs to one long run.
    a, b = _general(), _general()
    one = a.run(2000)
    c1, c2 = b.run(1234), b.run(766)
    for name in ("fx_n", "fy_n", "fz_n", "torque_nm", "x_m", "y_m", "chip_m", "time_s"):
        joined = np.concatenate([getattr(c1, name), getattr(c2, name)])
        assert np.array_equal(getattr(one, name), joined), name
    assert np.array_equal(a.poincare_xy_m, b.poincare_xy_m)


def test_rigid_tool_equals_static_model_with_runout_and_pitch() -> None:
    # Rigid structure: the regenerative surface reduces to the static chip envelope
    # (variable pitch 80/100°, helix, 60 µm runout with c = 40 µm so flutes leave the cut);
    # pitches are whole numbers of 1° bins, so forces agree to round-off.
    tool = EndMill(
        12e-3,
        4,
        pitch_angles_rad=tuple(np.radians([80.0, 100.0, 80.0, 100.0])),
        helix_rad=0.5,
        runout_offset_m=60e-6,
        runout_angle_rad=0.4,
    )
    k = CuttingCoefficients(ktc=7e8, krc=2.5e8, kac=1e8, kte=2e4, kre=1.5e4, kae=5e3)
    eng = Engagement.radial(4e-3, 12e-3, "down")
    sim = TimeDomainMillingSim(
        tool,
        k,
        eng,
        40e-6,
        2e-3,
        600.0,
        DirectionModes.rigid(),
        DirectionModes.rigid(),
        n_discs=6,
        steps_per_rev=360,
    )
    out = sim.run(720)
    static = milling_forces(tool, k, eng, 40e-6, 2e-3, out.spindle_angle_rad, n_discs=6)
    assert np.allclose(out.fx_n, static.fx_n, atol=1e-9)
    assert np.allclose(out.fy_n, static.fy_n, atol=1e-9)
    assert np.allclose(out.torque_nm, static.torque_nm, atol=1e-12)
    h = chip_thickness(tool, eng, 40e-6, out.spindle_angle_rad, tool.discs(2e-3, 6))
    assert np.allclose(out.chip_m, h.max(axis=2), atol=1e-15)
    assert np.any(h.max(axis=(0, 2)) == 0.0)  # one flute misses the cut altogether


def test_exact_modal_discretisation() -> None:
    # Free response of one mode over one step equals the analytic damped oscillation.
    m = DirectionModes.from_arrays([500.0], [0.05], [1e6])
    ad, bd = m.discrete(1e-4)
    w = 2 * math.pi * 500.0
    wd = w * math.sqrt(1 - 0.05**2)
    t = 1e-4
    x_free = math.exp(-0.05 * w * t) * (math.cos(wd * t) + 0.05 * w / wd * math.sin(wd * t))
    assert ad[0, 0, 0] == pytest.approx(x_free, rel=1e-12)
    # Static gain: a constant force held long enough gives F/k.
    s = np.zeros(2)
    for _ in range(20000):
        s = ad[0] @ s + bd[0] * 1.0
    assert s[0] == pytest.approx(1e-6, rel=1e-6)


def test_time_domain_validation_cases() -> None:
    # The registered time-domain cases (benchmarks.md §1 references) pass.
    from millsense.validation import run_case, select_cases

    cases = select_cases("stability.time_domain*", quick_only=True)
    assert len(cases) == 2
    for c in cases:
        r = run_case(c)
        assert r.passed, (c.id, r.measured, r.error)


def test_converged_cut_at_flip_lobe_peak_is_stable() -> None:
    # 8800 rev/min slotting, 0.9 × the SDM flip depth (2.635 mm, spectral radius 0.85 per tooth
    # at m = 100): the run converges and its Poincaré steps sit at round-off (~3e-9 of the
    # RMS); the verdict must call that converged, not growing
    # (docs/decisions/0017-time-domain-stability-verdict.md).
    from millsense.validation.cases.stability_time_domain import _td_sim

    sim = _td_sim(1.0, "down", 8800.0, 0.9 * 2.635e-3)
    sim.run_revolutions(400)
    assert sim.verdict(last_revolutions=200).stable


def test_flip_chatter_of_two_flute_tool_is_detected() -> None:
    # Period doubling of a 2-flute uniform tool repeats once per revolution; sampled once per
    # tooth period it is seen (a/D = 0.05, 18 200 rev/min, SDM flip depth ≈ 1.087 mm).
    from millsense.validation.cases.stability_time_domain import _td_sim

    sim = _td_sim(0.05, "down", 18200.0, 1.3e-3)
    assert sim.poincare_period_steps == sim.steps_per_rev // 2
    sim.run_revolutions(400)
    assert not sim.verdict(last_revolutions=200).stable


def test_entry_after_air_never_takes_an_uncut_bin_as_a_chip() -> None:
    """Decision 1796: a 3-flute Ø12 mm slot entered after air (11000 rev/min, 111 steps per
    revolution, a 1380/1450 Hz tool) — the rigid pass that lays the disc's surface missed a
    bin where a flute's angle later rounds onto the slot's edge, the flute took the never-cut
    surface (−1e30 m) as its chip and the simulation blew up within a third of a revolution
    (1e28 m of vibration) at most entry steps. A chip is now never larger than a physical one:
    twice the feed per tooth plus the limit cycle's vibration (80 µm measured, standalone)."""
    cc = CuttingCoefficients(ktc=758e6, krc=0.4 * 758e6)
    mx = DirectionModes.from_arrays([1380.0], [0.012], [3.0e6])
    my = DirectionModes.from_arrays([1450.0], [0.015], [3.5e6])
    for n_air in (30224, 30231, 30238, 30245):  # entry steps that blew up before the fix
        air = Engagement(layers=((),))
        td = TimeDomainMillingSim(EndMill(12e-3, 3), cc, air, 0.05e-3, 0.28e-3, 1151.897,
                                  mx, my, n_discs=1, steps_per_rev=111)  # fmt: skip
        td.run(n_air)
        td.set_engagement(Engagement.slot())
        td.lay_surface(np.array([True]))
        ch = td.run(300)
        assert np.all(np.isfinite(ch.x_m))
        assert float(np.max(ch.chip_m)) < 2 * 0.05e-3 + 0.2e-3
