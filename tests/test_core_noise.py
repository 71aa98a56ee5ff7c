"""core.noise.window_median: numpy's median, bit for bit, of the windows a controller keeps."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from millsense.core.noise import window_median


def test_window_median_is_numpys_median_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    special = [0.0, -0.0, 1.0, -1.0, math.inf, -math.inf, math.nan, 1e308, -1e308, 5e-324]
    for t in range(1000):
        n = int(rng.integers(1, 40))
        if t % 2:
            vals = [float(v) for v in rng.normal(size=n)]
        else:
            vals = [float(rng.choice(special)) if rng.random() < 0.3 else float(rng.normal())
                    for _ in range(n)]  # fmt: skip
        with np.errstate(invalid="ignore"):
            want = float(np.median(np.asarray(vals, dtype=np.float64)))
        got = window_median(deque(vals))
        if math.isnan(want):
            assert math.isnan(got), vals
        else:
            assert got == want and math.copysign(1.0, got) == math.copysign(1.0, want), vals
