"""Decision 1658: a chatter line must stand out of its own window's spectrum at the onset.

The stream reproduces the false alarm of a light Ø12 mm 3-flute slot at 8000 rev/min on the
compensated spindle torque: the observer's noise lines (the encoder's quantisation tones) sit on
the spindle harmonics in air, where the comb removes them and the background never sees them;
in the cut the speed sags by ~1e-5 and the same lines spread between the harmonics, a dozen of
them about as strong, one of which was read as chatter (ratio 1.71 against the entry's tooth
line). Levels from the recorded run (module notes of :mod:`millsense.monitoring.chatter.block`):
lines 0.25-0.36 N·m, tooth line 0.2 N·m, floor ≈ 0.06 N·m.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings, methods
from millsense.streaming.block import Chunk, Event

FS = 10000.0
RPM = 8000.0
FLUTES = 3


def _stream(chatter: float = 0.0, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """4 s: air to 2 s, then a slot (mean step 0.8, tooth line 0.2 at 400 Hz); white noise of
    σ 1.3 in air and 2.3 in the cut (a rectangular spectrum's median 0.035 and 0.06, as the
    observer's floor between the harmonics in air and in the cut); 40 noise lines of
    0.2-0.36 on spindle harmonics 9-18 (1.2-2.4 kHz) in air, between them in the cut (at 0.2,
    0.4, 0.6 and 0.8 of the spacing, off the comb's notches: the entry's part held 42 lines
    above 0.2, 15 above 0.25); from 3 s optionally a chatter line of
    amplitude ``chatter`` at 1000 Hz (between the 7th and 8th harmonics)."""
    rng = np.random.default_rng(seed)
    n = int(4.0 * FS)
    t = np.arange(n) / FS
    f_rev = RPM / 60.0
    ang = 2 * np.pi * f_rev * t
    cut = t >= 2.0
    x = 0.6 + np.where(cut, 2.3, 1.3) * rng.standard_normal(n)
    x += cut * (0.8 + 0.2 * np.cos(FLUTES * ang))
    slots = [(h, off) for h in range(9, 19) for off in (0.2, 0.4, 0.6, 0.8)]
    for (h, off), a in zip(slots, rng.uniform(0.2, 0.36, len(slots)), strict=True):
        f = np.where(cut, (h + off) * f_rev, h * f_rev)
        x += a * np.cos(2 * np.pi * np.cumsum(f) / FS + rng.uniform(0, 2 * np.pi))
    if chatter:
        x += chatter * (t >= 3.0) * np.cos(2 * np.pi * 1000.0 * t)
    return x, np.full(n, f_rev * 2 * np.pi)


def _run(x: np.ndarray, spd: np.ndarray) -> tuple[list[Event], dict[str, np.ndarray]]:
    b = ChatterMonitor(ChatterSettings(signal="s", n_flutes=FLUTES))
    b.reset(FS)
    ev: list[Event] = []
    parts: dict[str, list[np.ndarray]] = {}
    for s in range(0, len(x), 1000):
        o = b.process(Chunk(s, FS, 0.0, {"s": x[s : s + 1000], "spindle/speed": spd[s : s + 1000]}))
        ev += [e for e in o.events if e.name == "chatter"]
        for k, v in o.channels.items():
            parts.setdefault(k, []).append(v)
    return ev, {k: np.concatenate(v) for k, v in parts.items()}


def _alarms(x: np.ndarray, spd: np.ndarray) -> list[Event]:
    return _run(x, spd)[0]


def test_line_level_is_the_rayleigh_extreme_of_the_windows_own_tail() -> None:
    # white Gaussian noise, rectangular 4096-point spectra: the largest bin exceeds the level
    # with the chance asked (the union bound over N bins, the 99 % quantile estimated from the
    # spectrum itself); 4000 spectra give a binomial σ of 0.0034 on 0.05
    rng = np.random.default_rng(7)
    n, p, trials = 4096, 0.05, 4000
    masked = np.zeros(n // 2 + 1, dtype=bool)
    masked[::32] = True  # a comb of bins not searched, as the harmonics
    b0, b1 = 20, 1900
    over = 0
    for _ in range(trials):
        amp = np.abs(np.fft.rfft(rng.standard_normal(n))) * 2.0 / n
        level = methods.line_level(amp, masked, b0, b1, false_alarm=p)
        over += bool(np.max(np.where(masked[b0:b1], 0.0, amp[b0:b1])) > level)
    assert over / trials == pytest.approx(p, abs=0.015)


def test_a_part_counts_its_independent_bins() -> None:
    # a zero-padded part of a quarter window has a quarter of the independent bins: the level
    # over the same quantile is √(ln(N/4/p) / ln(N/p)) of the full window's
    amp = np.linspace(0.0, 1.0, 2049)
    masked = np.zeros(2049, dtype=bool)
    full = methods.line_level(amp, masked, 0, 2049)
    quarter = methods.line_level(amp, masked, 0, 2049, part=0.25)
    p = methods.LINE_FALSE_ALARM
    assert quarter / full == pytest.approx(
        math.sqrt(math.log(2049 * 0.25 / p) / math.log(2049 / p)), rel=1e-12
    )
    assert methods.line_level(amp, np.ones(2049, dtype=bool), 0, 2049) == math.inf


@pytest.mark.parametrize("test_lines", [True, False])
def test_noise_lines_spreading_in_the_cut_are_not_chatter(
    test_lines: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    # five draws of the stream (line amplitudes and phases, noise); without the line test
    # (decision 1658) the largest of the new lines reads as chatter 2-4 times per stream: novel
    # against a background that never saw it, 1.5-2.2 × the tooth line. With it a line that
    # is one of many is not chatter; one that, with the noise, stands 1.76 × above the top 1 %
    # of its window still is (2 alarms in the 5 streams: the test is statistical, a noise line
    # that stands out is read as chatter; measured 17 → 2). Since decision 1551 (the ratio read
    # at the lines' amplitudes, a run held down to half the threshold) the runs without the
    # line test merge: one alarm per stream, in every stream (89 flagged decisions against 60),
    # so the streams that alarm are counted; with the test the same 2 alarms
    if not test_lines:
        monkeypatch.setattr(methods, "line_level", lambda *a, **k: 0.0)
    per_stream = [_alarms(*_stream(seed=seed)) for seed in range(5)]
    alarms = [e for ev in per_stream for e in ev]
    assert all(1200.0 <= e.value <= 2600.0 for e in alarms)  # all of them noise lines
    if test_lines:
        assert len(alarms) <= 2
    else:
        assert sum(1 for ev in per_stream if ev) == 5
        assert all(e.values["energy_ratio"] > 1.5 for e in alarms)


def test_chatter_above_the_noise_lines_is_still_found() -> None:
    # a chatter line of 0.9 (2.5 × the strongest noise line, 4.5 × the tooth line) from 3 s at
    # 1000 Hz. The rectangular window holds it for 0.1, 0.2, 0.3 s at the decisions 3.1, 3.2,
    # 3.3 s (≈ 0.22, 0.44, 0.66): the ratio passes 1.5 at 3.2 s, the line stands 1.76 × above
    # the top 1 % of its window (≈ 0.45) only at 3.3 s. The cost of the line test in noise this
    # rich: one decision (0.1 s) later
    alarms, out = _run(*_stream(chatter=0.9))
    assert len(alarms) == 1
    assert alarms[0].value == pytest.approx(1000.0, abs=2.0)  # interpolated peak, 2.4 Hz bins
    assert alarms[0].time_s == pytest.approx(3.3, abs=1e-3)
    k = round(3.2 * FS) - 1  # the decision at 3.2 s: the seed's ratio passes, no verdict
    assert out["chatter-comb/energy_ratio"][k] > 1.5
    assert out["chatter-comb/chatter"][k] == 0.0


def test_a_short_parts_line_is_judged_without_its_own_main_lobe() -> None:
    # one line in a part of 300 samples (2.4 revolutions at 8000 rev/min) zero-padded to 4096:
    # its main lobe spans ±14 bins, more than the top 1 % of the band (16 bins), so with the
    # lobe counted as noise the level is set by the line's own spread (0.62 of the line here;
    # with a comb's ring-down and the harmonics' remains beside it, the abrupt entry of
    # tests/test_monitoring_chatter.py missed its chatter at 3 of 10 phases); without it the
    # tail is the sidelobes (the first of a rectangular window 0.22 of the line) and noise
    n, m, fc = 4096, 300, 1234.5
    rng = np.random.default_rng(3)
    t = np.arange(m) / FS
    x = np.zeros(n)
    x[:m] = np.sin(2 * np.pi * fc * t) + 0.02 * rng.standard_normal(m)
    amp = np.abs(np.fft.rfft(x)) * 2.0 / m
    masked = np.zeros(n // 2 + 1, dtype=bool)
    b0, b1 = 20, 1843
    k = int(np.argmax(amp[b0:b1])) + b0
    assert amp[k] == pytest.approx(1.0, abs=0.05)  # the line at its amplitude (zero-padded)
    assert methods.line_level(amp, masked, b0, b1, m / n) > 0.5 * amp[k]  # its lobe as tail
    assert methods.line_level(amp, masked, b0, b1, m / n, k) < 0.25 * amp[k]
