"""The spindle's cutting torque by a conventional disturbance observer, for tooth-period
averages (seed 001 Eq. 2-15 on the spindle; decision 1726).

Yamada's conventional DOB (seed 001 §2.2, Eq. 2-15) takes the motor's disturbance as what the
current's torque does not explain of the motor's acceleration:

    τ̂_cut = K_tS·I_ref − J_eS·Ω̇̂ − τ_fric(Ω),

with Ω̇̂ from a pseudo-differentiation of the encoder's speed. Here Ω̇̂ is the difference of two
consecutive means of the CNC's speed over ``window`` samples (an FIR pseudo-differentiation):
over a tooth period its samples telescope to J_eS·(Ω̄_end − Ω̄_start)/T, the speed at the
period's two ends averaged over ``window`` samples each. The encoder's quantisation, which a
speed from one encoder difference carries whole into each end (0.06 rad/s a count at
2^20 counts/rev and 10 kHz: 0.8 N·m of a 2.5 ms period's mean on the quaser-ux600's
0.032 kg·m²), is divided by the window.

This is not a per-sample torque: the window's mean follows the speed's tooth-frequency ripple
only in part, and no low-pass follows (Eq. 2-15's g_cut): its per-sample noise is large. It is
what the breakage monitor averages per tooth period (decision 1726); the machine file's LQE
observer (Aslan Eq. 5.17-5.21), tuned for the per-sample torque chatter and the adaptive feed
read, keeps that role.
"""

from __future__ import annotations

import math

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.models.friction import CoulombViscous
from millsense.streaming.block import Block, BlockOutput, Chunk

#: The pseudo-differentiation's window (decision 1726): 0.9 ms, 9 samples at 10 kHz. The
#: tooth-period contrasts' noise fell from 0.25 N·m (one encoder difference) to 0.15 (5
#: samples) and 0.08 (9 samples) on the six general cuts; a window of 0.6 of the shortest of
#: their tooth periods (15 samples: 4 flutes at 10 000 rev/min).
WINDOW_S = 0.9e-3
#: The output channel.
DOB_TORQUE = "spindle/dob_torque"


class SpindleDobTorque(Block):
    """``spindle/dob_torque`` (N·m) = K_tS·I_ref − J_eS·Ω̇̂ − τ_fric(Ω): seed 001 Eq. 2-15 on
    the spindle with Ω̇̂ the difference of the last two ``window``-sample means of the speed
    (module notes). The current is delayed by (window − 1)/2 samples to the means' centre,
    and so is the output.

    Parameters
    ----------
    torque_constants : K_tS of speed range 1 and 2, N·m/A.
    switch_rad_s : |speed command| at and above which range 2's K_tS applies, rad/s (inf: one
        range).
    inertia : J_eS, kg·m².
    friction : the spindle's friction subtracted (the observer's, so that both say the
        cutting torque), or None.
    window : samples of each speed mean (odd, ≥ 1; default :data:`WINDOW_S` at the stream's
        rate).
    prefix : reads ``{prefix}/current_cmd`` (A), ``{prefix}/speed`` and ``{prefix}/speed_cmd``
        (rad/s).
    """

    def __init__(
        self,
        torque_constants: tuple[float, float],
        switch_rad_s: float,
        inertia: float,
        friction: CoulombViscous | None = None,
        window: int | None = None,
        prefix: str = "spindle",
        out: str = DOB_TORQUE,
        name: str = "spindle_dob",
    ) -> None:
        kt = tuple(float(k) for k in torque_constants)
        if not (len(kt) == 2 and all(math.isfinite(k) and k > 0 for k in kt)):
            raise ConfigError("spindle DOB: two positive torque constants needed")
        if not (math.isfinite(inertia) and inertia > 0):
            raise ConfigError(f"spindle DOB: inertia must be > 0, got {inertia}")
        if window is not None and not (window >= 1 and window % 2 == 1):
            raise ConfigError(f"spindle DOB: the window must be odd and ≥ 1, got {window}")
        self.kt = kt
        self.switch = float(switch_rad_s)
        self.inertia = float(inertia)
        self.friction = friction
        self.window_given = window
        self.prefix = prefix
        self.out = out
        self.name = name
        self.inputs = (f"{prefix}/current_cmd", f"{prefix}/speed", f"{prefix}/speed_cmd")
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(self.out, "N*m", "spindle cutting torque by a disturbance observer "
                            "(seed 001 Eq. 2-15) for tooth-period averages")]  # fmt: skip

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        m = self.window_given
        if m is None:
            m = max(1, 2 * round((WINDOW_S * self.fs - 1) / 2) + 1)
        self.window = int(m)
        self.delay = (self.window - 1) // 2
        # the last `window` speeds and `delay` currents and speed commands before the chunk
        # (the stream's first sample repeated until there are as many)
        self._w: np.ndarray | None = None
        self._i = np.empty(0)
        self._c = np.empty(0)

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        i = np.asarray(d[self.inputs[0]], dtype=np.float64)
        w = np.asarray(d[self.inputs[1]], dtype=np.float64)
        c = np.asarray(d[self.inputs[2]], dtype=np.float64)
        n, m, h = w.size, self.window, self.delay
        if n == 0:
            return BlockOutput({self.out: np.empty(0)})
        if self._w is None:  # the stream's start: at rest before it, at its first values
            self._w = np.full(m, w[0])
            self._i = np.full(h, i[0])
            self._c = np.full(h, c[0])
        ww = np.concatenate([self._w, w])
        ii = np.concatenate([self._i, i])[:n]  # I_ref delayed by h samples
        cc = np.concatenate([self._c, c])[:n]
        # mean over m samples ending at k minus the one ending at k − 1: (Ω[k] − Ω[k − m])/m
        acc = (ww[m:] - ww[:n]) * (self.fs / m)
        kt = np.where(np.abs(cc) >= self.switch, self.kt[1], self.kt[0])
        tau = kt * ii - self.inertia * acc
        if self.friction is not None:
            # the speed at the window's centre, as the current
            tau -= self.friction.torque(ww[m - h : m - h + n])
        self._w = ww[-m:]
        if h:
            self._i = np.concatenate([self._i, i])[-h:]
            self._c = np.concatenate([self._c, c])[-h:]
        return BlockOutput({self.out: tau})
