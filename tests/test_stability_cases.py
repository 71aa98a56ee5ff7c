"""Case files, one-line configuration errors and the ``millsense lobes`` command."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from millsense.cli.main import main
from millsense.core.errors import ConfigError
from millsense.stability.cases import load_case

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "stability"

GOOD = """
[tool]
diameter_mm = 10.0
flutes = 2
[cutting]
kt_n_mm2 = 600.0
kr_n_mm2 = 200.0
[operation]
mode = "down"
radial_immersion_mm = 5.0
[[structure.x]]
natural_frequency_hz = 922.0
damping_ratio = 0.011
stiffness_n_m = 1340049.648
[lobes]
rpm_min = 21600
rpm_max = 21800
rpm_step = 100
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "case.toml"
    p.write_text(text)
    return p


def test_examples_load_in_si() -> None:
    # every shipped example parses; units converted once (600 N/mm² -> 6e8 N/m²)
    for f in sorted(EXAMPLES.glob("*.toml")):
        load_case(f)
    c = load_case(EXAMPLES / "insperger_1dof_slot.toml")
    assert c.kt == pytest.approx(6e8) and c.kr == pytest.approx(2e8)
    assert c.structure.x[0].stiffness == pytest.approx(1340049.648, rel=1e-12)
    assert len(c.rpm) == 201
    v = load_case(EXAMPLES / "variable_pitch_4flute.toml")
    assert v.pitch is not None and sum(v.pitch) == pytest.approx(2 * 3.141592653589793)


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (
            ('mode = "down"\n', ""),
            "missing required key 'operation.mode' (allowed: one of 'down', 'up')",
        ),
        (("damping_ratio = 0.011", "damping_ratio = -0.01"), "damping_ratio' = -0.01"),
        (
            ("radial_immersion_mm = 5.0", "radial_immersion_mm = 12.0"),
            "0 < value <= tool.diameter_mm = 10",
        ),
        (("flutes = 2", "flutes = 2\ncolour = 3"), "unknown key 'tool.colour'"),
        (("rpm_min = 21600", "rpm_min = 30000"), "lobes.rpm_min"),
    ],
)
def test_bad_case_files_one_line(tmp_path: Path, edit: tuple[str, str], needle: str) -> None:
    p = _write(tmp_path, GOOD.replace(*edit))
    with pytest.raises(ConfigError) as info:
        load_case(p)
    msg = str(info.value)
    assert "\n" not in msg and str(p) in msg and needle in msg


def test_cli_exit_status_2_on_bad_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = _write(tmp_path, GOOD.replace("damping_ratio = 0.011", "damping_ratio = 1.5"))
    with pytest.raises(SystemExit) as info:
        main(["lobes", str(p)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "damping_ratio" in err and "must be >= 0.0001 and < 1" in err


def test_cli_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # benchmarks.md §1 half immersion: 0.5995 mm near 21727 rev/min (grid of 100 rev/min)
    p = _write(tmp_path, GOOD)
    out = tmp_path / "lobes.json"
    png = tmp_path / "lobes.png"
    main(["lobes", str(p), "--json", str(out), "--plot", str(png)])
    d = json.loads(out.read_text())
    assert set(d) >= {
        "rpm",
        "critical_depth_mm",
        "chatter_hz",
        "bifurcation",
        "min_depth_mm",
        "min_depth_rpm",
    }
    assert d["rpm"] == [21600.0, 21700.0, 21800.0]
    assert d["min_depth_mm"] == pytest.approx(0.5995, rel=5e-3)
    # the grid minimum (21 700) is refined to 1 rev/min: benchmarks.md §1 gives 21 727
    assert d["min_depth_rpm"] == pytest.approx(21727.0, abs=3.0)
    assert d["status"] == ["limit"] * 3 and all(t <= 0.01 for t in d["tolerance"])
    assert png.stat().st_size > 1000
    main(["lobes", str(p), "--method", "zoa", "--rpm", "21000:22000:500", "--json", "-"])
    z = json.loads(capsys.readouterr().out)
    assert z["rpm"] == [21000.0, 21500.0, 22000.0]
    # half immersion down milling: ZOA is about 7 % above SDM here (mean directional factor)
    assert min(x for x in z["critical_depth_mm"] if x) > d["min_depth_mm"]


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_single_speed_lists_bands_and_island(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 14: a/D 0.5 up milling at 20 100 rev/min has an unstable band near 0.90-0.99 mm
    # below a stable island (test_stability_robust checks the band by brute force)
    p = _write(tmp_path, GOOD.replace('mode = "down"', 'mode = "up"'))
    code, out, err = _run(["lobes", str(p), "--rpm", "20100", "--json", "-"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["rpm"] == [20100.0]
    assert d["critical_depth_mm"][0] == pytest.approx(0.90, rel=0.03)
    assert len(d["unstable_bands_mm"][0]) >= 2
    island = d["stable_bands_mm"][0][0]
    assert island[0] == pytest.approx(d["unstable_bands_mm"][0][0][1], rel=1e-9)
    assert island[0] < island[1] <= 20.0
    assert d["bands_searched_to_mm"] == [20.0]
    assert "stable island" in err and "unstable" in err


def test_cli_no_limit_below_ceiling_is_explicit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # half immersion limit is 0.5995 mm near 21 727 rev/min: nothing below a 0.3 mm ceiling
    p = _write(tmp_path, GOOD.replace("rpm_step = 100", "rpm_step = 100\ndepth_max_mm = 0.3"))
    code, out, err = _run(["lobes", str(p), "--json", "-"], capsys)
    assert code == 0
    d = json.loads(out)
    assert d["status"] == ["no limit below 0.3 mm"] * 3
    assert d["min_depth_mm"] is None and d["no_limit_below_mm"] == 0.3
    assert "no limit below 0.3 mm" in err


def test_cli_zoa_warns_at_low_immersion(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a/D = 0.1: each tooth cuts 20.5 % of its period, flip lobes expected (decision 0909)
    p = _write(tmp_path, GOOD.replace("radial_immersion_mm = 5.0", "radial_immersion_mm = 1.0"))
    code, out, err = _run(["lobes", str(p), "--method", "zoa", "--json", "-"], capsys)
    assert code == 0
    d = json.loads(out)
    assert len(d["warnings"]) == 1 and "flip" in d["warnings"][0]
    assert "warning:" in err and "ZOA cannot show them" in err
    p2 = _write(tmp_path, GOOD.replace("radial_immersion_mm = 5.0", "radial_immersion_mm = 10.0"))
    code, out, _ = _run(["lobes", str(p2), "--method", "zoa", "--json", "-"], capsys)
    assert code == 0 and json.loads(out)["warnings"] == []


@pytest.mark.parametrize(
    ("edit", "args", "needle"),
    [
        (("stiffness_n_m = 1340049.648", "stiffness_n_m = 1e-9"), [], "stiffness_n_m"),
        (("damping_ratio = 0.011", "damping_ratio = 0.0"), [], "damping_ratio"),
        (("rpm_step = 100", "rpm_step = 0.001"), [], "lobes.rpm_step"),
        ((), ["--rpm", "5000:25000:0.001"], "--rpm"),
        (
            ("stiffness_n_m = 1340049.648", "modal_mass_kg = 1e-9"),
            [],
            "modal_mass_kg",
        ),
        ((), ["--rpm", "0"], "--rpm"),
        # an infinite maximum was "lobes: numerical failure (OverflowError ...)", no option
        ((), ["--rpm", "5000:inf:100"], "--rpm '5000:inf:100'"),
        ((), ["--rpm", "5000:6000:inf"], "--rpm '5000:6000:inf'"),
    ],
)
def test_cli_bad_numbers_one_line_exit_2(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    edit: tuple[str, str],
    args: list[str],
    needle: str,
) -> None:
    # the inputs of issue 14's review: tiny stiffness (was LinAlgError), a 0.001 rev/min step
    # (hung), zero damping (nan lobes): one line naming the parameter, exit status 2
    p = _write(tmp_path, GOOD.replace(*edit) if edit else GOOD)
    code, _, err = _run(["lobes", str(p), *args], capsys)
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in err


def test_modal_mass_key_equals_stiffness(tmp_path: Path) -> None:
    # k = m (2π f_n)² : 0.03993 kg at 922 Hz is the Insperger 1.34005e6 N/m
    p = _write(tmp_path, GOOD.replace("stiffness_n_m = 1340049.648", "modal_mass_kg = 0.03993"))
    c = load_case(p)
    k = 0.03993 * (2 * 3.141592653589793 * 922.0) ** 2
    assert c.structure.x[0].stiffness == pytest.approx(k, rel=1e-12)
    assert c.structure.x[0].stiffness == pytest.approx(1340049.648, rel=1e-5)
    bad = _write(
        tmp_path,
        GOOD.replace("stiffness_n_m = 1340049.648", "stiffness_n_m = 1e6\nmodal_mass_kg = 0.04"),
    )
    with pytest.raises(ConfigError, match="exactly one of"):
        load_case(bad)


def test_cli_blas_threads_set_to_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # decision 0907: the command runs the loaded OpenBLAS on one thread (2 before, here)
    import numpy as np

    from millsense.core.blas import limit_blas_threads

    np.linalg.eigvals(np.eye(3))  # OpenBLAS loaded
    before = limit_blas_threads(2)
    if before is None:
        pytest.skip("no OpenBLAS in this numpy")
    p = _write(tmp_path, GOOD)
    code, _, _ = _run(["lobes", str(p), "--rpm", "21700"], capsys)
    assert code == 0
    assert limit_blas_threads(None) == 1
