"""Decision 1734: the engagement monitor fits no tooth harmonic at or above the Nyquist
frequency (a revolution's coefficient there is another harmonic's alias)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from millsense.monitoring.engagement import EngagementBlock, harmonics_below_nyquist
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.streaming.block import Chunk

FS = 10000.0


def test_harmonics_below_nyquist_closed_form() -> None:
    """k·N·n/60 < f_s/2, at most ``wanted``: 4 flutes at 10 000 rev/min (666.7 Hz) leave 7
    below 5 kHz (7.5 → 7); 2 flutes there (333.3 Hz) put the 15th exactly on 5 kHz, which is
    excluded (14); 6 flutes at 30 000 rev/min (3 kHz) leave 1; 2 flutes at 1000 rev/min keep
    the default 12."""
    assert harmonics_below_nyquist(4, 10000.0, FS) == 7
    assert harmonics_below_nyquist(2, 10000.0, FS, wanted=20) == 14
    assert harmonics_below_nyquist(6, 30000.0, FS) == 1
    assert harmonics_below_nyquist(2, 1000.0, FS) == 12
    assert harmonics_below_nyquist(2, 180000.0, FS) == 0  # 6 kHz: the tooth frequency above
    with pytest.raises(ValueError):
        harmonics_below_nyquist(2, 0.0, FS)


def _band_limited_torque(
    rpm: float, seconds: float, n_flutes: int = 4, axial_m: float = 2e-3
) -> dict[str, np.ndarray]:
    """A Ø20 mm 30° down-milling cut (5 mm radial, 2 mm axial, 0.1 mm a
    tooth) of ``n_flutes`` flutes at ``rpm``, its torque synthesised from the revolution's
    harmonics below the Nyquist frequency only (what an anti-aliased channel holds)."""
    tool = EndMill(20e-3, n_flutes, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    m = 720
    phi = 2 * math.pi * np.arange(m) / m
    rev = milling_forces(tool, co, Engagement.radial(5e-3, 20e-3, "down"), 0.1e-3, axial_m,
                         phi).torque_nm  # fmt: skip
    coeff = np.fft.rfft(rev) / m
    omega = rpm * 2 * math.pi / 60
    n = int(seconds * FS)
    ang = omega * np.arange(n) / FS
    tq = np.full(n, coeff[0].real)
    for h in range(1, coeff.size):
        if h * omega / (2 * math.pi) >= 0.5 * FS:
            break
        tq += 2.0 * (coeff[h] * np.exp(1j * h * ang)).real
    return {"spindle/torque_est": tq, "spindle/speed": np.full(n, omega)}


def _run(block: EngagementBlock, data: dict[str, np.ndarray]) -> list:
    block.reset(FS)
    n = len(data["spindle/speed"])
    for a in range(0, n, 1000):
        block.process(Chunk(a, FS, 0.0, {k: v[a : a + 1000] for k, v in data.items()}))
    return [e for _, e in block.estimates]


@pytest.mark.parametrize(("rpm", "evaluated"), [(9000.0, True), (9500.0, False)])
def test_a_revolution_whose_harmonics_reach_the_nyquist_frequency_is_not_evaluated(
    rpm: float, evaluated: bool
) -> None:
    """8 harmonics of a 4-flute tool: the 8th at 9000 rev/min is 4800 Hz (below 5 kHz: the
    revolutions are evaluated, d_a within 2 % of the 2 mm cut), at 9500 rev/min 5067 Hz (every
    revolution left unevaluated and counted)."""
    data = _band_limited_torque(rpm, 1.0)
    block = EngagementBlock(4, 20.0, 30.0, feed_per_tooth_mm=0.1, n_harmonics=8)
    est = _run(block, data)
    if evaluated:
        got = [e for e in est if e is not None]
        assert len(got) == len(est) >= 140
        assert block.aliased_revolutions == 0
        assert np.median([e.axial_depth_m for e in got]) == pytest.approx(2e-3, rel=0.02)
    else:
        assert all(e is None for e in est)
        assert block.aliased_revolutions == len(est) >= 140


def test_the_harmonics_below_the_nyquist_frequency_give_the_depth_at_high_speed() -> None:
    """At 10 000 rev/min the 7 harmonics below 5 kHz identify the cut (d_a and
    d_r within 2 % of 2 and 5 mm, K_t within 3 % of 758 N/mm²) where the default 12 leave
    every revolution unevaluated."""
    data = _band_limited_torque(10000.0, 1.0)
    k = harmonics_below_nyquist(4, 10000.0, FS)
    got = [e for e in _run(EngagementBlock(4, 20.0, 30.0, feed_per_tooth_mm=0.1, n_harmonics=k),
                           data) if e is not None]  # fmt: skip
    assert len(got) >= 150
    assert np.median([e.axial_depth_m for e in got]) == pytest.approx(2e-3, rel=0.02)
    assert np.median([e.radial_depth_m for e in got]) == pytest.approx(5e-3, rel=0.02)
    assert np.median([e.kt_n_m2 for e in got]) == pytest.approx(758e6, rel=0.03)
    assert all(e is None for e in _run(EngagementBlock(4, 20.0, 30.0, feed_per_tooth_mm=0.1),
                                       data))  # fmt: skip


def _recording(path: Path, rpm: float, flutes: int) -> Path:
    data = _band_limited_torque(rpm, 0.5, flutes)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("spindle/torque_est", data["spindle/torque_est"], "N*m")
    rec.add_channel("spindle/speed", data["spindle/speed"], "rad/s")
    write_recording(path, rec)
    return path


def _tool(path: Path, flutes: int) -> Path:
    path.write_text(f'name = "D20"\nshape = "flat"\ndiameter_mm = 20.0\nflutes = {flutes}\n'
                    'helix_deg = 30.0\n')  # fmt: skip
    return path


def fast_cut_summary(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """`monitor --methods engagement`'s summary line on 0.5 s of the 4-flute cut at 10 000
    rev/min (:func:`_recording`)."""
    rec = _recording(tmp_path / "fast.h5", 10000.0, 4)
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                                 str(_tool(tmp_path / "t.toml", 4)), "--feed-per-tooth-mm", "0.1",
                                 "-o", str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    return next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))


def test_monitor_fits_the_harmonics_below_the_nyquist_frequency(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`monitor` takes the harmonics below the Nyquist frequency at the recording's top speed
    and says so; the 4-flute cut at 10 000 rev/min gives its 2 mm depth."""
    line = fast_cut_summary(tmp_path, capsys)
    assert "fitted on 7 tooth harmonics, those below the Nyquist frequency (5000 Hz)" in line
    words = line.replace(",", "").split()
    assert float(words[words.index("axial") + 2]) == pytest.approx(2.0, rel=0.02)


def test_monitor_refuses_a_rate_that_holds_too_few_tooth_harmonics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """6 flutes at 30 000 rev/min (3 kHz) leave one tooth harmonic below 5 kHz: one line
    naming the speed, the tooth frequency and the rate, exit 2."""
    rec = _recording(tmp_path / "too_fast.h5", 30000.0, 6)
    code, _, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                            str(_tool(tmp_path / "t.toml", 6)), "--feed-per-tooth-mm", "0.1",
                            "-o", str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 2
    msg = err.strip().splitlines()[-1]
    assert "30000 rev/min" in msg and "3000 Hz" in msg and "5000 Hz" in msg
    assert not (tmp_path / "ev.parquet").exists()
