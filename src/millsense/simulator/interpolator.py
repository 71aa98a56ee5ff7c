"""CNC interpolator: position commands along a polyline at feed × override, acceleration-limited.

Every interpolation period T (3 ms, Aslan §0: 333 Hz) the path speed v is advanced by

    v⁺ = max(v − a·T, min(v + a·T, f_i·o(t), v_brake)),   s⁺ = s + (v + v⁺)·T/2,

with f_i the programmed feed of the current segment, o(t) the effective override and
``v_brake`` the look-ahead limit: for every segment boundary j ahead (remaining distance D_j,
limit ``v_j = min(min(f_j, f_j+1)·o, v_corner,j)`` and 0 at the path end, v_corner from the
corner angle, :func:`junction_speeds`) the larger of v_j and the speed from which a discrete
deceleration at a reaches v_j in D_j: ``v²/(2a) + v·T ≤ D_j − v·T/2 + v_j²/(2a)``, solved for
v (a speed at or below v_j needs no braking for that boundary, so collinear vertices of a
finely sampled path do not slow the feed). So
|dv/dt| ≤ a always; an override cut or feed hold (o = 0) decelerates at a and stops within
``v²/(2a) + v·T`` (the discrete overhead is one period).

Override commands reach the interpolator after a latency and are quantised
(:class:`OverrideChannel`): an open CNC ≈ 2.5 ms continuous (Munasinghe §M1), a closed CNC
override switch 10 % steps, ≤ 200 %, ≈ 120 ms (Munasinghe §M9).

Arc length is measured on the first three columns (m); a segment with no linear motion (pure
rotation of a 5-axis path) is measured in rad with its feed in rad/s
(docs/decisions/0034-interpolator-arc-length-look-ahead-and-overrides.md). Results are resumable:
:meth:`Interpolator.advance` called chunk by chunk gives the same samples as one call when the
override commands are the same.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from millsense.core.errors import InputDataError


@dataclass(frozen=True)
class OverrideChannel:
    """How a feed-override command reaches the interpolator.

    Attributes
    ----------
    latency_s : delay between the command and its effect, s.
    step : quantisation step (fraction, e.g. 0.1 for 10 %); 0 = continuous.
    max_override : upper clip (fraction, e.g. 1.5 or 2.0).
    """

    latency_s: float = 2.5e-3
    step: float = 0.0
    max_override: float = 1.5

    @classmethod
    def open_cnc(cls) -> OverrideChannel:
        """Open CNC: ≈ 2.5 ms, continuous (Munasinghe §M1); Aslan's 20–150 % range."""
        return cls(latency_s=2.5e-3, step=0.0, max_override=1.5)

    @classmethod
    def closed_cnc(cls) -> OverrideChannel:
        """Closed CNC override switch: 10 % steps, ≤ 200 %, ≈ 120 ms (Munasinghe §M9)."""
        return cls(latency_s=0.120, step=0.10, max_override=2.0)

    def quantise(self, value: float) -> float:
        """The override the CNC realises for a requested value (nearest step, clipped)."""
        v = min(max(value, 0.0), self.max_override)
        if self.step > 0:
            v = round(v / self.step) * self.step
        return v


@numba.njit(cache=True)
def _profile_kernel(
    state: np.ndarray,
    override: np.ndarray,
    cum: np.ndarray,
    feed: np.ndarray,
    corner: np.ndarray,
    rapid: np.ndarray,
    acc: float,
    period: float,
    horizon: float,
    out_s: np.ndarray,
    out_v: np.ndarray,
) -> None:
    """state = [s, v, segment]; advances len(override) periods writing s and v after each.

    ``corner[j]`` is the junction speed limit at the end of segment j (m/s, inf: none);
    ``rapid[j]`` is 1 on a rapid (G0) segment, whose speed the feed override does not scale
    (only a feed hold, o = 0, stops it).
    """
    n_seg = feed.shape[0]
    s_end = cum[n_seg]
    for k in range(override.shape[0]):
        s, v, seg = state[0], state[1], int(state[2])
        o = override[k]
        o_rapid = 1.0 if o > 0.0 else 0.0
        cap = feed[seg] * (o_rapid if rapid[seg] else o)
        # look-ahead over boundaries within the braking horizon
        j = seg
        while j < n_seg:
            d = cum[j + 1] - s
            if j > seg and d > horizon:
                break
            if j == n_seg - 1:
                vj = 0.0
            else:
                fj = feed[j] * (o_rapid if rapid[j] else o)
                fj1 = feed[j + 1] * (o_rapid if rapid[j + 1] else o)
                vj = min(min(fj, fj1), corner[j])
            # v²/(2a) + v·T + v_prev·T/2 ≤ d + vj²/(2a)
            rhs = d - v * period / 2.0 + vj * vj / (2.0 * acc)
            if rhs <= 0.0:
                vb = 0.0
            else:
                vb = acc * (-period + math.sqrt(period * period + 2.0 * rhs / acc))
            # at or below vj this boundary never needs braking (its discrete overhead v·T
            # only applies to a speed that must still come down)
            if vb < vj:
                vb = vj
            if vb < cap:
                cap = vb
            j += 1
        v_new = min(v + acc * period, cap)
        if v_new < v - acc * period:
            v_new = v - acc * period
        if v_new < 0.0:
            v_new = 0.0
        s_new = s + (v + v_new) * period / 2.0
        scale = s_end if s_end > 1.0 else 1.0
        if s_new >= s_end - 1e-12 * scale or (v_new == 0.0 and s_end - s_new < 1e-9 * scale):
            s_new = s_end
            v_new = 0.0
        while seg < n_seg - 1 and s_new >= cum[seg + 1]:
            seg += 1
        state[0], state[1], state[2] = s_new, v_new, seg
        out_s[k] = s_new
        out_v[k] = v_new


def junction_speeds(
    delta: np.ndarray, linear: np.ndarray, accel: float, tolerance_m: float
) -> np.ndarray:
    """Speed limit at each interior vertex of a polyline from its corner angle, m/s.

    Parameters
    ----------
    delta : (n, d) segment vectors (first three columns m; rotary columns rad).
    linear : (n,) True where a segment moves the linear axes (else a pure rotation).
    accel : path acceleration limit a, m/s².
    tolerance_m : corner deviation δ, m.

    Returns
    -------
    (n − 1,) limit at the end of segment j (inf for collinear segments).

    Notes
    -----
    Junction deviation (the cornering rule of grbl-type CNC planners): the corner is
    treated as an arc tangent to both segments that passes δ from the vertex; with
    ``s = sin(θ/2) = √((1 + u_j·u_{j+1})/2)`` (θ the angle between the segments, so s = 1 for
    collinear ones) its radius is ``R = δ·s/(1 − s)`` and the centripetal limit ``v²/R ≤ a``
    gives ``v = √(a·R)``. A junction between a pure rotation and a linear move (directions in
    different spaces) stops (v = 0). Decision "Interpolator junction speed".
    """
    n = delta.shape[0]
    out = np.full(max(n - 1, 0), np.inf)
    if n < 2:
        return out
    lin = delta[:, :3]
    norm = np.linalg.norm(lin, axis=1)
    u = lin / np.where(norm > 0, norm, 1.0)[:, None]
    cos_turn = np.clip(np.sum(u[:-1] * u[1:], axis=1), -1.0, 1.0)
    s = np.sqrt(0.5 * (1.0 + cos_turn))
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = tolerance_m * s / (1.0 - s)
    v = np.where(s < 1.0, np.sqrt(accel * np.maximum(radius, 0.0)), np.inf)
    rot_rot = ~linear[:-1] & ~linear[1:]
    mixed = linear[:-1] != linear[1:]
    if delta.shape[1] > 3 and np.any(rot_rot):
        # two pure rotations: the same rule on the rotary directions (rad for m)
        r = delta[:, 3:]
        rn = np.linalg.norm(r, axis=1)
        ur = r / np.where(rn > 0, rn, 1.0)[:, None]
        cr = np.clip(np.sum(ur[:-1] * ur[1:], axis=1), -1.0, 1.0)
        sr = np.sqrt(0.5 * (1.0 + cr))
        with np.errstate(divide="ignore", invalid="ignore"):
            vr = np.where(sr < 1.0, np.sqrt(accel * tolerance_m * sr / (1.0 - sr)), np.inf)
        v = np.where(rot_rot, vr, v)
    v = np.where(mixed, 0.0, v)
    out[:] = v
    return out


class Interpolator:
    """Resumable feed interpolator along a polyline.

    Parameters
    ----------
    path : (N, 3) or (N, 5) points, m (and rad for the rotary columns).
    feed : (N−1,) programmed feed per segment, m/s (rad/s for pure rotations), or a scalar.
    accel : path acceleration limit, m/s².
    period_s : interpolation period, s (3 ms, Aslan §0).
    channel : override latency and quantisation.
    initial_override : override in effect at t = 0 (fraction), quantised by ``channel``.
    corner_tolerance_m : corner (junction) deviation δ, m: the speed through a vertex is
        limited to ``√(a·δ·sin(θ/2)/(1 − sin(θ/2)))`` (θ/2 from the direction change),
        unlimited for collinear segments (decision "Interpolator junction speed").
    rapid : (N−1,) True on rapid (G0) segments, or None (none). A rapid runs at its programmed
        (rapid) rate whatever the feed override; a feed hold (override 0) stops it too, as on a
        CNC, where G0 answers the rapid override, not the feed override (decision 1665).
    """

    def __init__(
        self,
        path: np.ndarray,
        feed: np.ndarray | float,
        accel: float,
        *,
        period_s: float = 3e-3,
        channel: OverrideChannel | None = None,
        initial_override: float = 1.0,
        corner_tolerance_m: float = 1e-5,
        rapid: np.ndarray | None = None,
    ) -> None:
        pts = np.asarray(path, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] not in (3, 5) or pts.shape[0] < 2:
            raise InputDataError(f"interpolator: path must be (N≥2, 3 or 5), got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise InputDataError("interpolator: path has non-finite points")
        seg = np.diff(pts, axis=0)
        lin = np.linalg.norm(seg[:, :3], axis=1)
        rot = np.linalg.norm(seg[:, 3:], axis=1) if pts.shape[1] == 5 else np.zeros(len(lin))
        length = np.where(lin > 1e-12, lin, rot)
        keep = length > 1e-12
        if not np.any(keep):
            raise InputDataError("interpolator: path has zero length")
        f = np.broadcast_to(np.asarray(feed, dtype=np.float64), (len(seg),))
        if np.any(~np.isfinite(f)) or np.any(f <= 0):
            raise InputDataError("interpolator: feed must be finite and > 0 on every segment")
        if not accel > 0:
            raise InputDataError(f"interpolator: acceleration limit must be > 0, got {accel}")
        if rapid is None:
            rap = np.zeros(len(seg), dtype=np.bool_)
        else:
            rap = np.asarray(rapid, dtype=np.bool_)
            if rap.shape != (len(seg),):
                raise InputDataError(
                    f"interpolator: rapid mask must have {len(seg)} entries (one per segment), "
                    f"got {rap.shape}"
                )
        self.rapid = np.ascontiguousarray(rap[keep].astype(np.uint8))
        self._start = pts[:-1][keep]
        self._delta = seg[keep]
        self._len = length[keep]
        self.feed = np.ascontiguousarray(f[keep])
        if not corner_tolerance_m > 0:
            raise InputDataError(
                f"interpolator: corner tolerance must be > 0, got {corner_tolerance_m}"
            )
        self.cum = np.concatenate([[0.0], np.cumsum(self._len)])
        self.corner = np.ascontiguousarray(
            junction_speeds(self._delta, lin[keep] > 1e-12, float(accel), corner_tolerance_m)
        )
        self.accel = float(accel)
        self.period = float(period_s)
        self.channel = channel or OverrideChannel.open_cnc()
        v_top = float(self.feed.max() * max(self.channel.max_override, 1.0))
        self._horizon = v_top**2 / (2 * self.accel) + 4 * v_top * self.period
        self._state = np.zeros(3)
        self._k = 0
        # effective override schedule: (time it takes effect, realised value)
        self._events: list[tuple[float, float]] = [
            (-math.inf, self.channel.quantise(initial_override))
        ]

    @property
    def length(self) -> float:
        """Total path parameter (m; a rotary-only segment counts its rotation in rad)."""
        return float(self.cum[-1])

    def tip_arc_length(self, s: np.ndarray) -> np.ndarray:
        """Tool-tip arc length (m, first three coordinates only) at path parameters ``s``.

        The interpolator's parameter advances over a rotary-only segment (A/C positioning) by
        its rotation, so that the segment takes time; the tip does not move along the path
        there. Engagement schedules are laid out on the tip's arc length
        (:meth:`millsense.simulator.machine.Job.arc_length`), so the process must be looked
        up with this map (decision "Path parameter and tip arc length").
        """
        lin = np.linalg.norm(self._delta[:, :3], axis=1)
        lin = np.where(lin > 1e-12, lin, 0.0)
        arc = np.concatenate([[0.0], np.cumsum(lin)])
        ss = np.asarray(s, dtype=np.float64)
        seg = np.clip(np.searchsorted(self.cum, ss, side="right") - 1, 0, len(self._len) - 1)
        frac = np.clip((ss - self.cum[seg]) / self._len[seg], 0.0, 1.0)
        return np.asarray(arc[seg] + frac * lin[seg])

    @property
    def time_s(self) -> float:
        """Time of the next sample to be produced, s."""
        return (self._k + 1) * self.period

    @property
    def done(self) -> bool:
        """True once the path end is reached (v = 0 at s = length)."""
        return bool(self._state[0] >= self.cum[-1] and self._state[1] == 0.0)

    def set_override(self, value: float, at_time_s: float | None = None) -> None:
        """Command a feed override (fraction; 0 = feed hold) at ``at_time_s`` (default: now).

        It takes effect ``channel.latency_s`` later, quantised by the channel.
        """
        t_cmd = self._k * self.period if at_time_s is None else float(at_time_s)
        t_eff = t_cmd + self.channel.latency_s
        self._events.append((t_eff, self.channel.quantise(value)))
        self._events.sort(key=lambda e: e[0])

    def override_at(self, t: np.ndarray) -> np.ndarray:
        """Effective override at times ``t`` (s)."""
        times = np.array([e[0] for e in self._events])
        vals = np.array([e[1] for e in self._events])
        idx = np.searchsorted(times, np.asarray(t), side="right") - 1
        return np.asarray(vals[idx])

    def advance(self, n_periods: int) -> dict[str, np.ndarray]:
        """Produce the next ``n_periods`` interpolation samples.

        Returns
        -------
        dict with ``t`` (s, sample times, the first call starts at T), ``s`` (m, arc length),
        ``v`` (m/s, path speed), ``override`` (fraction, effective), ``position`` (n, d) and
        ``velocity`` (n, d) in path units (m, rad; m/s, rad/s).
        """
        t = (self._k + 1 + np.arange(n_periods)) * self.period
        ovr = np.ascontiguousarray(self.override_at(t - 0.5 * self.period), dtype=np.float64)
        s = np.empty(n_periods)
        v = np.empty(n_periods)
        _profile_kernel(
            self._state,
            ovr,
            self.cum,
            self.feed,
            self.corner,
            self.rapid,
            self.accel,
            self.period,
            self._horizon,
            s,
            v,
        )
        self._k += n_periods
        pos, vel = self.sample_path(s, v)
        return {"t": t, "s": s, "v": v, "override": ovr, "position": pos, "velocity": vel}

    def sample_path(self, s: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities at arc lengths ``s`` with path speeds ``v``."""
        seg = np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self._len) - 1)
        frac = (s - self.cum[seg]) / self._len[seg]
        pos = self._start[seg] + frac[:, None] * self._delta[seg]
        vel = (v / self._len[seg])[:, None] * self._delta[seg]
        return pos, vel


class Upsampler:
    """Fine interpolation of the 333 Hz commands to the drive rate (e.g. 10 kHz), resumable.

    ``linear``: straight lines between consecutive coarse samples (one coarse period of
    delay, as a CNC's fine interpolator). ``hermite``: cubic Hermite with the coarse
    velocities, same delay, continuous velocity.

    On the :class:`Interpolator`'s samples, whose path advances by the trapezoid
    ``s⁺ − s = (v + v⁺)·T/2``, the Hermite cubic's cubic term ``2(p₀ − p₁) + T(v₀ + v₁)``
    vanishes: between two samples the position is the integral of the velocity ramped
    linearly from v to v⁺, its acceleration the interpolator's own (v⁺ − v)/T, constant over
    the period. ``linear`` instead holds the velocity over each period and steps it by a·T at
    every sample while accelerating: a line at 1/T (333 Hz) and its harmonics in the drives'
    velocity reference (decision 1682).
    """

    def __init__(
        self,
        ratio: int,
        initial_position: np.ndarray,
        method: str = "linear",
        initial_velocity: np.ndarray | None = None,
    ) -> None:
        if ratio < 1:
            raise InputDataError(f"upsampler: ratio must be ≥ 1, got {ratio}")
        if method not in ("linear", "hermite"):
            raise InputDataError(f"upsampler: method '{method}' (linear, hermite)")
        self.ratio = int(ratio)
        self.method = method
        self._p = np.asarray(initial_position, dtype=np.float64).copy()
        self._v = (
            np.zeros_like(self._p)
            if initial_velocity is None
            else np.asarray(initial_velocity, dtype=np.float64).copy()
        )

    def __call__(self, position: np.ndarray, velocity: np.ndarray, period_s: float) -> np.ndarray:
        """(n·ratio, d) fine samples for the (n, d) coarse samples that follow the last ones."""
        p1 = np.asarray(position, dtype=np.float64)
        v1 = np.asarray(velocity, dtype=np.float64)
        p0 = np.vstack([self._p[None, :], p1[:-1]])
        v0 = np.vstack([self._v[None, :], v1[:-1]])
        u = (np.arange(1, self.ratio + 1) / self.ratio)[None, :, None]
        if self.method == "linear":
            fine = p0[:, None, :] + u * (p1 - p0)[:, None, :]
        else:
            h00 = 2 * u**3 - 3 * u**2 + 1
            h10 = u**3 - 2 * u**2 + u
            h01 = -2 * u**3 + 3 * u**2
            h11 = u**3 - u**2
            fine = (
                h00 * p0[:, None, :]
                + h10 * period_s * v0[:, None, :]
                + h01 * p1[:, None, :]
                + h11 * period_s * v1[:, None, :]
            )
        self._p = p1[-1].copy()
        self._v = v1[-1].copy()
        return np.asarray(fine.reshape(-1, p1.shape[1]))
