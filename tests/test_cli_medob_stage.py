"""``millsense simulate`` on the ``yamada-b`` ball-screw stage and ``estimate --method medob``.

Scenario (Yamada 2017 Table 4-7 condition <5>, decision "Table 4-7 scenario"): A5052 with the
coefficients of Yamada Table 4-2 (K_tc, K_rc, K_ac = 1800, 820, 170 N/mm², no edge terms),
Ø6 mm 2-flute zero-helix end mill, down milling a_e = 1.5 mm, a_p = 2 mm, 10 000 rev/min,
600 mm/min (0.03 mm/tooth, tooth frequency 333.3 Hz), 0.6 s simulated; only the force along
the feed loads the stage (decision "Simulator on a 1-axis stage").

The simulation runs ``--ideal`` (the simulator file's dual-inertia model, not the yamada-b truth
of decision 1705): these tests exercise the CLI's plumbing with an estimator given the same
file, a debugging configuration; the MEDOB's acceptance on the truth is
``estimation.dob.table47_*`` (:mod:`millsense.validation.cases.estimation_dob`).

Mismatch between the estimators and the simulated machine: the MEDOB is built from the preset's
nominal parameters (``axes.x.ball_screw``, dead times, current bandwidth) while the simulator
adds what the observer does not model: the preset's position-periodic disturbances (screw lead
error, ball circulation and torque-ripple thrusts, scale and encoder interpolation errors),
encoder and scale quantisation and current noise.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from millsense.cli.main import main
from millsense.io import read_recording
from millsense.simulator.machine_file import simulator_machine, simulator_machine_path

#: The simulator's own yamada-b file: these tests exercise the CLI on a fully specified machine
#: (the nameplate preset has no identified values; decision 0991).
SIM_YAMADA_B = str(simulator_machine_path("yamada-b"))

PROGRAM = """G21 G90 G94
G0 X-4 Y0 Z0
S10000 M3
G1 X6 F600
M5
M30
"""
A5052 = """name = "A5052 (Yamada Table 4-2)"
ktc_n_mm2 = 1800.0
krc_n_mm2 = 820.0
kac_n_mm2 = 170.0
kte_n_mm = 0.0
kre_n_mm = 0.0
kae_n_mm = 0.0
source = "Yamada Table 4-2"
"""
D6 = """name = "D6 2-flute zero helix (Yamada)"
shape = "flat"
diameter_mm = 6.0
flutes = 2
helix_deg = 0.0
"""
FS = 10000.0
F_TOOTH = 10000.0 / 60.0 * 2  # 333.3 Hz
TOOTH_SAMPLES = 30  # FS / F_TOOTH


def _cli(args: list[str]) -> None:
    try:
        main(args)
    except SystemExit as exc:
        assert not exc.code, args


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("medob")
    (d / "cut.nc").write_text(PROGRAM)
    (d / "a5052.toml").write_text(A5052)
    (d / "d6.toml").write_text(D6)
    run = d / "run.h5"
    # 3 mm of air at the cutting feed (0.3 s) before the stock, then 0.5 s of cut
    _cli(
        [
            "simulate", "--machine", SIM_YAMADA_B, "--program", str(d / "cut.nc"),
            "--tool", str(d / "d6.toml"), "--material", str(d / "a5052.toml"),
            "--engagement", "ae_mm=1.5", "--depth-mm", "2", "--air-mm", "3",
            "--duration-s", "0.9", "--ideal", "-o", str(run),
        ]
    )  # fmt: skip
    out = {"run": run}
    # both with `--idle auto`, as a user must: the realism layer (on by default, decision 0976)
    # scales the stage's friction by a 1-3 % position ripple (decision "realism layer"), which
    # only the air phase at the cutting feed measures
    for method, idle in (("medob", "auto"), ("raw", "auto")):
        est = d / f"{method}.h5"
        _cli(
            [
                "estimate", str(run), "--machine", SIM_YAMADA_B, "--method", method,
                "--idle", idle, "-o", str(est),
            ]
        )  # fmt: skip
        out[method] = est
    return out


def _window(run: Path) -> slice:
    """Steady cut: 0.1 s after the engagement starts to the end, whole tooth periods."""
    rec = read_recording(run)
    cut = np.flatnonzero(rec.channel("truth/process/engagement") >= 0)
    i0 = int(cut[0]) + round(0.1 * FS)
    n = (int(cut[-1]) + 1 - i0) // TOOTH_SAMPLES * TOOTH_SAMPLES
    assert n >= 10 * TOOTH_SAMPLES
    return slice(i0, i0 + n)


def _tooth_amplitude(x: np.ndarray) -> float:
    """Amplitude at the tooth frequency (one DFT bin over whole tooth periods), N."""
    k = np.arange(len(x))
    return float(2.0 * abs(np.mean(x * np.exp(-2j * math.pi * F_TOOTH / FS * k))))


def test_stage_recording_has_the_medob_channels(runs: dict[str, Path]) -> None:
    rec = read_recording(runs["run"])
    names = set(rec.channel_names)
    assert {"x/current_cmd", "x/motor_angle", "x/scale", "truth/x/load"} <= names
    assert not any(n.startswith(("y/", "z/", "spindle/current")) for n in names)
    # constant spindle reference: 10 000 rev/min exactly (ideal spindle, no drive)
    spd = rec.channel("spindle/speed")
    assert np.allclose(spd, 10000.0 * 2 * math.pi / 60, rtol=1e-12)
    # the stage load is the feed-direction force on the tool, resisting +x: −F_x
    sl = _window(runs["run"])
    fx = rec.channel("truth/tool/force_x")[sl]
    assert np.allclose(rec.channel("truth/x/load")[sl], -fx, atol=1e-9)


def test_medob_mean_and_tooth_frequency(runs: dict[str, Path]) -> None:
    sl = _window(runs["run"])
    truth = read_recording(runs["run"]).channel("truth/x/load")[sl]
    est = read_recording(runs["medob"])
    medob = est.channel("est/medob/x/load")[sl]
    raw = read_recording(runs["raw"]).channel("est/raw/x/load")[sl]
    # The MEDOB estimates every disturbance on the table, Coulomb friction included (Yamada
    # §2.9 removes it with idling tests): `--idle auto` measured it in the 0.3 s air phase at
    # the cutting feed before the stock. Independent check of what was removed: the machine
    # file's friction F_c = T_c/R along +x (130 N, Yamada §3.6) within 2 % — the rest of the
    # idle mean is the periodic thrusts (≤ 1.5 N amplitudes) averaged over 0.2 s
    idle = json.loads(str(est.metadata["idle_tables"]))["medob/x"]
    ax = simulator_machine("yamada-b").axis("x")
    assert ax.friction is not None and ax.lead_mm_rev is not None
    f_c = ax.friction.coulomb_nm[0] / (ax.lead_mm_rev * 1e-3 / (2 * math.pi))
    assert idle["positive"] == pytest.approx(f_c, rel=0.02), idle
    mean_truth, mean_medob = float(np.mean(truth)), float(np.mean(medob))
    # brief: mean within 10 % of the truth axis load in the steady cut (measured 0.2 %);
    # uncompensated it would be off by the 130 N friction (16× the −7.9 N load)
    assert abs(mean_medob - mean_truth) <= 0.10 * abs(mean_truth), (mean_medob, mean_truth)
    # tooth frequency (333 Hz): the MEDOB (500 Hz Butterworth output filter, Yamada Table 4-3)
    # keeps the tooth-passing component, the raw rigid-body estimate (300 Hz low-pass, no ball
    # screw) does not: its amplitude error must be larger than the MEDOB's. The idle
    # compensation is a constant per direction here and leaves the harmonics as they were
    a_t = _tooth_amplitude(truth)
    err_medob = abs(_tooth_amplitude(medob) - a_t) / a_t
    err_raw = abs(_tooth_amplitude(raw) - a_t) / a_t
    assert err_medob < err_raw, (err_medob, err_raw)
    # and the MEDOB's is within 35 % (measured 23 %, raw 110 %; the 500 Hz filter's
    # gain and the unmodelled periodic disturbances at 333 Hz)
    assert err_medob < 0.35, err_medob


def test_raw_mean_matches_truth_on_the_ball_screw_stage(runs: dict[str, Path]) -> None:
    sl = _window(runs["run"])
    truth = read_recording(runs["run"]).channel("truth/x/load")[sl]
    raw = read_recording(runs["raw"]).channel("est/raw/x/load")[sl]
    # Issue 7 bug: the raw C3 estimate built from inertia_kg_m2 (J_r alone) and the friction
    # table missed the ball screw's damping thrust D_r·ω/R + C_t·v = 102.6 + 8.2 N at 10 mm/s
    # (mean +103 N against −7.9 N). With the rigid-body limit of the plant the remaining error
    # is what the model does not hold: the position-periodic thrusts (≤ 1.5 N amplitudes,
    # averaged over 30+ periods) and current noise: within 1 N (measured 0.08 N without the
    # realism layer). With realism on (decision 0976) the friction and damping thrust
    # (≈ 240 N at 10 mm/s) carry the layer's 1-3 % position ripple of 10 screw revolutions
    # (the thermal drift is < 0.01 K in 0.9 s): uncompensated −2.8 N; `--idle auto` measures
    # it in the air phase 3 mm before the cut (−2.3 N) and leaves −0.5 N (measured)
    assert abs(float(np.mean(raw)) - float(np.mean(truth))) < 1.0, (raw.mean(), truth.mean())


def test_rigid_limit_equals_the_plant_at_low_frequency() -> None:
    from millsense.estimation.feed.rigid_body import rigid_limit
    from millsense.models.ball_screw import plant_from_config

    ax = simulator_machine("yamada-b").axis("x")
    inertia, damping = rigid_limit(ax)
    plant = plant_from_config(ax)
    # independent: the plant's own reflected inertia, and its motor-speed/torque FRF at
    # 1 mHz (far below the 408 Hz resonance and the D/J corner at ≈ 27 Hz): ω/τ → 1/D_e
    assert inertia == pytest.approx(plant.inertia, rel=1e-12)
    h = plant.frf(np.array([1e-3]), 0, 1)[0]
    assert 1.0 / h.real == pytest.approx(damping, rel=1e-3)
