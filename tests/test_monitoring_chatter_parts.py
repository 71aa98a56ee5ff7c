"""Decision 1546: a window's part (decisions 1539, 1542, 1543) is judged against the background
as the part's own window shows it, and its comb row is detrended first."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tests.test_monitoring_chatter import _run_comb, _signal

from millsense.monitoring.chatter import block

FS = 10000.0


def test_a_background_line_seen_through_a_part_is_the_parts_own_spectrum_of_it() -> None:
    # independent computation: a line on a bin of the full window (n = 4096), cut to its last
    # m samples (rectangular, zero-padded to n, scaled 2/m) spreads over the bins beside it as
    # |sinc(d·m/n)| (Dirichlet kernel; within 1 % at these lengths); _seen_through gives a
    # one-bin background line exactly that shape over the part's main lobe
    n, b0, amp = 4096, 1000, 0.8
    t = np.arange(n)
    for m in (700, 1200, 2048):
        part = np.zeros(n)
        part[:m] = amp * np.cos(2 * np.pi * b0 * t[:m] / n)
        spec = np.abs(np.fft.rfft(part)) * 2.0 / m
        bg = np.zeros(n // 2 + 1)
        bg[b0] = amp
        ref = block._seen_through(bg, m / n)
        widen = math.ceil(n / m) - 1
        for d in range(-widen, widen + 1):
            sinc = abs(np.sinc(d * m / n))
            assert ref[b0 + d] == pytest.approx(amp * sinc, rel=1e-12)
            assert spec[b0 + d] == pytest.approx(amp * sinc, rel=0.01, abs=2e-3)
        assert ref[b0 + widen + 1] == 0.0 and ref[b0 - widen - 1] == 0.0  # main lobe only
    assert block._seen_through(bg, 1.0) is bg  # a full window: the background itself


def test_detrend_removes_a_line_and_keeps_a_tone() -> None:
    m = 500
    t = np.arange(m) / FS
    tone = 0.3 * np.cos(2 * np.pi * 937.0 * t)
    y = 4.0 - 30.0 * t + tone
    block._detrend(y)
    fit = np.polyfit(t, tone, 1)
    np.testing.assert_allclose(y, tone - np.polyval(fit, t), atol=1e-12)


@pytest.mark.parametrize("detrend", [True, False])
def test_an_entry_with_a_mean_step_raises_no_alarm_at_any_phase(
    detrend: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a stable cut entered with a mean step 6 × the tooth line at 20 phases of the decision grid
    # (5 ms apart): the parts of two revolutions and more after the step (decision 1543) hold
    # the comb's ring-down of the step, whose first rectangular sidelobe (1.5 f_s/L, 45-55 Hz
    # for L ≈ 300) read as chatter at two phases before the comb row was detrended
    if not detrend:
        monkeypatch.setattr(block, "_detrend", lambda y: None)
    alarms = []
    for ph in range(20):
        entry = 2.003 + 0.005 * ph
        x, spd = _signal(dur=3.0, onset=None, cut_start=entry, load_step=5.0, drift=0.0)
        alarms += [(entry, e.value) for e in _run_comb(x, spd, 4)]
    if detrend:
        assert alarms == []
    else:
        assert len(alarms) >= 1 and all(f < 100.0 for _, f in alarms)  # the step's sidelobe
