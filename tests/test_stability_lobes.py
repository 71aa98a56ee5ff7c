"""SDM lobes on the Insperger benchmark (benchmarks.md §1), small speed sets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.stability.lobes import chatter_frequency, critical_depth
from millsense.stability.milling import immersion_angles
from millsense.stability.zoa import zoa_lobes
from millsense.validation.cases.stability import (
    FLUTES,
    INSPERGER,
    KN,
    KT,
    insperger_family,
    insperger_lobes,
)


def test_slotting_at_15870_rpm() -> None:
    # benchmarks.md §1: 0.3174 mm, Hopf, chatter about 932 Hz; Richardson 20/40 within 0.5 %
    res = insperger_lobes(1.0, np.array([15870.0]))
    assert res.critical_depth_m[0] * 1e3 == pytest.approx(0.3174, rel=5e-3)
    assert res.bifurcation[0] == "hopf"
    assert res.chatter_hz[0] == pytest.approx(932.0, abs=5.0)


def test_first_order_sdm_converges_from_above_at_m40() -> None:
    # benchmarks.md §1: at m = 40 first-order SDM sits 0.2-2.6 % above the converged values
    w40 = critical_depth(insperger_family(1.0)(15870.0, 40), 2e-4, 0.05).depth
    assert 0.002 <= w40 * 1e3 / 0.3174 - 1 <= 0.026


def test_half_immersion_down_milling_minimum() -> None:
    # benchmarks.md §1: 0.5995 mm at 21727 rev/min, Hopf, about 912 Hz (speed grid ±100)
    rpm = np.array([21627.0, 21727.0, 21827.0])
    res = insperger_lobes(0.5, rpm)
    assert res.min_depth_rpm == 21727.0
    assert res.min_depth_m * 1e3 == pytest.approx(0.5995, rel=5e-3)
    assert res.chatter_hz[1] == pytest.approx(912.0, abs=5.0)


def test_low_immersion_flip_lobe_missed_by_zoa() -> None:
    # benchmarks.md §1: at a/D = 0.05 SDM finds period-doubling lobes; ZOA predicts stability
    # there well above the SDM boundary
    rpm = np.array([18000.0, 18200.0, 18400.0])
    res = insperger_lobes(0.05, rpm)
    st, ex = immersion_angles(0.05, 1.0, "down")
    z = zoa_lobes(INSPERGER, FLUTES, KT, KN, st, ex, rpm)
    flip = [i for i, b in enumerate(res.bifurcation) if b == "flip"]
    assert flip, "no period-doubling lobe found"
    i = flip[0]
    assert z.critical_depth_m[i] > 1.5 * res.critical_depth_m[i]
    # the flip chatter frequency is an odd multiple of half the tooth frequency
    f_tooth = rpm[i] * FLUTES / 60.0
    k = res.chatter_hz[i] / (f_tooth / 2)
    assert abs(k - round(k)) < 1e-6 and round(k) % 2 == 1


def test_chatter_frequency_branch_choice() -> None:
    # μ = e^{iθ}: candidates ±θ/2π f_T + k f_T; pick the one where the structure is compliant
    T = 60.0 / (15870.0 * 2)
    f_true = 932.0
    theta = 2 * math.pi * (f_true * T % 1.0)
    mu = complex(math.cos(theta), math.sin(theta))
    comp = lambda f: np.abs(INSPERGER.frf(f)[..., 0, 0])  # noqa: E731
    assert chatter_frequency(mu, T, comp, 2000.0) == pytest.approx(f_true, abs=1e-6)
