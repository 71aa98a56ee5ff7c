"""``millsense estimate --harmonics`` on the simulated slot of test_cli_estimate.

Same scenario as tests/test_cli_estimate.py (quaser-ux600, Ø20 mm 2-flute slot along +X at
3000 rev/min, tooth frequency 100 Hz, the simulator's truth with the realism layer on; the
estimator built from the machine file commissioned on the simulator, tests/commissioned.py,
as a user must: commission → identify → merge → estimate): the harmonic design reads
``spindle/speed_cmd`` and the 2 teeth (no ``flutes`` metadata: the default), so the 100 and
200 Hz lines get their own state pairs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.cli.main import main
from millsense.core.recording import Recording
from millsense.io import read_recording, write_recording
from slot_run import SIM_QUASER, XyFeed
from test_cli_estimate import _steady, run_cli


@pytest.fixture(scope="module")
def runs(
    tmp_path_factory: pytest.TempPathFactory,
    slot_run: Path,
    slot_xy_feed: XyFeed,
    commissioned: Path,
) -> tuple[Path, Path, Path]:
    # the slot and its random-walk (no --harmonics) x,y feed estimate are test_cli_estimate's,
    # computed once per session (tests/slot_run.py); here the harmonic design of the same
    h = tmp_path_factory.mktemp("estimate_harmonics") / "h.h5"
    machine = str(commissioned / "machine.toml")
    est = ["estimate", str(slot_run), "--machine", machine, "--axes", "x,y"]
    try:
        main([*est, "--method", "feed", "--harmonics", "-o", str(h)])
    except SystemExit as exc:
        assert not exc.code
    return slot_run, slot_xy_feed.estimates, h


def _line_error(est: np.ndarray, truth: np.ndarray) -> float:
    """Complex error at 100 and 200 Hz over whole tooth periods (100 samples each)."""
    n = len(truth)
    e, t = np.fft.rfft(est), np.fft.rfft(truth)
    idx = [n // 100, 2 * n // 100]
    return float(np.sqrt(np.sum(np.abs(e[idx] - t[idx]) ** 2) / np.sum(np.abs(t[idx]) ** 2)))


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: on the truth with the commissioned file the harmonic design's Y error at "
    "100/200 Hz is 9.2 % (bound 6 %; measured 2026-11-30; 16.3 % with the Coulomb C3 stage "
    "before decision 1695): the at-rest path misses the holding axis's 200 Hz line",
)
def test_harmonics_lower_the_y_error_at_the_tooth_lines(runs: tuple[Path, Path, Path]) -> None:
    run, rw, h = runs
    rt, r_rw, r_h = read_recording(run), read_recording(rw), read_recording(h)
    # the block read the CNC's commanded spindle speed (copied into the estimates file)
    np.testing.assert_array_equal(r_h.channel("spindle/speed_cmd"), rt.channel("spindle/speed_cmd"))
    i0, i1 = _steady(run)
    lag = 60
    truth = rt.channel("truth/y/load")[i0:i1]
    e_rw = _line_error(r_rw.channel("est/feed/y/load")[i0 + lag : i1 + lag], truth)
    e_h = _line_error(r_h.channel("est/feed/y/load")[i0 + lag : i1 + lag], truth)
    # Y: the random walk's own lag at 100/200 Hz goes away, what stays is the model error of the
    # preset tables against the simulated machine: measured 7.1 % → 4.0 %
    assert e_h < 0.06 and e_h < 0.7 * e_rw
    # the mean (DC) is the random walk's job in both designs: same to 0.5 % (measured 0.1 %)
    m_rw = r_rw.channel("est/feed/y/load")[i0 + lag : i1 + lag].mean()
    m_h = r_h.channel("est/feed/y/load")[i0 + lag : i1 + lag].mean()
    assert m_h == pytest.approx(m_rw, rel=0.005)


def test_harmonics_need_the_spindle_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = Recording(10_000.0)
    rec.add_channel("x/current_cmd", np.zeros(100), "A")
    rec.add_channel("x/motor_speed", np.zeros(100), "rad/s")
    p = tmp_path / "r.h5"
    write_recording(p, rec)
    args = ["estimate", str(p), "--machine", SIM_QUASER, "--axes", "x", "--harmonics"]
    code, _, err = run_cli([*args, "-o", str(tmp_path / "e.h5")], capsys)
    assert code == 2 and "'spindle/speed_cmd'" in err and len(err.strip().splitlines()) == 1
