"""``millsense commission``: commissioning recordings and the identify commands that read them."""

from __future__ import annotations

import shlex
import tomllib
from pathlib import Path

import pytest

from cli_run import run_cli
from millsense.core.config import DisturbancePathConfig, FrictionConfig, MachineConfig
from millsense.core.presets import load_preset
from millsense.io import read_recording
from millsense.simulator.truth_machine import load_truth


def test_commission_writes_the_tests_and_its_identify_commands_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(
        ["commission", "--machine", "quaser-ux600", "--axis", "y", "-o", "c", "--no-spindle"],
        capsys,
    )
    assert code == 0, err
    names = sorted(p.name for p in Path("c").iterdir())
    assert names == [
        f"quaser-ux600-y-{t}.h5"
        for t in (
            "acceleration",
            "air_cut",
            "friction",
            "presliding",
            "table_load_sweep",
            "table_load_sweep_at_rest",
        )
    ]
    sweep = read_recording(Path("c") / "quaser-ux600-y-table_load_sweep.h5")
    assert sweep.metadata["period_samples"] == 10_000 and "y/load" in sweep.channel_names
    lines = out.split("identify with:")[1].split("then merge")[0].splitlines()
    commands = [ln.strip() for ln in lines if ln.strip().startswith("millsense ")]
    # from the nameplate: friction, drive; their merge (the C3 stage) feeds the noise R (air
    # cut) and the path fits
    assert [shlex.split(c)[1:3] for c in commands] == [
        ["identify", "friction"],
        ["identify", "drive"],
        ["merge", "quaser-ux600"],
        ["identify", "noise"],
        ["identify", "path"],
        ["identify", "path"],
    ]
    for c in commands:
        code, _, err = run_cli(shlex.split(c)[1:], capsys)
        assert code == 0, (c, err)
    merge = next(
        ln.strip()
        for ln in out.split("then merge")[1].splitlines()
        if ln.strip().startswith("millsense merge")
    )
    code, _, err = run_cli(shlex.split(merge)[1:], capsys)
    assert code == 0, err
    assert Path("machine.toml").exists()  # the file the printed merge command writes
    frag = tomllib.loads(Path("y_friction.toml").read_text())
    fr = FrictionConfig(**frag["axes"]["y"]["friction"])
    # commission runs the simulator's truth (decision 1041): its Y Coulomb friction (1.85/1.81
    # N·m, not Table 3.2's 1.78/1.86) back within 2 % (issue 6 figure; measured +0.9/−0.1 %),
    # seen through the nameplate's K_t (2.023, decision 0991) while the truth's is 1.93: the
    # identification reads currents, so torques carry the ratio of the two
    truth = load_truth("quaser-ux600")["y"]
    scale = load_preset(MachineConfig, "quaser-ux600").axis("y").torque_constant_nm_a
    scale /= truth.torque_constant
    want = tuple(c * scale for c in truth.friction.coulomb)
    assert fr.coulomb_nm == pytest.approx(want, rel=0.02)
    assert abs(fr.coulomb_nm[0] / 1.78 - 1) > 0.04  # and it is not Table 3.2 (Y+: +6.7 %)
    path = tomllib.loads(Path("y_path.toml").read_text())["axes"]["y"]["estimator"]
    assert DisturbancePathConfig(**path["disturbance_path"]).rms_error < 0.05
    # the sweep at rest is recognised by its command and fills the at-rest key
    rest = tomllib.loads(Path("y_path_at_rest.toml").read_text())["axes"]["y"]["estimator"]
    assert list(rest) == ["disturbance_path_at_rest"]


def test_commission_user_errors_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "c"
    code, _, err = run_cli(["commission", "--machine", "quaser-ux600", "--axis", "q", "-o",
                            str(out)], capsys)  # fmt: skip
    assert code == 2 and "no axis 'q'" in err and not out.exists()
    f = tmp_path / "file"
    f.write_text("keep")
    code, _, err = run_cli(["commission", "--machine", "quaser-ux600", "-o", str(f)], capsys)
    assert code == 2 and "not a directory" in err and f.read_text() == "keep"


def test_commission_refuses_an_axis_named_twice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--axis x,x`` ran every X test twice (the second set over the first) and printed
    every identify command twice, the merge listing each fragment twice: one line naming the
    axis, exit 2, nothing written."""
    out = tmp_path / "c"
    code, _, err = run_cli(["commission", "--machine", "quaser-ux600", "--axis", "x,y,x", "-o",
                            str(out)], capsys)  # fmt: skip
    assert code == 2 and "--axis 'x,y,x': axis 'x' named twice" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_commission_identify_writes_the_shipped_spindle_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # decision 1708: `commission --identify` on the virtual quaser-ux600 reproduces the shipped
    # commissioned file's [spindle] key for key: the inertia from the sweep's rigid body, the
    # range-1 motor admittance from its current loop, the friction from the constant-speed
    # runs and the nameplate's keys (speed_from_encoder_difference among them) as merged
    from importlib import resources

    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(
        ["commission", "--machine", "quaser-ux600", "--axis", "x", "-o", "c", "--identify"],
        capsys,
    )
    assert code == 0, err
    got = tomllib.loads((Path("c") / "machine.toml").read_text())["spindle"]
    entry = resources.files("millsense.data").joinpath("commissioned", "quaser-ux600.toml")
    shipped = tomllib.loads(entry.read_text(encoding="utf-8"))["spindle"]
    assert got.keys() == shipped.keys()
    for key, value in shipped.items():
        if isinstance(value, float):
            # written to 6 significant digits, whose last one differs between processors (an
            # Intel host gave 0.032251 for the AMD host's 0.0322509 kg·m²): one unit of it, at
            # most 1e-5 of the value
            assert got[key] == pytest.approx(value, rel=1e-5), key
        else:
            assert got[key] == value, key
