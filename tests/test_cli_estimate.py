"""``millsense estimate`` end to end on a simulated slot, and estimators built from a config.

Scenario: quaser-ux600 (5-axis), Ø20 mm 2-flute end mill, Al7050, slot 4 mm deep along +X at
1200 mm/min and 3000 rev/min (0.2 mm/tooth, tooth frequency 100 Hz), 1.3 s simulated with the
realism layer on; the first 6 mm of the feed move (0.3 s) cut air (``simulate --air-mm 6``).
Configuration mismatch between the estimator and the machine: the estimator
is built from the preset's tables (Aslan Table 3.2 friction, Table 3.4 modes) while the
simulated machine has position-dependent mode frequencies (±2–6 %), friction drifting with
temperature and a 1–3 % position ripple, and one or two unmodelled modes above the identified
band; moreover Table 3.4 lacks the real poles of the velocity loop that the C3 torque sees.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from cli_run import run_cli
from millsense.core.config import FeedAxisConfig, MachineConfig
from millsense.core.errors import ConfigError
from millsense.core.presets import load_preset
from millsense.estimation.feed.estimator import FeedAxisModel
from millsense.estimation.from_config import build_estimators
from millsense.io import read_recording
from millsense.simulator.machine_file import simulator_machine
from slot_run import SIM_QUASER, SLOT, XyFeed


@pytest.fixture(scope="module")
def run_h5(slot_run: Path) -> Path:
    """The slot of the module docstring, simulated once per session (tests/slot_run.py)."""
    return slot_run


def _steady(rec_path: Path) -> tuple[int, int]:
    """Independent window: in-cut samples, trimmed, cut to whole tooth periods (100 samples)."""
    rec = read_recording(rec_path)
    cut = np.flatnonzero(rec.channel("truth/process/engagement") >= 0)
    i0, i1 = int(cut[0]), int(cut[-1]) + 1
    d = (i1 - i0) // 5
    i0, i1 = i0 + d, i1 - d
    return i0, i0 + 100 * ((i1 - i0) // 100)


def _tooth_amp(x: np.ndarray) -> float:
    """Amplitude at 100 Hz by FFT over whole periods (100 samples at 10 kHz per period)."""
    spec = np.fft.rfft(x - x.mean())
    return float(2 * abs(spec[len(x) // 100]) / len(x))


def test_feed_mean_within_5pct_and_better_than_raw_at_tooth_frequency(
    run_h5: Path,
    slot_xy_feed: XyFeed,
    commissioned: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # the feed estimate (exit 0 asserted) with the machine file a user makes: commission →
    # identify → merge (tests/commissioned.py); computed once per session (tests/slot_run.py)
    feed, png, raw = slot_xy_feed.estimates, slot_xy_feed.plot, tmp_path / "raw.h5"
    assert "tooth" in slot_xy_feed.stdout and png.stat().st_size > 10_000
    machine = str(commissioned / "machine.toml")
    base = ["estimate", str(run_h5), "--machine", machine, "--axes", "x,y"]
    code, _, err = run_cli([*base, "--method", "raw", "-o", str(raw)], capsys)
    assert code == 0, err
    rf, rr, rt = read_recording(feed), read_recording(raw), read_recording(run_h5)
    i0, i1 = _steady(run_h5)
    lag = 60  # fixed-lag smoother (Aslan App. B), removed before comparing
    truth = rt.channel("truth/y/load")[i0:i1]
    est_f = rf.channel("est/feed/y/load")[i0 + lag : i1 + lag]
    est_r = rr.channel("est/raw/y/load")[i0:i1]
    # the estimates file carries copies of the inputs it used, sample for sample
    np.testing.assert_array_equal(rf.channel("y/current_cmd"), rt.channel("y/current_cmd"))
    # Y (cross-feed) axis, the largest mean load in the slot, held: the Kalman estimate inverts
    # the identified paths and lands within 5 % (measured 4.3 %; the mean from the moving path,
    # decision 0129 — the at-rest path alone put it 37.9 % high). The raw C3 estimate is 5.7 %
    # off: the truth's Φ_d(0) ≈ 1 comes from the mechanics (on the printed model the raw
    # estimate kept Table 3.4's Φ_d(0) = 0.79 and was 16 % low, issue 12 item 1).
    assert abs(est_f.mean() / truth.mean() - 1) < 0.05
    # tooth frequency (100 Hz): feed amplitude error below raw's (measured 3 % vs 62 %)
    at = _tooth_amp(truth)
    ef, er = abs(_tooth_amp(est_f) / at - 1), abs(_tooth_amp(est_r) / at - 1)
    assert ef < er
    assert ef < 0.15  # ±3 dB design band, measured 3 %


def test_user_errors_exit_2(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    o = str(tmp_path / "e.h5")
    cases = [
        (["--machine", SIM_QUASER, "--method", "magic"], "unknown method 'magic'"),
        (["--machine", "no-such-machine"], "no machine preset 'no-such-machine'"),
        (["--machine", SIM_QUASER, "--method", "medob", "--axes", "x"], "axes.x.ball_screw"),
        (["--machine", SIM_QUASER, "--axes", "q"], "no axis 'q'"),
    ]
    for args, text in cases:
        code, _, err = run_cli(["estimate", str(run_h5), *args, "-o", o], capsys)
        assert code == 2 and text in err and len(err.strip().splitlines()) == 1, err


def test_spindle_mean_torque_within_10pct(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    est = tmp_path / "sp.h5"
    args = ["estimate", str(run_h5), "--machine", SIM_QUASER, "--method", "spindle"]
    code, _, err = run_cli([*args, "-o", str(est)], capsys)
    assert code == 0, err
    re_, rt = read_recording(est), read_recording(run_h5)
    i0, i1 = _steady(run_h5)
    truth = rt.channel("truth/spindle/torque")[i0:i1]
    tau = re_.channel("est/spindle/spindle/load")[i0:i1]
    np.testing.assert_array_equal(re_.channel("truth/spindle/torque")[i0:i1], truth)
    # Mismatch: the observer's G_dτ is rigid-body (the preset has no [spindle.residual_modes])
    # while the simulated spindle has Aslan's ten App. E residual modes, and the realism layer
    # loads the spindle; the DC gain of G_dτ is 1/K_tS in both (PI integral action), so the mean
    # of the steady cut (3000 rev/min, range 1) is the cutting torque once the configured
    # viscous friction B_eS·Ω is subtracted: within 10 % (measured 0.04 %)
    assert abs(tau.mean() / truth.mean() - 1) < 0.10


def test_spindle_missing_key_named(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    m = simulator_machine("quaser-ux600")
    assert m.spindle is not None
    bad = m.model_copy(update={"spindle": m.spindle.model_copy(update={"current_kp_v_a": None})})
    with pytest.raises(ConfigError, match=r"missing key 'spindle.current_kp_v_a'"):
        build_estimators(bad, ["spindle"], ["x"], 10_000.0)


def test_missing_channel_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from millsense.core.recording import Recording
    from millsense.io import write_recording

    rec = Recording(10_000.0)
    rec.add_channel("x/current_cmd", np.zeros(100), "A")
    p = tmp_path / "r.h5"
    write_recording(p, rec)
    args = ["estimate", str(p), "--machine", SIM_QUASER, "--method", "raw", "--axes", "x"]
    code, _, err = run_cli([*args, "-o", str(tmp_path / "e.h5")], capsys)
    assert code == 2 and "'x/motor_speed'" in err and len(err.strip().splitlines()) == 1


def test_from_config_r_is_lowpassed_current_noise_and_keys_override() -> None:
    cfg = simulator_machine("quaser-ux600").axes["x"]
    # the TOML key [axes.x.estimator] q_nm2_s, validated as a machine file would be
    tuned = FeedAxisConfig.model_validate(cfg.model_dump() | {"estimator": {"q_nm2_s": 500.0}})
    m = FeedAxisModel.from_config("x", tuned, sample_rate_hz=1e4)
    # independent check of R: white current noise σ_I = current_noise_a through the 600 Hz
    # 2nd-order Butterworth, variance by simulation (4·10⁵ samples: ±1 % sampling error)
    rng = np.random.default_rng(0)
    noise = cfg.torque_constant_nm_a * cfg.current_noise_a * rng.standard_normal(400_000)
    sos = signal.butter(2, 600.0, fs=1e4, output="sos")
    assert m.r == pytest.approx(np.var(signal.sosfilt(sos, noise)[1000:]), rel=0.03)
    assert m.q == 500.0 and m.lugre is not None
    # static gain of the config's Φ_d equals Table 3.4's printed modes (Σ α/ω², X: 0.56)
    dm = cfg.disturbance_modes
    assert dm is not None
    g0 = sum(
        a / (2 * math.pi * f) ** 2 for a, f in zip(dm.alpha, dm.natural_frequency_hz, strict=True)
    )
    assert abs(m.disturbance.continuous_frf([0.0])[0]) == pytest.approx(g0, rel=1e-9)


def test_from_config_missing_modes_names_key() -> None:
    cfg = simulator_machine("quaser-ux600").axes["x"]
    with pytest.raises(ConfigError, match=r"axes\.x\.disturbance_modes"):
        FeedAxisModel.from_config("x", cfg.model_copy(update={"disturbance_modes": None}))


def _estimate_x(
    run_h5: Path,
    out: Path,
    capsys: pytest.CaptureFixture[str],
    *extra: str,
    machine: str = SIM_QUASER,
) -> tuple[int, str]:
    args = ["estimate", str(run_h5), "--machine", machine, "--axes", "x"]
    code, _, err = run_cli([*args, *extra, "-o", str(out)], capsys)
    return code, err


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: on the truth with the commissioned file the uncompensated X bias is "
    "+10.0 % (not > 15 %): the amplification 1/0.56 of Table 3.4's Φ_d(0) is not physical",
)
def test_idle_auto_removes_the_x_friction_bias(
    run_h5: Path, commissioned: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    none, auto = tmp_path / "none.h5", tmp_path / "auto.h5"
    m = str(commissioned / "machine.toml")
    assert _estimate_x(run_h5, none, capsys, "--method", "feed", machine=m)[0] == 0
    code, err = _estimate_x(run_h5, auto, capsys, "--method", "feed", "--idle", "auto", machine=m)
    assert code == 0, err
    rt = read_recording(run_h5)
    i0, i1 = _steady(run_h5)
    lag = 60
    truth = rt.channel("truth/x/load")[i0:i1]
    e_none = read_recording(none).channel("est/feed/x/load")[i0 + lag : i1 + lag]
    e_auto = read_recording(auto).channel("est/feed/x/load")[i0 + lag : i1 + lag]
    # Issue 7 item C: with the realism layer the machine's X friction drifts away from the
    # preset's Table 3.2 values; the Kalman estimate inverts Φ_d(0) = 0.56 (Table 3.4), so the
    # friction mismatch reaches the estimate amplified 1/0.56 ≈ 1.8×: without compensation the
    # X mean is biased by more than 15 % (measured +25.5 %)
    bias_none = float(e_none.mean() / truth.mean() - 1)
    assert bias_none > 0.15, bias_none
    # the air phase at the cutting feed measures that bias (same feed, same direction, the
    # same estimator): with it removed the mean is within 6 % (measured −3.4 %; what is left
    # is the friction's position ripple and drift between the air phase and the cut, again
    # through 1/0.56)
    bias_auto = float(e_auto.mean() / truth.mean() - 1)
    assert abs(bias_auto) < 0.06, bias_auto
    # the compensation is a constant per direction: the tooth-frequency amplitude is unchanged
    # (R from the air phase rescales Q with it — tune_q keeps Q/R, hence the gain, the same)
    assert _tooth_amp(e_auto) == pytest.approx(_tooth_amp(e_none), rel=0.01)


def test_air_window_is_before_the_cut_at_cutting_feed(run_h5: Path) -> None:
    from millsense.estimation.feed.idle_compensation import (
        AIR_GUARD_M,
        AIR_SETTLE_S,
        find_air_window,
    )

    rec = read_recording(run_h5)
    w = find_air_window(rec, "run")
    fs = rec.sample_rate_hz
    # truth (which the search never reads): no engagement in the window, feed at 1200 mm/min
    assert np.all(rec.channel("truth/process/engagement")[w] < 0)
    np.testing.assert_allclose(rec.channel("cnc/feed")[w], 0.02, rtol=0.01)
    # 6 mm of air at 20 mm/s = 0.3 s, less the settling and the 0.5 mm guard (25 ms); the
    # 10 ms acceleration at 2 m/s² shortens it by ≤ 10 ms (measured 0.219 s)
    expect = 0.3 - AIR_SETTLE_S - AIR_GUARD_M / 0.02
    assert (w.stop - w.start) / fs == pytest.approx(expect, abs=0.01)
    # the metadata's path length to the stock is where truth engages: ∫cnc/feed dt there
    # equals it within one sample of travel (2 µm) plus the interpolator's rounding (0.1 mm)
    s = np.cumsum(rec.channel("cnc/feed")) / fs
    i_cut = int(np.flatnonzero(rec.channel("truth/process/engagement") >= 0)[0])
    assert s[i_cut] == pytest.approx(float(rec.metadata["first_engagement_path_m"]), abs=1e-4)


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: on the truth the hand window's raw X idle mean is 43.0 N against 41.6 N "
    "auto (1.4 N > 1 N): the truth's friction (Stribeck, ripple of the motor angle) varies more "
    "over the 0.6 mm the windows differ by than the printed model's",
)
def test_idle_file_and_window_agree_with_auto(
    run_h5: Path, commissioned: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    outs = {}
    for name, extra in (
        ("auto", ["--idle", "auto"]),
        ("file", ["--idle", str(run_h5)]),
        ("window", ["--idle", "auto", "--air-s", "0.43:0.64"]),
    ):
        p = tmp_path / f"{name}.h5"
        code, err = _estimate_x(
            run_h5, p, capsys, "--method", "raw", *extra, machine=str(commissioned / "machine.toml")
        )
        assert code == 0, err
        outs[name] = json.loads(str(read_recording(p).metadata["idle_tables"]))["raw/x"]
    # the same recording as FILE: the same air phase, bit for bit
    assert outs["file"] == outs["auto"]
    # a hand window inside the found one (0.428–0.647 s): the same mean within 1 N (the raw
    # estimate's air fluctuation is ≈ 2 N RMS at 300 Hz: ±0.1 N over 0.2 s, plus the friction
    # ripple over the 0.6 mm the windows differ by)
    assert outs["window"]["positive"] == pytest.approx(outs["auto"]["positive"], abs=1.0)
    assert outs["auto"]["negative"] is None and outs["auto"]["rest"] is None


def test_idle_user_errors_exit_2(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.core.recording import Recording
    from millsense.io import write_recording

    bare = tmp_path / "bare.h5"
    rec = Recording(10_000.0)
    rec.add_channel("x/current_cmd", np.zeros(100), "A")
    write_recording(bare, rec)
    o = tmp_path / "e.h5"
    cases = [
        (run_h5, ["--idle", "auto", "--air-s", "0.5:0.2"], "--air-s '0.5:0.2': needs 0 ≤ START"),
        (run_h5, ["--idle", "auto", "--air-s", "soon"], "expected START:END in s"),
        (run_h5, ["--idle", "auto", "--air-s", "0.1:0.12"], "must last ≥ 0.05 s"),
        (run_h5, ["--air-s", "0.1:0.3"], "--air-s: needs --idle auto or --idle FILE.h5"),
        (run_h5, ["--idle", str(tmp_path / "missing.h5")], "--idle: no file"),
        (run_h5, ["--idle", "table.csv"], "none, auto or an air-run recording (.h5)"),
        (bare, ["--idle", "auto"], "metadata 'first_engagement_path_m'"),
    ]
    for path, extra, text in cases:
        args = ["estimate", str(path), "--machine", SIM_QUASER, "--axes", "x"]
        code, _, err = run_cli([*args, "--method", "raw", *extra, "-o", str(o)], capsys)
        assert code == 2 and text in err and len(err.strip().splitlines()) == 1, err


def test_simulate_air_mm_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT)
    base = ["simulate", "--machine", SIM_QUASER, "--program", str(prog), "-o"]
    # the feed move is 75 mm long (X−15 → X60)
    for air, text in (("80", "not shorter than the first run of feed moves (75 mm)"),
                      ("-1", "--air-mm: must be ≥ 0")):  # fmt: skip
        code, _, err = run_cli([*base, str(tmp_path / "s.h5"), "--air-mm", air], capsys)
        assert code == 2 and text in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: on the truth R from the air phase is 14.9x the noise-only R (0.152 vs "
    "0.0102 N²m², bound 10x): the truth's torque ripple (1, 24, 36, 48 per rev), 1.1x current "
    "noise and current-loop dynamics are not in the commissioned file's noise figure",
)
def test_r_from_the_air_phase(run_h5: Path, commissioned: Path) -> None:
    from millsense.core.config import FeedEstimatorConfig
    from millsense.estimation.feed.idle_compensation import find_air_window, with_air_r

    rec = read_recording(run_h5)
    w = find_air_window(rec, "run")
    m = load_preset(MachineConfig, str(commissioned / "machine.toml"))
    m2, r = with_air_r(m, ["x"], rec, w, "run")
    # the default R in closed form: (K_t·σ_I)² through the 600 Hz 2nd-order Butterworth
    ax = m.axis("x")
    sos = signal.butter(2, 600.0, fs=1e4, output="sos")
    h = signal.sosfilt(sos, np.r_[1.0, np.zeros(9999)])
    r_noise = float((ax.torque_constant_nm_a * ax.current_noise_a) ** 2 * np.sum(h**2))
    # Aslan Eq. 3.30: R is the torque fluctuation in air. It holds the current noise the
    # default R is made of (current_noise_a through the 600 Hz low-pass) plus what the model
    # lacks: the realism layer's friction position ripple and the encoder noise through
    # J·dω/dt — so above the noise-only R, by less than 10× (measured 4.2×)
    assert r_noise < r["x"] < 10 * r_noise, (r, r_noise)
    est = m2.axis("x").estimator
    assert est is not None and est.r_nm2 == r["x"]
    # a configured R is the user's and is kept
    fixed = m.axis("x").model_copy(update={"estimator": FeedEstimatorConfig(r_nm2=0.5)})
    m3 = m.model_copy(update={"axes": {**m.axes, "x": fixed}})
    assert with_air_r(m3, ["x"], rec, w, "run")[1] == {}


def test_band_hz_quieter_estimate_and_unreachable_band_exit_2(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wide, banded = tmp_path / "wide.h5", tmp_path / "banded.h5"
    base = ["estimate", str(run_h5), "--machine", SIM_QUASER, "--axes", "x", "--method"]
    code, _, err = run_cli([*base, "feed", "-o", str(wide)], capsys)
    assert code == 0, err
    code, _, err = run_cli([*base, "feed", "--band-hz", "200", "-o", str(banded)], capsys)
    assert code == 0, err
    rw, rb = read_recording(wide), read_recording(banded)
    # the air phase before the cut (6 mm at 1200 mm/min = 0.3 s, after the 60-sample lag and a
    # 0.1 s settling): the estimate there is noise; the 200 Hz rule's white-noise gain on the
    # X Table 3.4 model is < 0.6 of the widest band's (test_tuning_least_noise), so its RMS is
    # clearly lower
    air = slice(1000 + 60, 3000)
    nw = float(np.std(np.diff(rw.channel("est/feed/x/load")[air])))
    nb = float(np.std(np.diff(rb.channel("est/feed/x/load")[air])))
    assert nb < 0.6 * nw, (nb, nw)
    code, _, err = run_cli([*base, "feed", "--band-hz", "900", "-o", str(banded)], capsys)
    assert code == 2 and "axes.x.estimator.band_hz" in err and len(err.strip().splitlines()) == 1


def test_forces_at_the_tool_from_the_five_feed_estimates(
    run_h5: Path,
    slot_xy_feed: XyFeed,
    commissioned: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "all.h5"
    machine = str(commissioned / "machine.toml")
    code, stdout, err = run_cli(
        ["estimate", str(run_h5), "--machine", machine, "--method", "feed", "-o", str(out)],
        capsys,
    )
    assert code == 0, err
    assert "tool_y" in stdout
    rf, rt = read_recording(out), read_recording(run_h5)
    i0, i1 = _steady(run_h5)
    lag = 60
    truth = rt.channel("truth/tool/force_y")[i0:i1]
    est = rf.channel("est/feed/tool/force_y")[i0 + lag : i1 + lag]
    # at A = C = 0 Eq. 3.51 turns the Y load into the tool's Y force with the sign of the
    # reaction (τ = −JᵀT·F): the mean lands within 5 % like the Y load itself (measured ≈ 2 %),
    # and the independent truth/tool/force_y of the simulator has the opposite sign of the load
    assert abs(est.mean() / truth.mean() - 1) < 0.05
    assert np.sign(truth.mean()) == -np.sign(rt.channel("truth/y/load")[i0:i1].mean())
    # fewer than five axes: no forces at the tool, no error (the session's x,y feed estimate,
    # exit 0 asserted there: the same command, feed being the default method, with a plot)
    assert "est/feed/tool/force_y" not in read_recording(slot_xy_feed.estimates).channel_names


@pytest.mark.xfail(
    strict=True,
    reason="issue 12: on the truth with the commissioned file at A 30°, C 45° the tool's X force "
    "mean is within 5 % but Y is +22.1 % (136 N vs 112 N; 2026-11-28): the A/C axes' "
    "identified paths (C at rest fits to 16 % RMS) and friction carry a bias that Eq. 3.51 "
    "spreads onto Y",
)
def test_forces_at_the_tool_on_a_tilted_table(
    commissioned: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the same slot with the table at A 30°, C 45° (the drives share the feed and the load):
    # Eq. 3.51 at a general pose brings the five drive loads back to the tool's force, the
    # means within 5 % of the simulator's truth/tool/force (measured 0.3 % and 1.3 %)
    prog = tmp_path / "tilt.nc"
    prog.write_text(SLOT.replace("G0 X-15 Y0 Z0", "G0 A30 C45\nG0 X-15 Y0 Z0"))
    run, est = tmp_path / "tilt.h5", tmp_path / "est.h5"
    code, _, err = run_cli(["simulate", "--machine", SIM_QUASER, "--program", str(prog),
                            "--depth-mm", "4", "--air-mm", "6", "--duration-s", "3.6", "-o",
                            str(run)], capsys)  # fmt: skip
    assert code == 0, err
    machine = str(commissioned / "machine.toml")
    code, _, err = run_cli(
        ["estimate", str(run), "--machine", machine, "--method", "feed", "-o", str(est)],
        capsys,
    )
    assert code == 0, err
    rt, re_ = read_recording(run), read_recording(est)
    i0, i1 = _steady(run)
    for c in "xy":
        truth = rt.channel(f"truth/tool/force_{c}")[i0:i1]
        got = re_.channel(f"est/feed/tool/force_{c}")[i0 + 60 : i1 + 60]
        assert abs(truth.mean()) > 50.0
        assert abs(got.mean() / truth.mean() - 1) < 0.05, c


def test_json_summary_is_the_table_in_numbers(
    run_h5: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    out = tmp_path / "j.h5"
    base = ["estimate", str(run_h5), "--machine", SIM_QUASER, "--axes", "y", "-o", str(out)]
    code, stdout, err = run_cli([*base, "--json", "-"], capsys)
    assert code == 0, err
    doc = json.loads(stdout)  # stdout is the JSON alone
    (row,) = doc["comparisons"]
    # tooth frequency from the measured spindle speed: 3000 rev/min × 2 teeth within 0.01 %
    assert row["axis"] == "y" and row["unit"] == "N"
    assert row["tooth_hz"] == pytest.approx(100.0, rel=1e-4)
    # the relative errors are the amplitudes' (independently recomputed from the two lists)
    est, tru = np.array(row["amplitude_est"]), np.array(row["amplitude_truth"])
    np.testing.assert_allclose(row["error"], np.abs(est / tru - 1), rtol=1e-9)
    assert doc["estimates"] == [
        {"method": "feed", "axis": "y", "channel": "est/feed/y/load", "delay_samples": 60}
    ]
    # a folder is not a JSON file: refused before anything runs
    code, _, err = run_cli([*base, "--json", str(tmp_path)], capsys)
    assert code == 2 and "not a file in an existing folder" in err
    js = tmp_path / "s.json"
    code, stdout, err = run_cli([*base, "--json", str(js)], capsys)
    assert code == 0 and "tooth" in stdout and json.loads(js.read_text())["samples"] > 0
