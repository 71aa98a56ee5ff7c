"""The CNC's commanded motion of an axis, from its command channels only.

Decisions that depend on how an axis moves (the idle table's direction of motion, the moving or
at-rest model) read the interpolator's command, never the measured or true motion: a loaded axis
at rest trembles by a few encoder counts, a command is exact (decision "Holding axis: Φ_d and R
identified at rest").
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError
from millsense.core.recording import Recording


def velocity_source(axis: str) -> str:
    """Channel giving the commanded velocity of ``axis``: its position command (differenced)
    or, for the spindle, the speed reference."""
    return "spindle/speed_cmd" if axis == "spindle" else f"{axis}/position_cmd"


def commanded_velocity(rec: Recording, axis: str, where: str) -> np.ndarray:
    """Commanded velocity of ``axis`` per sample of a recording (m/s, rad/s).

    Raises
    ------
    InputDataError naming the missing channel.
    """
    ch = velocity_source(axis)
    if ch not in rec:
        raise InputDataError(f"{where}: no channel '{ch}' (the commanded velocity of {axis})")
    stream = CommandedVelocity(axis)
    stream.reset(rec.sample_rate_hz)
    return stream(np.asarray(rec.channel(ch), dtype=float))


class CommandedVelocity:
    """Streaming commanded velocity of an axis: ``Δx_cmd·f_s`` of its position command (the
    spindle's speed reference as it is), the last sample carried across chunks so that the
    result does not depend on the chunking; the first sample of a stream reads 0 (the axis
    stood at its first command before it)."""

    def __init__(self, axis: str) -> None:
        self.axis = axis
        self.channel = velocity_source(axis)
        self._prev: float | None = None
        self._fs = 0.0

    def reset(self, sample_rate_hz: float) -> None:
        self._fs = float(sample_rate_hz)
        self._prev = None

    def __call__(self, command: np.ndarray) -> np.ndarray:
        x = np.asarray(command, dtype=float)
        if self.axis == "spindle":
            return x
        if len(x) == 0:
            return np.zeros(0)
        prev = x[0] if self._prev is None else self._prev
        self._prev = float(x[-1])
        out = np.empty(len(x))
        difference_into(np.ascontiguousarray(x), prev, self._fs, out)
        return out


@numba.njit(cache=True)
def difference_into(
    x: NDArray[np.float64], prev: float, fs: float, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """``out[k] = (x[k] − x[k−1])·f_s`` with ``x[−1] = prev`` (the sample before the chunk):
    the commanded velocity of :class:`CommandedVelocity`, callable from compiled code."""
    for k in range(x.shape[0]):
        out[k] = (x[k] - prev) * fs
        prev = x[k]
