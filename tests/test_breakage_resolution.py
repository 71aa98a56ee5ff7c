"""Decision 1732: a change within the DOB's encoder resolution is no broken flute.

Found on the general cuts' intact 4-flute half immersion at 10 000 rev/min (numpy 2.4.6, scipy
1.17.1, numba 0.68.1): the flute pattern confirmed a break at 8.1σ on an intact tool. The
spindle DOB's tooth-period mean holds J·(Ω̄_end − Ω̄_start)/T, each window-mean speed quantised
at one encoder count over 0.9 ms; at 15 samples a tooth period (exactly 2^18 counts) a count
at a period's end holds for revolutions while the speed holds. Two ends flipped at once, one
up and one down: flute 1 +0.14 N·m, flute 2 −0.28, flute 3 +0.14, the pattern of a broken
flute 2 (a drop, the next flute's rise), persistent, against a 128-period scale of 0.036 N·m
and just past the drop gate (0.273 N·m, half the 40 % band).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.core.errors import ConfigError
from millsense.estimation.spindle_dob import SpindleDobTorque
from millsense.monitoring.breakage import BreakageBlock
from millsense.monitoring.breakage_phased import PhasedBreakage
from millsense.streaming.block import Chunk
from millsense.validation.cases.monitoring_breakage import run_block

FS = 10000.0
COUNTS = 2**20
INERTIA = 0.0322509  # kg·m², J_eS of the commissioned quaser-ux600 (its DOB's)
N, TOOTH = 4, 15  # 4 flutes at 10 000 rev/min: 15 samples a tooth period
RPM = 60.0 * FS / (N * TOOTH)
PLAN = 1.36  # N·m, the intact cut's expected torque per tooth period
PERIODS = 1600
FLIP = 1000  # the period at which two ends' counts flip


def _dob() -> SpindleDobTorque:
    return SpindleDobTorque((1.0, 1.0), 1e9, INERTIA, encoder_counts_rev=COUNTS)


def test_dob_tooth_period_means_move_in_steps_of_its_resolution() -> None:
    """The closed form J·2π·f_s/(counts·m) (m = 9 samples at 10 kHz) against the DOB itself:
    with no current, a speed 0.3 % off 10 000 rev/min from a quantised encoder, every tooth
    period's mean of the output is an integer multiple of the resolution over the period
    (the telescoped window means, decision 1732), and some are not zero."""
    dob = _dob()
    r = dob.mean_resolution_nms(FS)
    assert r == pytest.approx(INERTIA * 2 * math.pi * FS / (COUNTS * 9), rel=1e-12)
    k = np.arange(40 * TOOTH * 100)
    theta = 2 * math.pi * (RPM * 1.003 / 60.0) * k / FS
    counts = np.floor(theta * COUNTS / (2 * math.pi))
    speed = np.diff(counts, prepend=counts[0]) * 2 * math.pi / COUNTS * FS
    z = np.zeros(k.size)
    dob.reset(FS)
    chan = {"spindle/current_cmd": z, "spindle/speed": speed, "spindle/speed_cmd": speed}
    out = dob.process(Chunk(0, FS, 0.0, chan)).channels[dob.out]
    means = out[TOOTH * 4 :].reshape(-1, TOOTH).mean(axis=1)  # past the rings' start
    steps = means / (r / (TOOTH / FS))
    assert np.allclose(steps, np.round(steps), atol=1e-6)
    assert np.count_nonzero(np.round(steps)) > 10


def _stream(values: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    period = np.arange(values.size * TOOTH) // TOOTH
    rng = np.random.default_rng(seed)
    return {
        "tq": values[period] + 0.08 * rng.standard_normal(period.size),  # 0.02 N·m a period
        "w": np.full(period.size, RPM * 2 * math.pi / 60),
        "ex": np.full(period.size, PLAN),
    }


def _quantised(step: float, seed: int) -> np.ndarray:
    """Tooth-period means of an intact cut on the DOB: the plan, plus step·(e_end − e_start)
    of each period's two ends' count errors (revolution-periodic), two of which flip at FLIP,
    one up and one down (flute 1 +step, flute 2 −2 step, flute 3 +step), and hold."""
    e = np.zeros(PERIODS + 1)  # e[p + 1]: the count error at the end of period p
    rng = np.random.default_rng(seed)
    ends = rng.integers(0, 2, N).astype(float)
    for p in range(PERIODS):
        e[p + 1] = ends[p % N]
        if p >= FLIP and p % N == 1:
            e[p + 1] += 1.0
        if p >= FLIP and p % N == 2:
            e[p + 1] -= 1.0
    return PLAN + step * np.diff(e)


def _alarms(data: dict[str, np.ndarray], resolution: float) -> list[float]:
    det = PhasedBreakage(N, method="virtual", signal_channels=("tq",), speed_channel="w",
                         expected_channel="ex", min_expected_nm=0.5, mean_resolution=resolution,
                         name="breakage")  # fmt: skip
    events, _ = run_block(det, data, 100, FS)
    return [e.time_s * FS / TOOTH for e in events if e.name == "breakage"]


def test_a_quantisation_flip_is_no_break_with_the_resolution_given() -> None:
    """The flip pattern above at the DOB's step at 10 000 rev/min (0.144 N·m; two steps pass
    the pattern's gate of half the 40 % band, 0.272 N·m): the flute pattern alarms on it
    without the resolution (the finding; every seed of the count errors), and with it no
    detector alarms."""
    step = _dob().mean_resolution_nms(FS) / (TOOTH / FS)
    assert 2 * step > 0.5 * 0.4 * PLAN
    without, with_ = 0, 0
    for seed in range(4):
        data = _stream(_quantised(step, seed), seed)
        without += bool([a for a in _alarms(data, 0.0) if a >= FLIP])
        with_ += len(_alarms(data, step * TOOTH / FS))
    assert without == 4
    assert with_ == 0


@pytest.mark.parametrize("drop", [0.45, 0.6])
def test_a_broken_flute_is_still_found_with_the_resolution_given(drop: float) -> None:
    """A flute losing 45 % or 60 % of the plan's torque (the next cutting its chip, less its
    broken edge's 10 %) 200 periods after the flip of the quantised cut: the first alarm
    within 3 tooth periods of the break, none before it, with the resolution given."""
    step = _dob().mean_resolution_nms(FS) / (TOOTH / FS)
    for seed in range(4):
        x = _quantised(step, seed)
        brk = 1200 + seed
        for j in range(brk, PERIODS):
            if j % N == brk % N:
                x[j] -= drop * PLAN
            elif j % N == (brk + 1) % N:
                x[j] += (drop - 0.1) * PLAN
        alarms = _alarms(_stream(x, seed), step * TOOTH / FS)
        assert alarms and alarms[0] > brk and alarms[0] - brk <= 3.0, (seed, alarms)


def test_a_negative_resolution_is_refused() -> None:
    with pytest.raises(ConfigError, match="mean_resolution"):
        BreakageBlock(N, "dual", signal_channels=("tq",), mean_resolution=-1.0)
