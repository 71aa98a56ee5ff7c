"""The held-out chatter cases' own machinery (decision 1795): the reference chatter frequency
is read without the monitors' estimator, the default stream is the one the monitor's constants
were set on, and the held-out conditions differ from it."""

from __future__ import annotations

import math

import numpy as np

from millsense.core.config import ToolConfig
from millsense.core.presets import load_preset
from millsense.process.geometry import EndMill
from millsense.validation.cases import monitoring_chatter as mc


def test_truth_chatter_frequency_reads_a_line_between_bins_without_peak_interpolation() -> None:
    t = np.arange(8192) / mc.FS_HZ
    rpm = 6000.0  # 100 Hz spindle: its harmonics are masked even when stronger
    f_c = 1234.567  # between the 2.44 Hz bins of a 4096-point window
    x = 5.0 * np.cos(2 * math.pi * 1200.0 * t) + np.cos(2 * math.pi * f_c * t + 0.3)
    assert abs(mc.simulated_chatter_hz(x, rpm) - f_c) < 0.05  # the 0.038 Hz grid
    y = 2.0 * np.cos(2 * math.pi * 777.7 * t)
    assert abs(mc.simulated_chatter_hz(x, rpm, y=y) - 777.7) < 0.05  # powers summed
    assert abs(mc.simulated_chatter_hz(x, rpm, end=4096) - f_c) < 0.05


def test_default_stream_profile_is_the_tuned_stream() -> None:
    pr = mc.StreamProfile()
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    assert (pr.diameter_m, pr.flutes) == (tool.diameter_m, tool.n_flutes)
    assert math.isclose(math.radians(pr.helix_deg), tool.helix_rad, rel_tol=1e-15)
    assert (pr.tone_hz, pr.resonance_hz, pr.radial_fraction) == (1234.0, 1500.0, 1.0)


def test_heldout_conditions_differ_from_the_tuned_ones() -> None:
    tuned = mc.StreamProfile()
    for seed, pr in mc.HELDOUT_STREAMS.values():
        assert seed != 3  # false_alarms_10min's seed
        assert pr.flutes != tuned.flutes and pr.diameter_m != tuned.diameter_m
        assert pr.tone_hz != tuned.tone_hz and pr.resonance_hz != tuned.resonance_hz
        assert set(pr.rpm_choices) != set(tuned.rpm_choices)
    for name, r in mc.HELDOUT_RAMPS.items():
        assert r.rpm not in (15870.0, *(v[2] for v in mc.TOOLS.values())), name


def test_heldout_stream_is_reproducible_and_uses_its_profile() -> None:
    seed, pr = mc.HELDOUT_STREAMS["b"]
    a = mc.stable_stream(6.0, seed=seed, spindle=False, profile=pr)
    b = mc.stable_stream(6.0, seed=seed, spindle=False, profile=pr)
    assert np.array_equal(a["sensor"], b["sensor"])
    rpm = a["spindle/speed"] * 60 / (2 * math.pi)
    assert rpm.min() >= min(pr.rpm_choices) * min(pr.override_choices) - 1e-6
    assert rpm.max() <= max(pr.rpm_choices) * max(pr.override_choices) + 1e-6


def test_phase_latencies_move_with_the_start_of_the_recording() -> None:
    """Decision 1541: the latency is judged at ten start phases; each alarm lands on a decision
    instant of its own grid (a multiple of 0.1 s from the recording's start), so the ten
    latencies differ and the worst is up to one decision interval above the best."""
    rng = np.random.default_rng(5)
    fs = mc.FS_HZ
    n = int(5.0 * fs)
    t = np.arange(n) / fs
    # 100 Hz spindle (2 flutes: a 200 Hz tooth line), run up from rest over 0.3 s, a steady
    # cut throughout (no entry: an entry's own transient is not what this judges), chatter
    # from 3.503 s
    speed = np.minimum(t / 0.3, 1.0) * 6000.0 * 2 * np.pi / 60
    cut = 1.0
    onset = 3.503
    x = 0.02 * rng.standard_normal(n)
    x += cut * (np.sin(2 * np.pi * 200 * t) + 0.5 * np.sin(2 * np.pi * 400 * t))
    x += (t >= onset) * 3.0 * np.sin(2 * np.pi * 1234.5 * t)  # chatter at full size
    lat = mc.phase_latencies(x, speed, 2, onset)
    assert len(lat) == mc.LATENCY_PHASES
    assert all(math.isfinite(v) and 0.0 < v < 0.5 for v in lat), lat
    for k, v in enumerate(lat):
        alarm = onset + k * mc.LATENCY_PHASE_STEP_S + v  # in the shifted recording's time
        assert abs(alarm * 10 - round(alarm * 10)) * 0.1 <= 2.0 / fs, (k, alarm)
    # one decision interval separates the phases' latencies (the alarm window the same)
    assert 0.08 <= max(lat) - min(lat) <= 0.1 + 1e-9, lat


def test_an_entry_over_half_a_second_raises_no_alarm_at_any_start_phase() -> None:
    """A cut entered over 0.5 s (a tool radius of travel) on an accelerometer-like signal, no
    mean step: before decision 1542 chatter-comb false-alarmed at the entry at 3 of the 10
    start phases (the comb's ring-down against the Hann-weighted tooth line); the chatter
    line after it is still found at every phase."""
    rng = np.random.default_rng(5)
    fs = mc.FS_HZ
    n = int(5.0 * fs)
    t = np.arange(n) / fs
    speed = np.minimum(t / 0.3, 1.0) * 6000.0 * 2 * np.pi / 60
    cut = np.clip((t - 2.5) / 0.5, 0.0, 1.0)
    x = 0.02 * rng.standard_normal(n)
    x += cut * (np.sin(2 * np.pi * 200 * t) + 0.5 * np.sin(2 * np.pi * 400 * t))
    x += (t >= 3.503) * 3.0 * np.sin(2 * np.pi * 1234.5 * t)
    for k in range(mc.LATENCY_PHASES):
        n0 = k * 100
        ev, _ = mc.detect(np.concatenate([np.full(n0, x[0]), x]),
                          np.concatenate([np.zeros(n0), speed]), 2)  # fmt: skip
        times = [e.time_s - n0 / fs for e in ev]
        assert times and all(s >= 3.503 for s in times), (k, times)
        assert abs(ev[0].value - 1234.5) < 2.0
