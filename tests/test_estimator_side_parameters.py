"""Issue 12: the accelerometer and DOB estimators take R, the tool helix and the encoder period
from a simulated measurement or from catalogue data they own, never from the simulator's
constants (decision 1720)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from millsense.validation.cases import _accel_sim as sim
from millsense.validation.cases import estimation_accel as acc
from millsense.validation.cases import estimation_dob as dob


def _scaled_ilme(factor: float) -> Any:
    real = sim.simulate_ilme

    def wrapped(*a: Any, **kw: Any) -> sim.IlmeRecord:
        rec = real(*a, **kw)
        return dataclasses.replace(rec, accel_y=factor * rec.accel_y)

    return wrapped


def test_ilme_r_is_the_variance_of_a_simulated_free_state_record(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    test = sim.ILME_TESTS[0]
    air = sim.simulate_ilme(test, acc.ILME_AIR_S, seed=acc.ILME_AIR_SEED, cutting=False)
    assert not np.any(air.force_y_true) and not np.any(air.force_x_true)  # no cutting force
    r = acc._ilme_r(test)
    assert r == float(np.var(air.accel_y))
    # a realisation, not the simulator's constant squared
    assert r != sim.ILME_NOISE_RMS**2 and r == pytest.approx(sim.ILME_NOISE_RMS**2, rel=0.05)
    # R follows whatever the measurement chain records
    monkeypatch.setattr(sim, "simulate_ilme", _scaled_ilme(2.0))
    assert acc._ilme_r(test) == pytest.approx(4.0 * r, rel=1e-12)


def test_aslan_r_is_the_variance_of_a_simulated_air_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    r = acc._aslan_r(9000.0)
    assert len(r) == sim.ASLAN_N_SENSORS and all(v > 0 for v in r)
    assert len(set(r)) == len(r)  # one record per channel, not one noise constant
    real = sim.simulate_aslan_cut

    def wrapped(*a: Any, **kw: Any) -> sim.AslanRecord:
        assert kw.get("cutting") is False
        rec = real(*a, **kw)
        assert not np.any(rec.force_true)
        return dataclasses.replace(rec, accel=3.0 * rec.accel)

    monkeypatch.setattr(sim, "simulate_aslan_cut", wrapped)
    assert acc._aslan_r(9000.0) == pytest.approx([9.0 * v for v in r], rel=1e-9)
    # the simulator's noise constant alone no longer sets it
    monkeypatch.setattr(sim, "simulate_aslan_cut", real)
    monkeypatch.setattr(sim, "ASLAN_NOISE_RMS", 2 * sim.ASLAN_NOISE_RMS)
    r2 = acc._aslan_r(9000.0)
    assert r2 == pytest.approx([4.0 * v for v in r], rel=1e-9)  # through the record


class _Stop(Exception):
    pass


def test_ilme_estimator_helix_is_the_catalogue_value(monkeypatch: pytest.MonkeyPatch) -> None:
    """The CutSetup helix is İlme Table 4.4's 45°, whatever the simulator's tool has."""
    import millsense.estimation.accel.harmonic_kf as hkf

    seen: list[tuple[Any, ...]] = []

    def cut_setup(*a: Any) -> None:
        seen.append(a)
        raise _Stop

    n = 64
    z = np.zeros(n)
    rec = sim.IlmeRecord(sim.ILME_TESTS[0], sim.ILME_FS_HZ, z, z, z, z, z)
    monkeypatch.setattr(sim, "ILME_HELIX_RAD", math.radians(30.0))
    monkeypatch.setattr(sim, "ilme_frf", lambda *a, **k: None)
    monkeypatch.setattr(sim, "simulate_ilme", lambda *a, **k: rec)
    monkeypatch.setattr(hkf, "CutSetup", cut_setup)
    with pytest.raises(_Stop):
        acc._ilme_table.__wrapped__()
    assert seen[0][2] == acc.ILME_TOOL_HELIX_RAD == math.radians(45.0)


def test_dob_notch_wavelength_follows_the_nameplate(monkeypatch: pytest.MonkeyPatch) -> None:
    from millsense.core import presets
    from millsense.core.config import MachineConfig

    dob.encoder_wavelength_m.cache_clear()
    plate = presets.load_preset(MachineConfig, "yamada-b")
    ax = plate.axis("x")
    assert ax.encoder_signal_periods_rev == 512  # Yamada Table 3-2
    assert dob.encoder_wavelength_m() == pytest.approx(5e-3 / 512, rel=1e-12)
    # a nameplate with another line count moves the notches with it
    other = ax.model_copy(update={"encoder_signal_periods_rev": 1000})
    fake = plate.model_copy(update={"axes": {**plate.axes, "x": other}})
    monkeypatch.setattr(presets, "load_preset", lambda *a, **k: fake)
    dob.encoder_wavelength_m.cache_clear()
    try:
        assert dob.encoder_wavelength_m() == pytest.approx(5e-3 / 1000, rel=1e-12)
        # and the Table 4-7 notch bank is built on it (observer stubbed out)
        import millsense.estimation.dob.notch as notch_mod
        import millsense.estimation.dob.observers as obs_mod

        specs: list[Any] = []

        def bank(spec: Any, fs: float) -> None:
            specs.append(spec)
            raise _Stop

        p = SimpleNamespace(transmission_m_rad=5e-3 / (2 * math.pi), force_constant_n_a=1.0)
        observer = SimpleNamespace(process=lambda *a: np.zeros(4))
        monkeypatch.setattr(dob, "_identified", lambda: p)
        monkeypatch.setattr(dob, "_belief", lambda: SimpleNamespace(current_bandwidth_hz=796.0))
        monkeypatch.setattr(dob, "_delays", lambda sync: (0.0, 0.0, 0.0))
        monkeypatch.setattr(dob, "torsion_notch_hz", lambda: 778.5)
        monkeypatch.setattr(obs_mod, "with_table_mass", lambda p, m: p)
        monkeypatch.setattr(obs_mod, "medob_observer", lambda *a, **k: observer)
        monkeypatch.setattr(notch_mod, "NotchBank", bank)
        out = {"current_cmd": np.zeros(4), "angle": np.zeros(4), "scale": np.zeros(4)}
        with pytest.raises(_Stop):
            dob._estimate("medob", dob.CONDITIONS[4], out, sync=True, mass=1.0, notch=True)
        assert specs[0].wavelength_m == pytest.approx(5e-3 / 1000, rel=1e-12)
        assert specs[0].harmonics == dob.NOTCH_HARMONICS
    finally:
        dob.encoder_wavelength_m.cache_clear()
