"""Position-scheduled feed-axis estimator: a bank of models identified along the stroke.

The disturbance modes Φ_d of a feed axis move with the table (issue 7; the simulator's
``mode_shift_per_m``, :mod:`millsense.simulator.feed_drive`). No single linear estimator can be
flat to 180 Hz for modes anywhere within ±2 %
(:func:`millsense.estimation.feed.tuning.flatness_bound`),
so, as a commissioning engineer would, Φ_d is identified at N positions along the stroke
(:func:`identify_feed_bank`) and the estimator uses the model of where the axis is commanded to
be (:class:`ScheduledFeedEstimator`).

Scheduling (docs/decisions/0116-position-scheduled-feed-estimator.md): the members share one C3
stage and each has its own Kalman filter and smoother, run while the commanded position is near
its identification position and warmed up by replaying the recent C3 torque when it starts, so
a switch is bumpless. The output is the estimate of the member identified nearest to the CNC's
commanded position ``{axis}/position_cmd`` (never a measured or true position), cross-faded
linearly over ``crossfade`` × the spacing around each midpoint between identification positions.
The position used is the command delayed by the smoother lag, i.e. the position at the instant
the delayed estimate refers to.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from itertools import pairwise
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.feed import tuning
from millsense.estimation.feed.estimator import (
    TARGET_BAND_HZ,
    FeedAxisEstimator,
    FeedAxisModel,
    measurement_model,
)
from millsense.estimation.feed.path_fit import SweepResult
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.estimation.kalman.smoother import ASLAN_LAG_SAMPLES
from millsense.streaming.block import Block, BlockOutput, Chunk

#: Cross-fade width around each midpoint, as a fraction of the spacing (decision
#: "Position-scheduled feed estimator": chosen analytically by :func:`interval_worst_db`).
DEFAULT_CROSSFADE = 1.0
#: Multisine periods of a bank sweep (1 s each, first discarded), as
#: :func:`~millsense.bench.feed_commissioning.disturbance_sweep`'s default.
SWEEP_PERIODS = 13
#: Lead-in of a sweep before the multisine starts, s (as disturbance_sweep).
SWEEP_LEAD_S = 0.3
#: Torque history replayed into a member when it starts running, s (decision
#: "Position-scheduled feed estimator": the slowest filter pole, a Table 3.4 mode's own decay
#: of about 5 1/s that the filter barely moves, has decayed to < 1 % over it).
WARMUP_S = 1.0
#: A member also runs this fraction of the spacing beyond its weight support (no switching on
#: and off at the support's edge, where its weight is zero anyway).
ACTIVE_MARGIN = 0.1

Design = Literal["nominal", "robust"]
DesignChoice = Literal["nominal", "robust", "auto"]


def relative_shift(fit_a: RationalFit, sweep_b: SweepResult, band_hz: tuple[float, float]) -> float:
    """Relative mode-frequency change from the model ``fit_a`` to the sweep ``sweep_b``.

    The λ − 1 minimising ``Σ |H_b(f) − Φ_a(f; λ)|²`` over the measured lines of ``sweep_b`` in
    ``band_hz`` (Hz), with ``Φ_a(·; λ)`` = :meth:`RationalFit.with_modes_scaled` (bounded
    search, λ in 0.8…1.2).
    """
    est = sweep_b.frf
    sel = (est.freq_hz >= band_hz[0]) & (est.freq_hz <= band_hz[1])
    f, h = est.freq_hz[sel], est.h1[sel]
    if len(f) < 3:
        raise InputDataError("relative shift: fewer than 3 FRF lines in the band")

    def cost(lam: float) -> float:
        return float(np.sum(np.abs(h - fit_a.with_modes_scaled(lam).frf(f)) ** 2))

    res = optimize.minimize_scalar(
        cost, bounds=(0.8, 1.2), method="bounded", options={"xatol": 1e-6}
    )
    return float(res.x) - 1.0


@dataclass(frozen=True)
class FeedModelBank:
    """Estimator models of one axis identified at positions along its stroke.

    Attributes
    ----------
    positions : identification positions (load position, m; rad rotary), strictly ascending.
    models : one :class:`~millsense.estimation.feed.estimator.FeedAxisModel` per position.
    half_shifts : per member, the relative mode change to its farther neighbour midpoint (half
        of the measured neighbour shift, :func:`relative_shift`); what a robust member is
        designed for.
    crossfade : cross-fade width around each midpoint, fraction of the local spacing (0, 1];
        1 = linear interpolation between neighbouring members.
    design : how the members were tuned (``nominal`` or ``robust``).
    analytic_db : (nominal, robust) analytic worst deviation over an interval, dB
        (:func:`interval_worst_db`, ``auto`` design only; NaN otherwise).
    """

    positions: tuple[float, ...]
    models: tuple[FeedAxisModel, ...]
    half_shifts: tuple[float, ...]
    crossfade: float = DEFAULT_CROSSFADE
    design: str = "nominal"
    analytic_db: tuple[float, float] = (math.nan, math.nan)

    def __post_init__(self) -> None:
        if len(self.positions) != len(self.models) or len(self.models) == 0:
            raise ConfigError("model bank: need one model per position (at least one)")
        if any(b <= a for a, b in pairwise(self.positions)):
            raise ConfigError("model bank: positions must be strictly ascending")
        if not 0 < self.crossfade <= 1:
            raise ConfigError(f"model bank: crossfade must be in (0, 1], got {self.crossfade}")
        if len({m.axis for m in self.models}) != 1:
            raise ConfigError("model bank: all models must belong to one axis")

    @property
    def axis(self) -> str:
        return self.models[0].axis

    def weights(self, position: ArrayLike1) -> NDArray[np.float64]:
        """(n, N) member weights at commanded positions (m; rad rotary); rows sum to 1.

        Nearest identification position, cross-faded linearly over ``crossfade`` × spacing around
        each midpoint; beyond the end positions the end member alone.
        """
        x = np.asarray(position, dtype=float)
        if not np.all(np.isfinite(x)):
            raise InputDataError(f"model bank {self.axis}: non-finite commanded position")
        p = np.asarray(self.positions)
        w = np.zeros((x.size, p.size))
        if p.size == 1:
            w[:, 0] = 1.0
            return w
        i = np.clip(np.searchsorted(p, x, side="right") - 1, 0, p.size - 2)
        u = (x - p[i]) / (p[i + 1] - p[i])
        hi = np.clip((u - 0.5) / self.crossfade + 0.5, 0.0, 1.0)
        rows = np.arange(x.size)
        w[rows, i] = 1.0 - hi
        w[rows, i + 1] += hi
        return w

    def active(self, position: ArrayLike1, margin: float) -> NDArray[np.bool_]:
        """(n, N): member j's weight support (p_{j−1}, p_{j+1}) widened by ``margin`` × the
        adjacent spacing on each side (unbounded beyond the end members)."""
        x = np.asarray(position, dtype=float)[:, None]
        p = np.asarray(self.positions)
        if p.size == 1:
            return np.ones((x.shape[0], 1), dtype=bool)
        gap = np.diff(p)
        lo = np.concatenate([[-np.inf], p[:-2] - margin * gap[:-1], [p[-2] - margin * gap[-1]]])
        hi = np.concatenate([[p[1] + margin * gap[0]], p[2:] + margin * gap[1:], [np.inf]])
        return np.asarray((x > lo[None, :]) & (x < hi[None, :]))


ArrayLike1 = NDArray[np.float64] | Sequence[float]


def design_member(model: FeedAxisModel, design: Design, half_shift: float) -> FeedAxisModel:
    """Q (and design damping) of one bank member.

    ``nominal``: :func:`~millsense.estimation.feed.tuning.tune_q` on the member's own Φ_d;
    ``robust``: :func:`~millsense.estimation.feed.tuning.tune_robust` for modes within
    ±``half_shift`` of the member's (its residual uncertainty: the mode change to the midpoint
    to its neighbour); both through :meth:`FeedAxisModel.tuned`.
    """
    if design == "nominal" or half_shift <= 0:
        return model.tuned(0.0)
    return model.tuned(half_shift)


def interval_worst_db(
    model: FeedAxisModel,
    half_shift: float,
    *,
    design: Design = "robust",
    crossfade: float = DEFAULT_CROSSFADE,
    n_positions: int = 41,
) -> dict[str, float]:
    """Analytic worst deviation (dB, 1 Hz … target) of the scheduled estimator over one interval.

    Two members identified at mode scales 1 − h and 1 + h around ``model``'s Φ_d (h =
    ``half_shift``), each designed by :func:`design_member`; the plant moves linearly from one to
    the other (scale ``1 − h + 2h·u``, u ∈ [0, 1]) and the output is the weighted sum of the two
    smoothed estimators with the weights of :meth:`FeedModelBank.weights`. Compensated FRF
    ``Φ(u)·Σ w_j(u)·Φ_KF,j`` (C3 low-pass in both; the smoother's FRF realigned).

    Returns
    -------
    ``worst_db`` over all positions; ``midpoint_db`` at u = ½; ``hard_switch_db`` the worst
    without cross-fade (one member at the full half shift h); ``lti_bound_db``
    :func:`~millsense.estimation.feed.tuning.flatness_bound` of a single LTI estimator for modes in
    ±h.
    """
    fit, lp, dt = model.disturbance, model.lowpass_hz, model.dt
    target = TARGET_BAND_HZ[model.kind]
    f = np.concatenate([np.arange(0.0, 300.0, 0.05), np.arange(300.0, 1000.5, 1.0)])
    sel = (f >= 1.0) & (f <= target)
    members = [
        design_member(
            replace(model, disturbance=fit.with_modes_scaled(1.0 + s)), design, half_shift
        )
        for s in (-half_shift, half_shift)
    ]
    ests = [tuning.estimator_frf(m.design(), f, ASLAN_LAG_SAMPLES) for m in members]
    bank = FeedModelBank((0.0, 1.0), tuple(members), (half_shift,) * 2, crossfade)
    u = np.linspace(0.0, 1.0, n_positions)
    w = bank.weights(u)
    worst, mid = 0.0, 0.0
    for k, uk in enumerate(u):
        plant = tuning.model_frf(
            measurement_model(
                fit.with_modes_scaled(1.0 - half_shift + 2 * half_shift * uk), lp, dt
            ),
            f,
        )
        dev = float(
            np.max(tuning.deviation_db((plant * (w[k, 0] * ests[0] + w[k, 1] * ests[1]))[sel]))
        )
        worst = max(worst, dev)
        if math.isclose(uk, 0.5):
            mid = dev
    plant_mid = tuning.model_frf(measurement_model(fit, lp, dt), f)
    hard = max(float(np.max(tuning.deviation_db((plant_mid * e)[sel]))) for e in ests)
    fam = tuning.mode_family(fit, half_shift, 9)
    bound, _ = tuning.flatness_bound(
        np.array([tuning.model_frf(measurement_model(m, lp, dt), f) for m in fam]), f, target
    )
    return {"worst_db": worst, "midpoint_db": mid, "hard_switch_db": hard, "lti_bound_db": bound}


class ScheduledFeedEstimator(Block):
    """Feed-axis estimator scheduled on the CNC's commanded position (a bank of estimators).

    Parameters
    ----------
    bank : models identified along the stroke (sharing drive model, friction, low-pass and
        sample rate: they differ in Φ_d and Q).
    lag : smoother lag of every member, samples.
    warmup_s : history replayed into a member when it starts running, s.
    margin : a member runs while the (delayed) commanded position is within its weight support
        widened by this fraction of the spacing on each side.
    all_members : run every member on every sample (no warm-up needed; N× the cost).

    Reads ``{axis}/current_cmd``, ``{axis}/motor_speed`` and ``{axis}/position_cmd`` (load
    position commanded by the interpolator, m; rad rotary). Writes the same channels as
    :class:`~millsense.estimation.feed.estimator.FeedAxisEstimator` (``{axis}/load_est``,
    ``{axis}/force_est``), delayed by ``lag`` samples.

    Notes
    -----
    One C3 stage (Aslan Eq. 3.10, shared) feeds one fixed-lag smoother per member; the output is
    ``Σ_j w_j(x_cmd(k − L))·τ̂_j`` with the weights of :meth:`FeedModelBank.weights` at the
    commanded position delayed by the lag L. A member runs only while the position is within
    its support plus ``margin`` (with linear interpolation at most two members carry weight);
    when it starts, it is reset and the last ``warmup_s`` of C3 torque are replayed through it
    first, so it enters (at zero weight) with the state it would have had running all along,
    to within the decay of its slowest filter pole over the replay (bumpless). Activation is
    decided per sample and the torque history is carried, so streaming equals batch.
    """

    def __init__(
        self,
        bank: FeedModelBank,
        lag: int = ASLAN_LAG_SAMPLES,
        *,
        warmup_s: float = WARMUP_S,
        margin: float = ACTIVE_MARGIN,
        all_members: bool = False,
    ) -> None:
        from millsense.estimation.feed.estimator import C3Torque
        from millsense.estimation.kalman.smoother import FixedLagSmoother

        self.bank = bank
        ax = bank.axis
        self.name = f"feed_force_{ax}_scheduled"
        self.inputs: tuple[str, ...] = (
            f"{ax}/current_cmd",
            f"{ax}/motor_speed",
            f"{ax}/position_cmd",
        )
        self.lag = int(lag)
        m0 = bank.models[0]
        for m in bank.models[1:]:
            if (m.drive, m.lugre, m.lowpass_hz, m.sample_rate_hz, m.kind) != (
                m0.drive,
                m0.lugre,
                m0.lowpass_hz,
                m0.sample_rate_hz,
                m0.kind,
            ):
                raise ConfigError(
                    f"block {self.name}: bank members must share drive, friction, low-pass and "
                    "sample rate"
                )
        if not (warmup_s >= 0 and margin >= 0):
            raise ConfigError(f"block {self.name}: warmup_s and margin must be >= 0")
        self._template = FeedAxisEstimator(m0, self.lag)
        self._c3 = C3Torque(m0.drive, m0.lowpass_hz, m0.sample_rate_hz, m0.lugre)
        self.smoothers = [FixedLagSmoother(m.design(), self.lag) for m in bank.models]
        self.warmup = round(warmup_s * m0.sample_rate_hz)
        self.margin = float(margin)
        self.all_members = bool(all_members)
        d = m0.drive
        self._gain = d.efficiency / d.transmission
        self._force_gain: float | None = None
        if m0.kind == "linear":
            self._force_gain = -self._gain
        elif m0.moment_arm_m is not None:
            self._force_gain = -self._gain / m0.moment_arm_m
        self._running = np.zeros(len(self.smoothers), dtype=bool)
        self._pos_hist = np.zeros(0)
        self._tau_hist = np.zeros(0)
        self._buf = np.empty(2 * self.warmup)
        self._fill = 0
        self._started = False

    @property
    def delay_samples(self) -> int:
        return self.lag

    def output_channels(self) -> list[ChannelInfo]:
        out = self._template.output_channels()
        return [
            ChannelInfo(c.name, c.unit, c.description + ", position-scheduled bank") for c in out
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self._template.reset(sample_rate_hz)  # checks the rate
        self._c3.reset()
        for sm in self.smoothers:
            sm.reset()
        self._running[:] = False
        self._pos_hist = np.zeros(0)
        self._tau_hist = np.zeros(0)
        self._fill = 0
        self._started = False

    def torque(
        self, current_a: ArrayLike1, speed_rad_s: ArrayLike1, position_cmd: ArrayLike1
    ) -> NDArray[np.float64]:
        """Scheduled τ̂_a (N·m, motor side) of one chunk, delayed by ``lag`` samples."""
        cur = np.ascontiguousarray(current_a, dtype=np.float64)
        spd = np.ascontiguousarray(speed_rad_s, dtype=np.float64)
        pos = np.asarray(position_cmd, dtype=np.float64)
        n = len(cur)
        if not (n == len(spd) == len(pos)):
            raise InputDataError(f"block {self.name}: input channels differ in length")
        if n == 0:
            return np.zeros(0)
        if not np.all(np.isfinite(pos)):
            raise InputDataError(f"block {self.name}: non-finite commanded position")
        if not self._started:
            # before the first sample the axis stood at its first commanded position
            self._pos_hist = np.full(self.lag, pos[0])
        # the commanded position delayed by the lag: the position the estimate refers to
        allx = np.concatenate([self._pos_hist, pos])
        x, self._pos_hist = allx[:n], allx[n:]
        w = self.bank.weights(x)
        active = self.bank.active(x, self.margin)
        if self.all_members:
            active[:] = True
        tau = self._c3.process(cur, spd)
        base = self._append_history(tau)
        tau_all = self._tau_hist
        out = np.zeros(n)
        for j, sm in enumerate(self.smoothers):
            col = active[:, j]
            if col[0] and col[-1] and col.all():
                edges = np.array([0, n])
            elif not col.any():
                self._running[j] = False
                continue
            else:
                a = col.astype(np.int8)
                edges = np.flatnonzero(np.diff(np.concatenate([[0], a, [0]])))
            for s0, s1 in zip(edges[::2], edges[1::2], strict=True):
                if not (s0 == 0 and self._running[j]):
                    sm.reset()
                    if self._started or s0 > 0:
                        sm.process(tau_all[max(0, base + s0 - self.warmup) : base + s0])
                y = sm.process(tau[s0:s1])[:, 0]
                out[s0:s1] += w[s0:s1, j] * y
            self._running[j] = bool(col[-1])
        self._started = True
        return out

    def _append_history(self, tau: NDArray[np.float64]) -> int:
        """Append a chunk's C3 torque to the history buffer; returns the chunk's start index in
        ``self._tau_hist`` (at least ``warmup`` samples, or all since the start, precede it).

        The buffer keeps room for 2·warmup samples and moves the last ``warmup`` to its front
        only when full (amortised cost per sample O(1), no per-chunk copy of the history).
        """
        n = len(tau)
        buf = self._buf
        if self._fill + n > len(buf):
            keep = min(self._fill, self.warmup)
            cap = max(2 * self.warmup, keep + n)
            new = np.empty(cap)
            new[:keep] = buf[self._fill - keep : self._fill]
            self._buf, buf, self._fill = new, new, keep
        base = self._fill
        buf[base : base + n] = tau
        self._fill = base + n
        self._tau_hist = buf[: self._fill]
        return base

    def process(self, chunk: Chunk) -> BlockOutput:
        tau = self.torque(
            chunk.data[self.inputs[0]], chunk.data[self.inputs[1]], chunk.data[self.inputs[2]]
        )
        ax = self.bank.axis
        out = {f"{ax}/load_est": self._gain * tau}
        if self._force_gain is not None:
            out[f"{ax}/force_est"] = self._force_gain * tau
        return BlockOutput(out)
