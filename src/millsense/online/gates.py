"""Gates of the on-line session: when the controllers may trust what they regulate.

:class:`SpindleAtSpeed` is 1 where the spindle has run within ``tolerance`` of its commanded
speed for ``settle_s``: while it runs up or changes speed, a spindle torque observer's
estimate carries the acceleration torque its model does not match exactly (tens of N·m on the
virtual machine's run-up against a cutting torque of a few), so the adaptive feed control
holds its override instead of acting on it (decision 1622).
"""

from __future__ import annotations

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk


class SpindleAtSpeed(Block):
    """``spindle/at_speed``: 1 after ``settle_s`` within ``tolerance`` of the command."""

    def __init__(
        self,
        speed_channel: str = "spindle/speed",
        command_channel: str = "spindle/speed_cmd",
        tolerance: float = 0.03,
        settle_s: float = 0.1,
        name: str = "spindle_gate",
    ) -> None:
        if not (0 < tolerance < 1 and settle_s >= 0):
            raise ConfigError("spindle gate: 0 < tolerance < 1 and settle_s ≥ 0 needed")
        self.inputs = (speed_channel, command_channel)
        self.tolerance = float(tolerance)
        self.settle_s = float(settle_s)
        self.name = name
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo("spindle/at_speed", "1", "1: spindle settled at its commanded speed")]

    def reset(self, sample_rate_hz: float) -> None:
        self.n_settle = round(self.settle_s * sample_rate_hz)
        self._run = 0

    def process(self, chunk: Chunk) -> BlockOutput:
        w = np.asarray(chunk.data[self.inputs[0]], dtype=np.float64)
        cmd = np.asarray(chunk.data[self.inputs[1]], dtype=np.float64)
        ok = (np.abs(cmd) > 0) & (np.abs(w - cmd) <= self.tolerance * np.abs(cmd))
        n = ok.size
        if n == 0:
            return BlockOutput({"spindle/at_speed": np.zeros(0)})
        idx = np.arange(1, n + 1)
        last_bad = np.maximum.accumulate(np.where(~ok, idx, 0))
        run = np.where(last_bad == 0, self._run + idx, idx - last_bad)
        self._run = int(run[-1])
        return BlockOutput({"spindle/at_speed": (run > self.n_settle).astype(np.float64)})
