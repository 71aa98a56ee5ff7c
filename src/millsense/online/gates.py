"""Gates of the on-line session: when the controllers may trust what they regulate.

:class:`SpindleAtSpeed` is 1 where the spindle has run within ``tolerance`` of its commanded
speed for ``settle_s``: while it runs up or changes speed, a spindle torque observer's
estimate carries the acceleration torque its model does not match exactly (tens of N·m on the
virtual machine's run-up against a cutting torque of a few), so the adaptive feed control
holds its override instead of acting on it (decisions 1622, 1662).
"""

from __future__ import annotations

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.online._sync_kernels import (
    CUT_GATE_STATE,
    CUT_LOWEST,
    CUT_PREMISE_SAMPLES,
    air_reference_kernel,
    at_speed_kernel,
    torque_cut_gate_kernel,
)
from millsense.streaming.block import Block, BlockOutput, Chunk

#: Largest relative change of the speed command from one sample to the next that counts as a
#: command standing still (decision 1662).
STILL = 1e-6


class SpindleAtSpeed(Block):
    """``spindle/at_speed``: 1 after ``settle_s`` within ``tolerance`` of the command, with the
    command standing still.

    A CNC's speed-command channel may be the drive's ramp setpoint rather than the programmed
    speed: the measured speed then follows it within a few per cent all through a run-up or a
    speed change, while the observer's estimate still carries the acceleration torque (85 N·m
    through the T1 pass's run-up to 4500 rev/min on the virtual machine, where the gate opened at
    3834 rev/min). So a sample counts only where the command equals the previous sample's within
    ``STILL`` of its value (a ramp of 100 rad/s² moves it 2·10⁻⁵ per sample at 4500 rev/min); a
    step (an override) restarts the settling as well (decision 1662).

    With ``fault_channel`` (the source guard's ``guard/fault``) the gate is also closed where
    the guard marks a fault and for ``settle_s`` after it: held, filled or frozen samples are
    not the process, and the blocks the gate enables (the air reference, the plan's judged
    torque and calibration, the adaptive feed, the breakage monitor) must not take them for it
    (decision 1559).
    """

    def __init__(
        self,
        speed_channel: str = "spindle/speed",
        command_channel: str = "spindle/speed_cmd",
        tolerance: float = 0.03,
        settle_s: float = 0.1,
        name: str = "spindle_gate",
        fault_channel: str | None = None,
    ) -> None:
        if not (0 < tolerance < 1 and settle_s >= 0):
            raise ConfigError("spindle gate: 0 < tolerance < 1 and settle_s ≥ 0 needed")
        self.fault_channel = fault_channel
        self.inputs = (speed_channel, command_channel) + (
            (fault_channel,) if fault_channel is not None else ()
        )
        self.tolerance = float(tolerance)
        self.settle_s = float(settle_s)
        self.name = name
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo("spindle/at_speed", "1", "1: spindle settled at its commanded speed")]

    def reset(self, sample_rate_hz: float) -> None:
        self.n_settle = round(self.settle_s * sample_rate_hz)
        self._state = np.array([np.nan, 0.0])  # previous command, run of ok samples

    def process(self, chunk: Chunk) -> BlockOutput:
        w = np.ascontiguousarray(chunk.data[self.inputs[0]], dtype=np.float64)
        cmd = np.ascontiguousarray(chunk.data[self.inputs[1]], dtype=np.float64)
        out = np.empty(cmd.size)
        fault = (
            np.ascontiguousarray(chunk.data[self.fault_channel], dtype=np.float64)
            if self.fault_channel is not None
            else np.zeros(cmd.size)
        )
        # [previous command, run of ok samples], one compiled loop (decision 1653)
        at_speed_kernel(w, cmd, fault, self._state, self.tolerance, STILL, self.n_settle, out)
        return BlockOutput({"spindle/at_speed": out})


class AirReference(Block):
    """The air-cut reference of the spindle torque, learned on line and subtracted.

    A spindle observer's estimate in air is not zero: the friction of the machine file (a
    nameplate viscous term, an identified Coulomb term) differs from the machine's, by about
    1 N·m at 1000 rev/min on the virtual quaser-ux600 — a quarter of a light cut's torque. Seed
    004 ch. 3 subtracts an air-cut reference before it judges contact; the session does the
    same for everything that reads the torque (decision 1622): while the plan has said "not in
    cut" for ``settle_s`` and the spindle is settled at speed, the reference follows the
    estimate with a first-order average of time constant ``tau_s``; in cut it is held.
    ``{out}`` = torque − reference. A speed change re-learns it at the new speed (the gate
    closes while the spindle changes speed, and the average then follows the new level).

    The average starts, at the stream's start and again after the spindle was off speed (its
    air torque then belongs to another speed), as the running mean of the first ``tau_s`` of
    used samples (the k-th with weight 1/k, then α). Started from one sample, it carried that
    sample's noise (σ ≈ 2 N·m for the commissioned quaser-ux600 observer at 1000 rev/min) for
    a second after the gate opened: the adaptive feed read it as a 150 W cut in air and
    toggled its override between its limits (decision 1555).
    """

    def __init__(
        self,
        torque_channel: str,
        in_cut_channel: str = "plan/in_cut",
        at_speed_channel: str = "spindle/at_speed",
        out: str = "spindle/cutting_torque",
        tau_s: float = 0.3,
        settle_s: float = 0.2,
        name: str = "air_reference",
    ) -> None:
        if not (tau_s > 0 and settle_s >= 0):
            raise ConfigError("air reference: tau_s > 0 and settle_s ≥ 0 needed")
        self.inputs = (torque_channel, in_cut_channel, at_speed_channel)
        self.out = out
        self.tau_s = float(tau_s)
        self.settle_s = float(settle_s)
        self.name = name
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [
            ChannelInfo(self.out, "N*m", "spindle torque less the air-cut reference"),
            ChannelInfo(f"{self.name}/torque", "N*m", "air-cut reference (learned in air)"),
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self.alpha = 1.0 - float(np.exp(-1.0 / (self.tau_s * sample_rate_hz)))
        self.n_settle = round(self.settle_s * sample_rate_hz)
        self.n_start = max(1, round(self.tau_s * sample_rate_hz))  # running mean's length
        self._state = np.zeros(3)  # reference, samples used (up to n_start), run in air

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        return BlockOutput(self.run(d[self.inputs[0]], d[self.inputs[1]], d[self.inputs[2]]))

    def run(
        self, torque: np.ndarray, in_cut: np.ndarray, at_speed: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The outputs of one chunk of the three input channels (what :meth:`process` gives;
        :class:`~millsense.online.plan_sync.PlanSync` calls it with its own in-cut flag)."""
        tq = np.ascontiguousarray(torque, dtype=np.float64)
        n = tq.size
        out = np.empty((2, n))
        # [reference, samples used, run in air], one compiled loop (decisions 1653, 1555)
        air_reference_kernel(tq, np.ascontiguousarray(in_cut, dtype=np.float64),
                             np.ascontiguousarray(at_speed, dtype=np.float64), self._state,
                             self.alpha, self.n_settle, self.n_start, out[0],
                             out[1])  # fmt: skip
        return {self.out: out[0], f"{self.name}/torque": out[1]}


class TorqueCutGate(Block):
    """``out`` = 1 where the torque itself says the tool is in a steady cut (decision 1706):
    what the plan-free breakage detectors (seed 002's dual residuals, the constant reference)
    learn and judge on in a recording without a plan.

    Seed 002 learns its thresholds, 2·max|ε| over the first 5 revolutions, on the premise that
    these are cut. A recording that starts with the spindle's run-up starts in the air: learnt
    there (0.22 N·m on the example data's observer torque) the thresholds are the air's noise,
    and the cut's entry (4.4 N·m) is an alarm. After the spindle's start the gate therefore
    waits for the cut: the revolutions' mean torque rising above the air's (``k_sigma``
    standard deviations of the air revolutions' means, and ``rel_tol`` of their level) and then
    steady (two revolutions within ``rel_tol`` of the cut's torque above the air); a revolution
    back at the air's level closes it. A stream that starts with the spindle already at speed
    keeps the seed's premise (the gate is ``at_speed_channel``). ``rel_tol`` = 0.1 is decision
    1681's steady-revolution tolerance; ``k_sigma`` = 5 keeps a rise of the air's noise out
    (one revolution in 3.5 million of Gaussian noise); ``min_air`` = 3 revolutions give the air's
    first spread.

    The air's level is learnt per spindle speed and kept across speed changes (decision 1723):
    at a speed it has not seen in the air the gate judges against the line through the levels
    learnt at the speeds around it, or beyond them against the nearest level with the band a
    drag between all Coulomb and all viscous allows, so a cut that begins during the ramp to a
    new speed is seen as a rise; and a revolution below the level learnt at its speed says that
    level was a cut's, which is learnt again. A start (in the air, the levels forgotten) is a
    spindle that ran below a tenth of its new speed, a stop; an S word's ramp is not one.
    """

    def __init__(
        self,
        torque_channel: str,
        speed_channel: str = "spindle/speed",
        at_speed_channel: str = "spindle/at_speed",
        out: str = "monitor/breakage_steady_gate",
        min_air: int = 3,
        k_sigma: float = 5.0,
        rel_tol: float = 0.1,
        name: str = "torque_cut_gate",
    ) -> None:
        if not (min_air >= 2 and k_sigma > 0 and 0 < rel_tol < 1):
            raise ConfigError("torque cut gate: min_air ≥ 2, k_sigma > 0, 0 < rel_tol < 1 needed")
        self.inputs = (torque_channel, speed_channel, at_speed_channel)
        self.out = out
        self.min_air = int(min_air)
        self.k_sigma = float(k_sigma)
        self.rel_tol = float(rel_tol)
        self.name = name
        self.reset(10000.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(self.out, "1", "1 where the torque has risen from the air and is "
                            "steady in the cut (or the stream started at speed)")]  # fmt: skip

    def reset(self, sample_rate_hz: float) -> None:
        self._state = np.zeros(CUT_GATE_STATE)
        self._state[CUT_LOWEST] = np.inf
        self.fs = float(sample_rate_hz)

    @property
    def premise_samples(self) -> int:
        """Samples the gate held open on seed 002's premise since the reset: the stream started
        with the spindle at speed, and its revolutions were taken as cut until the spindle
        stopped, whatever the torque (decision 1725: said so in `monitor`'s summary)."""
        return int(self._state[CUT_PREMISE_SAMPLES])

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        tq = np.ascontiguousarray(d[self.inputs[0]], dtype=np.float64)
        w = np.ascontiguousarray(d[self.inputs[1]], dtype=np.float64) / self.fs
        out = np.empty(tq.size)
        torque_cut_gate_kernel(tq, w, np.ascontiguousarray(d[self.inputs[2]], dtype=np.float64),
                               self._state, self.min_air, self.k_sigma, self.rel_tol,
                               out)  # fmt: skip
        return BlockOutput({self.out: out})


class AllOf(Block):
    """``out`` = 1 where every one of ``channels`` is above its level in ``above`` (default 0.5:
    1/0 flags), else 0 (e.g. the spindle at speed *and* the plan's tool in the cut: where
    `millsense monitor` judges breakage on a session's recording, decision 1550)."""

    def __init__(
        self,
        channels: tuple[str, ...],
        out: str,
        name: str = "all_of",
        above: tuple[float, ...] | None = None,
    ) -> None:
        if not channels:
            raise ConfigError("all-of gate: no channel")
        if above is not None and len(above) != len(channels):
            raise ConfigError("all-of gate: one level per channel")
        self.inputs = tuple(channels)
        self.above = tuple(above) if above is not None else (0.5,) * len(channels)
        self.out = out
        self.name = name

    def output_channels(self) -> list[ChannelInfo]:
        where = [f"{c} > {a:g}" for c, a in zip(self.inputs, self.above, strict=True)]
        return [ChannelInfo(self.out, "1", "1 where " + " and ".join(where))]

    def reset(self, sample_rate_hz: float) -> None:
        pass

    def process(self, chunk: Chunk) -> BlockOutput:
        ok = np.ones(chunk.n, dtype=bool)
        for c, level in zip(self.inputs, self.above, strict=True):
            ok &= np.asarray(chunk.data[c]) > level
        return BlockOutput({self.out: ok.astype(np.float64)})
