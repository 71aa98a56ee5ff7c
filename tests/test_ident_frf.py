"""FRF estimators of millsense.ident.frf: H1/H2 variance and bias, stepped sine, multisine,
impact tests and bad records."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from millsense.core.errors import InputDataError
from millsense.core.recording import Recording
from millsense.ident.frf import (
    check_records,
    frf_from_recording,
    h1_random_error,
    impact_frf,
    multisine_frf,
    multisine_signal,
    stepped_sine_frf,
    stepped_sine_signal,
    welch_frf,
)

FS = 1000.0
# A smooth discrete system (two real poles, one zero): exact FRF from freqz, no sharp peak so
# Welch leakage bias stays far below the random error.
B, A = [0.2, 0.1], [1.0, -0.9, 0.2]


def _truth(f: np.ndarray) -> np.ndarray:
    return scipy.signal.freqz(B, A, worN=f, fs=FS)[1]


def _random_io(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return u, scipy.signal.lfilter(B, A, u)


def test_h1_within_bendat_random_error() -> None:
    u, y = _random_io(200_000, 1)
    y = y + np.random.default_rng(2).normal(0, 0.1, len(y))
    est = welch_frf(u, y, FS, resolution_hz=4.0, window="hann", overlap=0.0)
    rel = np.abs(est.h1 / _truth(est.freq_hz) - 1)
    eps = h1_random_error(est.coherence, est.n_averages)
    # Bendat & Piersol Eq. 9.90/9.91: the magnitude error of H1 has RMS ε and the phase error
    # (rad) the same, so the complex relative error |ΔH|/|H| has RMS √2 ε (non-overlapping
    # segments are independent); over 125 lines its RMS lies within 0.8–1.25 of √2 ε.
    ratio = float(np.sqrt(np.mean((rel / (np.sqrt(2) * eps)) ** 2)))
    assert 0.8 < ratio < 1.25
    # and no line beyond 4 √2 ε (a 4-sigma excursion in 125 lines is improbable)
    assert float(np.max(rel / (np.sqrt(2) * eps))) < 4.0


def test_output_noise_biases_h2_not_h1() -> None:
    u, y = _random_io(400_000, 3)
    noise_var = 0.05
    y_n = y + np.random.default_rng(4).normal(0, np.sqrt(noise_var), len(y))
    est = welch_frf(u, y_n, FS, resolution_hz=5.0)
    h = _truth(est.freq_hz)
    band = (est.freq_hz > 20) & (est.freq_hz < 200)
    # H1 unbiased: mean ratio 1 within 1 % (random error per line ~1 %, 36 lines averaged)
    assert abs(float(np.mean(np.abs(est.h1[band] / h[band]))) - 1) < 0.01
    # H2 biased up by G_yy/G_vv = 1 + G_nn/G_vv (closed form, Bendat & Piersol §9.1)
    gvv = np.abs(h[band]) ** 2 * 2 / FS  # one-sided PSD of y for unit-variance white input
    gnn = noise_var * 2 / FS
    expect = 1 + gnn / gvv
    got = np.abs(est.h2[band] / h[band])
    assert float(np.mean(got / expect)) == pytest.approx(1.0, abs=0.02)
    assert float(np.min(expect)) > 1.05  # the bias tested is material


def test_input_noise_biases_h1_not_h2() -> None:
    u, y = _random_io(400_000, 5)
    u_n = u + np.random.default_rng(6).normal(0, 0.5, len(u))  # G_mm / G_uu = 0.25
    est = welch_frf(u_n, y, FS, resolution_hz=5.0)
    h = _truth(est.freq_hz)
    band = (est.freq_hz > 20) & (est.freq_hz < 200)
    # H1 ≈ H · G_uu/(G_uu + G_mm) = 0.8 H (closed form)
    assert float(np.mean(np.abs(est.h1[band] / h[band]))) == pytest.approx(0.8, abs=0.01)
    # H2 unbiased
    assert float(np.mean(np.abs(est.h2[band] / h[band]))) == pytest.approx(1.0, abs=0.015)
    # coherence = 1/(1 + 0.25) = 0.8 in this case
    assert float(np.mean(est.coherence[band])) == pytest.approx(0.8, abs=0.01)


def test_stepped_sine_exact_for_noiseless_linear_system() -> None:
    # lightly damped discrete resonator: poles at radius 0.98, settle 1 s -> 0.98^1000 ≈ 2e-9
    b, a = [0.05, 0.02], [1.0, -2 * 0.98 * np.cos(0.3), 0.98**2]
    freqs = [5.0, 30.0, 47.7, 48.0, 120.0, 333.3]
    u = stepped_sine_signal(FS, freqs, settle_s=1.5, dwell_s=0.5, amplitude=2.0)
    y = scipy.signal.lfilter(b, a, u)
    est = stepped_sine_frf(u, y, FS, freqs, settle_s=1.5, dwell_s=0.5)
    exact = scipy.signal.freqz(b, a, worN=freqs, fs=FS)[1]
    # exact up to the decayed transient (0.98^1500 ≈ 7e-14 relative) and round-off
    assert float(np.max(np.abs(est.h1 / exact - 1))) < 1e-9


def test_multisine_exact_without_noise_and_averages_periods() -> None:
    u, lines = multisine_signal(FS, 1000, 2.0, 300.0, 6, rms=1.0)
    y = scipy.signal.lfilter(B, A, u)
    est = multisine_frf(u, y, FS, 1000, skip_periods=2)
    assert est.n_averages == 4  # 6 periods minus 2 skipped
    assert np.allclose(est.freq_hz, lines)
    # periodic steady state (poles 0.5, 0.4: transient decayed after 2000 samples): exact
    assert float(np.max(np.abs(est.h1 / _truth(est.freq_hz) - 1))) < 1e-10
    assert float(np.min(est.coherence)) > 1 - 1e-10


def _impact_record(
    hits: list[tuple[float, float]], fs: float = 5000.0, n: int = 5000 * 8, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Force of half-sine hits (time s, peak N) into one mode 150 Hz / ζ = 0.02 / k = 1e6."""
    f = np.zeros(n)
    w_p = int(0.0008 * fs)
    for t0, pk in hits:
        i = int(t0 * fs)
        f[i : i + w_p] += pk * np.sin(np.pi * np.arange(w_p) / w_p)
    fn, zeta, k = 150.0, 0.02, 1e6
    wn = 2 * np.pi * fn
    num, den, _ = scipy.signal.cont2discrete(
        ([wn**2 / k], [1, 2 * zeta * wn, wn**2]), 1 / fs, method="foh"
    )
    x = scipy.signal.lfilter(np.ravel(num), den, f)
    x = x + np.random.default_rng(seed).normal(0, 1e-8, n)
    return f, x, fn, zeta, k


def test_impact_rejects_double_hit_and_overload_and_estimates_frf() -> None:
    from millsense.ident.modal_fit import fit_modes

    hits = [(0.1, 100.0), (1.1, 120.0), (2.1, 90.0), (2.115, 40.0), (3.1, 110.0), (4.1, 300.0)]
    f, x, fn, zeta, k = _impact_record(hits)
    est = impact_frf(f, x, 5000.0, record_s=0.8, double_hit_fraction=0.1, force_clip_level=250.0)
    assert est.n_averages == 3  # 5 hits... minus the double hit and the 300 N overload
    assert len(est.notes) == 2
    assert "double hit" in est.notes[0] and "overload" in est.notes[1]
    assert all("\n" not in n for n in est.notes)
    # static compliance 1/k at low frequency within 2 % (windowing of a 0.8 s record)
    low = est.freq_hz < 20
    assert float(np.median(np.abs(est.h1[low]))) * k == pytest.approx(1.0, rel=0.02)
    # modal fit with the exponential-window pole shift removed recovers fn and ζ
    fit = fit_modes(est, (50.0, 400.0))
    m = fit.modes[0]
    assert m.natural_frequency_hz == pytest.approx(fn, rel=0.005)
    assert m.damping_ratio == pytest.approx(zeta, rel=0.05)


def test_impact_with_only_bad_hits_raises_one_line() -> None:
    f, x, *_ = _impact_record([(0.1, 100.0), (0.11, 60.0)])
    with pytest.raises(InputDataError, match=r"no usable hit.*double hit") as err:
        impact_frf(f, x, 5000.0, record_s=0.5, names=("hammer", "acc"))
    assert "\n" not in str(err.value) and "'hammer'" in str(err.value)


def test_bad_records_one_line_errors() -> None:
    u, y = _random_io(1000, 7)
    with pytest.raises(InputDataError, match=r"'u'.*1000 samples.*'y'.*999"):
        check_records(u, y[:-1], FS, names=("u", "y"))
    with pytest.raises(InputDataError, match=r"too short for a 0.5 Hz resolution"):
        welch_frf(u, y, FS, resolution_hz=0.5)
    with pytest.raises(InputDataError, match=r"no excitation"):
        welch_frf(np.full(1000, 3.0), y, FS, resolution_hz=10.0)
    u_clip = np.clip(u, -1.5, 1.5)  # white noise clipped: many samples at exactly ±1.5
    with pytest.raises(InputDataError, match=r"'input' is clipped: .* at its extreme value 1.5"):
        welch_frf(u_clip, y, FS, resolution_hz=10.0)
    sweep = np.clip(np.sin(2 * np.pi * 5 * np.arange(1000) / FS), -0.9, 0.9)  # smooth, held
    with pytest.raises(InputDataError, match=r"'input' is clipped: .*extreme value 0.9"):
        check_records(sweep + 0 * u, y, FS)
    # an unclipped sine is not flagged (no run at, and < 1 % of samples on, its peak)
    sine = np.sin(2 * np.pi * 37.3 * np.arange(1000) / FS + 0.3)
    assert check_records(sine, y, FS)[0].shape == (1000,)
    with pytest.raises(InputDataError, match=r"'output' is clipped: .*full-scale level 0.5"):
        welch_frf(u, y, FS, resolution_hz=10.0, clip_levels=(None, 0.5))


def test_recording_errors_name_the_channel() -> None:
    u, y = _random_io(4000, 8)
    rec = Recording(FS)
    rec.add_channel("y/torque_a", u, "N*m")
    rec.add_channel("y/torque_c", y, "N*m")
    rec.add_channel("y/flat", np.zeros(4000), "N*m")
    est = frf_from_recording(rec, "y/torque_a", "y/torque_c", resolution_hz=10.0)
    # noiseless random input through the known system: H1 within Welch leakage, which is
    # largest at the first lines where the FRF slope over one Hann main lobe is steepest
    sel = est.freq_hz >= 20
    assert float(np.max(np.abs(est.h1[sel] / _truth(est.freq_hz[sel]) - 1))) < 0.015
    with pytest.raises(InputDataError, match=r"'y/flat' carries no excitation"):
        frf_from_recording(rec, "y/flat", "y/torque_c", resolution_hz=10.0)
    with pytest.raises(InputDataError, match=r"'y/missing' is not in the recording"):
        frf_from_recording(rec, "y/missing", "y/torque_c", resolution_hz=10.0)
    with pytest.raises(InputDataError, match=r"'y/torque_a'.*too short"):
        frf_from_recording(rec, "y/torque_a", "y/torque_c", resolution_hz=0.1)
