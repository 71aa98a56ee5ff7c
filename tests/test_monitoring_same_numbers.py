"""The monitors' faster paths give the numbers of the paths they replace, bit for bit: the
chatter gate's band median by bit patterns; and the streaming Chunk's constructor keeps a
frozen dataclass."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest

from millsense.monitoring.chatter import _kernels as kn
from millsense.streaming.block import Chunk


def _same(a: float, b: float) -> bool:
    return (a == b and math.copysign(1.0, a) == math.copysign(1.0, b)) or (a != a and b != b)


def test_radix_median_is_the_quickselect_value() -> None:
    """Every order statistic, on spectra-like values, ties, zeros, +inf, and the values it
    hands back to the quickselect (NaN, −0, negatives)."""
    rng = np.random.default_rng(3)
    for trial in range(600):
        n = int(rng.integers(1, 2500))
        kind = trial % 5
        if kind == 0:
            a = np.abs(rng.standard_normal(n)) * 10 ** rng.uniform(-5, 5)
        elif kind == 1:
            a = np.abs(rng.standard_normal(n)) ** 3
        elif kind == 2:
            a = rng.integers(0, 5, n).astype(float)
        elif kind == 3:
            a = np.abs(rng.standard_cauchy(n))
            a[rng.integers(0, n, n // 10)] = 0.0
        else:
            a = np.full(n, 3.3)
        if trial % 7 == 0:
            a[0] = np.inf
        if trial % 11 == 0:
            a[-1] = -0.0
        if trial % 13 == 0:
            a[n // 2] = np.nan
        if trial % 17 == 0:
            a[0] = -1.0
        k = int(rng.integers(0, n))
        before = a.copy()
        assert _same(kn._select_radix(a, k), kn._select(a, k))
        np.testing.assert_array_equal(a, before)  # left unchanged


def test_chunk_is_frozen_and_keeps_its_fields() -> None:
    c = Chunk(5, 1e4, 0.5, {"a": np.arange(3.0)})
    assert (c.start, c.sample_rate_hz, c.t0_s, c.n) == (5, 1e4, 0.5, 3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.start = 3  # type: ignore[misc]
    assert dataclasses.replace(c, start=7).start == 7
    for d in (pickle.loads(pickle.dumps(c)), c.restricted(("a",))):
        assert (d.start, d.sample_rate_hz, d.t0_s, list(d.data)) == (5, 1e4, 0.5, ["a"])
    assert [f.name for f in dataclasses.fields(c)] == ["start", "sample_rate_hz", "t0_s", "data"]
