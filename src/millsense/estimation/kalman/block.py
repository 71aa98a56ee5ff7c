"""Generic streaming block running a steady-state Kalman filter (and optional smoother).

Estimators of millsense (feed-drive disturbance filters, spindle observer, accelerometer
filters) prepare their measurement channel(s) — e.g. the cutting torque of Aslan Eq. 3.10 —
and hand them to a :class:`KalmanBlock`, which runs the frozen-gain filter of a
:class:`~millsense.estimation.kalman.design.KalmanDesign` per chunk with its state carried, and
emits
one channel per selected row (by default the disturbance estimate ``τ̂_a``). With ``lag > 0`` it
runs the fixed-lag smoother (Aslan Appendix B) and its outputs are delayed by exactly ``lag``
samples: output sample k is the estimate of sample k − lag.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.estimation.kalman.design import KalmanDesign, Output
from millsense.estimation.kalman.lti_filter import Realisation, StreamingFilter
from millsense.estimation.kalman.smoother import FixedLagSmoother
from millsense.streaming.block import Block, BlockOutput, Chunk


class KalmanBlock(Block):
    """Streaming steady-state Kalman filter or fixed-lag smoother.

    Parameters
    ----------
    name : block name.
    inputs : measurement channels, in the order of the rows of C (p channels).
    outputs : one ChannelInfo per estimated row.
    design : the steady-state design; its ``dt`` must match the stream's sample rate.
    rows : (d, n) selection of the state to emit; default the design's disturbance rows.
    output : ``"filtered"`` (x̂(k|k)) or ``"predicted"`` (x̂(k|k−1)); ignored with a smoother.
    lag : smoother lag in samples (0: no smoother; 60 = 6 ms at 10 kHz, Aslan Appendix B).
    realisation : kernel of the filter (``auto``, ``modal``, ``dense``).
    """

    def __init__(
        self,
        name: str,
        inputs: Sequence[str],
        outputs: Sequence[ChannelInfo],
        design: KalmanDesign,
        *,
        rows: ArrayLike | None = None,
        output: Output = "filtered",
        lag: int = 0,
        realisation: Realisation = "auto",
    ) -> None:
        self.name = name
        self.inputs = tuple(inputs)
        self._outputs = list(outputs)
        self.design = design
        s = design.disturbance if rows is None else np.atleast_2d(np.asarray(rows, dtype=float))
        if len(self.inputs) != design.c.shape[0]:
            raise ConfigError(
                f"block {name}: {len(self.inputs)} input channels for {design.c.shape[0]} "
                "measurements"
            )
        if len(self._outputs) != s.shape[0]:
            raise ConfigError(
                f"block {name}: {len(self._outputs)} output channels for {s.shape[0]} rows"
            )
        self.lag = int(lag)
        self._smoother: FixedLagSmoother | None = None
        self._filter: StreamingFilter | None = None
        if self.lag > 0:
            self._smoother = FixedLagSmoother(design, self.lag, s, realisation)
        else:
            self._filter = StreamingFilter(design.filter(output, s), realisation)

    @property
    def delay_samples(self) -> int:
        """Samples by which the outputs lag the inputs (the smoother lag)."""
        return self.lag

    def output_channels(self) -> list[ChannelInfo]:
        return list(self._outputs)

    def reset(self, sample_rate_hz: float) -> None:
        if not np.isclose(sample_rate_hz * self.design.dt, 1.0, rtol=1e-9):
            raise ConfigError(
                f"block {self.name}: designed for {1.0 / self.design.dt:g} Hz, stream is "
                f"{sample_rate_hz:g} Hz"
            )
        if self._smoother is not None:
            self._smoother.reset()
        if self._filter is not None:
            self._filter.reset()

    def process(self, chunk: Chunk) -> BlockOutput:
        y = np.column_stack([np.asarray(chunk.data[c], dtype=float) for c in self.inputs])
        if len(y) == 0:
            return BlockOutput({c.name: np.zeros(0) for c in self._outputs})
        if self._smoother is not None:
            est = self._smoother.process(y)
        else:
            assert self._filter is not None
            est = self._filter.process(y)
        return BlockOutput({c.name: est[:, i].copy() for i, c in enumerate(self._outputs)})
