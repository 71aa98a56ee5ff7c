"""Idling disturbance table (seed 001 §2.9, issue 6 item 6)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core.errors import ConfigError, InputDataError
from millsense.ident.idle_table import IdleTable, build_idle_table, periodic_amplitude
from millsense.validation.cases.ident_drive import idle_case


def _run(seed: int, x0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.linspace(x0, x0 + 0.02, 20000)
    y = 3.0 * np.sin(2 * math.pi * x / 5e-3) + 1.0 * np.sin(2 * math.pi * x / 0.61e-3 + 0.3)
    return x, y + 10.0 + 0.5 * rng.standard_normal(len(x))


def test_periodic_amplitude_of_a_pure_sine() -> None:
    x = np.linspace(0, 0.02, 5000)
    # closed form: amplitude of a·sin + b·cos is √(a² + b²)
    assert periodic_amplitude(x, 3 * np.sin(2 * math.pi * x / 5e-3) + 4 * np.cos(
        2 * math.pi * x / 5e-3) + 7.0, 5e-3) == pytest.approx(5.0, rel=1e-9)  # fmt: skip


def test_table_removes_synthetic_position_periodic_terms() -> None:
    table = build_idle_table([_run(k) for k in range(3)], bin_m=10e-6, feed_m_s=0.01)
    x, y = _run(7)
    keep = table.covers(x)
    comp = table.compensate(x[keep], y[keep])
    # 3 N and 1 N terms; 10 µm bins attenuate the 0.61 mm term by sinc(π·10/610) (0.04 %),
    # white noise 0.5 N over ~170 samples per bin and 3 runs leaves < 0.02 N
    assert periodic_amplitude(x[keep], comp, 5e-3) < 0.03
    assert periodic_amplitude(x[keep], comp, 0.61e-3) < 0.03
    assert float(np.mean(comp)) == pytest.approx(0.0, abs=0.02)


def test_csv_round_trip_through_the_config_table(tmp_path: Path) -> None:
    table = build_idle_table([_run(k) for k in range(2)], bin_m=20e-6, feed_m_s=0.01)
    table.to_csv(tmp_path / "x-idle.csv")
    cfg = table.config_table("x-idle.csv")
    assert cfg["feed_mm_min"] == pytest.approx(600.0)  # 0.01 m/s
    back = IdleTable.from_config(cfg, tmp_path)
    np.testing.assert_allclose(back.position_m, table.position_m, rtol=1e-8)
    np.testing.assert_allclose(back.value, table.value, rtol=1e-8)
    with pytest.raises(ConfigError, match="missing key 'runs'"):
        IdleTable.from_config({k: v for k, v in cfg.items() if k != "runs"}, tmp_path)


def test_bad_inputs_are_one_line_errors() -> None:
    with pytest.raises(InputDataError, match="needs 2 or more"):
        build_idle_table([_run(0)], bin_m=1e-5, feed_m_s=0.01)
    table = build_idle_table([_run(0), _run(1)], bin_m=1e-5, feed_m_s=0.01)
    with pytest.raises(InputDataError, match="fall outside"):
        table.compensate(np.array([0.5]), np.array([1.0]))
    # 'hold' clamps to the edge value instead
    assert table(np.array([0.5]), outside="hold")[0] == pytest.approx(table.value[-1])


def test_yamada_b_air_cuts_remove_the_periodic_thrust() -> None:
    # issue 6 acceptance: residual within 10 % of each simulated thrust term's amplitude
    # (Yamada B preset: 0.61 mm ball circulation 1 N, 30 and 60 per motor rev 1.5 / 0.75 N)
    for lam_mm, amp, res in idle_case("yamada-b"):
        assert res < 0.1 * amp, lam_mm
