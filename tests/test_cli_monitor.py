"""``millsense monitor``: chatter on a recording, event log, plot, plan location, bad input.

The recordings are synthetic (tests/test_monitoring_chatter.py's signal: a 4-flute cut at
6000 rev/min, chatter at 937 Hz from 2.5 s) so the expected event is known exactly.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.recording import Recording
from millsense.io.recording_file import write_recording
from millsense.plan.virtual_plan import COLUMNS, VirtualPlan
from millsense.streaming import read_event_log
from millsense.streaming.event_log import event_log_recording
from test_monitoring_chatter import FS, _signal


def _recording(path: Path, *, speed: bool = True, zero_speed: bool = False,
               program: str = "part.nc", truth: bool = False,
               **metadata: object) -> Path:  # fmt: skip
    x, spd = _signal()
    rec = Recording(FS, 0.0, {"program": program, "flutes": 4, **metadata})
    rec.add_channel("mic/pressure", x, "Pa", "microphone")
    if truth:  # a simulator's recording keeps its ground truth beside the CNC's channels
        rec.add_channel("truth/mic/pressure", x, "Pa")
    if speed:
        rec.add_channel("spindle/speed", 0.0 * spd if zero_speed else spd, "rad/s")
        nc = np.where(np.arange(len(x)) < 2.0 * FS, 10, 12)
        rec.add_channel("cnc/nc_line", nc.astype(np.float64), "1")
    write_recording(path, rec)
    return path


def _plan(path: Path, program: str = "part.nc", duration_s: float = 4.0) -> Path:
    """A straight path at 10 mm/s, NC line 10 before 2 s and 12 after, ``duration_s`` long."""
    n = round(12.5 * duration_s)
    cols: dict[str, np.ndarray] = {c: np.zeros(n) for c in COLUMNS}
    cols["t_s"] = np.linspace(0.0, duration_s, n)
    cols["x_mm"] = 10.0 * cols["t_s"]
    cols["nc_line"] = np.where(cols["t_s"] < 2.0, 10, 12).astype(np.int64)
    for c in ("tool", "source_line", "n_intervals"):
        cols[c] = np.zeros(n, dtype=np.int64)
    cols["rapid"] = np.zeros(n, dtype=bool)
    cols["in_cut"] = np.ones(n, dtype=bool)
    VirtualPlan(cols, {"program": program}).write(path)
    return path


def test_monitor_microphone_only_with_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _recording(tmp_path / "run.h5", speed=False)
    out, png = tmp_path / "ev.parquet", tmp_path / "m.png"
    code, stdout, err = run_cli(["monitor", str(rec), "--spindle-rpm", "6000", "--methods",
                                 "chatter-comb,chatter-sdft", "-o", str(out), "--plot", str(png)],
                                capsys)  # fmt: skip
    assert code == 0, err
    ev = [e for e in read_event_log(out) if e.name == "chatter"]
    assert sorted(e.source for e in ev) == ["chatter-comb", "chatter-sdft"]
    assert event_log_recording(out) == "run.h5"  # the log names what it monitored
    for e in ev:
        assert e.value == pytest.approx(937.0, rel=0.005)  # the synthetic chatter frequency
        assert 2.5 < e.time_s <= 2.7
    assert png.stat().st_size > 10_000
    assert "chatter-comb: 1 chatter alarm" in stdout


def test_monitor_takes_the_speed_from_the_recordings_metadata(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A microphone-only recording whose import map stated ``spindle_rpm``: the monitor runs on
    that speed without ``--spindle-rpm`` (the same event as with the option), and a stated 0
    is refused naming the metadata."""
    rec = _recording(tmp_path / "run.h5", speed=False, spindle_rpm=6000)
    events = {}
    for name, extra in (("meta", []), ("option", ["--spindle-rpm", "6000"])):
        out = tmp_path / f"{name}.parquet"
        code, _, err = run_cli(["monitor", str(rec), "-o", str(out), *extra], capsys)
        assert code == 0, err
        events[name] = [(e.time_s, e.value) for e in read_event_log(out) if e.name == "chatter"]
    assert events["meta"] == events["option"]
    ((t, hz),) = events["meta"]
    assert 2.5 < t <= 2.7  # chatter from 2.5 s, within one 0.1 s decision
    assert hz == pytest.approx(937.0, rel=0.005)  # the synthetic chatter frequency
    rec = _recording(tmp_path / "zero.h5", speed=False, spindle_rpm=0)
    code, _, err = run_cli(["monitor", str(rec), "-o", str(tmp_path / "z.parquet")], capsys)
    assert code == 2
    assert "metadata spindle_rpm is 0" in err


@pytest.mark.parametrize("plan_s", [4.0, 40.0])
def test_monitor_with_plan_locates_the_event(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], plan_s: float
) -> None:
    """The plan of the recording's program locates the chatter event; a plan ten times as
    long as the recording (a run stopped by a feed hold covers the start of its program) is
    the same program's and is accepted."""
    rec = _recording(tmp_path / "run.h5")
    plan = _plan(tmp_path / "plan.parquet", duration_s=plan_s)
    out = tmp_path / "ev.parquet"
    code, _, err = run_cli(["monitor", str(rec), "--plan", str(plan), "-o", str(out)], capsys)
    assert code == 0, err
    (e,) = [e for e in read_event_log(out) if e.name == "chatter"]
    assert e.nc_line == 12
    # nearest plan row in time of NC line 12: x = 10 mm/s × t (row spacing 0.82 mm)
    assert e.x_mm == pytest.approx(10.0 * e.time_s, abs=0.5)


@pytest.mark.parametrize(
    ("kind", "needle"),
    [
        ("no-speed", "spindle speed"),
        ("zero-speed", "zero throughout"),
        ("bad-channel", "--channel 'accel/x'"),
        ("other-plan", "other.nc"),
        ("bad-method", "unknown monitor 'chatter-fft'"),
        ("zero-rpm-option", "--spindle-rpm: must be > 0, got 0"),
        ("truth-channel", "--channel 'truth/mic/pressure' is the simulator's ground truth"),
    ],
)
def test_monitor_bad_input_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, needle: str
) -> None:
    rec = _recording(tmp_path / "run.h5", speed=kind != "no-speed", zero_speed=kind == "zero-speed",
                     truth=kind == "truth-channel")  # fmt: skip
    args = ["monitor", str(rec), "-o", str(tmp_path / "ev.parquet")]
    if kind == "bad-channel":
        args += ["--channel", "accel/x"]
    if kind == "truth-channel":  # decision 1734's note: a one-line error, not a traceback
        args += ["--channel", "truth/mic/pressure"]
    if kind == "other-plan":
        args += ["--plan", str(_plan(tmp_path / "p.parquet", program="other.nc"))]
    if kind == "bad-method":
        args += ["--methods", "chatter-fft"]
    if kind == "zero-rpm-option":  # refused although the speed channel would make it unused
        args += ["--spindle-rpm", "0"]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "ev.parquet").exists()


def _engagement_recording(
    path: Path, fz_mm: float = 0.2, path_feed: bool = False, seconds: float = 2.0,
    noise_nm: float = 0.05,
) -> Path:  # fmt: skip
    """``seconds`` of the spindle torque of a Ø20 mm 2-flute 30° cut (the preset
    aslan-d20-2flute): down milling, 5 mm radial, 2 mm axial, ``fz_mm`` per tooth, 1000 rev/min,
    ``noise_nm`` of white noise per sample; with ``path_feed`` the CNC's path feed ``cnc/feed``
    (m/s) too."""
    import math

    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    n = int(seconds * FS)
    omega = 1000 * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    phi = 2 * math.pi * np.arange(600) / 600
    eng = Engagement.radial(5e-3, 20e-3, "down")
    rev = milling_forces(tool, co, eng, fz_mm * 1e-3, 2e-3, phi).torque_nm
    tq = np.interp(np.mod(omega * np.arange(n) / FS, 2 * math.pi), phi, rev, period=2 * math.pi)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    noise = noise_nm * np.random.default_rng(1).standard_normal(n)
    rec.add_channel("spindle/torque_est", tq + noise, "N*m")
    rec.add_channel("spindle/speed", np.full(n, omega), "rad/s")
    if path_feed:
        rec.add_channel("cnc/feed", np.full(n, fz_mm * 1e-3 * 2 * omega / (2 * math.pi)), "m/s")
    write_recording(path, rec)
    return path


def test_monitor_engagement_takes_the_feed_the_machine_ran(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The cut ran at 80 % override (0.16 mm/tooth) and the recording holds the CNC's path feed:
    without --feed-per-tooth-mm the monitor takes it, and K_t is the material's 758 N/mm²
    (within 3 %, as at the programmed feed above); the programmed 0.2 mm/tooth given instead
    reads the chip 25 % too thick and K_t 20 % low."""
    rec = _engagement_recording(tmp_path / "eng.h5", fz_mm=0.16, path_feed=True)
    kt = {}
    for key, extra in (("path", []), ("programmed", ["--feed-per-tooth-mm", "0.2"])):
        code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                                     "aslan-d20-2flute", *extra, "-o",
                                     str(tmp_path / f"{key}.parquet")], capsys)  # fmt: skip
        assert code == 0, err
        line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
        words = line.replace(",", "").split()
        assert float(words[words.index("axial") + 2]) == pytest.approx(2.0, abs=0.05)
        kt[key] = float(words[words.index("K_t") + 1])
    assert kt["path"] == pytest.approx(758.0, rel=0.03)
    assert kt["programmed"] == pytest.approx(0.8 * 758.0, rel=0.03)


def test_monitor_engagement_from_the_tool_preset(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _engagement_recording(tmp_path / "eng.h5")
    out = tmp_path / "ev.parquet"
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                                 "aslan-d20-2flute", "--feed-per-tooth-mm", "0.2", "-o", str(out)],
                                capsys)  # fmt: skip
    assert code == 0, err
    line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
    # 33 revolutions in 2 s; the medians of the seed 004 estimates: the noise (σ 0.05 N·m on a
    # ≈ 3 N·m torque) leaves d_a within ≈ 1 % (tests/test_monitoring_engagement.py)
    words = line.replace(",", "").split()
    assert int(words[1]) >= 30
    assert float(words[words.index("axial") + 2]) == pytest.approx(2.0, abs=0.05)
    assert float(words[words.index("radial") + 2]) == pytest.approx(5.0, abs=0.1)
    assert float(words[words.index("K_t") + 1]) == pytest.approx(758.0, rel=0.03)


def test_monitor_engagement_of_a_sensorless_cut_from_its_averaged_harmonics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1698: 30 s of the 2 mm cut with the sensorless estimate's noise (2.1 N·m per
    sample): few revolutions pass decision 1807's test alone, and the line reports the 499
    revolutions' averaged harmonics: d_a within 10 % of 2 mm, with its profile interval around
    it (neither "not determined" nor a revolution's other basin)."""
    import re

    rec = _engagement_recording(tmp_path / "eng.h5", seconds=30.0, noise_nm=2.1)
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                                 "aslan-d20-2flute", "--feed-per-tooth-mm", "0.2", "-o",
                                 str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
    m = re.search(r"harmonics averaged: axial depth ([\d.]+) mm \(profile interval ([\d.]+)–"
                  r"([\d.]+) mm\)", line)  # fmt: skip
    assert m, line
    depth, lo, hi = (float(g) for g in m.groups())
    assert depth == pytest.approx(2.0, rel=0.10)
    assert lo < 2.0 < hi


def test_monitor_engagement_with_the_air_torque_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the recording's torque is the cutting torque alone (a tared dynamometer): with
    # --air-torque-nm 0 the mean torque is used where the harmonics do not observe K_e
    # (decision 1806); the line says where K_e came from. Without it there is no air
    # revolution to learn from (the tool cuts throughout): K_e is flagged less reliable.
    rec = _engagement_recording(tmp_path / "eng.h5")
    base = ["monitor", str(rec), "--methods", "engagement", "--tool", "aslan-d20-2flute",
            "--feed-per-tooth-mm", "0.2"]  # fmt: skip
    lines = {}
    for key, extra in (("given", ["--air-torque-nm", "0"]), ("none", [])):
        code, stdout, err = run_cli([*base, *extra, "-o", str(tmp_path / f"{key}.parquet")],
                                    capsys)  # fmt: skip
        assert code == 0, err
        lines[key] = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
    words = lines["given"].replace(",", "").split()
    assert float(words[words.index("axial") + 2]) == pytest.approx(2.0, abs=0.05)
    # the recording's K_e: K_te = 25 N/mm (the coefficients of _engagement_recording)
    assert float(words[words.index("K_e") + 1]) == pytest.approx(25.0, rel=0.15)
    assert lines["given"].endswith("(from the mean torque)")
    assert lines["none"].endswith("(harmonics only, no air torque known: less reliable)")


def test_monitor_refuses_a_non_finite_air_torque(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _engagement_recording(tmp_path / "eng.h5")
    out = tmp_path / "ev.parquet"
    code, _, err = run_cli(["monitor", str(rec), "--methods", "engagement", "--tool",
                            "aslan-d20-2flute", "--feed-per-tooth-mm", "0.2", "--air-torque-nm",
                            "nan", "-o", str(out)], capsys)  # fmt: skip
    assert code == 2 and "--air-torque-nm" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        ([], "--tool"),
        (["--tool", "aslan-d20-2flute"], "--feed-per-tooth-mm"),
        (["--tool", "aslan-d20-2flute", "--feed-per-tooth-mm", "-1"], "--feed-per-tooth-mm"),
    ],
)
def test_monitor_engagement_names_what_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], needle: str
) -> None:
    rec = _engagement_recording(tmp_path / "eng.h5")
    out = tmp_path / "ev.parquet"
    code, _, err = run_cli(["monitor", str(rec), "--methods", "engagement", "-o", str(out),
                            *extra], capsys)  # fmt: skip
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


#: Contact recording: 10 kHz, spindle period 0.05 s, the X feed starting after 5 revolutions
#: at 2 mm/s from 0.5 mm above the surface at X = 0 (contact 0.5 s into the cut motion).
_C_PERIOD, _C_MOTION_S = 0.05, 0.8


def _contact_recording(path: Path) -> tuple[Path, np.ndarray, np.ndarray, np.ndarray]:
    import math

    rng = np.random.default_rng(7)
    m = int(_C_MOTION_S * FS)
    t = np.arange(m) / FS
    theta = 2 * math.pi * t / _C_PERIOD
    ripple = 0.2 * np.sin(theta + 0.3) + 0.05 * np.sin(3 * theta + 1.1)  # repeatable
    x = 0.5 - 2.0 * np.maximum(t - 5 * _C_PERIOD, 0.0)
    air = ripple + 0.01 * rng.standard_normal(m)
    cut = ripple + 10.0 * np.clip(-x, 0.0, None) ** 1.5 + 0.01 * rng.standard_normal(m)
    rec = Recording(FS, 0.0, {"program": "probe.nc"})
    rec.add_channel("spindle/torque_cmd", np.concatenate([air, cut]), "N*m")
    rec.add_channel("x/position", np.concatenate([np.full(m, 0.5), x]), "mm")
    rec.add_channel("spindle/speed", np.full(2 * m, 2 * math.pi / _C_PERIOD), "rad/s")
    write_recording(path, rec)
    return path, cut, air, x


def test_monitor_contact_with_the_air_cut_window(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.monitoring.contact import detect_contact

    rec, cut, air, x = _contact_recording(tmp_path / "probe.h5")
    out = tmp_path / "ev.parquet"
    code, stdout, err = run_cli(["monitor", str(rec), "--methods", "contact", "--air-s",
                                 f"0:{_C_MOTION_S}", "-o", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    ev = [e for e in read_event_log(out) if e.name == "contact"]
    assert len(ev) == 1
    # the same contact as the batch detector on the cut motion alone, on the recording's clock
    ref = detect_contact(cut, air, x, FS, _C_PERIOD)
    assert ev[0].value == pytest.approx(ref.position, abs=1e-12)
    assert ev[0].time_s == pytest.approx(_C_MOTION_S + ref.time_s, abs=1e-9)
    assert ev[0].value == pytest.approx(0.0, abs=0.01)  # the surface, within 10 µm
    assert "contact at" in stdout


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        ([], "--air-s"),
        (["--air-s", "0.5"], "--air-s"),
        (["--air-s", "0:9"], "--air-s"),
        (["--air-s", f"0:{_C_MOTION_S}", "--position", "y/scale"], "y/scale"),
    ],
)
def test_monitor_contact_names_what_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], needle: str
) -> None:
    rec, *_ = _contact_recording(tmp_path / "probe.h5")
    out = tmp_path / "ev.parquet"
    code, _, err = run_cli(["monitor", str(rec), "--methods", "contact", "-o", str(out),
                            *extra], capsys)  # fmt: skip
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_monitors_grouped_as_the_command_runs_them() -> None:
    """Chatter criteria on one signal become one ChatterGroup, breakage detectors on one speed
    one BreakageGroup (decision 1536); detectors on another speed and other monitors stay."""
    from millsense.cli.cmd_monitor import _grouped
    from millsense.monitoring.breakage import BreakageBlock, BreakageGroup
    from millsense.monitoring.chatter import ChatterGroup, ChatterMonitor, ChatterSettings
    from millsense.monitoring.engagement import EngagementBlock

    chatter = [ChatterMonitor(ChatterSettings(method=m)) for m in ("chatter-comb", "chatter-sdft")]
    breakage = [BreakageBlock(2, "constant"), BreakageBlock(2, "dual")]
    engagement = EngagementBlock(2, 20.0, 30.0, feed_per_tooth_mm=0.2)
    out = _grouped([chatter[0], breakage[0], engagement, chatter[1], breakage[1]])
    assert [type(b) for b in out] == [ChatterGroup, BreakageGroup, EngagementBlock]
    assert out[1].members == breakage
    apart = [BreakageBlock(2, "constant"), BreakageBlock(3, "dual")]
    assert _grouped(apart) == apart


def test_monitor_breakage_skips_the_spindle_run_up(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1550: a CNC recording (speed and its command, the observer's torque) that starts
    with a 0.3 s run-up to 1000 rev/min carrying 80 N·m of acceleration torque, 0.5 s of air
    (0.2 N·m of drag), then a steady 2-flute cut of 3 N·m whose flute 0 breaks at 4.2 s.
    `monitor` gates the breakage monitors on the spindle reaching its commanded speed (made
    from the two speed channels): the constant detector then learns its reference in the cut
    and alarms within 3 tooth periods of the break; learnt on the run-up (the block without the
    gate) it would be blind to it. Decision 1706: after a spindle start the level at speed is
    the air's; a cut there from the first revolution at speed (no air) is taken for the air and
    not judged, which the summary says (decision 1724's line: 'no alarm' alone would read as an
    intact tool)."""
    rng = np.random.default_rng(4)
    n = int(6.0 * FS)
    t = np.arange(n) / FS
    w = 1000 * 2 * np.pi / 60
    speed = np.minimum(t / 0.3, 1.0) * w
    tooth = 300  # samples a tooth period
    period = np.arange(n) // tooth
    tq = np.where(period >= 140, np.where(period % 2 == 0, 0.0, 6.0), 3.0)
    noise = 0.05 * np.sqrt(tooth) * rng.standard_normal(n)
    out = tmp_path / "ev.parquet"
    for air in (True, False):
        cut = np.where(t < 0.8, 0.2, tq) if air else tq
        rec = Recording(FS, 0.0, {"flutes": 2})
        rec.add_channel("spindle/speed", speed, "rad/s")
        rec.add_channel("spindle/speed_cmd", np.full(n, w), "rad/s")
        rec.add_channel("est/spindle/spindle/load", np.where(t < 0.3, 80.0, cut) + noise, "N*m")
        write_recording(tmp_path / "run.h5", rec)
        code, stdout, err = run_cli(["monitor", str(tmp_path / "run.h5"), "--methods",
                                     "breakage-constant", "-o", str(out)], capsys)  # fmt: skip
        assert code == 0, err
        ev = read_event_log(out)
        # the summary says where the detectors judged: the gate's steady cut against the time
        # at speed (the spindle within 3 % of its command from 0.29 s, at speed 0.1 s later)
        (gate,) = [ln for ln in stdout.splitlines() if "breakage without a plan" in ln]
        assert "on est/spindle/spindle/load:" in gate  # the recording's estimate, no --machine
        opened, at_speed = (float(v) for v in re.findall(r"([\d.]+) s", gate)[:2])
        assert at_speed == pytest.approx(5.6, abs=0.05)
        if not air:
            assert ev == []
            assert opened == 0.0 and "nothing judged" in gate  # not an intact tool's silence
            continue
        assert len(ev) == 1
        assert 4.2 < ev[0].time_s <= 4.2 + 3 * 0.03 + 1e-9
        # the cut from 0.8 s, steady after its onset revolution and one more (0.06 s each),
        # judged to the end: 5.2 s less those revolutions and the gate's one of 3 air ones
        assert 4.9 <= opened <= 5.2
        assert "nothing judged" not in gate


def test_monitor_says_when_it_judged_on_the_seed_premise(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1725: a recording that starts with the spindle already at speed (a trace
    started during a rapid move) keeps seed 002's premise: its first revolutions are taken as
    cut, in the air or not (decision 1706). The summary said 'judged where the torque showed a
    steady cut, 5.9 s of 5.9 s', although the torque showed nothing: 0.8 s of air (0.2 N·m),
    then the cut. It now says that time apart, as judged on the premise; a recording that
    starts with the run-up says nothing of a premise."""
    n = int(6.0 * FS)
    t = np.arange(n) / FS
    w = 1000 * 2 * np.pi / 60
    rng = np.random.default_rng(5)
    tq = np.where(t < 0.8, 0.2, 3.0) + 0.05 * np.sqrt(300) * rng.standard_normal(n)
    out = tmp_path / "ev.parquet"
    lines = {}
    for start in ("at_speed", "run_up"):
        speed = np.full(n, w) if start == "at_speed" else np.minimum(t / 0.3, 1.0) * w
        rec = Recording(FS, 0.0, {"flutes": 2})
        rec.add_channel("spindle/speed", speed, "rad/s")
        rec.add_channel("spindle/speed_cmd", np.full(n, w), "rad/s")
        rec.add_channel("est/spindle/spindle/load", tq, "N*m")
        write_recording(tmp_path / f"{start}.h5", rec)
        code, stdout, err = run_cli(["monitor", str(tmp_path / f"{start}.h5"), "--methods",
                                     "breakage-constant", "-o", str(out)], capsys)  # fmt: skip
        assert code == 0, err
        (lines[start],) = [ln for ln in stdout.splitlines() if "breakage without a plan" in ln]
    steady, at_speed, premise = (float(v) for v in
                                 re.findall(r"([\d.]+) s", lines["at_speed"])[:3])  # fmt: skip
    # at speed from its first samples, never stopped: every second at speed on the premise
    assert at_speed == pytest.approx(6.0, abs=0.15)
    assert premise == pytest.approx(at_speed, abs=1e-9)
    assert steady == 0.0
    assert "seed 002's premise" in lines["at_speed"]
    # after a run-up the gate waits for the cut (0.8 s), steady 2 revolutions later, to the end
    steady_run_up = float(re.findall(r"([\d.]+) s", lines["run_up"])[0])
    assert 4.9 <= steady_run_up <= 5.2
    assert "premise" not in lines["run_up"]


def test_monitor_engagement_not_determined_on_noise(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1807: a torque whose tooth harmonics are noise (a mean of 1 N·m and the
    spindle observer's 1.6 N·m of white noise at 8000 rev/min, as on a light 3-flute full slot)
    gives per-revolution fits that match the noise: the summary says the engagement is not
    determined instead of medians of them (a few revolutions pass σ ≥ 0.8 by chance)."""
    import math

    n = int(2.0 * FS)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    noise = 1.6 * np.random.default_rng(3).standard_normal(n)
    rec.add_channel("spindle/torque_est", 1.0 + noise, "N*m")
    rec.add_channel("spindle/speed", np.full(n, 8000 * 2 * math.pi / 60), "rad/s")
    write_recording(tmp_path / "noise.h5", rec)
    code, stdout, err = run_cli(["monitor", str(tmp_path / "noise.h5"), "--methods",
                                 "engagement", "--tool", "aslan-d20-2flute",
                                 "--feed-per-tooth-mm", "0.05", "-o",
                                 str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
    assert "engagement not determined" in line and "median axial depth" not in line


def test_monitor_plot_draws_each_monitor_that_ran(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 15 item 6: the figure carries the spectrogram and the chatter ratios, each breakage
    detector's residuals against its thresholds and the engagement's depth tracks: one panel
    per monitor that ran (the engagement recording: a torque, a speed, no chatter)."""
    from millsense.report.monitor_plots import monitor_panels

    rec = _engagement_recording(tmp_path / "eng.h5")
    png = tmp_path / "m.png"
    code, _, err = run_cli(["monitor", str(rec), "--methods",
                            "chatter-comb,breakage-dual,breakage-constant,engagement", "--tool",
                            "aslan-d20-2flute", "--feed-per-tooth-mm", "0.2", "-o",
                            str(tmp_path / "ev.parquet"), "--plot", str(png)], capsys)  # fmt: skip
    assert code == 0, err
    assert png.stat().st_size > 30_000
    data = {"signal": np.zeros(10)}
    for m, keys in (("chatter-comb", ("energy_ratio",)), ("breakage-dual", ("residual1",)),
                    ("breakage-constant", ("residual1",)), ("engagement", ("axial_depth",))):
        data.update({f"{m}/{k}": np.zeros(10) for k in keys})  # fmt: skip
    names = ["chatter-comb", "breakage-dual", "breakage-constant", "engagement", "contact"]
    assert monitor_panels(data, names) == [
        ("spectrogram", None), ("ratio", ["chatter-comb"]), ("breakage", "breakage-dual"),
        ("breakage", "breakage-constant"), ("engagement", "engagement"),
    ]  # fmt: skip


def test_a_session_recordings_observer_machine_is_found(tmp_path: Path) -> None:
    """Decision 1554: the engagement's equaliser needs the machine file the session's observer
    ran on: the file named in the metadata, else the commissioned file shipped for the machine
    (what `run` takes without --machine-file), else none."""
    from millsense.cli.cmd_monitor import _session_machine
    from millsense.io.recording_reader import opened_recording

    machine_file = Path(__file__).resolve().parents[1] / (
        "examples/walkthrough/quaser-ux600-commissioned.toml"
    )
    cases = {
        "file": ({"machine_file": str(machine_file)}, str(machine_file)),
        "shipped": (
            {"machine_file": "commissioned quaser-ux600 (...)", "machine": "quaser-ux600"},
            "quaser-ux600",
        ),
        "none": ({}, None),
    }
    for key, (meta, where) in cases.items():
        path = _recording(tmp_path / f"{key}.h5", speed=False, **meta)
        with opened_recording(path) as rec:
            found = _session_machine(rec)
        if where is None:
            assert found is None
        else:
            assert found is not None and where in found[1]
            assert found[0].spindle is not None  # the observer's section is there


def test_monitor_engagement_summary_over_the_plans_steady_cut(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1558: on a session's recording (``plan/judged_torque``) the engagement summary
    counts only the revolutions that end where the plan is steady. 6 s of a Ø20 mm 2-flute
    cut at 1000 rev/min, 5 mm deep where the plan is not steady (judged 0, the first 3.6 s)
    and 2 mm where it is: the median is the steady cut's 2 mm (within its standard error × 3
    and 5 %), of the 40 revolutions there, not the 5 mm of the majority, less the first: it
    began in the 5 mm part, and its level is no steady cut's (decision 1739)."""
    import math
    import re

    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces
    from millsense.process.geometry import EndMill

    n = int(6.0 * FS)
    om = 1000 * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    phi = 2 * math.pi * np.arange(600) / 600
    ang = np.mod(om * np.arange(n) / FS, 2 * math.pi)
    eng = Engagement.radial(5e-3, 20e-3, "down")
    deep, shallow = (milling_forces(tool, co, eng, 0.2e-3, d, phi).torque_nm for d in (5e-3, 2e-3))
    steady = np.arange(n) >= int(3.6 * FS)
    tq = np.where(steady, np.interp(ang, phi, shallow, period=2 * math.pi),
                  np.interp(ang, phi, deep, period=2 * math.pi))  # fmt: skip
    tq = tq + 0.2 * np.random.default_rng(5).standard_normal(n)
    rec = Recording(FS, 0.0, {"program": "part.nc"})
    rec.add_channel("spindle/torque_est", tq, "N*m")
    rec.add_channel("spindle/speed", np.full(n, om), "rad/s")
    rec.add_channel("plan/judged_torque", np.where(steady, 3.0, 0.0), "N*m")
    write_recording(tmp_path / "run.h5", rec)
    code, stdout, err = run_cli(["monitor", str(tmp_path / "run.h5"), "--methods",
                                 "engagement", "--tool", "aslan-d20-2flute",
                                 "--feed-per-tooth-mm", "0.2", "-o",
                                 str(tmp_path / "ev.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("engagement:"))
    m = re.search(r"of (\d+) revolutions in the plan's steady cut reliable .* median axial depth "
                  r"([\d.]+) mm \(standard error ([\d.]+) mm", line)  # fmt: skip
    assert m, line
    assert int(m.group(1)) == 39
    median, se = float(m.group(2)), float(m.group(3))
    assert abs(median - 2.0) < 3 * se and median == pytest.approx(2.0, rel=0.05)


def _session_recording(path: Path, judged: bool = True) -> Path:
    """A session's recording (`millsense run`'s channels) of a 2-flute cut at 1000 rev/min: air
    to 1 s, a light entry whose tooth-period torque rises from 0.05 to 0.6 N·m to 3 s (the plan
    in cut, not steady), a steady 3 N·m cut (the plan steady from 3.2 s), flute 0 broken at
    6.0 s (its periods 0.2 N·m, the next flute's 5.8 N·m); 0.05 N·m of noise on the tooth-period
    average. ``judged``: with ``plan/judged_torque`` (else a recording without it)."""
    rng = np.random.default_rng(11)
    n = int(7.0 * FS)
    t = np.arange(n) / FS
    tooth = 300
    period = np.arange(n) // tooth
    light = np.interp(t, [1.0, 3.0], [0.05, 0.6])
    tq = np.where(t < 1.0, 0.0, np.where(t < 3.0, light, 3.0))
    tq = np.where(period >= 200, np.where(period % 2 == 0, 0.2, 5.8), tq)
    tq = tq + 0.05 * np.sqrt(tooth) * rng.standard_normal(n)
    rec = Recording(FS, 0.0, {"flutes": 2, "program": "part.nc"})
    rec.add_channel("spindle/speed", np.full(n, 1000 * 2 * np.pi / 60), "rad/s")
    rec.add_channel("spindle/at_speed", np.ones(n), "1")
    rec.add_channel("plan/in_cut", (t >= 1.0).astype(np.float64), "1")
    rec.add_channel("plan/cutting_torque", tq, "N*m")
    if judged:
        rec.add_channel("plan/judged_torque", np.where(t >= 3.2, 3.0, 0.0), "N*m")
    write_recording(path, rec)
    return path


def test_plan_free_breakage_detectors_judge_the_plans_steady_cut(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1676: on a session's recording the dual (seed 002) and constant detectors learn
    and judge where the plan is steady in the cut: each alarms once, within 3 tooth periods of
    the break at 6.0 s. Gated on the plan's cut alone (a recording without the judged torque)
    they learn their thresholds and reference on the light entry (0.05-0.2 N·m): the dual
    detector alarmed where the cut reached its 3 N·m, before the break; with decision 1707's
    flute check that rise of every flute is no alarm, and the break still is (the constant
    detector, its reference the entry's, stays silent)."""
    out = tmp_path / "ev.parquet"
    for judged in (False, True):
        rec = _session_recording(tmp_path / f"run{judged}.h5", judged)
        code, _stdout, err = run_cli(["monitor", str(rec), "--methods",
                                      "breakage-dual,breakage-constant", "-o", str(out)],
                                     capsys)  # fmt: skip
        assert code == 0, err
        ev = read_event_log(out)
        assert not [e for e in ev if e.time_s < 6.0]
        for src in ("breakage-dual", "breakage-constant") if judged else ("breakage-dual",):
            times = [e.time_s for e in ev if e.source == src]
            assert len(times) == 1 and 6.0 < times[0] <= 6.0 + 3 * 0.03 + 1e-9, (src, times)
        if not judged:  # the recording of a session before 1622: the entry is learnt on
            assert not [e for e in ev if e.source == "breakage-constant"]


def test_monitor_plot_breakage_axes_in_the_judged_torques_unit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each breakage panel of ``monitor --plot`` is labelled with the unit of the torque its
    detector judges ('N·m' for spindle/torque_est), not 'N·m or N' (found by the qa4 helper);
    a detector whose unit is not known keeps 'N·m or N'. The residuals drawn are the
    detector's own: 0.25 N·m in the figure's data is 0.25 on the axis."""
    import millsense.report.monitor_plots as mp

    seen: dict[str, object] = {}
    real = mp.plot_monitor

    def capture(*args: object) -> None:
        seen["units"] = args[-1]
        real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(mp, "plot_monitor", capture)
    rec = _engagement_recording(tmp_path / "eng.h5")
    code, _, err = run_cli(["monitor", str(rec), "--methods", "breakage-dual,breakage-constant",
                            "-o", str(tmp_path / "ev.parquet"), "--plot",
                            str(tmp_path / "m.png")], capsys)  # fmt: skip
    assert code == 0, err
    assert seen["units"] == {"breakage-dual": "N*m", "breakage-constant": "N*m"}
    data = {"signal": np.zeros(100), "breakage-dual/residual1": np.full(10, 0.25)}
    for k in ("limit1", "residual2", "limit2"):
        data[f"breakage-dual/{k}"] = np.ones(10)
    fig = mp.monitor_figure(data, 1000.0, 10, 0.0, "spindle/torque_est", ["breakage-dual"], [],
                            {"breakage-dual": "N*m"})  # fmt: skip
    ax = fig.axes[-1]
    assert ax.get_ylabel() == "breakage-dual\n[N·m]"
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == "residual 1"]
    assert float(np.max(line.get_ydata())) == 0.25
    fig = mp.monitor_figure(data, 1000.0, 10, 0.0, "x", ["breakage-dual"], [])
    assert fig.axes[-1].get_ylabel() == "breakage-dual\n[N·m or N]"


def test_depth_panel_shows_as_results_only_the_revolutions_the_summary_reports() -> None:
    """On an imported slot the depth panel drew every revolution's held value as dots, one per
    plotted step, which read as lines: 27 mm "depths" of a 4 mm slot and K_t of 1e18 N/m²
    in air looked like results while the summary said "1 of 57 revolutions reliable" (K_e ≥ 0
    is not in the plotted data). The command passes the revolutions it reports; the others are
    one hollow circle each. Here 4 revolutions of 10 steps: σ passes on 3, the summary keeps
    2 (one has K_e < 0): the depth line holds 20 steps, 2 circles mark the rest."""
    from types import SimpleNamespace

    from millsense.cli.monitor_engagement import depth_panel, engagement_verdict
    from millsense.report.monitor_plots import monitor_figure

    def est(sigma: float, kt: float, ke: float) -> SimpleNamespace:
        # a down-milling window (decision 1738's side cut)
        return SimpleNamespace(reliability=sigma, kt_n_m2=kt, edge_n_m=ke, entry_rad=2.0,
                               exit_rad=math.pi)  # fmt: skip

    fs, step = 1000.0, 10
    revs = [est(0.9, 8e8, 1e4), est(0.9, 8e8, -5e3), est(0.5, 8e8, 1e4), est(0.95, 8e8, 1e4)]
    block = SimpleNamespace(name="engagement",
                            estimates=[(0.1 * (k + 1), e) for k, e in enumerate(revs)])
    n = 50  # steps of 10 samples: 0.5 s; revolution k is held from 0.1 (k + 1) s on
    panel = depth_panel(block, engagement_verdict(block), n, step, fs)
    assert set(panel) == {"engagement/reported"}  # the medians: no averaged band
    reported = panel["engagement/reported"]
    held = np.searchsorted([0.1, 0.2, 0.3, 0.4], np.arange(n) * step / fs, side="right") - 1
    np.testing.assert_array_equal(reported, np.isin(held, [0, 3]))
    depth = np.where(held >= 0, 1e-3 * (4.0 + held), np.nan)  # 4, 5, 6, 7 mm
    data = {
        "engagement/axial_depth": depth,
        "engagement/reliability": np.array([np.nan, 0.9, 0.9, 0.5, 0.95])[held + 1],
        "engagement/kt": np.full(n, 8e8),
        "engagement/reported": reported,
    }
    fig = monitor_figure(data, fs, step, 0.0, "spindle/torque", ["engagement"], [])
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    y = np.asarray(lines["axial depth"].get_ydata(), dtype=float)
    assert np.count_nonzero(np.isfinite(y)) == 20
    assert set(np.round(y[np.isfinite(y)] * 1.0, 6)) == {4.0, 7.0}
    circles = [ln for ln in fig.axes[0].get_lines() if ln.get_marker() == "o"]
    assert len(circles[0].get_xdata()) == 2  # revolutions 1 and 2 (5 and 6 mm)


@pytest.mark.parametrize("determined", [True, False])
def test_depth_panel_shades_the_averaged_depth_where_the_summary_reports_it(
    determined: bool,
) -> None:
    """Decision 1704: where fewer than half of the revolutions pass decision 1807's test, the
    summary reports the revolutions' averaged harmonics (decision 1698), but the depth panel
    drew the few revolutions that pass alone as the result. Here 2 of 10 pass. Where the
    average determines the depth (2.065 mm, profile interval 1.905–2.232 mm, the 30 s
    sensorless cut's figures) the panel draws no revolution as reported, the averaged depth as
    a line over the averaged revolutions and its interval as a band; where it does not
    (1.50–2.80 mm: ±32 %), a hatched band of the depths allowed and no depth line."""
    from types import SimpleNamespace

    from millsense.cli.monitor_engagement import depth_panel, engagement_summary, engagement_verdict
    from millsense.monitoring.torque_spectrum import AveragedEstimate, EngagementEstimate
    from millsense.report.monitor_plots import monitor_figure

    def est(depth: float, sigma: float) -> EngagementEstimate:
        return EngagementEstimate(depth, 5e-3, 2.0, math.pi, 7.4e8, 1e-6, 0.0, sigma, 1e-3,
                                  20.0, 0.1, 2e4, 1.0)  # fmt: skip

    lo, hi = (1.905e-3, 2.232e-3) if determined else (1.5e-3, 2.8e-3)
    avg = AveragedEstimate(10, est(2.065e-3, 0.95), lo, hi, True)
    revs = [est(1e-3 * (2 + k), 0.9 if k in (3, 7) else 0.5) for k in range(10)]
    block = SimpleNamespace(
        name="engagement",
        averaged=lambda which: avg,
        estimates=[(0.1 * (k + 1), e) for k, e in enumerate(revs)],
    )
    verdict = engagement_verdict(block)
    assert verdict.kind == ("averaged" if determined else "undetermined")
    line = engagement_summary(block, verdict=verdict)
    assert ("harmonics averaged: axial depth 2.065 mm" in line) == determined, line
    fs, step, n = 1000.0, 10, 120  # 1.2 s; revolution k is held from 0.1 (k + 1) s on
    panel = depth_panel(block, verdict, n, step, fs)
    assert not panel["engagement/reported"].any()
    held = np.arange(n) * step / fs >= 0.1 - 1e-12
    np.testing.assert_array_equal(np.isfinite(panel["engagement/averaged_low"]), held)
    assert np.isfinite(panel["engagement/averaged_depth"]).sum() == (110 if determined else 0)
    axial = np.repeat([np.nan, *[e.axial_depth_m for e in revs]], [10] + [10] * 9 + [20])
    data = {
        "engagement/axial_depth": axial,
        "engagement/reliability": np.full(n, 0.5),
        "engagement/kt": np.full(n, 7.4e8),
        **panel,
    }
    ax = monitor_figure(data, fs, step, 0.0, "spindle/torque", ["engagement"], []).axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    y = np.asarray({ln.get_label(): ln for ln in ax.get_lines()}["axial depth"].get_ydata())
    assert not np.isfinite(y).any()  # no revolution drawn as a result
    if determined:
        assert "axial depth of the averaged harmonics 2.065 mm" in labels
        assert "averaged harmonics' profile interval 1.905–2.232 mm" in labels
    else:
        assert "not determined: averaged harmonics allow 1.50–2.80 mm" in labels
        assert not any("axial depth of the averaged" in label for label in labels)


def _slot_from_spindle_start(path: Path, break_at_s: float | None) -> Path:
    """The example data's slot on the virtual quaser-ux600 (Ø20 mm 2-flute, 4 mm deep, 3000
    rev/min, 1200 mm/min, 6 mm of air after the spindle's start; `millsense example-data`'s
    program), 2.0 s, flute 0 broken at ``break_at_s`` (None: intact)."""
    from millsense.cli.cmd_simulate import run_simulation
    from millsense.cli.example_data import SLOT

    prog = path.with_suffix(".nc")
    prog.write_text(SLOT)
    run_simulation(machine="quaser-ux600", program=prog, plan=None, tool=None, material=None,
                   engagement="slot", depth_mm=4.0, out=path, air_mm=6.0, duration_s=2.0,
                   seed=0, cnc="open", break_at_s=break_at_s, break_flute=0, realism=None,
                   accelerometer=False, microphone=False, chunk=1000)  # fmt: skip
    return path


def test_plan_free_detectors_wait_for_the_cut_after_the_spindle_start(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1706: without a plan, a recording that starts with the spindle's run-up starts
    in the air. Seed 002's dual detector learnt its thresholds there (0.23 N·m of the
    observer's noise) and alarmed at the cut's entry (0.68 s, residual 4.4 N·m) of the intact
    slot, and the constant detector, its reference learnt in the air, missed the break. Gated
    on the torque's rise from the air and its steadiness (`TorqueCutGate`) they learn on the
    cut (dual thresholds 0.34 N·m on the LQE observer's torque; 0.130 on the spindle DOB's
    that `monitor --machine` gives them since decision 1728, against 0.095 learnt on its
    air): no alarm on the intact slot; on the broken one each alarms
    once after the break at 1.5 s (tooth periods of 10 ms at 3000 rev/min, 2 flutes): the dual
    at 2.3 periods (the next flute's rise after the broken flute's drop, decision 1707; 0.3
    by seed 002's rule alone, at the partial period where the flute broke), the constant at
    3.3 (before: the dual at 0.68, 1.50 and 1.54 s, the constant never)."""
    machine = str(Path(__file__).resolve().parents[1]
                  / "examples/walkthrough/quaser-ux600-commissioned.toml")  # fmt: skip
    for brk in (None, 1.5):
        rec = _slot_from_spindle_start(tmp_path / f"slot_{brk}.h5", brk)
        out = tmp_path / f"ev_{brk}.parquet"
        code, stdout, err = run_cli(["monitor", str(rec), "--machine", machine, "--methods",
                                     "breakage-dual,breakage-constant", "-o", str(out)],
                                    capsys)  # fmt: skip
        assert code == 0, err
        # the summary names the torque they averaged: the DOB's (decision 1728)
        assert "breakage without a plan on spindle/dob_torque:" in stdout
        ev = read_event_log(out)
        if brk is None:
            assert ev == []
            continue
        # the dual alarms where a flute's drop and the next flute's rise are seen (decision
        # 1707), the constant one at its third violating period (seed 000's confirmation):
        # within 3 periods of the break (the figure), and 1 more for the constant's
        # confirmation, whose first violation comes up to a period after the break
        for src, periods in (("breakage-dual", 3), ("breakage-constant", 4)):
            times = [e.time_s for e in ev if e.source == src]
            assert len(times) == 1 and brk < times[0] <= brk + periods * 0.01, (src, times)
        dual = next(e for e in ev if e.source == "breakage-dual")
        # learnt on the cut (0.130), not on the air (0.095): the DOB's (decision 1728)
        assert dual.values["limit1_nm"] == pytest.approx(0.130, abs=0.015)


def test_torque_cut_gate_keeps_the_seed_premise_and_follows_the_cut() -> None:
    """`TorqueCutGate` on synthetic revolution torques at 1000 rev/min (600 samples a
    revolution, 0.02 N·m of noise): after a spindle start it opens on the second steady
    revolution of a rise from 0.5 to 3 N·m (the first two cut revolutions ramp up) and closes
    one revolution after the torque is back at the air's level; a stream that starts at speed
    is the at-speed gate from its first sample (seed 002's premise) until the spindle stops
    and starts again (a tool change at 2.2 s): then it waits for the cut again (at 2.8 s); a
    speed change in the cut keeps it open. The same in 10-sample and 7000-sample chunks."""
    fs, rev = 10000.0, 600
    w = 2 * np.pi * fs / rev
    n = 60 * rev
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)

    def ramp(t_on: float, t_off: float) -> np.ndarray:
        return np.clip((t - t_on) / (2 * rev / fs), 0.0, 1.0) * (t < t_off)

    cut = ramp(0.5, 1.8) + ramp(2.8, np.inf)  # in the cut 0.5-1.8 s and from 2.8 s on
    tq = 0.5 + 2.5 * cut + 0.02 * rng.standard_normal(n)
    stop = (t >= 2.2) & (t < 2.4)  # a tool change: the spindle stops and starts again
    speed = np.where(t < 0.1, w * t / 0.1, w) * np.where(stop, 0.0, 1.0)
    speed = np.where((t >= 3.1) & (t < 3.15), 0.8 * w, speed)  # a speed change in the cut
    at_speed = ((t >= 0.2) & ~((t >= 2.2) & (t < 2.5)) & ~((t >= 3.1) & (t < 3.2))).astype(float)

    def gate(speed: np.ndarray, at_speed: np.ndarray, chunk: int) -> np.ndarray:
        return _gate_run(t, tq, speed, at_speed, chunk, fs)

    r = rev / fs
    for chunk in (10, 7000):
        g = gate(speed, at_speed, chunk)
        opened = t[np.flatnonzero(np.diff(g) > 0) + 1]
        closed = t[np.flatnonzero(np.diff(g) < 0) + 1]
        # the ramps end 0.12 s after the cut's start: the first revolution at 3 N·m after it
        # is the onset's, the next confirms it (within 3 revolutions of the ramp's end); the
        # speed change at 3.1-3.2 s closes the at-speed gate only
        assert len(opened) == 3 and len(closed) == 2, (opened, closed)
        assert 0.62 < opened[0] < 0.62 + 3 * r
        assert 1.8 < closed[0] <= 1.8 + 2 * r
        assert 2.92 < opened[1] < 2.92 + 3 * r
        assert closed[1] == pytest.approx(3.1) and opened[2] == pytest.approx(3.2)
        assert not g[(t < 0.6) | ((t > 1.8 + 2 * r) & (t < 2.9))].any()
        # the spindle at speed from the stream's start: the at-speed gate until the stop
        premise = gate(np.where(stop, 0.0, w), at_speed, chunk)
        np.testing.assert_array_equal(premise[t < 2.2], at_speed[t < 2.2])
        assert not premise[(t >= 2.2) & (t < 2.9)].any() and premise[t > 3.5].all()


def test_monitor_reports_its_progress(tmp_path: Path) -> None:
    """`monitor` draws a progress bar from ``run_monitor``'s ``on_progress``: the fraction of
    the recording monitored after each chunk, rising to 1 (2 s at 10 kHz in 1000-sample
    chunks: 20 reports, 0.05 apart)."""
    from millsense.cli.cmd_monitor import run_monitor

    rec = _engagement_recording(tmp_path / "eng.h5")
    seen: list[float] = []
    run_monitor(recording=rec, out=tmp_path / "ev.parquet", methods="chatter-comb",
                on_progress=seen.append)  # fmt: skip
    np.testing.assert_allclose(seen, np.arange(1, 21) / 20, rtol=1e-12)


def _gate_run(t: np.ndarray, tq: np.ndarray, speed: np.ndarray, at_speed: np.ndarray,
              chunk: int, fs: float = 10000.0) -> np.ndarray:  # fmt: skip
    """`TorqueCutGate`'s output on a synthetic stream, fed in chunks of ``chunk`` samples."""
    from millsense.online.gates import TorqueCutGate
    from millsense.streaming.block import Chunk

    g = TorqueCutGate("tq", "w", "ok", out="g")
    g.reset(fs)
    data = {"tq": tq, "w": speed, "ok": at_speed}
    return np.concatenate([g.process(Chunk(a, fs, 0.0, {k: v[a : a + chunk]
                                                      for k, v in data.items()})).channels["g"]
                           for a in range(0, len(t), chunk)])  # fmt: skip


def _speed_steps(t: np.ndarray, steps: list[tuple[float, float]], w1: float,
                 ramp_s: float = 0.05) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """A spindle started at t = 0 and stepped to ``steps`` (time s, speed / w1): linear ramps of
    ``ramp_s``; at speed where no ramp runs and 0.05 s after each."""
    speed = np.zeros_like(t)
    ok = np.ones_like(t)
    prev = 0.0
    for t0, r in steps:
        speed = np.where(t >= t0, prev + (r - prev) * np.clip((t - t0) / ramp_s, 0, 1), speed)
        ok[(t >= t0) & (t < t0 + ramp_s + 0.05)] = 0.0
        prev = r
    return w1 * speed, ok


def test_torque_cut_gate_keeps_the_air_of_each_speed() -> None:
    """Decision 1723: the gate learns the air's drag per spindle speed (synthetic drag 0.3 +
    0.4·w/w₁ N·m, Coulomb + viscous; 600-sample revolutions at w₁ = 1000 rev/min, 0.02 N·m of
    noise).

    - Air at w₁ and 1.5 w₁, then a cut (+0.6 N·m) that begins during the ramp to 1.25 w₁: the
      gate judged it against the line through the two air levels and opens within 3
      revolutions of the speed (decision 1706's restart of the air statistics at every speed
      change learnt the cut as the air and never opened); it closes after the exit.
    - Air at w₁ only, then a cut (+1 N·m) that begins in the ramp to 2.5 w₁: judged against
      the band from all Coulomb to all viscous drag (0.7-1.75 N·m), it opens; a ramp from below
      half the new speed is no spindle start (decision 1706 took it for one).
    - Air at w₁ only, then 2 w₁ in the air (drag 0.7 → 1.1 N·m, inside the band from all
      Coulomb to all viscous, 0.7-1.4): no opening; a cut at 2 w₁ after 0.5 s of its air opens.
    - A cut that begins before the spindle is at speed (learnt as the air, decision 1706) ends
      at 1.0 s: the revolution below that level restarts the air, and the next cut (1.5 s)
      opens (before: no opening).
    The same in 10-sample and 7000-sample chunks."""
    fs, rev = 10000.0, 600
    w1 = 2 * np.pi * fs / rev
    t = np.arange(int(3.5 * fs)) / fs
    rng = np.random.default_rng(5)
    noise = 0.02 * rng.standard_normal(t.size)

    def drag(speed: np.ndarray) -> np.ndarray:
        return 0.3 + 0.4 * speed / w1

    def edges(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return t[np.flatnonzero(np.diff(g) > 0) + 1], t[np.flatnonzero(np.diff(g) < 0) + 1]

    for chunk in (10, 7000):
        # three speeds, the cut beginning in the ramp to the third (at speed from 2.1 s)
        speed, ok = _speed_steps(t, [(0.0, 1.0), (1.0, 1.5), (2.0, 1.25)], w1)
        cut = (t >= 2.02) & (t < 3.0)
        g = _gate_run(t, drag(speed) + 0.6 * cut + noise, speed, ok, chunk)
        opened, closed = edges(g)
        r3 = rev / fs / 1.25
        assert len(opened) == 1 and 2.1 < opened[0] <= 2.1 + 3 * r3, opened
        assert len(closed) == 1 and 3.0 < closed[0] <= 3.0 + 2 * r3, closed
        # one air speed known, a cut (+1 N·m) beginning in the ramp to 2.5 w1: not a start
        # (decision 1706 took a ramp from below half the new speed for one and forgot the air)
        speed, ok = _speed_steps(t, [(0.0, 1.0), (1.0, 2.5)], w1)
        cut = t >= 1.02
        g = _gate_run(t, drag(speed) + 1.0 * cut + noise, speed, ok, chunk)
        opened, _ = edges(g)
        assert len(opened) == 1 and 1.1 < opened[0] <= 1.1 + 3 * rev / fs / 2.5, opened
        # one air speed known, the speed doubled in the air, then a cut at 2 w1 from 2.0 s
        speed, ok = _speed_steps(t, [(0.0, 1.0), (1.0, 2.0)], w1)
        cut = t >= 2.0
        g = _gate_run(t, drag(speed) + 0.6 * cut + noise, speed, ok, chunk)
        opened, _ = edges(g)
        assert len(opened) == 1 and 2.0 < opened[0] <= 2.0 + 3 * rev / fs / 2, opened
        # a cut from before the spindle is at speed (0.08-1.0 s), then air, then a cut from 1.5 s
        speed, ok = _speed_steps(t, [(0.0, 1.0)], w1)
        cut = ((t >= 0.08) & (t < 1.0)) | (t >= 1.5)
        g = _gate_run(t, drag(speed) + 0.6 * cut + noise, speed, ok, chunk)
        opened, _ = edges(g)
        assert not g[t < 1.5].any()
        assert len(opened) == 1 and 1.5 < opened[0] <= 1.5 + 3 * rev / fs, opened
