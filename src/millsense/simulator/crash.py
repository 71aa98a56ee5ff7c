"""Crash events of the virtual machine: what a real machine would not survive.

The simulator evaluates the cutting model whatever the input, so without a check it reports a
30 MN force or a cut with the spindle stopped without a word. :class:`CrashMonitor` watches the
coupled blocks and raises an :class:`~millsense.streaming.block.Event` of kind ``crash``
(decision 0942 "Machine limits and crash events") when

- the tool engages the stock (engagement and depth > 0) with the spindle slower than
  :data:`millsense.core.plausibility.SPINDLE_STOPPED_RPM` (``spindle_stopped``, value rev/min);
- the load on a linear feed axis exceeds the machine's ``limits.axis_force_n``
  (``axis_force``, value N, the peak of the block);
- the mean cutting power of a block (torque × spindle speed) exceeds ``limits.spindle_power_kw``
  (``spindle_power``, value W).

One event per condition when it starts, re-armed only once the condition has been clear for
:data:`REARM_S` (the mean torque of a short block swings with every tooth pass), so a crash
that lasts is one event, not one per block or tooth. The simulation goes on (the recording
shows what the model predicts beyond the limit); stopping is the caller's choice.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from millsense.core.config import MachineConfig
from millsense.core.plausibility import SPINDLE_STOPPED_RPM
from millsense.simulator.fast_block import peak_abs
from millsense.streaming.block import Event, EventKind, Severity

FloatArray = NDArray[np.float64]

#: A condition must have been clear this long before it raises a new event, s.
REARM_S = 0.5


class CrashMonitor:
    """Crash conditions of one simulated machine, checked block by block.

    Parameters
    ----------
    machine : the machine (its ``limits``; axes of kind ``linear`` carry forces in N).
    axes : the simulated axes, in the order of the load columns.
    """

    source = "virtual machine"

    def __init__(self, machine: MachineConfig, axes: tuple[str, ...]) -> None:
        lim = machine.limits
        self.force_limit_n = None if lim is None else lim.axis_force_n
        self.power_limit_w = (
            None if lim is None or lim.spindle_power_kw is None else lim.spindle_power_kw * 1e3
        )
        self.linear = np.array([machine.axes[a].kind == "linear" for a in axes], dtype=bool)
        self.axes = axes
        self._any_linear = bool(self.linear.any())
        self._linear_axes = [a for a, m in zip(axes, self.linear, strict=True) if m]
        self._last_on: dict[str, float] = {}  # time each condition was last seen, s
        self.events: list[Event] = []

    def _raise(self, name: str, on: bool, time_s: float, value: float, message: str) -> None:
        if not on:
            return
        last = self._last_on.get(name)
        if last is None or time_s - last > REARM_S:
            self.events.append(
                Event(
                    time_s,
                    EventKind.CRASH,
                    self.source,
                    message,
                    name=name,
                    value=value,
                    severity=Severity.CRITICAL,
                )
            )
        self._last_on[name] = time_s

    def check(
        self,
        t: FloatArray,
        engaged: NDArray[np.bool_],
        omega_rad_s: float,
        loads: FloatArray,
        torque_nm: FloatArray,
    ) -> None:
        """One block: sample times (s), engagement mask, spindle speed (rad/s, the block's),
        axis loads (n, n_axes) in N or N·m, cutting torque (n,) in N·m."""
        rpm = abs(omega_rad_s) * 60.0 / (2.0 * math.pi)
        stopped = bool(engaged.any()) and rpm < SPINDLE_STOPPED_RPM
        k = int(np.argmax(engaged)) if stopped else 0
        self._raise(
            "spindle_stopped",
            stopped,
            float(t[k]),
            rpm,
            f"crash at {t[k]:.4f} s: the tool engages the stock with the spindle stopped "
            f"({rpm:.3g} rev/min)",
        )
        if self.force_limit_n is not None and self.linear.any():
            lin = np.abs(loads[:, self.linear])
            peak = float(lin.max()) if lin.size else 0.0
            over = peak > self.force_limit_n
            if over:
                i, j = np.unravel_index(int(np.argmax(lin)), lin.shape)
                axis = [a for a, m in zip(self.axes, self.linear, strict=True) if m][int(j)]
                msg = (
                    f"crash at {t[int(i)]:.4f} s: {peak:.4g} N on axis {axis}, beyond the "
                    f"machine's axis_force_n {self.force_limit_n:g} N"
                )
                self._raise("axis_force", True, float(t[int(i)]), peak, msg)
        if self.power_limit_w is not None:
            power = float(np.mean(torque_nm)) * abs(omega_rad_s)
            over = power > self.power_limit_w
            self._raise(
                "spindle_power",
                over,
                float(t[0]),
                power,
                f"crash at {t[0]:.4f} s: cutting power {power / 1e3:.4g} kW beyond the "
                f"machine's spindle_power_kw {self.power_limit_w / 1e3:g} kW",
            )

    def check_block(
        self,
        t: FloatArray,
        engagement_index: NDArray[np.int64],
        depth_m: FloatArray,
        omega_rad_s: float,
        loads: FloatArray,
        torque_nm: FloatArray,
        mean_torque_nm: float | None = None,
    ) -> None:
        """:meth:`check` with the peak load found by a compiled scan and the engagement mask
        (``engagement_index ≥ 0`` and ``depth_m > 0``) formed only with the spindle stopped
        (the simulator's block loop, decision 1081): the same events without the per-block
        temporaries; ``mean_torque_nm``: the block's mean torque when the caller has it)."""
        rpm = abs(omega_rad_s) * 60.0 / (2.0 * math.pi)
        engaged = (engagement_index >= 0) & (depth_m > 0) if rpm < SPINDLE_STOPPED_RPM else None
        if engaged is not None and engaged.any():
            k = int(np.argmax(engaged))
            self._raise(
                "spindle_stopped",
                True,
                float(t[k]),
                rpm,
                f"crash at {t[k]:.4f} s: the tool engages the stock with the spindle stopped "
                f"({rpm:.3g} rev/min)",
            )
        if self.force_limit_n is not None and self._any_linear:
            peak, i, j = peak_abs(loads, self.linear)
            if peak > self.force_limit_n:
                axis = self._linear_axes[j]
                msg = (
                    f"crash at {t[i]:.4f} s: {peak:.4g} N on axis {axis}, beyond the "
                    f"machine's axis_force_n {self.force_limit_n:g} N"
                )
                self._raise("axis_force", True, float(t[i]), peak, msg)
        if self.power_limit_w is not None:
            mean = float(np.mean(torque_nm)) if mean_torque_nm is None else mean_torque_nm
            power = mean * abs(omega_rad_s)
            if power > self.power_limit_w:
                self._raise(
                    "spindle_power",
                    True,
                    float(t[0]),
                    power,
                    f"crash at {t[0]:.4f} s: cutting power {power / 1e3:.4g} kW beyond the "
                    f"machine's spindle_power_kw {self.power_limit_w / 1e3:g} kW",
                )

    def take_events(self) -> list[Event]:
        """The events raised since the last call (removed from the queue)."""
        out, self.events = self.events, []
        return out
