"""Decision 1717: the engagement monitor's monitoring cycle of n revolutions.

Lee (seed 004 digest A3): "one estimate per revolution, or per n revolutions (e.g. one
monitoring cycle for 3 tool revolutions)"; his spindle turned at 1200 min⁻¹, 50 ms a
revolution. The fits grow with the revolutions a second: at 10 000 rev/min the monitor alone ran
at 58× real time on the sensorless estimate's noise. `millsense monitor` now takes the whole
number of revolutions nearest 50 ms at the recording's running speed as one cycle; the cycle's
coefficients are the mean of its revolutions' (√n less noise).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.monitoring.engagement import EngagementBlock, cycle_revolutions
from millsense.streaming.block import Chunk
from test_engagement_nyquist import _band_limited_torque, fast_cut_summary

FS = 10000.0


def _noisy_cut(seconds: float, noise_nm: float, rpm: float = 1000.0) -> dict[str, np.ndarray]:
    """The 4-flute 2 mm cut of :func:`_band_limited_torque` with white noise added."""
    data = _band_limited_torque(rpm, seconds)
    tq = data["spindle/torque_est"]
    data["spindle/torque_est"] = tq + noise_nm * np.random.default_rng(2).standard_normal(tq.size)
    return data


def _block(cycle: int, data: dict[str, np.ndarray], chunk: int = 1000) -> EngagementBlock:
    block = EngagementBlock(4, 20.0, 30.0, feed_per_tooth_mm=0.1, cycle_revolutions=cycle)
    block.reset(FS)
    n = len(data["spindle/speed"])
    for a in range(0, n, chunk):
        block.process(Chunk(a, FS, 0.0, {k: v[a : a + chunk] for k, v in data.items()}))
    return block


def test_cycle_revolutions_nearest_lees_50_ms() -> None:
    """One revolution is 50 ms at Lee's 1200 min⁻¹: 1 cycle revolution below 1800 rev/min
    (1.5 revolutions in 50 ms), 2 from it, 5 at 6000, 8 at 10 000 (8.3 revolutions)."""
    assert [cycle_revolutions(r) for r in (300.0, 1200.0, 1799.0, 1800.0, 6000.0, 10000.0)] == [
        1, 1, 1, 2, 5, 8,
    ]  # fmt: skip
    with pytest.raises(ValueError, match="positive speed"):
        cycle_revolutions(0.0)
    with pytest.raises(ConfigError, match="cycle_revolutions must be an integer ≥ 1"):
        EngagementBlock(4, 20.0, 30.0, feed_per_tooth_mm=0.1, cycle_revolutions=0)


def test_a_cycle_is_the_mean_of_its_revolutions_in_any_chunking() -> None:
    """A cycle of 4 revolutions' coefficients are the mean of the 4 revolutions' (to rounding,
    1e-12 of their magnitude), whatever the chunks (137 or 1000 samples: bit for bit), and
    the 40 cycles of 10 s read the cut's 2 mm."""
    data = _noisy_cut(10.0, 0.05)
    one, four = _block(1, data), _block(4, data)
    h1, h4 = one.revolution_harmonics, four.revolution_harmonics
    assert len(h4) == len(h1) // 4
    for j, cyc in enumerate(h4):
        assert cyc is not None
        mean = np.mean([h1[i][0] for i in range(4 * j, 4 * j + 4)], axis=0)  # type: ignore[index]
        assert np.abs(cyc[0] - mean).max() <= 1e-12 * np.abs(mean).max()
    again = _block(4, data, chunk=137).revolution_harmonics
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(h4, again, strict=True))  # type: ignore[index]
    depths = [e.axial_depth_m for _, e in four.estimates if e is not None]
    assert float(np.median(depths)) == pytest.approx(2e-3, rel=0.01)


def test_a_cycle_of_4_halves_the_depths_scatter() -> None:
    """With 1 N·m of noise a sample on the 4-flute cut, the depth's scatter (1.4826 × its
    median absolute deviation) over cycles of 4 revolutions is half that over revolutions (√4;
    within 1.5 to 2.7: the fit is nonlinear in the noise)."""
    data = _noisy_cut(20.0, 1.0)

    def scatter(block: EngagementBlock) -> float:
        da = np.array([e.axial_depth_m for _, e in block.estimates if e is not None])
        return 1.4826 * float(np.median(np.abs(da - np.median(da))))

    ratio = scatter(_block(1, data)) / scatter(_block(4, data))
    assert 1.5 <= ratio <= 2.7, ratio


def test_monitor_takes_the_cycle_of_the_running_speed_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 10 000 rev/min `monitor` takes cycles of 8 revolutions (48 ms), says so, counts the
    0.5 s record's 10 whole cycles (83.3 revolutions) and the 4-flute cut still reads its 2 mm
    (decision 1734's case)."""
    line = fast_cut_summary(tmp_path, capsys)
    assert "one estimate per monitoring cycle of 8 revolutions" in line, line
    words = line.replace(",", "").split()
    assert float(words[words.index("axial") + 2]) == pytest.approx(2.0, rel=0.02)
    assert line.strip().startswith("engagement: 10 of 10 revolutions reliable"), line
