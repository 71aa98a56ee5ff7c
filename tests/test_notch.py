"""Predictive notch bank (Yamada C10, Table 4-5)."""

from __future__ import annotations

import numpy as np

from millsense.estimation.dob.notch import (
    NotchBank,
    NotchBankSpec,
    NotchBlock,
    encoder_notch_frequencies,
)
from millsense.streaming.block import Chunk

FS = 10000.0
LAM = 5e-3 / 512.0  # rotary encoder signal period in travel (Yamada §2.8)


def test_notch_frequencies_closed_form() -> None:
    # 2000 min⁻¹, f_z 0.03 mm, 2 flutes → 2 mm/s; f_k = k·v/λ = k·204.8 Hz (Table 4-5: 204.7)
    f = encoder_notch_frequencies([2e-3], LAM, (1, 2, 3))[0]
    assert np.allclose(f, [204.8, 409.6, 614.4], rtol=1e-12)


def _ramp(n: int, v: float) -> np.ndarray:
    return v * np.arange(n) / FS


def test_tracked_notch_removes_the_encoder_component() -> None:
    # at 2 mm/s the k = 1 notch sits at 204.8 Hz: a sine there is removed (< 1 % after the
    # transient), a 60 Hz sine passes (gain within 1 %)
    n = 20000
    t = np.arange(n) / FS
    pos = _ramp(n, 2e-3)
    bank = NotchBank(NotchBankSpec(LAM, harmonics=(1,), bandwidth_hz=10.0), FS)
    y = bank.process(np.sin(2 * np.pi * 204.8 * t), pos)
    assert np.max(np.abs(y[-2000:])) < 0.01
    bank.reset()
    y2 = bank.process(np.sin(2 * np.pi * 60.0 * t), pos)
    assert abs(np.max(np.abs(y2[-2000:])) - 1.0) < 0.01


def test_notch_follows_the_speed() -> None:
    # speed doubles to 4 mm/s: the notch moves to 409.6 Hz and removes that component
    n = 30000
    t = np.arange(n) / FS
    v = np.where(t < 1.0, 2e-3, 4e-3)
    pos = np.cumsum(v) / FS
    x = np.where(t < 1.0, np.sin(2 * np.pi * 204.8 * t), np.sin(2 * np.pi * 409.6 * t))
    y = NotchBank(NotchBankSpec(LAM, harmonics=(1,), bandwidth_hz=10.0), FS).process(x, pos)
    assert np.max(np.abs(y[-2000:])) < 0.01


def test_fixed_torsional_notch() -> None:
    # the 778.5 Hz screw torsional mode (Yamada §3.4) is notched whatever the speed
    n = 10000
    t = np.arange(n) / FS
    spec = NotchBankSpec(LAM, harmonics=(), fixed_hz=(778.5,), bandwidth_hz=10.0)
    y = NotchBank(spec, FS).process(np.sin(2 * np.pi * 778.5 * t), np.zeros(n))
    assert np.max(np.abs(y[-1000:])) < 0.01


def test_notch_block_chunk_invariant() -> None:
    # Block contract: any chunking gives the same output (state carried in the kernel)
    n = 500
    rng = np.random.default_rng(3)
    data = {
        "x/force_medob": rng.standard_normal(n),
        "x/motor_angle": np.cumsum(np.full(n, 2e-3 / FS / (5e-3 / (2 * np.pi)))),
    }
    spec = NotchBankSpec(LAM, fixed_hz=(778.5,))
    outs = []
    for size in (n, 13, 1):
        b = NotchBlock("x", "force_medob", spec, 5e-3 / (2 * np.pi))
        b.reset(FS)
        res = [
            b.process(Chunk(k, FS, 0.0, {c: v[k : k + size] for c, v in data.items()}))
            for k in range(0, n, size)
        ]
        outs.append(np.concatenate([r.channels["x/force_medob_notched"] for r in res]))
    assert np.array_equal(outs[0], outs[1]) and np.array_equal(outs[0], outs[2])
