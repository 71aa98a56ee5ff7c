"""The on-disk cache of pure computations (decision 2006) and the spindle tuning that uses it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from millsense.core import disk_cache
from millsense.estimation import spindle_observer as so
from millsense.estimation.kalman.design import StateSpaceModel


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(disk_cache.CACHE_DIR_ENV, str(tmp_path))
    return tmp_path


def _model() -> StateSpaceModel:
    # a lightly damped discrete mode at the velocity-loop period (0.2 ms): a small G_dτ
    dt = 2e-4
    w, z = 2 * math.pi * 600.0, 0.05
    a = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
    e = np.eye(2) + dt * a + (dt * a) @ (dt * a) / 2
    return StateSpaceModel.from_arrays(e, [0.0, dt], [w**2 * 1e-3, 0.0], 0.3, dt=dt)


def _tune(model: StateSpaceModel) -> so.SpindleTuning:
    # the search itself, not the per-process memo
    return so._tune_spindle_q(model, 1e-4, 2.0, 10.0, 1.0, 100, ((-6.0, 2.0),))


def test_values_round_trip_exactly(cache: Path) -> None:
    # floats go through JSON by repr: bit for bit, NaN included
    v = {"x": 0.1 + 0.2, "y": -1.2345678901234567e-300, "n": float("nan")}
    assert disk_cache.store("t", "k", v)
    back = disk_cache.load("t", "k")
    assert back is not None and back["x"] == v["x"] and back["y"] == v["y"]
    assert math.isnan(back["n"])


def test_a_corrupt_or_missing_entry_is_a_miss_and_off_is_off(
    cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert disk_cache.load("t", "absent") is None
    (cache / "t").mkdir()
    (cache / "t" / "bad.json").write_text("{not json")
    assert disk_cache.load("t", "bad") is None
    (cache / "t" / "list.json").write_text("[1, 2]")
    assert disk_cache.load("t", "list") is None
    monkeypatch.setenv(disk_cache.CACHE_DIR_ENV, "off")
    assert disk_cache.cache_dir() is None
    assert not disk_cache.store("t", "k", {"a": 1.0})
    assert disk_cache.load("t", "k") is None


def test_an_unwritable_folder_is_not_an_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(disk_cache.CACHE_DIR_ENV, str(blocker / "below-a-file"))
    assert not disk_cache.store("t", "k", {"a": 1.0})


def test_keys_tell_arguments_apart() -> None:
    # the length prefix keeps (b"ab", b"c") and (b"a", b"bc") apart; floats by exact repr
    assert disk_cache.key_digest(b"ab", b"c") != disk_cache.key_digest(b"a", b"bc")
    assert disk_cache.key_digest(0.1 + 0.2) != disk_cache.key_digest(0.3)
    assert disk_cache.key_digest((1, 2), 3.0) == disk_cache.key_digest((1, 2), 3.0)


def test_the_tuning_from_the_cache_is_the_searched_one_bit_for_bit(cache: Path) -> None:
    model = _model()
    first = _tune(model)
    entries = list((cache / so._CACHE_NAMESPACE).glob("*.json"))
    assert len(entries) == 1
    # a second process would read the optimum and design from it: the same observer exactly
    again = _tune(model)
    assert (again.q_states, again.q_torque) == (first.q_states, first.q_torque)
    assert again.rms_db == first.rms_db and again.noise_std_nm == first.noise_std_nm
    np.testing.assert_array_equal(again.design.k_filter, first.design.k_filter)
    # and it did read it: a doctored entry is what the next tuning uses
    disk_cache.store(so._CACHE_NAMESPACE, entries[0].stem,
                     {"log_q_states": -3.0, "log_q_torque": 1.0})  # fmt: skip
    assert _tune(model).q_states == pytest.approx(1e-3, rel=1e-12)


def test_a_corrupt_tuning_entry_is_searched_again(cache: Path) -> None:
    model = _model()
    first = _tune(model)
    (entry,) = (cache / so._CACHE_NAMESPACE).glob("*.json")
    entry.write_text('{"log_q_states": "x"}')
    assert _tune(model).q_states == first.q_states
    # the search stored its optimum again
    assert disk_cache.load(so._CACHE_NAMESPACE, entry.stem) is not None
    assert "log_q_torque" in (disk_cache.load(so._CACHE_NAMESPACE, entry.stem) or {})


def test_another_model_is_another_entry(cache: Path) -> None:
    m = _model()
    _tune(m)
    other = StateSpaceModel.from_arrays(m.a, m.b * 1.01, m.c, m.d, dt=m.dt)
    _tune(other)
    assert len(list((cache / so._CACHE_NAMESPACE).glob("*.json"))) == 2
