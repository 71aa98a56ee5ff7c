"""``simulate --tool-modes``: regenerative chatter from the command line.

Scenario: benchmarks.md §1 (Insperger 2003) 1-DOF slot — Ø10 mm 2-flute straight tool,
K_t = 600, K_r = 200 N/mm², tool mode 922 Hz, ζ 0.011, k 1.34 N/µm along the feed, 15 870
rev/min, 0.05 mm/tooth; SDM critical depth 0.3174 mm, chatter at about 932 Hz. The modes come
from the stability case file itself (examples/stability/insperger_1dof_slot.toml).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.io import read_recording

CASE = Path(__file__).parents[1] / "examples" / "stability" / "insperger_1dof_slot.toml"
TOOL = (
    'name = "D10 2-flute straight"\nshape = "flat"\ndiameter_mm = 10.0\nflutes = 2\n'
    "helix_deg = 0.0\n"
)
MATERIAL = (
    'name = "Insperger benchmark"\nktc_n_mm2 = 600.0\nkrc_n_mm2 = 200.0\nkac_n_mm2 = 0.0\n'
    "kte_n_mm = 0.0\nkre_n_mm = 0.0\nkae_n_mm = 0.0\n"
)
PROGRAM = "G21 G90 G94\nG0 X-15 Y0 Z0\nS15870 M3\nG1 X200 F1587\nM5\nM30\n"
RPM = 15870.0


def _run(tmp_path: Path, depth_mm: float, capsys: pytest.CaptureFixture[str]) -> dict:
    for name, text in (("t.toml", TOOL), ("m.toml", MATERIAL), ("p.nc", PROGRAM)):
        (tmp_path / name).write_text(text)
    out = tmp_path / f"run_{depth_mm}.h5"
    code, _, err = run_cli(["simulate", "--machine", "quaser-ux600", "--program",
                            str(tmp_path / "p.nc"), "--tool", str(tmp_path / "t.toml"),
                            "--material", str(tmp_path / "m.toml"), "--depth-mm", str(depth_mm),
                            "--tool-modes", str(CASE), "--accelerometer", "--duration-s", "2.5",
                            "-o", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    rec = read_recording(out)
    return {c: rec.channel(c)[-5000:] for c in ("truth/process/chatter",
                                                 "truth/tool/vibration_x", "accel/x")}  # fmt: skip


def _peak_hz(x: np.ndarray) -> float:
    """Largest peak above 100 Hz away from the spindle harmonics (±3 bins), Hz."""
    x = (x - x.mean()) * np.hanning(len(x))
    spec = np.abs(np.fft.rfft(x))
    f = np.fft.rfftfreq(len(x), 1e-4)
    f_rev = RPM / 60
    spec[(np.abs(f / f_rev - np.rint(f / f_rev)) * f_rev <= 3 * f[1]) | (f < 100)] = 0.0
    return float(f[int(np.argmax(spec))])


def test_chatter_above_the_sdm_limit_not_below(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stable = _run(tmp_path, 0.8 * 0.3174, capsys)
    chatter = _run(tmp_path, 1.2 * 0.3174, capsys)
    # 0.8 × the SDM critical depth: periodic with the revolution, no chatter flag
    assert stable["truth/process/chatter"].max() == 0.0
    # 1.2 ×: flagged chatter, at the SDM chatter frequency (932 Hz) within 2 % (measured
    # 934 Hz), with the vibration ≥ 5× the stable cut's and visible in the accelerometer
    assert chatter["truth/process/chatter"].mean() > 0.9
    assert _peak_hz(chatter["truth/tool/vibration_x"]) == pytest.approx(932.0, rel=0.02)
    assert _peak_hz(chatter["accel/x"]) == pytest.approx(932.0, rel=0.02)
    assert np.std(chatter["truth/tool/vibration_x"]) > 5 * np.std(stable["truth/tool/vibration_x"])


def test_tool_modes_file_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "p.nc").write_text(PROGRAM)
    bad = tmp_path / "bad.toml"
    damping = "[[structure.x]]\nnatural_frequency_hz = 900.0\ndamping_ratio = 1.5\n"
    for text, msg in (
        ("[tool]\ndiameter_mm = 10.0\n", "missing table [structure]"),
        (damping + "stiffness_n_m = 1e6\n", "damping_ratio"),
    ):
        bad.write_text(text)
        code, _, err = run_cli(["simulate", "--program", str(tmp_path / "p.nc"), "--tool-modes",
                                str(bad), "-o", str(tmp_path / "r.h5")], capsys)  # fmt: skip
        assert code == 2 and msg in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "r.h5").exists()
