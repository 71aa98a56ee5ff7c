"""The monitors' faster paths give the numbers of the paths they replace, bit for bit: the
engagement fit's memo (the start point's and the fitted point's phases, lengths and G), the
chatter gate's band median by bit patterns, and the streaming Chunk's constructor."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest

from millsense.monitoring import _spectrum_kernels as sk
from millsense.monitoring.chatter import _kernels as kn
from millsense.monitoring.engagement import EngagementBlock
from millsense.monitoring.torque_spectrum import SpectrumIdentifier
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
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


def _revolutions(n: int) -> tuple[SpectrumIdentifier, list[tuple[np.ndarray, float]]]:
    """The identifier of an engagement block and the harmonics and feeds of ``n`` revolutions
    of a noisy 2-flute Ø20 mm down-milling cut at 1000 rev/min (the monitoring benchmark's)."""
    fs = 10000.0
    omega = 1000 * 2 * math.pi / 60
    tool = EndMill(20e-3, 2, helix_rad=math.radians(30))
    co = CuttingCoefficients(ktc=758e6, krc=379e6, kte=25e3, kre=35e3)
    phi = 2 * math.pi * np.arange(600) / 600
    rev = milling_forces(tool, co, Engagement.radial(5e-3, 20e-3, "down"), 0.2e-3, 2e-3, phi)
    m = 600 * (n + 1)
    t = np.arange(m) / fs
    tq = np.interp(np.mod(omega * t, 2 * math.pi), phi, rev.torque_nm, period=2 * math.pi)
    tq = tq + 0.05 * np.random.default_rng(0).standard_normal(m)
    block = EngagementBlock(2, 20.0, 30.0, feed_per_tooth_mm=0.2, n_harmonics=15)
    block.reset(fs)
    out = []
    for i in range(0, m, 600):
        block.process(Chunk(i, fs, 0.0, {"spindle/torque_est": tq[i : i + 600],
                                         "spindle/speed": np.full(600, omega)}))  # fmt: skip
        out.append((block._done_sums[0].copy(), float(block._done[0, sk.DONE_FEED])))
    return block._ident, out[1:]


def test_fit_with_memo_gives_the_fit_without() -> None:
    """Revolution after revolution from the previous solution (the streaming path), the fit
    and estimate with one memo equal the memo-less ones in every field, bit for bit."""
    ident, revs = _revolutions(40)
    g = ident.geom
    memo = sk.memo_for(15)
    est = ident.identify_array(revs[0][0][1:], complex(revs[0][0][0]), revs[0][1])
    prev = est[[sk.EST_AXIAL, sk.EST_ENTRY, sk.EST_EXIT]].copy()
    hits = accepted = 0
    for coeff, c in revs[1:]:
        x = np.ascontiguousarray(coeff[1:])
        a = np.zeros(sk.EST_SIZE)
        b = np.zeros(sk.EST_SIZE)
        tail = (g.radius_m, g.n_flutes, g.axial_pitch_m, 1e-6)
        args = (ident.k, ident._kb, True, ident._lo, ident._hi, ident._scl, ident.accept)
        hits += sk._memo_at(memo, prev[0], prev[1], prev[2])
        ok_a = sk.identify_from(prev, x, coeff[0], c, *args, *tail, a)
        ok_b = sk.identify_from_memo(prev, x, coeff[0], c, *args, *tail, b, memo)
        assert ok_a == ok_b
        assert all(_same(u, v) for u, v in zip(a.tolist(), b.tolist(), strict=True))
        if ok_a:
            accepted += 1
            prev = a[[sk.EST_AXIAL, sk.EST_ENTRY, sk.EST_EXIT]].copy()
    assert accepted >= 35 and hits >= 35  # the streaming path, the memo serving its starts


def test_chunk_is_frozen_and_keeps_its_fields() -> None:
    c = Chunk(5, 1e4, 0.5, {"a": np.arange(3.0)})
    assert (c.start, c.sample_rate_hz, c.t0_s, c.n) == (5, 1e4, 0.5, 3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.start = 3  # type: ignore[misc]
    assert dataclasses.replace(c, start=7).start == 7
    for d in (pickle.loads(pickle.dumps(c)), c.restricted(("a",))):
        assert (d.start, d.sample_rate_hz, d.t0_s, list(d.data)) == (5, 1e4, 0.5, ["a"])
    assert [f.name for f in dataclasses.fields(c)] == ["start", "sample_rate_hz", "t0_s", "data"]
