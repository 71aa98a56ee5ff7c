"""The load an estimate holds, judged against a drive's limit (decision 1690): the largest
|mean| over 10 ms windows, whatever the chunking."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.plausibility import HeldLoad

FS = 10000.0


def _held(v: np.ndarray, chunk: int) -> HeldLoad:
    h = HeldLoad(FS)
    for a in range(0, v.size, chunk):
        h.add(a, v[a : a + chunk])
    return h


def _ringing_on_a_cut() -> np.ndarray:
    """160 N of cut for 1 s with an estimator's ringing at an axis stop: 11 kN at 280 Hz
    decaying over 3 ms from 0.5 s (the Fusion pocket's Y axis at its corner, decision 1690)."""
    t = np.arange(int(FS)) / FS
    ring = np.where(t >= 0.5, 11e3 * np.exp(-(t - 0.5) / 3e-3), 0.0) * np.sin(
        2 * np.pi * 280.0 * (t - 0.5)
    )
    return -160.0 + ring


@pytest.mark.parametrize("chunk", [1, 37, 100, 1000, 10000])
def test_a_ringing_averages_out_and_the_chunking_does_not_matter(chunk: int) -> None:
    """The ringing's largest sample is 6.9 kN; its 10 ms window means stay within a few hundred
    newtons of the cut (a decaying sine's mean over the window: at most its amplitude × the
    decay time over the window, 11 kN × 3 ms / 10 ms ≈ 3.3 kN as a bound; measured 441 N),
    the same for every chunking (1e-9)."""
    v = _ringing_on_a_cut()
    assert np.max(np.abs(v)) > 6e3
    ref = _held(v, v.size)
    h = _held(v, chunk)
    assert h.peak == pytest.approx(ref.peak, rel=1e-9) and h.at == ref.at
    assert h.peak < 0.15 * np.max(np.abs(v))
    assert ref.at % 100 == 50  # a window's middle


def test_a_sustained_load_is_its_value() -> None:
    """A 10 kN load held over 30 ms from 0.3 s: its windows read 10 kN (a wrong K_t scales the
    whole estimate); the middle of the first full window in it."""
    v = np.full(int(FS), 50.0)
    v[3000:3300] = 1e4
    h = _held(v, 64)
    assert h.peak == pytest.approx(1e4, rel=1e-12)
    assert h.at == 3050
    # shorter than a window: its fraction of the window
    short = _held(np.r_[np.zeros(1000), np.full(20, 5e3), np.zeros(980)], 100)
    assert short.peak == pytest.approx(5e3 * 20 / 100)
