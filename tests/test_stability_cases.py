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
    assert "damping_ratio" in err and "must be >= 0 and < 1" in err


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
    assert d["min_depth_rpm"] == 21700.0
    assert png.stat().st_size > 1000
    main(["lobes", str(p), "--method", "zoa", "--rpm", "21000:22000:500", "--json", "-"])
    z = json.loads(capsys.readouterr().out)
    assert z["rpm"] == [21000.0, 21500.0, 22000.0]
    # half immersion down milling: ZOA is about 7 % above SDM here (mean directional factor)
    assert min(x for x in z["critical_depth_mm"] if x) > d["min_depth_mm"]
