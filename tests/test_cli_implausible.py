"""Issue 21 items 2 and 3 (not lobes): impossible input exits 2 with one line naming it,
implausible input is a warning in the CLI output and the JSON/metadata, and the inputs'
checksums are unchanged afterwards."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.simulator.machine_file import simulator_machine_path

DEMO = Path(__file__).resolve().parents[1] / "examples" / "demo_part"
STAB = Path(__file__).resolve().parents[1] / "examples" / "stability"
DATA = Path(__file__).resolve().parents[1] / "src" / "millsense" / "data"
HEAD = "%\nG21 G90 G94 G17\n"


def _sums(*paths: Path) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def _plan_args(prog: Path, out: Path) -> list[str]:
    return [
        "plan", str(prog),
        "--stock", str(DEMO / "stock.toml"),
        "--tool", str(DEMO / "tool.toml"),
        "--material", str(DEMO / "material.toml"),
        "-o", str(out),
    ]  # fmt: skip


def _one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("millsense: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]


def _inputs() -> list[Path]:
    return [DEMO / "stock.toml", DEMO / "tool.toml", DEMO / "material.toml"]


def test_plan_30_km_move_refused_before_allocating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prog = tmp_path / "huge.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F400\nG1 X30000000\nM30\n%\n")
    before = _sums(prog, *_inputs())
    out = tmp_path / "p.parquet"
    code, _, err = run_cli(_plan_args(prog, out), capsys)
    # 3e7 mm of path at 0.4 mm = 7.5e7 steps (ceiling 4e6); the longest move is line 6
    _one_line_error(code, err, "huge.nc", "7.5e+07 steps", "line 6", "--step-mm")
    assert not out.exists() and _sums(prog, *_inputs()) == before


def test_feed_1e9_mm_min_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "fast.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F1000000000\nG1 X50\nM30\n%\n")
    before = _sums(prog, *_inputs())
    out = tmp_path / "p.parquet"
    code, _, err = run_cli(_plan_args(prog, out), capsys)
    _one_line_error(code, err, "fast.nc:5", "exceeds 100000 mm/min")  # no machine: 100 m/min
    code, _, err = run_cli([*_plan_args(prog, out), "--machine", "quaser-ux600"], capsys)
    _one_line_error(code, err, "fast.nc:5", "exceeds 36000 mm/min")  # the UX600's limit
    h5 = tmp_path / "s.h5"
    code, _, err = run_cli(["simulate", "--program", str(prog), "-o", str(h5)], capsys)
    _one_line_error(code, err, "fast.nc:5", "1e+09 mm/min")
    assert not out.exists() and not h5.exists() and _sums(prog, *_inputs()) == before


def test_simulate_500_mm_depth_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "ok.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nG1 X50\nM30\n%\n")
    before = _sums(prog)
    h5 = tmp_path / "s.h5"
    code, _, err = run_cli(
        ["simulate", "--program", str(prog), "--depth-mm", "500", "-o", str(h5)], capsys
    )
    _one_line_error(code, err, "--depth-mm", "500 mm", "20 mm")  # the Ø20 mm default tool
    code, _, err = run_cli(
        ["simulate", "--program", str(prog), "--engagement", "ae_mm=25", "-o", str(h5)], capsys
    )
    _one_line_error(code, err, "--engagement ae_mm=25", "exceeds the tool diameter 20 mm")
    assert not h5.exists() and _sums(prog) == before


def test_simulate_spindle_stopped_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prog = tmp_path / "nospin.nc"
    # S1000 M3, then M5 before the second cut (the first cut is fine)
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nX0\nM5\nX50\nM30\n%\n")
    before = _sums(prog)
    h5 = tmp_path / "s.h5"
    code, _, err = run_cli(["simulate", "--program", str(prog), "-o", str(h5)], capsys)
    _one_line_error(code, err, "nospin.nc:8", "spindle stopped")
    assert not h5.exists() and _sums(prog) == before


@pytest.mark.parametrize(
    ("key", "value", "needle"),
    [
        # the case-file ranges of stability.cases fire first (decision 0906), naming the key
        ("damping_ratio", "0.0", "key 'x.0.damping_ratio' = 0.0 is out of range"),
        ("stiffness_n_m", "1e-9", "key 'x.0.stiffness_n_m' = 1e-09 is out of range"),
    ],
)
def test_simulate_tool_modes_without_damping_or_stiffness_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], key: str, value: str, needle: str
) -> None:
    text = (STAB / "insperger_1dof_slot.toml").read_text()
    lines = [
        f"{key} = {value}" if ln.strip().startswith(f"{key} =") else ln for ln in text.splitlines()
    ]
    modes = tmp_path / "modes.toml"
    modes.write_text("\n".join(lines) + "\n")
    prog = tmp_path / "ok.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nG1 X50\nM30\n%\n")
    before = _sums(prog, modes)
    h5 = tmp_path / "s.h5"
    args = ["simulate", "--program", str(prog), "--tool-modes", str(modes), "-o", str(h5)]
    code, _, err = run_cli(args, capsys)
    _one_line_error(code, err, "modes.toml [structure]", needle)
    assert not h5.exists() and _sums(prog, modes) == before


def test_simulate_duration_beyond_ceiling_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prog = tmp_path / "ok.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nG1 X50\nM30\n%\n")
    h5 = tmp_path / "s.h5"
    args = ["simulate", "--program", str(prog), "--duration-s", "1e9", "-o", str(h5)]
    code, _, err = run_cli(args, capsys)
    _one_line_error(code, err, "--duration-s 1e+09", "ceiling of 14400 s")
    assert not h5.exists()


def test_schedule_unreachable_force_limit_warns(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prog = tmp_path / "ok.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nG1 X50\nM30\n%\n")
    before = _sums(prog, *_inputs())
    out = tmp_path / "opt.nc"
    args = _plan_args(prog, out)
    args[0] = "schedule"
    # 5 N: the edge forces alone (K_te 25 N/mm, K_re 35 N/mm over 1 mm depth) exceed it
    code, _, err = run_cli([*args, "--limit-force-n", "5"], capsys)
    assert code == 0, err
    warn = [ln for ln in err.splitlines() if ln.startswith("millsense: warning: ")]
    assert len(warn) == 1 and "--limit-force-n 5 N: no feed reaches it" in warn[0]
    assert "edge forces alone" in warn[0] and "lines 6" in warn[0]
    assert out.exists() and _sums(prog, *_inputs()) == before
    # 2000 N: reachable everywhere (the plan peaks near 210 N at F400): no warning
    code, _, err = run_cli([*args, "--limit-force-n", "2000"], capsys)
    assert code == 0 and "warning" not in err


def test_plan_warnings_in_output_and_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.plan.virtual_plan import VirtualPlan

    prog = tmp_path / "coarse.nc"
    # F3000 at 1000 rev/min, 2 teeth: 1.5 mm per tooth, implausible (> 0.5 mm), not impossible
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F3000\nG1 X50\nM30\n%\n")
    before = _sums(prog, *_inputs())
    out = tmp_path / "p.parquet"
    code, _, err = run_cli([*_plan_args(prog, out), "--machine", "quaser-ux600"], capsys)
    assert code == 0, err
    warn = [ln.removeprefix("millsense: warning: ") for ln in err.splitlines() if "warning" in ln]
    assert len(warn) == 1 and "feed per tooth 1.5 mm is above 0.5 mm" in warn[0]
    meta = VirtualPlan.read(out).metadata
    assert meta["warnings"] == warn and meta["machine"] == "quaser-ux600"
    assert _sums(prog, *_inputs()) == before


def test_simulate_crash_events_in_output_and_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.io import read_recording

    prog = tmp_path / "heavy.nc"
    # a 30 mm deep slot at 1.5 mm/tooth: ~11 kN on the feed axis, beyond the UX600's 9.6 kN
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F3000\nG1 X50\nM30\n%\n")
    before = _sums(prog)
    h5 = tmp_path / "s.h5"
    args = ["simulate", "--program", str(prog), "--depth-mm", "30", "--duration-s", "0.4"]
    code, _, err = run_cli([*args, "-o", str(h5)], capsys)
    assert code == 0, err
    warn = [ln.removeprefix("millsense: warning: ") for ln in err.splitlines() if "warning" in ln]
    assert any("feed per tooth 1.5 mm" in w for w in warn)
    crash = [w for w in warn if w.startswith("crash at ")]
    assert crash and "beyond the machine's axis_force_n 9600 N" in crash[0]
    meta = read_recording(h5).metadata
    assert meta["warnings"] == warn
    events = meta["crash_events"]
    assert isinstance(events, list) and events[0]["kind"] == "crash"  # type: ignore[index]
    assert events[0]["name"] == "axis_force" and events[0]["value"] > 9600  # type: ignore[index]
    assert _sums(prog) == before


def test_estimate_beyond_axis_force_limit_warns_in_output_and_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    prog = tmp_path / "ok.nc"
    # in the stock from 0.35 s (feed from 0.30 s after the spindle's run-up, 1 mm of air)
    prog.write_text(HEAD + "S6000 M3\nG0 X-11 Y5 Z-1\nG1 X20 F1200\nM30\n%\n")
    run = tmp_path / "run.h5"
    code, _, err = run_cli(
        ["simulate", "--program", str(prog), "--duration-s", "0.5", "-o", str(run)], capsys
    )
    assert code == 0, err
    # the UX600 with a 1 N axis force limit: every estimate of a cut exceeds it
    # the simulator's own file (friction and modes given): this tests the limit, not the
    # identification (decision 0991)
    text = simulator_machine_path("quaser-ux600").read_text()
    machine = tmp_path / "weak.toml"
    machine.write_text(text.replace("axis_force_n = 9600.0", "axis_force_n = 1.0"))
    before = _sums(run, machine)
    js = tmp_path / "e.json"
    args = ["estimate", str(run), "--machine", str(machine), "--method", "raw", "--axes", "x"]
    code, _, err = run_cli([*args, "-o", str(tmp_path / "e.h5"), "--json", str(js)], capsys)
    assert code == 0, err
    warn = [ln.removeprefix("millsense: warning: ") for ln in err.splitlines() if "warning" in ln]
    force = [w for w in warn if "axis_force_n" in w]
    assert len(force) == 1 and "raw estimate of axis x" in force[0]
    assert "exceeds the machine's axis_force_n 1 N" in force[0]
    # the warning says when the largest load came: the middle of the 10 ms window of the
    # written file whose mean is largest (decision 1690)
    from millsense.io.recording_file import read_recording

    est = read_recording(tmp_path / "e.h5")
    v = np.asarray(est.channel("est/raw/x/load"))
    w = round(0.01 * est.sample_rate_hz)
    means = v[: v.size // w * w].reshape(-1, w).mean(axis=1)
    t_peak = (int(np.argmax(np.abs(means))) * w + w // 2) / est.sample_rate_hz
    assert f"(over 10 ms, largest at {t_peak:.3f} s)" in force[0]
    assert json.loads(js.read_text())["warnings"] == warn
    assert _sums(run, machine) == before
    # the preset's 9.6 kN: a 1 mm slot at 0.1 mm/tooth is far below, no force warning
    code, _, err = run_cli(
        ["estimate", str(run), "--machine", str(simulator_machine_path("quaser-ux600")),
         "--method", "raw", "--axes", "x", "-o", str(tmp_path / "e2.h5")], capsys,
    )  # fmt: skip
    assert code == 0 and "axis_force_n" not in err


@pytest.mark.parametrize(
    ("exc", "needle"),
    [
        (np.linalg.LinAlgError("Singular matrix"), "numerical failure (LinAlgError: Singular"),
        (FloatingPointError("overflow encountered"), "numerical failure (FloatingPointError"),
        (MemoryError(), "out of memory; reduce the input"),
    ],
)
def test_numerical_failures_are_one_line_at_the_edge(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    exc: BaseException,
    needle: str,
) -> None:
    import millsense.cli.cmd_simulate as cmd

    def fail(**_: object) -> None:
        raise exc

    monkeypatch.setattr(cmd, "run_simulation", fail)
    code, _, err = run_cli(["simulate", "--program", "p.nc", "-o", str(tmp_path / "s.h5")], capsys)
    _one_line_error(code, err, "simulate: ", needle)


@pytest.mark.parametrize(
    ("opts", "needle"),
    [
        (["--min-feed-mm-min", "1000"], "--min-feed-mm-min 1000.0: schedule: minimum feed"),
        (["--min-feed-mm-min", "-5"], "--min-feed-mm-min -5.0: must be > 0"),
        (["--min-feed-mm-min", "500", "--max-feed-mm-min", "300"], "exceeds --max-feed-mm-min"),
    ],
)
def test_schedule_feed_bounds_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], opts: list[str], needle: str
) -> None:
    # found by the fuzz suite: "schedule: minimum feed exceeds the maximum feed" named no option
    prog = tmp_path / "ok.nc"
    prog.write_text(HEAD + "S1000 M3\nG0 X-15 Y5 Z5\nG1 Z-1 F400\nG1 X50\nM30\n%\n")
    out = tmp_path / "opt.nc"
    args = _plan_args(prog, out)
    args[0] = "schedule"
    code, _, err = run_cli([*args, "--limit-force-n", "300", *opts], capsys)
    _one_line_error(code, err, needle)
    assert not out.exists()
