"""The feed-drive estimators of all axes as one block, one compiled call per chunk
(decision 1652).

:class:`FeedEstimatorBank` takes the blocks :func:`~millsense.estimation.from_config.
build_estimators` builds for the feed axes (each an :class:`~millsense.estimation.feed.
condition.OperatingConditionFeedEstimator` — the moving and the at-rest estimator of an axis,
Aslan Eq. 3.10–3.29 and Appendix B, blended by the command, decisions 0106/0129 — renamed into
``est/feed/{axis}/load``) and runs them in :func:`~millsense.estimation.feed._bank_kernel.
bank_kernel`: same inputs, same outputs bit for bit, ten filters side by side instead of ten
calls. :func:`bank_or_blocks` falls back to the blocks themselves when one of them is not of
that kind (a harmonic design, a dense realisation, another method).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.feed._bank_kernel import bank_kernel, pairs_of
from millsense.estimation.feed.condition import OperatingConditionFeedEstimator
from millsense.estimation.feed.estimator import C3Torque, FeedAxisEstimator
from millsense.streaming.block import Block, BlockOutput, Chunk

_GAINS = {"load_est": "_gain", "force_est": "_force_gain"}


def _bankable(est: FeedAxisEstimator) -> bool:
    kf = est._smoother._kf
    return (
        est.teeth is None
        and bool(kf.kernel_args[0])  # the modal realisation
        and kf.kernel_args[5].shape[1] == 1  # one input (the C3 torque)
        and kf.kernel_args[6].shape[0] == 2  # outputs [τ̂_a prediction; innovation]
        and est._smoother._taps_t.shape[:2] == (1, 1)
    )


def _condition_block(b: Block) -> OperatingConditionFeedEstimator | None:
    """The condition estimator a renamed block wraps, if the bank can run it."""
    inner = getattr(b, "inner", None)
    mapping = getattr(b, "mapping", None)
    if not isinstance(inner, OperatingConditionFeedEstimator) or not mapping:
        return None
    ax = inner.moving.model.axis
    for old in mapping:
        suffix = old.removeprefix(f"{ax}/")
        if suffix not in _GAINS or getattr(inner.moving, _GAINS[suffix]) is None:
            return None
    if not (_bankable(inner.moving) and _bankable(inner.at_rest)):
        return None
    return inner


def _same_c3(a: C3Torque, b: C3Torque) -> bool:
    """The two C3 stages compute the same torque from the same inputs (same state, drive,
    friction and low-pass)."""
    return (
        a._mode == b._mode
        and all(
            np.array_equal(x, y)
            for x, y in ((a._state, b._state), (a._drive, b._drive), (a._fric, b._fric),
                         (a._sos, b._sos))
        )
    )  # fmt: skip


def bank_or_blocks(blocks: Sequence[Block]) -> list[Block]:
    """``blocks`` as one :class:`FeedEstimatorBank` when every one is a renamed condition
    estimator of the kind it runs (with one lag and one blend window), else unchanged."""
    inner = [_condition_block(b) for b in blocks]
    if len(blocks) < 2 or any(c is None for c in inner):
        return list(blocks)
    conds = [c for c in inner if c is not None]
    if len({(c.lag, c.mean_window_s, c.crossfade_s) for c in conds}) != 1:
        return list(blocks)
    return [FeedEstimatorBank(blocks)]


class FeedEstimatorBank(Block):
    """Renamed :class:`OperatingConditionFeedEstimator` blocks run as one (see the module).

    The wrapped blocks are its configuration: their estimators are reset with it and their
    state is packed into the bank's arrays, which carry it from chunk to chunk (the wrapped
    estimators' own state is not advanced).
    """

    def __init__(self, blocks: Sequence[Block], name: str = "feed_bank") -> None:
        self.blocks = list(blocks)
        self.name = name
        self._conds: list[OperatingConditionFeedEstimator] = []
        for b in self.blocks:
            c = _condition_block(b)
            if c is None:
                raise ValueError(f"feed bank: block '{b.name}' is not a bankable estimator")
            self._conds.append(c)
        self.inputs = tuple(dict.fromkeys(i for b in self.blocks for i in b.inputs))
        self._channels: list[tuple[int, str, str, float]] = []  # axis, old, new, factor
        for a, b in enumerate(self.blocks):
            for old, (new, factor, _) in b.mapping.items():  # type: ignore[attr-defined]
                self._channels.append((a, old, new, float(factor)))
        self._names = [new for _, _, new, _ in self._channels]
        self.reset(self._conds[0].moving.model.sample_rate_hz)

    @property
    def delay_samples(self) -> int:
        return self._conds[0].lag

    def output_channels(self) -> list[ChannelInfo]:
        return [info for b in self.blocks for info in b.output_channels()]

    def reset(self, sample_rate_hz: float) -> None:
        for b in self.blocks:
            b.reset(sample_rate_hz)
        conds = self._conds
        ests = [e for c in conds for e in (c.moving, c.at_rest)]
        nf = len(ests)
        nz = max(e._smoother._kf.z.shape[0] for e in ests)
        nz += nz % 2
        self._moving_of = np.arange(0, nf, 2, dtype=np.int64)
        self._at_rest_of = np.arange(1, nf, 2, dtype=np.int64)
        # one C3 stage per axis and drive model: the moving and the at-rest model of an axis
        # usually share K_t, J_e, the friction and the low-pass, and so the torque
        stages: list[tuple[int, C3Torque]] = []
        c3_of = []
        for f, e in enumerate(ests):
            a, c3 = f // 2, e._c3
            same = [i for i, (b, o) in enumerate(stages) if b == a and _same_c3(o, c3)]
            if not same:
                stages.append((a, c3))
            c3_of.append(same[0] if same else len(stages) - 1)
        c3s = [c3 for _, c3 in stages]
        self._axis_of = np.array([a for a, _ in stages], dtype=np.int64)
        self._c3_of = np.array(c3_of, dtype=np.int64)
        self._c3_state = np.array([c._state for c in c3s])
        self._c3_drive = np.array([c._drive for c in c3s])
        self._fric_mode = np.array([c._mode for c in c3s], dtype=np.int64)
        width = max(len(c._fric) for c in c3s)
        self._fric = np.zeros((len(c3s), width))
        for i, c in enumerate(c3s):
            self._fric[i, : len(c._fric)] = c._fric
        self._sos = np.array([c._sos for c in c3s])
        lti = np.zeros((9, nf, nz))
        self._z = np.zeros((nf, nz))
        self._n_states = np.array([len(e._smoother._kf.z) for e in ests], dtype=np.int64)
        for f, e in enumerate(ests):
            kf = e._smoother._kf
            _, diag, off, n_pairs, _, g, h, j = kf.kernel_args
            n = len(kf.z)
            lti[0, f, :n] = h[0]
            lti[1, f, :n] = h[1]
            lti[2, f, :n] = g[:, 0]
            d = np.zeros(nz)
            d[:n] = diag
            for pair in range(nz // 2):
                i = 2 * pair
                if pair < n_pairs:  # a 2×2 block
                    lti[3:7, f, pair] = diag[i], off[i], off[i + 1], diag[i + 1]
                else:  # two 1×1 blocks (or one and a padding state)
                    lti[3:7, f, pair] = d[i], 0.0, 0.0, d[i + 1]
            lti[7, f, 0] = j[0, 0]
            lti[8, f, 0] = j[1, 0]
            self._z[f, :n] = kf.z
        self._lti = lti
        self._pairs = pairs_of(lti)
        self._taps = np.array([e._smoother._taps_t for e in ests])
        self._hist_pred = np.array([e._smoother._hist_pred for e in ests])
        self._hist_innov = np.array([e._smoother._hist_innov for e in ests])
        self._rw_state = np.array([c._state for c in conds])
        self._rw_drive = np.array([c._drive for c in conds])
        self._rw_hist = np.array([c._hist for c in conds])
        self._width = np.array([c._width for c in conds], dtype=np.int64)
        self._channel = np.array([
            [a, getattr(conds[a].moving, _GAINS[old.split("/")[-1]]),
             getattr(conds[a].at_rest, _GAINS[old.split("/")[-1]]), factor, 0.0]
            for a, old, _, factor in self._channels
        ], dtype=np.float64)  # fmt: skip
        self._recent = np.zeros((len(self._channels), conds[0]._window))
        # the currents, speeds and position commands of the axes, read as one (3A, n) array
        self._rows = [
            *(c.moving.inputs[0] for c in conds),
            *(c.moving.inputs[1] for c in conds),
            *(c.position_channel for c in conds),
        ]

    def process(self, chunk: Chunk) -> BlockOutput:
        n = chunk.n
        if n == 0:
            return BlockOutput({k: np.zeros(0) for k in self._names})
        a = len(self._conds)
        flat = np.concatenate([chunk.data[k] for k in self._rows], dtype=np.float64)
        rows: NDArray[np.float64] = flat.reshape(len(self._rows), n)
        cur, spd, pos = rows[:a], rows[a : 2 * a], rows[2 * a :]
        out = np.empty((len(self._channels), n))
        ok = bank_kernel(cur, spd, pos, self._axis_of, self._c3_of, self._c3_state, self._c3_drive,
                         self._fric_mode, self._fric, self._sos, self._lti, self._pairs,
                         self._n_states, self._z, self._taps, self._hist_pred, self._hist_innov,
                         self._rw_state, self._rw_drive, self._rw_hist, self._width,
                         self._moving_of, self._at_rest_of, self._channel, self._recent,
                         out)  # fmt: skip
        if not ok:
            bad = next(
                c for c in self._conds if not np.isfinite(chunk.data[c.position_channel]).all()
            )
            raise InputDataError(f"block {bad.name}: non-finite {bad.position_channel}")
        return BlockOutput(dict(zip(self._names, out, strict=True)))
