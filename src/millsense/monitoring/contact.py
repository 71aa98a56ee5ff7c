"""Sensorless tool–workpiece contact detection and the rotational centre (seed 004 ch. 3).

Contact (Lee Secs. 3.2.1, 3.3.2, Fig. 3.6; digest §2.7): the spindle torque of an air-cut
motion (same spindle/C motion, no feed) is subtracted from that of the cut motion, which cancels
the repeatable ripple of bearings and cogging; both are smoothed by a moving average (100
samples at 100 kHz in the thesis; decision 1526: applied to the difference, which is the same
for a linear filter). Over the revolution before the feed starts (t₀+4T ≤ t < t₀+5T) the mean η
and standard deviation κ of Δτ are taken; the first sample after it above η + 4κ is point A
(decision 1526: the first that stays above for one moving-average length, so that a noise
excursion of the smoothed difference — a few in a million samples at 4κ — is not a contact); the
walk back from A to the last sample at or below η + κ is point B (decision 1533: the thesis
walks back to η, which the smoothed noise crosses repeatedly just before the rise, so B landed
up to 6 µm of approach early); a least-squares line through Δτ from B to the end of the
confirming run (A + one moving-average length) crosses η at point C, the contact time t_C, and
the axis position at t_C is the contact coordinate.

Rotational centre (Lee Sec. 3.3.3, digest §2.8 [S]): a geometric circle fit by Gauss–Newton
(Gander, Golub & Strebel 1994) of ≥ 3 contact points: residual r_i = ‖p_i − c‖ − R, Jacobian
row [−(x_i−x_c)/d_i, −(y_i−y_c)/d_i, −1], start from the algebraic (Kåsa) fit. The uncertainty
is the usual least-squares one, s²(JᵀJ)⁻¹ with s² = Σr²/(n−3) (decision 1527; the thesis gives
none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind, Severity

FloatArray = NDArray[np.float64]

#: Seed 004 §3.2: moving-average length (samples at 100 kHz) and threshold factor.
MOVING_AVERAGE = 100
K_SIGMA = 4.0
#: Preliminary revolutions before the feed starts; η, κ over the last of them.
PRELIMINARY_REVS = 5


@dataclass(frozen=True)
class Contact:
    """One detected contact.

    Attributes
    ----------
    time_s : contact time t_C since the spindle start t₀, s.
    position : axis position at t_C (unit of the position signal).
    eta, kappa : mean and standard deviation of Δτ over the reference revolution.
    index_a, index_b : samples of points A (threshold crossing) and B (walk-back to η + κ).
    slope : slope of the regression line, torque unit per s.
    """

    time_s: float
    position: float
    eta: float
    kappa: float
    index_a: int
    index_b: int
    slope: float


def detect_contact(
    torque_cut: FloatArray,
    torque_air: FloatArray,
    position: FloatArray,
    sample_rate_hz: float,
    period_s: float,
    moving_average: int = MOVING_AVERAGE,
    k_sigma: float = K_SIGMA,
    preliminary_revs: int = PRELIMINARY_REVS,
) -> Contact:
    """Contact time and position of one cut motion (module notes; Lee Fig. 3.6).

    The signals start at the spindle start t₀ and share one clock; ``period_s`` is the
    rotation period T.

    Raises
    ------
    InputDataError
        Signals of different lengths, a record shorter than the reference revolution, or no
        sample above the threshold (no contact).
    """
    cut = np.asarray(torque_cut, dtype=np.float64)
    air = np.asarray(torque_air, dtype=np.float64)
    pos = np.asarray(position, dtype=np.float64)
    if not (cut.shape == air.shape == pos.shape) or cut.ndim != 1:
        raise InputDataError(
            f"contact: torque_cut, torque_air and position must be 1-D of one length, got "
            f"{cut.shape}, {air.shape}, {pos.shape}"
        )
    if not (sample_rate_hz > 0 and period_s > 0):
        raise InputDataError("contact: sample_rate_hz and period_s must be positive")
    fs = float(sample_rate_hz)
    i0 = round((preliminary_revs - 1) * period_s * fs)
    i1 = round(preliminary_revs * period_s * fs)
    if i1 >= cut.size:
        raise InputDataError(
            f"contact: the record ({cut.size / fs:.3f} s) ends before the reference revolution "
            f"({preliminary_revs} × {period_s:g} s)"
        )
    d = uniform_filter1d(cut - air, size=max(int(moving_average), 1), mode="nearest")
    ref = d[i0:i1]
    eta = float(np.mean(ref))
    kappa = float(np.std(ref))
    # A: first sample of a run of ≥ `persist` samples above the threshold (decision 1526)
    persist = max(int(moving_average), 1)
    over = (d[i1:] > eta + k_sigma * kappa).astype(np.int64)
    runs = np.convolve(over, np.ones(persist, dtype=np.int64), mode="valid")
    above = np.nonzero(runs == persist)[0]
    if above.size == 0:
        raise InputDataError(
            f"contact: the torque difference never exceeds η + {k_sigma:g}κ "
            f"({eta + k_sigma * kappa:.4g}) after the reference revolution: no contact"
        )
    a = i1 + int(above[0])
    # B: where the rise leaves the noise band, the last sample at or below η + κ (decision
    # 1533; the smoothed noise crosses η itself again and again just before the rise); the
    # line runs through the rise from B to the end of the confirming run
    below = np.nonzero(d[i1 : a + 1] <= eta + kappa)[0]
    b = i1 + int(below[-1]) if below.size else i1
    if a - b < 2:
        b = max(a - 2, 0)
    end = min(a + persist - 1, d.size - 1)
    t = np.arange(b, end + 1) / fs
    slope, intercept = np.polyfit(t, d[b : end + 1], 1)
    if not slope > 0:
        raise InputDataError("contact: the torque does not rise between points B and A")
    t_c = (eta - intercept) / slope
    x_c = float(np.interp(t_c * fs, np.arange(pos.size), pos))
    return Contact(float(t_c), x_c, eta, kappa, a, b, float(slope))


@dataclass(frozen=True)
class CircleFit:
    """Geometric circle fit: centre, diameter, their standard uncertainties, residuals."""

    x_c: float
    y_c: float
    diameter: float
    sigma_x: float
    sigma_y: float
    sigma_diameter: float
    residuals: FloatArray
    iterations: int


def fit_circle(x: FloatArray, y: FloatArray, tol: float = 1e-12, max_iter: int = 50) -> CircleFit:
    """Gauss–Newton geometric circle fit (module notes) of ≥ 3 points.

    Raises
    ------
    InputDataError
        Fewer than 3 points, or collinear points.
    """
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.shape != ys.shape or xs.ndim != 1 or xs.size < 3:
        raise InputDataError(f"circle fit: needs ≥ 3 points (x, y of one length), got {xs.shape}")
    # algebraic (Kåsa) start: x² + y² + D x + E y + F = 0
    a = np.column_stack([xs, ys, np.ones_like(xs)])
    rhs = -(xs**2 + ys**2)
    sol, *_ = np.linalg.lstsq(a, rhs, rcond=None)
    if np.linalg.matrix_rank(a) < 3:
        raise InputDataError("circle fit: the points are collinear")
    xc, yc = -sol[0] / 2.0, -sol[1] / 2.0
    r = math.sqrt(max(xc**2 + yc**2 - sol[2], 0.0))
    p = np.array([xc, yc, r])
    it = 0
    for _ in range(max_iter):
        it += 1
        dx, dy = xs - p[0], ys - p[1]
        dist = np.hypot(dx, dy)
        res = dist - p[2]
        jac = np.column_stack([-dx / dist, -dy / dist, -np.ones_like(dist)])
        step, *_ = np.linalg.lstsq(jac, res, rcond=None)
        p = p - step
        if np.max(np.abs(step)) <= tol * max(1.0, abs(p[2])):
            break
    dx, dy = xs - p[0], ys - p[1]
    dist = np.hypot(dx, dy)
    res = dist - p[2]
    jac = np.column_stack([-dx / dist, -dy / dist, -np.ones_like(dist)])
    dof = xs.size - 3
    s2 = float(res @ res) / dof if dof > 0 else math.nan
    cov = s2 * np.linalg.inv(jac.T @ jac)
    sd = np.sqrt(np.abs(np.diag(cov)))
    return CircleFit(
        float(p[0]),
        float(p[1]),
        float(2 * p[2]),
        float(sd[0]),
        float(sd[1]),
        float(2 * sd[2]),
        res,
        it,
    )


class ContactBlock(Block):
    """Streaming contact detector for one cut motion (seed 004 Fig. 3.6).

    The stream starts at the spindle start t₀ of the cut motion; ``air_torque_nm`` is the
    torque of the matching air-cut motion on the same clock (recorded before). Samples are
    buffered; once Δτ has stayed above η + 4κ for one moving-average length, and one more
    length of samples has arrived (so the centred average near point A no longer depends on
    where the stream was cut), :func:`detect_contact` runs on the buffer and a ``contact``
    NOTE event carries t_C and the position. One event per motion.

    Parameters
    ----------
    air_torque_nm : air-cut torque from t₀, N·m (at least as long as the cut motion).
    period_s : rotation period T, s.
    torque_channel, position_channel : torque command (N·m) and axis position (m).
    """

    def __init__(
        self,
        air_torque_nm: FloatArray,
        period_s: float,
        torque_channel: str = "spindle/torque_cmd",
        position_channel: str = "x/position",
        moving_average: int = MOVING_AVERAGE,
        k_sigma: float = K_SIGMA,
        preliminary_revs: int = PRELIMINARY_REVS,
        name: str = "contact",
    ) -> None:
        if not (period_s > 0 and math.isfinite(period_s)):
            raise ConfigError(f"contact: period_s must be positive, got {period_s!r}")
        self.air = np.asarray(air_torque_nm, dtype=np.float64)
        self.period_s = float(period_s)
        self.torque_channel = torque_channel
        self.position_channel = position_channel
        self.moving_average = max(int(moving_average), 1)
        self.k_sigma = float(k_sigma)
        self.preliminary_revs = int(preliminary_revs)
        self.name = name
        self.inputs = (torque_channel, position_channel)
        self.result: Contact | None = None

    def output_channels(self) -> list[ChannelInfo]:
        return []

    def reset(self, sample_rate_hz: float) -> None:
        self.fs = float(sample_rate_hz)
        self._cut = np.empty(self.air.size)
        self._pos = np.empty(self.air.size)
        self._n = 0
        self._ref: tuple[float, float] | None = None
        self._run = 0
        self._found_at = -1
        self.result = None

    def process(self, chunk: Chunk) -> BlockOutput:
        out = BlockOutput()
        if self.result is not None:
            return out
        cut = np.asarray(chunk.data[self.torque_channel], dtype=np.float64)
        start = self._n
        if start + cut.size > self.air.size:
            raise InputDataError(
                f"{self.name}: the cut motion is longer than the air-cut reference "
                f"({self.air.size} samples)"
            )
        self._cut[start : start + cut.size] = cut
        self._pos[start : start + cut.size] = chunk.data[self.position_channel]
        self._n += cut.size
        i1 = round(self.preliminary_revs * self.period_s * self.fs)
        ma = self.moving_average
        if self._found_at < 0 and self._n > i1 + ma:
            # cheap screening on the raw difference smoothed causally; the exact detection
            # below runs on the whole buffer with the centred average
            lo = max(start, i1) - ma
            seg = self._cut[lo : self._n] - self.air[lo : self._n]
            sm = np.convolve(seg, np.ones(ma) / ma, mode="valid")
            if self._ref is None:
                i0 = round((self.preliminary_revs - 1) * self.period_s * self.fs)
                d = self._cut[i0:i1] - self.air[i0:i1]
                ref = np.convolve(d, np.ones(ma) / ma, mode="valid")
                self._ref = (float(np.mean(ref)), float(np.std(ref)))
            eta, kappa = self._ref
            over = sm > eta + self.k_sigma * kappa
            idx = np.arange(over.size)
            last_false = np.maximum.accumulate(np.where(over, -1, idx))
            run = np.where(last_false < 0, idx + 1 + self._run, idx - last_false)
            hit = np.nonzero(run >= ma)[0]
            if hit.size:
                self._found_at = lo + ma - 1 + int(hit[0])
            else:
                self._run = int(run[-1]) if run.size else self._run
        if self._found_at >= 0 and self._n >= self._found_at + 2 * ma:
            n = self._found_at + 2 * ma
            c = detect_contact(
                self._cut[:n],
                self.air[:n],
                self._pos[:n],
                self.fs,
                self.period_s,
                self.moving_average,
                self.k_sigma,
                self.preliminary_revs,
            )
            self.result = c
            sample = round(c.time_s * self.fs)
            out.events.append(
                Event(
                    time_s=chunk.t0_s + c.time_s,
                    kind=EventKind.NOTE,
                    source=self.name,
                    message=f"tool-workpiece contact at {c.position:.6g} (t = {c.time_s:.5f} s)",
                    name="contact",
                    value=c.position,
                    sample=sample,
                    severity=Severity.INFO,
                    values={"eta_nm": c.eta, "kappa_nm": c.kappa, "slope_nm_s": c.slope},
                )
            )
        return out


def make_contact_block(**options: Any) -> Block:
    """Seed 004 ch. 3 contact detector (needs ``air_torque_nm`` and ``period_s``)."""
    return ContactBlock(**options)
