"""The simulated tap test of the tool (millsense.simulator.tap_test) and its identification
(millsense.bench.tap_test): decision 1750, issue 12."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from millsense.bench.tap_test import receptance, tap_test_fits, tap_tested_structure
from millsense.ident.frf import FrfEstimate
from millsense.simulator.tap_test import ModeSet, TapTestOptions, _hammer, tap_test
from millsense.validation.cases.control_chatter_avoidance import truth_modes

#: seed 000 T1 (Aslan Tables 5.3-5.4) as the plant runs it (x = thesis Y, y = thesis X)
T1 = truth_modes()


def _errors(opts: TapTestOptions) -> np.ndarray:
    """(6, 3) relative errors of f, ζ, k of the fitted modes against T1 (x then y)."""
    out = []
    for fit, d in zip(tap_test_fits(T1, opts), (T1.x, T1.y), strict=True):
        assert len(fit.modes) == 3
        for m in fit.modes:
            i = int(np.argmin(np.abs(d.natural_hz - m.natural_frequency_hz)))
            out.append([m.natural_frequency_hz / d.natural_hz[i] - 1,
                        m.zeta / d.damping_ratio[i] - 1,
                        m.stiffness / d.stiffness_n_per_m[i] - 1])  # fmt: skip
    return np.array(out)


@pytest.fixture(scope="module")
def noiseless() -> np.ndarray:
    return _errors(TapTestOptions().noiseless())


def test_noiseless_tap_test_gives_the_table_back(noiseless: np.ndarray) -> None:
    # without noise, hammer error, accelerometer mass or extra mode only the test's own
    # numerics remain (first-order hold at 16 × the DAQ rate, windows, the fit): 0.5 %
    assert np.max(np.abs(noiseless)) < 0.005


def test_noise_makes_the_error_bigger_but_bounded(noiseless: np.ndarray) -> None:
    # ten times the default accelerometer noise (0.5 m/s² rms) on an otherwise perfect test:
    # the worst damping/stiffness error grows past the noiseless one, and stays within the
    # H1 random error's reach (γ² ≥ 0.9 in the band, 10 hits: ε ≲ 7 % per line, averaged
    # over the ~10-30 lines of a half-power band): 5 %
    noisy = _errors(replace(TapTestOptions().noiseless(), accel_noise_m_s2=0.5))
    worst = np.max(np.abs(noisy[:, 1:]))
    assert worst > np.max(np.abs(noiseless[:, 1:]))
    assert worst < 0.05
    # frequencies are the best-determined parameters: within 0.2 %
    assert np.max(np.abs(noisy[:, 0])) < 0.002


def test_accelerometer_mass_lowers_every_mode_by_half_its_mass_ratio() -> None:
    ms = ModeSet.from_direction(T1.x, added_mass_kg=0.005)
    w = 2 * np.pi * T1.x.natural_hz
    m = T1.x.stiffness_n_per_m / w**2
    np.testing.assert_allclose(ms.frequency_hz / T1.x.natural_hz - 1, -0.005 / (2 * m), rtol=0.01)


def test_hammer_hits_vary_within_their_ranges() -> None:
    opts = TapTestOptions(seed=3)
    f = _hammer(opts, np.random.default_rng(3))
    fs = opts.sample_rate_hz * opts.oversample
    on = np.flatnonzero(f > 0)
    starts = np.concatenate(([0], np.flatnonzero(np.diff(on) > 1) + 1))
    ends = np.append(starts[1:], on.size)
    assert starts.size == opts.n_hits
    widths = (on[ends - 1] - on[starts] + 1) / fs
    peaks = np.array([f[on[a:b]].max() for a, b in zip(starts, ends, strict=True)])
    lo, hi = opts.pulse_s
    assert np.all((widths > lo - 2 / fs) & (widths < hi + 2 / fs))
    assert np.all(np.abs(peaks / opts.peak_force_n - 1) <= opts.peak_spread + 1e-9)
    assert np.std(peaks) > 0.05 * opts.peak_force_n  # they do differ


def test_receptance_undoes_the_window_shift() -> None:
    # an exponentially windowed accelerance A(s + σ) = (s + σ)² H(s + σ) of one mode gives
    # H(s + σ) exactly; dividing by (iω)² alone would not
    sigma, wn, zeta, alpha = 9.2, 2 * math.pi * 282.0, 0.053, 1.0 / 18.8
    f = np.linspace(100.0, 600.0, 251)
    s = 2j * np.pi * f + sigma
    h = alpha / (s**2 + 2 * zeta * wn * s + wn**2)
    a = np.asarray(s**2 * h, dtype=np.complex128)
    est = FrfEstimate(f, a, a, np.ones(f.size), 10, "impact", sigma)
    np.testing.assert_allclose(receptance(est).h1, h, rtol=1e-12)
    naive = s**2 * h / (2j * np.pi * f) ** 2
    assert np.max(np.abs(naive / h - 1)) > 1e-3


def test_the_records_carry_the_sensor_noise() -> None:
    opts = TapTestOptions(n_hits=2, seed=5)
    rec = tap_test(T1.x, T1.y, "x", opts)
    quiet = slice(0, round(0.2 * opts.sample_rate_hz))  # before the first hit
    assert np.std(rec.force_n[quiet]) == pytest.approx(opts.force_noise_n, rel=0.1)
    assert np.std(rec.accel_m_s2[quiet]) == pytest.approx(opts.accel_noise_m_s2, rel=0.1)


def test_structure_is_cached_on_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from millsense.bench import tap_test as bt

    monkeypatch.setenv("MILLSENSE_CACHE_DIR", str(tmp_path))
    opts = TapTestOptions(seed=7).noiseless()
    first = tap_tested_structure(T1, opts)
    assert list(tmp_path.rglob("*.json"))
    bt._structure.cache_clear()
    monkeypatch.setattr(bt, "tap_test_fits", lambda *a: pytest.fail("not read from the cache"))
    assert tap_tested_structure(T1, opts) == first
    assert [m.natural_frequency_hz for m in first.x] == pytest.approx([300, 546, 1607], rel=5e-3)
