"""The compiled first-order average of the streaming blocks against scipy's ``lfilter`` (the
filter it replaces in :class:`~millsense.online.gates.AirReference`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from millsense.streaming.recursions import exponential_average


@pytest.mark.parametrize("alpha", [1e-4, 3.3e-4, 0.3, 1.0])
def test_exponential_average_is_lfilter(alpha: float) -> None:
    x = np.random.default_rng(0).normal(5.0, 3.0, 20000)
    want, _ = lfilter([alpha], [1.0, alpha - 1.0], x, zi=[(1.0 - alpha) * 2.5])
    np.testing.assert_allclose(exponential_average(x, alpha, 2.5), want, rtol=1e-13, atol=1e-12)
    # continued over two calls from the last value: the same as one call
    k = 7777
    a = exponential_average(x[:k], alpha, 2.5)
    b = exponential_average(x[k:], alpha, float(a[-1]))
    np.testing.assert_array_equal(np.concatenate([a, b]), exponential_average(x, alpha, 2.5))
