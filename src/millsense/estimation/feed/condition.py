"""Feed-axis estimator that follows the axis' operating condition (moving or holding).

Decision docs/decisions/0106-holding-axis-phi-d-and-r-identified-at-rest-issue-7-v1.md: an axis that
holds position while the others cut feels the load partly through its friction bristles (LuGre
presliding, Aslan Eq. 3.2–3.3), so its disturbance path differs from the one measured in a
move; the model must come from the condition the axis runs in, chosen by the CNC's command.
:class:`OperatingConditionFeedEstimator` runs the moving and the at-rest estimators of one
axis side by side and blends their outputs by the commanded motor speed.

The mean of a holding axis's load comes from the moving path (decision 0129): the at-rest
path is identified from a zero-mean sweep, in which the bristles carry about a fifth of the
load down to 0.25 Hz (the truth's Y: |Φ| 0.80–0.83 from 0.25 to 5 Hz), but a load that stays
is carried by the motor — the servo's integral action returns the held motor to its command
and the friction hunts around zero (a held Y axis under a −367 N step, or under the slot's
cutting load: motor share of the mean 0.99–1.00 on the truth). Read as linear, the at-rest
path's static gain (0.77) put the V1 slot's Y mean 38 % high. The at-rest estimate therefore
contributes only its deviation from its own mean over the last :data:`REST_MEAN_WINDOW_S`:
``ŷ = ŷ_moving + w·(d − mean_T d)``, ``d = ŷ_at_rest − ŷ_moving``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.feed._condition_kernels import highpass_blend, rest_weight_kernel
from millsense.estimation.feed.commanded import velocity_source
from millsense.estimation.feed.estimator import REST_SPEED_RAD_S, FeedAxisEstimator
from millsense.streaming.block import Block, BlockOutput, Chunk

#: Width of the blend between the two models around a change of condition, s.
CROSSFADE_S = 0.005
#: Window of the mean a holding axis takes from the moving path (decision 0129), s. A boxcar of
#: T passes none of a line at a multiple of 1/T (10 Hz: every tooth frequency of a 2-flute
#: cutter at a multiple of 300 rev/min) and at most 1/(π·f·T) of any line f (8 % at 33 Hz,
#: 1000 rev/min with 2 flutes, 1.7 % at 183 Hz) of the two paths' difference; a step in
#: the mean passes over in T. A first-order split with the same leak at 33 Hz (1 Hz corner)
#: takes 0.5 s to settle: 12 % of the V1 slot's mean still in a window that starts 0.2 s
#: into the cut.
REST_MEAN_WINDOW_S = 0.1


class OperatingConditionFeedEstimator(Block):
    """The moving and the at-rest feed estimators of an axis, blended by the command.

    Parameters
    ----------
    moving, at_rest : the axis' estimators on the models identified in a move and at rest
        (same axis, same smoother lag, same outputs).
    transmission : r_g of the axis, m/rad (rad/rad rotary): the commanded motor speed is
        ``Δx_cmd·f_s/r_g``.
    rest_speed_rad_s : largest |commanded motor speed| of an axis that holds, rad/s
        (:data:`~millsense.estimation.feed.estimator.REST_SPEED_RAD_S`).
    crossfade_s : width of the centred blend around a change of condition, s (at most twice
        the lag: the blend for output sample k uses commands up to k).
    mean_window_s : the window of the mean taken from the moving estimate whatever the
        condition (decision 0129); 0 blends the two estimates whole.

    Reads both estimators' inputs and ``{axis}/position_cmd`` (the interpolator's commanded
    position, m; rad rotary); writes their outputs, delayed by the common lag L: output sample
    k is ``moving + w·HP(at_rest − moving)`` with ``w`` the fraction of the commanded speeds
    within ±rest_speed over the ``crossfade_s`` window centred on sample k − L (the sample the
    estimate belongs to) and ``HP(d)[k] = d[k] − mean(d[k−N+1 … k])``, N samples of
    ``mean_window_s`` (before the stream, d stood at its first value). Both estimators run on
    every sample, so a change of condition needs no start-up and streaming equals batch.
    """

    def __init__(
        self,
        moving: FeedAxisEstimator,
        at_rest: FeedAxisEstimator,
        transmission: float,
        *,
        rest_speed_rad_s: float = REST_SPEED_RAD_S,
        crossfade_s: float = CROSSFADE_S,
        mean_window_s: float = REST_MEAN_WINDOW_S,
    ) -> None:
        ax = moving.model.axis
        self.name = f"feed_force_{ax}_condition"
        if at_rest.model.axis != ax or at_rest.lag != moving.lag:
            raise ConfigError(f"block {self.name}: the two estimators differ in axis or lag")
        if not (
            transmission > 0 and rest_speed_rad_s >= 0 and crossfade_s >= 0
            and mean_window_s >= 0
        ):  # fmt: skip
            raise ConfigError(
                f"block {self.name}: transmission > 0, rest speed, crossfade and mean "
                "window >= 0 needed"
            )
        self.moving, self.at_rest = moving, at_rest
        self.lag = moving.lag
        self.transmission = float(transmission)
        self.rest_speed = float(rest_speed_rad_s)
        self.crossfade_s = float(crossfade_s)
        self.mean_window_s = float(mean_window_s)
        self._window = 0
        self._recent: dict[str, NDArray[np.float64]] = {}
        self.position_channel = velocity_source(ax)
        self.inputs = tuple(dict.fromkeys((*moving.inputs, *at_rest.inputs, self.position_channel)))
        self._width = 1
        self._hist: NDArray[np.float64] = np.zeros(0)
        #: [previous command, started] and [f_s, r_g, rest speed] of the compiled weight
        self._state = np.zeros(2)
        self._drive = np.zeros(3)

    @property
    def delay_samples(self) -> int:
        return self.lag

    def output_channels(self) -> list[ChannelInfo]:
        return [
            ChannelInfo(c.name, c.unit, c.description + ", moving/at-rest by the command")
            for c in self.moving.output_channels()
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self.moving.reset(sample_rate_hz)
        self.at_rest.reset(sample_rate_hz)
        half = min(self.lag, round(0.5 * self.crossfade_s * sample_rate_hz))
        self._width = 2 * half + 1
        self._hist = np.zeros(self.lag + half)
        self._state = np.zeros(2)
        self._drive = np.array([sample_rate_hz, self.transmission, self.rest_speed])
        self._window = round(self.mean_window_s * sample_rate_hz)
        self._recent = {}

    def _blend(
        self,
        channel: str,
        mov: NDArray[np.float64],
        rest: NDArray[np.float64],
        w: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """``mov + w·(d − mean_N d)``, ``d = rest − mov``, the mean over the last N samples at
        each sample of the chunk (state carried; before the stream, d stood at its first
        value): the mean is the moving path's (decision 0129)."""
        if len(mov) == 0 or self._window == 0:
            return mov + w * (rest - mov)
        recent = self._recent.get(channel)
        if recent is None:
            recent = self._recent[channel] = np.full(self._window, rest[0] - mov[0])
        out = np.empty(len(mov))
        highpass_blend(mov, rest, w, recent, out)
        return out

    def rest_weight(self, position_cmd: NDArray[np.float64]) -> NDArray[np.float64]:
        """Weight of the at-rest model for the output samples of one chunk (state carried)."""
        pos = np.ascontiguousarray(position_cmd, dtype=np.float64)
        n = len(pos)
        if n == 0:
            return np.zeros(0)
        w = np.empty(n)
        if not rest_weight_kernel(pos, self._state, self._drive, self._hist, self._width, w):
            raise InputDataError(f"block {self.name}: non-finite {self.position_channel}")
        return w

    def process(self, chunk: Chunk) -> BlockOutput:
        w = self.rest_weight(chunk.data[self.position_channel])
        om = self.moving.process(chunk).channels
        orr = self.at_rest.process(chunk).channels
        out = {}
        for k, v in om.items():
            mov = np.ascontiguousarray(v, dtype=np.float64)
            rest = np.ascontiguousarray(orr[k], dtype=np.float64)
            out[k] = self._blend(k, mov, rest, w)
        return BlockOutput(out)
