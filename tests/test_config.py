"""Configuration models: SI conversion and the promised one-line errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from millsense.core.config import (
    MachineConfig,
    MaterialConfig,
    StockConfig,
    ToolConfig,
    load_config,
)
from millsense.core.errors import ConfigError
from millsense.core.presets import load_preset, preset_names
from millsense.simulator.machine_file import simulator_machine


def write(tmp_path: Path, text: str, name: str = "cfg.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_tool_si_conversion(tmp_path: Path) -> None:
    p = write(tmp_path, "diameter_mm = 20\nflutes = 2\nhelix_deg = 30\nrunout_um = 12\n")
    tool = load_config(ToolConfig, p)
    assert tool.diameter_m == pytest.approx(0.020, rel=1e-12)  # 20 mm
    assert tool.helix_rad == pytest.approx(math.pi / 6, rel=1e-12)  # 30°
    assert tool.runout_m == pytest.approx(12e-6, rel=1e-12)
    assert tool.pitch_rad == pytest.approx((math.pi, math.pi))  # uniform 2 flutes


def test_material_si_conversion(tmp_path: Path) -> None:
    p = write(tmp_path, "ktc_n_mm2 = 758\nkrc_n_mm2 = 379\nkte_n_mm = 25\n")
    mat = load_config(MaterialConfig, p)
    assert mat.ktc == pytest.approx(758e6)  # N/mm² -> N/m²
    assert mat.kte == pytest.approx(25e3)  # N/mm -> N/m


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("diameter_mm = -3\nflutes = 2\n", "key 'diameter_mm' = -3 is out of range: must be > 0"),
        ('diameter_mm = "ten"\nflutes = 2\n', "key 'diameter_mm' = 'ten'"),
        ("diameter_mm = 10\nflutes = 2\ndiamter = 3\n", "unknown key 'diamter'"),
        ("flutes = 2\n", "missing required key 'diameter_mm'"),
        ("diameter_mm = 10\nflutes = 3\npitch_deg = [100, 100, 100]\n", "must sum to 360"),
        ("diameter_mm = 10\nflutes = 2\nhelix_deg = 80\n", "must be >= 0 and < 70"),
        ("diameter_mm = 10\nflutes = 2\nshape = 'bull'\n", "key 'shape' = 'bull'"),
        ("diameter_mm = 10\nflutes = [2\n", "not valid TOML"),
    ],
)
def test_tool_errors_are_one_line_naming_file_and_key(
    tmp_path: Path, text: str, expected: str
) -> None:
    p = write(tmp_path, text, "tool.toml")
    with pytest.raises(ConfigError) as err:
        load_config(ToolConfig, p)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(str(p))
    assert expected in msg


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such file"):
        load_config(ToolConfig, tmp_path / "nope.toml")


def test_nested_machine_error_names_full_key(tmp_path: Path) -> None:
    text = """
name = "m"
[axes.x]
inertia_kg_m2 = 0.01
torque_constant_nm_a = 2
lead_mm_rev = 12
[axes.x.friction]
coulomb_nm = [1.0, -1.0]
viscous_nm_s_rad = [0.1, 0.1]
"""
    with pytest.raises(ConfigError) as err:
        load_config(MachineConfig, write(tmp_path, text))
    assert "key 'axes.x.friction.coulomb_nm.1' = -1.0 is out of range: must be >= 0" in str(
        err.value
    )


def test_stock_box_must_have_volume(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="max_mm must exceed min_mm in y"):
        load_config(StockConfig, write(tmp_path, "min_mm = [0, 0, 0]\nmax_mm = [10, 0, 5]\n"))


def test_quaser_preset_matches_aslan_tables() -> None:
    m = simulator_machine("quaser-ux600")
    x = m.axis("x")
    # Aslan Table 3.1 J_e and K_t; Table 3.3 lead 12 mm: r_g = 12 mm / 2π
    assert x.inertia_kg_m2 == 0.01366
    assert x.torque_constant_nm_a == 1.964
    assert x.transmission_m_rad == pytest.approx(0.012 / (2 * math.pi), rel=1e-12)
    # digest P3: F = η·τ/r_g ≈ 481.7 N per N·m of motor torque on the linear axes
    assert x.efficiency / x.transmission_m_rad == pytest.approx(481.7, abs=0.05)
    # Eq. 3.30 R = 0.0776 read as torque variance: current noise sqrt(R)/K_t
    assert x.current_noise_a == pytest.approx(math.sqrt(0.0776) / 1.964, rel=1e-3)
    assert set(m.axes) == {"x", "y", "z", "a", "c"}


def test_presets_listed_and_unknown_named() -> None:
    assert "quaser-ux600" in preset_names(MachineConfig)
    with pytest.raises(ConfigError, match=r"no machine preset 'nosuch'.*quaser-ux600"):
        load_preset(MachineConfig, "nosuch")


def test_tool_and_material_presets_found_whatever_their_case() -> None:
    """A material named as the demo part's stock file spells it (Al7050) is the preset
    al7050, and a tool preset likewise; a machine's name stays exact (it also names the
    commissioned file)."""
    assert load_preset(MaterialConfig, "Al7050") == load_preset(MaterialConfig, "al7050")
    tool = load_preset(ToolConfig, "aslan-d20-2flute")
    assert load_preset(ToolConfig, "ASLAN-D20-2FLUTE") == tool
    with pytest.raises(ConfigError, match=r"no machine preset 'Quaser-UX600'"):
        load_preset(MachineConfig, "Quaser-UX600")


def test_process_objects_from_config() -> None:
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill

    tool = load_preset(ToolConfig, "aslan-d20-2flute")
    em = EndMill.from_config(tool)
    assert em.diameter_m == pytest.approx(0.020) and em.n_flutes == 2
    assert em.helix_rad == pytest.approx(math.radians(30.0))
    k = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    assert k.ktc == pytest.approx(758e6) and k.krc == pytest.approx(379e6)  # Aslan P10, Ch. 5


def test_spindle_residual_modes_key_loads() -> None:
    # `millsense identify spindle` writes [spindle.residual_modes] with DisturbanceModesConfig
    # keys; the machine model must accept it (Aslan App. E form, ζ as fractions).
    from millsense.core.config import SpindleConfig, parse_config

    sp = parse_config(
        SpindleConfig,
        {
            "max_rpm": 24000,
            "inertia_kg_m2": 0.0316,
            "torque_constant_nm_a": 1.343,
            "residual_modes": {
                "natural_frequency_hz": [457.9],
                "damping_ratio": [0.5],
                "alpha": [-8.9],
                "beta": [-10.0],
            },
        },
        "frag.toml",
    )
    assert sp.residual_modes is not None
    assert sp.residual_modes.natural_frequency_hz == [457.9]


def test_with_axes_keeps_only_the_named_axes_and_refuses_a_missing_one() -> None:
    from millsense.core.config import MachineConfig
    from millsense.core.errors import ConfigError
    from millsense.core.presets import load_preset

    m = load_preset(MachineConfig, "quaser-ux600")
    three = m.with_axes("xyz", "3-axis")
    assert list(three.axes) == ["x", "y", "z"] and three.kinematics == "3-axis"
    assert three.axes["y"] == m.axes["y"] and m.kinematics == "5-axis-trunnion-ac"
    with pytest.raises(ConfigError, match="no axis 'b'"):
        m.with_axes("xb", "3-axis")


def test_read_toml_parses_a_file_again_only_when_it_changed(tmp_path: Path) -> None:
    """``read_toml`` keeps the parse of an unchanged file (a batch worker reads its machine
    file for every step of every recording); a changed file (modification time or size) is
    parsed again, and a caller that edits its copy changes nothing for the next."""
    import os

    from millsense.core.config import read_toml

    p = tmp_path / "m.toml"
    p.write_text("a = 1\n[t]\nb = [1, 2]\n", encoding="utf-8")
    first = read_toml(p)
    first["t"]["b"].append(3)
    assert read_toml(p) == {"a": 1, "t": {"b": [1, 2]}}
    st = p.stat()
    p.write_text("a = 2\n[t]\nb = [1, 2]\n", encoding="utf-8")  # same size
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert read_toml(p)["a"] == 2
