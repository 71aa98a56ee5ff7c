"""Least-noise Q for a requested band (tuning.least_noise_q, estimator.band_hz, --band-hz)."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.config import FeedEstimatorConfig
from millsense.core.errors import ConfigError, InputDataError
from millsense.estimation.feed import tuning
from millsense.estimation.feed.estimator import FeedAxisModel, measurement_model
from millsense.estimation.from_config import with_feed_band
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.models.modal_ss import ModalStateSpace
from millsense.simulator.machine_file import simulator_machine

FS = 10_000.0
#: Aslan Eq. 3.30 R of the X axis, N²·m²
R_X = 0.0776


@pytest.fixture(scope="module")
def x_model() -> object:
    cfg = simulator_machine("quaser-ux600").axis("x")
    assert cfg.disturbance_modes is not None
    fit = RationalFit.from_modes(ModalStateSpace.from_config(cfg.disturbance_modes))
    return measurement_model(fit, 600.0, 1 / FS)


def _worst_db(model: object, q: float, band_hz: float) -> float:
    # independent of least_noise_q's own loop: the compensated FRF on a 0.5 Hz grid
    f = np.arange(0.5, band_hz + 0.25, 0.5)
    d = tuning._design(model, q, R_X)  # type: ignore[arg-type]
    h = tuning.compensated_frf(model, d, f)  # type: ignore[arg-type]
    return float(np.max(np.abs(20 * np.log10(np.abs(h)))))


def test_least_noise_q_is_the_least_flat_one_and_quieter_than_the_widest_band(
    x_model: object,
) -> None:
    res = tuning.least_noise_q(x_model, R_X, 200.0)  # type: ignore[arg-type]
    # flat within ±1 dB to 200 Hz at Q, not at 2 % less (bisection to 0.23 % in Q)
    assert _worst_db(x_model, res.q, 200.0) <= 1.0 + 1e-3
    assert _worst_db(x_model, res.q / 1.02, 200.0) > 1.0
    widest = tuning.tune_q(x_model, R_X)  # type: ignore[arg-type]
    # the widest-band tuning sits at the noise limit √10; the 200 Hz rule well below it
    assert widest.noise_gain == pytest.approx(np.sqrt(10.0), rel=0.02)
    assert res.noise_gain < 0.6 * widest.noise_gain
    assert res.bandwidth_hz >= 200.0


def test_unreachable_band_names_the_widest(x_model: object) -> None:
    with pytest.raises(InputDataError, match=r"within ±1 dB up to 900 Hz.*widest ±3 dB band"):
        tuning.least_noise_q(x_model, R_X, 900.0)  # type: ignore[arg-type]
    with pytest.raises(InputDataError, match="band must be in"):
        tuning.least_noise_q(x_model, R_X, -5.0)  # type: ignore[arg-type]


def test_band_key_excludes_a_fixed_q_and_a_mode_shift_margin() -> None:
    with pytest.raises(ValueError, match="q_nm2_s or band_hz"):
        FeedEstimatorConfig(band_hz=200.0, q_nm2_s=500.0)
    with pytest.raises(ValueError, match="nominal tuning"):
        FeedEstimatorConfig(band_hz=200.0, mode_shift_pct=2.0)
    assert FeedEstimatorConfig(band_hz=200.0).band_hz == 200.0


def test_machine_band_rule_reaches_the_estimator(x_model: object) -> None:
    machine = simulator_machine("quaser-ux600")
    banded = with_feed_band(machine, ["x"], 200.0)
    model = FeedAxisModel.from_config("x", banded.axis("x"), sample_rate_hz=FS)
    expect = tuning.least_noise_q(model.measurement_model(), model.r, 200.0).q
    assert model.q == pytest.approx(expect, rel=1e-9)
    default = FeedAxisModel.from_config("x", machine.axis("x"), sample_rate_hz=FS)
    assert model.q < default.q
    with pytest.raises(ConfigError, match=r"axes\.y\.estimator\.band_hz: tuning: no Q"):
        FeedAxisModel.from_config(
            "y", with_feed_band(machine, ["y"], 900.0).axis("y"), sample_rate_hz=FS
        )
    with pytest.raises(ConfigError, match="--band-hz"):
        with_feed_band(machine, ["x"], 0.0)
