"""Spindle-torque streams for the breakage acceptance runs (process model + observer noise).

The cutting torque comes from the process model of the virtual machine
(:class:`~millsense.simulator.process_coupling.ProcessCoupling`: mechanistic forces with the
chip a broken flute leaves to the next one, depth steps, air cuts) evaluated at the spindle
angle Ω t. What the monitor sees is that torque as the spindle observer delivers it (Aslan
ch. 5: an LQE estimate with a bandwidth of a few hundred Hz and a noise floor): low-pass
filtered (2nd order, 400 Hz), plus white noise, a slow offset drift and a once-per-revolution
ripple (bearing/cogging) — the "realistic noise" of the brief.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from millsense.core.config import MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.process_coupling import EngagementSource, ProcessCoupling, ProcessEvent

FloatArray = NDArray[np.float64]
FS = 10000.0


@dataclass(frozen=True)
class TorqueNoise:
    """Observer-like noise on the cutting torque (N·m, Hz)."""

    white_nm: float = 0.08
    drift_nm: float = 0.05
    ripple_nm: float = 0.05
    bandwidth_hz: float = 400.0


def aslan_tool_and_coeffs() -> tuple[EndMill, CuttingCoefficients]:
    """Seed 000's Ø20 mm 2-flute 30° helix end mill and the Al7050 coefficients."""
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    return tool, coeffs


def observed_torque(
    torque_nm: FloatArray, t_s: FloatArray, omega_rad_s: float, noise: TorqueNoise, seed: int
) -> FloatArray:
    """The cutting torque as the spindle observer reports it (module notes)."""
    rng = np.random.default_rng(seed)
    sos = signal.butter(2, noise.bandwidth_hz, fs=FS, output="sos")
    out = signal.sosfilt(sos, torque_nm)
    out = out + noise.white_nm * rng.standard_normal(len(t_s))
    out = out + noise.drift_nm * np.sin(2 * math.pi * 0.05 * t_s + rng.uniform(0, 2 * math.pi))
    out = out + noise.ripple_nm * np.sin(omega_rad_s * t_s + 0.3)
    return np.asarray(out, dtype=np.float64)


def simulate_torque(
    source: EngagementSource,
    s_of_t: FloatArray,
    t_s: FloatArray,
    rpm: float,
    feed_m_s: FloatArray,
    events: tuple[ProcessEvent, ...] = (),
    tool: EndMill | None = None,
    coeffs: CuttingCoefficients | None = None,
    noise: TorqueNoise | None = None,
    seed: int = 0,
    block: int = 20000,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """True cutting torque, observed torque (N·m) and true force on the tool (n, 3; feed,
    normal, axis; N) at times ``t_s`` along arc length ``s_of_t`` at constant ``rpm``."""
    if tool is None or coeffs is None:
        tool, coeffs = aslan_tool_and_coeffs()
    pc = ProcessCoupling(tool, coeffs, source, events=events, n_discs=8, sample_rate_hz=FS)
    omega = rpm * 2 * math.pi / 60.0
    true = np.zeros(len(t_s))
    force = np.zeros((len(t_s), 3))
    for i in range(0, len(t_s), block):
        sl = slice(i, i + block)
        tt = t_s[sl]
        po = pc.evaluate(
            tt, s_of_t[sl], omega * tt, np.full(len(tt), omega), np.asarray(feed_m_s)[sl]
        )
        true[sl] = po.torque
        force[sl] = po.force
    obs = observed_torque(true, t_s, omega, noise or TorqueNoise(), seed)
    return true, obs, force
