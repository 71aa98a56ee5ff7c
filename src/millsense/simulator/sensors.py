"""Sensors of the virtual machine beyond the drives' own (encoders, currents, linear scales).

The feed drives (:mod:`.feed_drive`) already produce the CNC's current command, actual current
(with the white torque noise of Aslan Eq. 3.30, ``current_noise_a`` of the preset), encoder
angle and speed and the linear scale. This module adds the optional external sensors and the
measurement noise of the spindle current, each from its own seeded generator:

- accelerometer: structural acceleration of the tool (regenerative tool modes) plus the
  acceleration of the table along the same machine axes, plus white noise;
- microphone: the accelerometer sum through a second-order band-pass (50 Hz – 13 kHz, the
  band of Munasinghe's microphone, limited to 0.45·f_s) scaled to pascals, plus white noise;
- spindle current: white measurement noise (no seed gives a level; decision "Spindle current
  noise": 0.05 A RMS, ≈ 0.07 N·m at K_tS = 1.343 N·m/A, a quarter of the X drive's air-cut
  torque RMS √R of Aslan Eq. 3.30).

Everything is causal and keeps its filter state between blocks (``scipy.signal.lfilter``
with ``zi``), so the outputs do not depend on the chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from millsense.core.errors import ConfigError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SensorOptions:
    """Which optional sensors to simulate and their noise.

    Attributes
    ----------
    accelerometer : simulate ``accel/x``, ``accel/y`` (m/s²).
    microphone : simulate ``mic/pressure`` (Pa).
    accel_noise_m_s2 : RMS white noise of the accelerometer per sample, m/s².
    mic_noise_pa : RMS white noise of the microphone per sample, Pa.
    mic_gain_pa_per_m_s2 : pressure per unit structural acceleration, Pa/(m/s²).
    mic_band_hz : band-pass corners, Hz (the upper one is limited to 0.45·f_s).
    spindle_current_noise_a : RMS measurement noise on the spindle currents, A.
    """

    accelerometer: bool = False
    microphone: bool = False
    accel_noise_m_s2: float = 0.05
    mic_noise_pa: float = 0.002
    mic_gain_pa_per_m_s2: float = 0.01
    mic_band_hz: tuple[float, float] = (50.0, 13000.0)
    spindle_current_noise_a: float = 0.05

    def __post_init__(self) -> None:
        for name in ("accel_noise_m_s2", "mic_noise_pa", "spindle_current_noise_a"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"sensors: {name} must be ≥ 0, got {getattr(self, name)!r}")
        lo, hi = self.mic_band_hz
        if not 0 < lo < hi:
            raise ConfigError(
                f"sensors: mic_band_hz must be 0 < low < high, got {self.mic_band_hz}"
            )


class SensorBank:
    """Stateful external sensors (resumable: block by block equals one call).

    Parameters
    ----------
    options : which sensors and their noise.
    sample_rate_hz : sample rate, Hz.
    rng : generator of this bank (spawned from the simulator's seed).
    """

    def __init__(
        self, options: SensorOptions, sample_rate_hz: float, rng: np.random.Generator
    ) -> None:
        self.options = options
        self.fs = sample_rate_hz
        self._rng = rng
        lo, hi = options.mic_band_hz
        hi = min(hi, 0.45 * sample_rate_hz)
        if not lo < hi:
            raise ConfigError(
                f"sensors: microphone band {options.mic_band_hz} Hz is empty at {sample_rate_hz} Hz"
            )
        self._b, self._a = scipy.signal.butter(1, [lo, hi], btype="bandpass", fs=sample_rate_hz)
        self._zi = np.zeros(max(len(self._a), len(self._b)) - 1)

    def measure(
        self,
        tool_acc_xy: FloatArray,
        table_acc_xy: FloatArray,
        spindle_currents: tuple[FloatArray, FloatArray],
    ) -> dict[str, FloatArray]:
        """Sensor channels of one block.

        Parameters
        ----------
        tool_acc_xy : (n, 2) tool structural acceleration along machine x, y, m/s².
        table_acc_xy : (n, 2) table (feed-drive load) acceleration along x, y, m/s².
        spindle_currents : (command, actual) spindle currents, A.
        """
        n = len(tool_acc_xy)
        o = self.options
        # one draw per sample and kind in a fixed order keeps the stream chunk-invariant
        noise = self._rng.standard_normal((n, 5))
        out: dict[str, FloatArray] = {
            "spindle/current_cmd": spindle_currents[0] + o.spindle_current_noise_a * noise[:, 0],
            "spindle/current": spindle_currents[1] + o.spindle_current_noise_a * noise[:, 1],
        }
        structural = tool_acc_xy + table_acc_xy
        if o.accelerometer:
            out["accel/x"] = structural[:, 0] + o.accel_noise_m_s2 * noise[:, 2]
            out["accel/y"] = structural[:, 1] + o.accel_noise_m_s2 * noise[:, 3]
        if o.microphone:
            y, self._zi = scipy.signal.lfilter(
                self._b, self._a, structural[:, 0] + structural[:, 1], zi=self._zi
            )
            out["mic/pressure"] = o.mic_gain_pa_per_m_s2 * y + o.mic_noise_pa * noise[:, 4]
        return out
