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
only in part, and no low-pass follows (Eq. 2-15's g_cut): its per-sample noise is large. A
session's breakage monitor averages it per tooth period (decision 1726; by default since
decision 1727 told a chatter onset, which grows, from a break, which steps; ``--breakage-torque
observer`` averages the LQE observer's instead); the machine file's LQE observer (Aslan
Eq. 5.17-5.21), tuned for the per-sample torque chatter and the adaptive feed read, keeps every
other role.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.models.friction import CoulombViscous, coulomb_viscous_torque
from millsense.streaming.block import Block, BlockOutput, Chunk

#: The pseudo-differentiation's window (decision 1726): 0.9 ms, 9 samples at 10 kHz. The
#: tooth-period contrasts' robust scatter on the six general cuts was 0.25-0.75 N·m with one
#: encoder difference, 0.10-0.23 with 5 samples and 0.075-0.13 with 9 (0.11-0.39 on the LQE
#: observer's torque); 0.6 of the shortest of their tooth periods (15 samples: 4 flutes at
#: 10 000 rev/min).
WINDOW_S = 0.9e-3
#: The output channel.
DOB_TORQUE = "spindle/dob_torque"


#: :func:`dob_kernel`'s state: [started, position in the speed ring, in the current ring],
#: then the rings: ``window`` speeds, then ``delay`` currents and ``delay`` speed commands.
DOB_STARTED, DOB_POS_W, DOB_POS_I, DOB_RINGS = 0, 1, 2, 3


@numba.njit(cache=True)
def dob_kernel(
    current: NDArray[np.float64],
    speed: NDArray[np.float64],
    speed_cmd: NDArray[np.float64],
    state: NDArray[np.float64],
    m: int,
    params: NDArray[np.float64],
    friction: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """One chunk of :class:`SpindleDobTorque` (seed 001 Eq. 2-15): ``out[k]`` = K_tS·I[k − h]
    − J·(Ω[k] − Ω[k − m])·f_s/m − τ_fric(Ω[k − h]), h = (m − 1)/2, K_tS of range 2 where
    |Ω_cmd[k − h]| ≥ the switch speed. ``params`` = [K_t1, K_t2, switch rad/s, J, f_s];
    ``friction`` = :meth:`~millsense.models.friction.CoulombViscous.as_array` (empty: none).
    Before the stream's first sample the rings hold its first values (at rest before it)."""
    h = (m - 1) // 2
    ring_w = DOB_RINGS
    ring_i = ring_w + m
    ring_c = ring_i + h
    kt1, kt2, switch, inertia, fs = params[0], params[1], params[2], params[3], params[4]
    if current.shape[0] and state[DOB_STARTED] == 0.0:
        state[ring_w : ring_w + m] = speed[0]
        state[ring_i : ring_i + h] = current[0]
        state[ring_c : ring_c + h] = speed_cmd[0]
        state[DOB_STARTED] = 1.0
    pw = int(state[DOB_POS_W])
    pi = int(state[DOB_POS_I])
    has_friction = friction.shape[0] > 0
    for k in range(current.shape[0]):
        w_old = state[ring_w + pw]  # Ω[k − m]
        state[ring_w + pw] = speed[k]
        w_mid = state[ring_w + (pw - h) % m]  # Ω[k − h]
        pw = (pw + 1) % m
        if h > 0:
            i_del = state[ring_i + pi]
            c_del = state[ring_c + pi]
            state[ring_i + pi] = current[k]
            state[ring_c + pi] = speed_cmd[k]
            pi = (pi + 1) % h
        else:
            i_del = current[k]
            c_del = speed_cmd[k]
        kt = kt2 if abs(c_del) >= switch else kt1
        tau = kt * i_del - inertia * (speed[k] - w_old) * (fs / m)
        if has_friction:
            tau -= coulomb_viscous_torque(w_mid, friction)
        out[k] = tau
    state[DOB_POS_W] = pw
    state[DOB_POS_I] = pi


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
    encoder_counts_rev : the spindle encoder's counts per revolution, where known: the speed
        channel's resolution, whence :meth:`mean_resolution_nms`.
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
        encoder_counts_rev: int | None = None,
    ) -> None:
        kt = tuple(float(k) for k in torque_constants)
        if not (len(kt) == 2 and all(math.isfinite(k) and k > 0 for k in kt)):
            raise ConfigError("spindle DOB: two positive torque constants needed")
        if not (math.isfinite(inertia) and inertia > 0):
            raise ConfigError(f"spindle DOB: inertia must be > 0, got {inertia}")
        if window is not None and not (window >= 1 and window % 2 == 1):
            raise ConfigError(f"spindle DOB: the window must be odd and ≥ 1, got {window}")
        if encoder_counts_rev is not None and not encoder_counts_rev >= 1:
            raise ConfigError(f"spindle DOB: encoder counts must be ≥ 1, got {encoder_counts_rev}")
        self.encoder_counts_rev = encoder_counts_rev
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

    def _window(self, sample_rate_hz: float) -> int:
        m = self.window_given
        if m is None:
            m = max(1, 2 * round((WINDOW_S * sample_rate_hz - 1) / 2) + 1)
        return int(m)

    def mean_resolution_nms(self, sample_rate_hz: float) -> float:
        """The resolution of the output's mean over a span T, times T (N·m·s; 0 where the
        encoder's counts are not known): the inertial term's mean telescopes to J·(Ω̄_end −
        Ω̄_start)/T (module notes), and a window's mean speed Ω̄ moves in steps of one encoder
        count over the window, 2π/(counts·m/f_s), so the mean moves in steps of
        J·2π·f_s/(counts·m)/T (decision 1732). A step holds while the speed holds the encoder's
        phase at that end: on a tooth period it is no white noise that averages away."""
        if self.encoder_counts_rev is None:
            return 0.0
        m = self._window(sample_rate_hz)
        return self.inertia * 2.0 * math.pi * sample_rate_hz / (self.encoder_counts_rev * m)

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        self.window = self._window(self.fs)
        self.delay = (self.window - 1) // 2
        self._state = np.zeros(DOB_RINGS + self.window + 2 * self.delay)
        self._params = np.array([*self.kt, self.switch, self.inertia, self.fs])
        self._friction = self.friction.as_array() if self.friction is not None else np.empty(0)

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        i = np.ascontiguousarray(d[self.inputs[0]], dtype=np.float64)
        out = np.empty(i.size)
        # the rings, the range's K_tS and the friction in one compiled loop
        dob_kernel(i, np.ascontiguousarray(d[self.inputs[1]], dtype=np.float64),
                   np.ascontiguousarray(d[self.inputs[2]], dtype=np.float64), self._state,
                   self.window, self._params, self._friction, out)  # fmt: skip
        return BlockOutput({self.out: out})
