"""The T4 replica of seed 000 V5 (validation ``monitoring.chatter.v5_t4_compensated_hz``):
pin what the compensated detector sees.

T4: Ø10 mm 2-flute, 10 000 rev/min, 2 mm slot, Al7050, modal tables of Aslan Tables 5.3-5.4.
The tool vibrates at the simulated chatter frequency ω_c (≈ 1943 Hz), but the cutting torque's
strongest chatter line is the sideband ω_c + N·Ω (N·Ω = 333.3 Hz, Aslan Eq. 5.25) and it is
only about 1.8-2 × the tooth-passing line. Until decision 1696 the observer, identified on a
torque held over the velocity period, passed that band at 0.43-0.45 of its amplitude and the
compensated ratio stayed below the seed's 1.5 (a known gap, decision 1688); identified on a
torque that changes every CNC sample it passes 0.51-0.66, and the case passes (decisions 1696,
1697).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.validation.cases.monitoring_chatter import (
    TOOLS,
    detect,
    simulate,
    simulated_chatter_hz,
)


def test_v5_tools_table() -> None:
    # decision 1501: T3 has 2 flutes (166.67 Hz tooth passing at 5000 rev/min, digest P9)
    assert TOOLS["T3"][1] * TOOLS["T3"][2] / 60 == pytest.approx(166.67, abs=0.01)
    assert [TOOLS[t][1] for t in ("T1", "T2", "T4")] == [5, 4, 2]


def test_t4_replica_torque_peak_is_a_sideband() -> None:
    d = simulate("T4", 2.0)
    f_rev = 10000.0 / 60
    vib = simulated_chatter_hz(d["truth/tool/vibration_x"], 10000.0)
    tq = simulated_chatter_hz(d["truth/spindle/torque"], 10000.0)
    assert np.mean(d["truth/process/chatter"][-8000:]) > 0.9  # the cut chatters
    assert 1900.0 < vib < 2000.0  # near the 1915/1924 Hz modes (thesis: 1979 Hz)
    # the +N·Ω sideband dominates the torque: of a vibration chatter line within 3 dB of the
    # largest (on the truth spindle, decision 1210, the vibration shows two lines 24 Hz apart,
    # 1919 and 1942 Hz, within 0.6 dB of each other; the torque's peak is the sideband of 1942)
    x = d["truth/tool/vibration_x"][-4096:]
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x))))
    f = np.fft.rfftfreq(len(x), 1e-4)
    band = (f > 1900.0) & (f < 2000.0)
    lines = f[band][spec[band] >= spec[band].max() / math.sqrt(2.0)]
    assert np.min(np.abs(tq / (lines + 2 * f_rev) - 1.0)) < 0.01, (tq, lines)
    # the clean simulated torque itself barely passes the seed's 1.5 (the gap's margin):
    # median 1.94 with straight-line fine interpolation, 2.03 with decision 1682's Hermite (the
    # limit cycle's amplitude moves with the references at the sample level)
    _, ratio = detect(d["truth/spindle/torque"], d["spindle/speed"], 2)
    assert 1.2 < np.median(ratio[-8000:]) < 2.5
