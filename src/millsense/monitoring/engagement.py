"""Streaming depth-of-cut, runout and K_t monitor (seed 004 ch. 2), once per revolution.

The spindle angle is integrated from the speed channel (decision 1524: the angle reference of
the runout direction is the stream start, flute 0 at angle 0; a spindle index pulse would fix
it on a real machine). At the end of every revolution the samples of that revolution give the
Fourier-series coefficients T_k = mean(τ e^{−ikφ}) at k = 1 and at the tooth-passing harmonics
k = N…KN, and :class:`~millsense.monitoring.torque_spectrum.SpectrumIdentifier` returns
d_a, d_r, θ_st, θ_ex, K_t, ε, θ_ec and the reliability index σ (Lee Fig. 2.9). Revolutions
whose mean torque is below ``min_torque_nm`` (air) give NaN; their mean torque at the running
speed is the air-cut reference (unless ``air_torque_nm`` is given) that the mean torque of a
cut revolution is taken against where the harmonics do not observe the edge coefficient
(decision 1806). The values are held on the
output channels from the sample after the revolution ends until the next one.

A revolution whose highest tooth harmonic K·N·Ω/2π is not below the Nyquist frequency f_s/2
is not evaluated (decision 1734): at or above it the revolution's coefficient is another
harmonic's alias, and the fit scatters (a 4-flute slot at 10 000 rev/min sampled at 10 kHz
with 12 harmonics: d_a's standard deviation over the revolutions 0.76 mm against 0.03 mm with
the 7 below it). :func:`harmonics_below_nyquist` gives the harmonics a recording can hold at
its top speed; ``millsense monitor`` takes them.

Per chunk the work is one compiled call (decision 1535): the angle, the harmonic sums of the
running revolution (added sample by sample in the order of a whole-revolution sum, so any
chunking gives the same coefficients bit for bit) and, at a revolution's end, the fit from the
previous revolution's solution; only a revolution that needs the coarse grid search returns to
Python for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.monitoring import _spectrum_kernels as _sk
from millsense.monitoring.index_pulse import index_angle, index_state
from millsense.monitoring.torque_spectrum import (
    RUNOUT_RCOND,
    AveragedEstimate,
    EngagementEstimate,
    SpectrumIdentifier,
    ToolGeometry,
    identify_averaged,
)
from millsense.streaming.block import Block, BlockOutput, Chunk, HeldViews, held_views

_FIELDS = (
    ("axial_depth", "m", "axial depth of cut d_a (Lee Eq. 2.14 by harmonic fit)"),
    ("radial_depth", "m", "radial depth of cut d_r = r(cos θst − cos θex)"),
    ("entry_angle", "rad", "entry angle θ_st"),
    ("exit_angle", "rad", "exit angle θ_ex"),
    ("kt", "N/m^2", "specific cutting force K_t (Lee Eq. 2.19)"),
    ("runout", "m", "runout ε (Lee Eq. 2.18 / 2.20-2.22 re-derived)"),
    ("runout_angle", "rad", "runout direction λ (geometry convention)"),
    ("reliability", "1", "reliability index σ (Lee Eq. 2.23)"),
    ("axial_depth_sd", "m", "standard deviation of d_a from its harmonics (decision 1558)"),
)


#: Relative error (complex, one s.d.) of the spindle observer's response model from the
#: machine file at the tooth harmonics: ≈ 10 % in gain and a few degrees in phase against the
#: response measured on the virtual machine (decision 1554); `millsense monitor` gives it to
#: the equaliser it builds from a machine file (decision 1698). Kept after decision 1708,
#: whose commissioned model is within 3 % and 0.2° at 33–200 Hz in range 1 (0.5 % between
#: the tooth harmonics): range 2's motor admittance is the nameplate's still, and the motor's
#: torque ripple, synchronous with the revolution, adds to the harmonics what no response
#: holds (≈ 7 % of T_6 on the 3 mm slot of `monitoring.sensorless_engagement`); 2 % would
#: not determine that slot's depth either (2.41–3.20 mm).
OBSERVER_RESPONSE_REL_ERROR = 0.1

#: Reliability index σ (Lee Eq. 2.23) from which a revolution's estimate enters the summary:
#: the lowest σ among the results Lee's Tables 2.3–2.5 report (0.83), rounded down (decision
#: 1807).
RELIABLE_SIGMA = 0.8

#: Largest half-width of a cut's depth interval (two standard deviations, Δχ² ≤ 4), as a
#: fraction of d_a, with which its averaged harmonics determine the depth: Lee's accuracy
#: (Tables 2.3–2.5, d_a mostly within ±10 %) with 95 % confidence (decision 1698).
DEPTH_REL_TOL = 0.1


#: How far from 0 or π a steady side cut's fitted window may start or end, rad (10°; decision
#: 1738): the fits of steady up, down and slot cuts on the virtual machine land within 1°.
SIDE_CUT_TOL_RAD = math.radians(10.0)


def side_cut_window(entry_rad: float, exit_rad: float) -> bool:
    """Whether a fitted engagement window is a steady side cut's in the spindle angle's frame
    (decision 1738): it starts at 0 (up milling, a slot) or ends at π (down milling, a slot),
    within :data:`SIDE_CUT_TOL_RAD` (Lee Eq. 2.6 takes θ_ex ≈ π). A window inside the half-turn
    is a transient (an entry, an exit, a corner), or the spindle angle's zero is not the tool's
    reference, where the depths read wrong."""
    return bool(entry_rad <= SIDE_CUT_TOL_RAD or exit_rad >= math.pi - SIDE_CUT_TOL_RAD)


def determined(avg: AveragedEstimate) -> bool:
    """The averaged harmonics determine the cut's engagement (decision 1698): their estimate
    passes decision 1807's test (σ ≥ :data:`RELIABLE_SIGMA`, K_t > 0, K_e ≥ 0) and decision
    1738's (a side cut's window, :func:`side_cut_window`), the profile
    set of d_a is one interval (no second basin within the noise) inside the search range,
    and its half-width (two standard deviations) is at most :data:`DEPTH_REL_TOL` of d_a."""
    e = avg.estimate
    lo, hi = avg.depth_low_m, avg.depth_high_m
    return bool(
        e.reliability >= RELIABLE_SIGMA
        and side_cut_window(e.entry_rad, e.exit_rad)
        and e.kt_n_m2 > 0
        and e.edge_n_m >= 0
        and avg.connected
        and math.isfinite(lo)
        and math.isfinite(hi)
        and hi - lo <= 2 * DEPTH_REL_TOL * e.axial_depth_m
    )


#: Tooth-passing harmonics the engagement monitor uses where the recording holds them (Lee's
#: method needs the harmonics up to the depth's notch; the block's default).
DEFAULT_HARMONICS = 12
#: Fewest tooth-passing harmonics the fit is run with (the block's lower limit).
MIN_HARMONICS = 2


def harmonics_below_nyquist(
    n_flutes: int, speed_rpm: float, sample_rate_hz: float, wanted: int = DEFAULT_HARMONICS
) -> int:
    """The tooth-passing harmonics k = 1 … K (frequencies k·N·n/60) below the Nyquist
    frequency ``sample_rate_hz``/2 at ``speed_rpm``, at most ``wanted`` (decision 1734: a
    revolution's coefficient at or above it is another harmonic's alias). 0 where not even the
    tooth-passing frequency is below it."""
    if not (speed_rpm > 0 and sample_rate_hz > 0 and n_flutes >= 1):
        raise ValueError(
            f"harmonics_below_nyquist: need flutes ≥ 1, speed > 0 and rate > 0, got "
            f"{n_flutes}, {speed_rpm}, {sample_rate_hz}"
        )
    tooth_hz = n_flutes * speed_rpm / 60.0
    # the largest k with k·f_tooth < f_s/2 (strictly below)
    k = math.ceil(0.5 * sample_rate_hz / tooth_hz) - 1
    return int(max(0, min(wanted, k)))


#: Lee's monitoring cycle, s: one revolution at his 1200 min⁻¹ (seed 004 digest A3: "one
#: estimate per revolution, or per n revolutions"). ``millsense monitor`` takes the whole number
#: of revolutions nearest it at the recording's running speed (decision 1717).
MONITORING_CYCLE_S = 0.05


def cycle_revolutions(speed_rpm: float, cycle_s: float = MONITORING_CYCLE_S) -> int:
    """The revolutions of one monitoring cycle at ``speed_rpm``: the whole number nearest
    ``cycle_s`` of them, at least 1 (decision 1717: 1 below 1800 rev/min, 5 at 6000, 8 at
    10 000)."""
    if not (speed_rpm > 0 and math.isfinite(speed_rpm) and cycle_s > 0):
        raise ValueError(f"cycle_revolutions: need a positive speed, got {speed_rpm}")
    return max(1, round(speed_rpm / 60.0 * cycle_s))


@dataclass(frozen=True)
class DepthSummary:
    """The axial depth over many revolutions (decision 1558), in m: the median of the reliable
    revolutions' d_a, its standard error (1.2533 × the scatter / √n), the scatter (1.4826 ×
    the median absolute deviation) and the median of the revolutions' own standard
    deviations (:attr:`EngagementEstimate.axial_depth_sd_m`)."""

    n: int
    median_m: float
    standard_error_m: float
    scatter_m: float
    predicted_sd_m: float


def depth_summary(estimates: Sequence[EngagementEstimate]) -> DepthSummary:
    """:class:`DepthSummary` of ``estimates`` (the reliable revolutions; at least one)."""
    da = np.array([e.axial_depth_m for e in estimates], dtype=np.float64)
    med = float(np.median(da))
    scatter = 1.4826 * float(np.median(np.abs(da - med)))
    predicted = float(np.median([e.axial_depth_sd_m for e in estimates]))
    return DepthSummary(int(da.size), med, 1.2533 * scatter / math.sqrt(da.size), scatter,
                        predicted)  # fmt: skip


#: The outputs of a revolution not evaluated (read only: shared by every such revolution).
_NOT_EVALUATED = np.full(len(_FIELDS), math.nan)
_NOT_EVALUATED.flags.writeable = False


@dataclass(frozen=True)
class TorqueResponse:
    """A torque channel's frequency response to the cutting torque, tabulated for the
    engagement monitor's equaliser (decision 1554): ``table[r, j]`` at ``j·step_hz`` for speed
    range ``r`` (0 below ``switch_rad_s``, 1 from it; one range: the same row twice)."""

    step_hz: float
    switch_rad_s: float
    table: np.ndarray
    #: the response model's relative error at the tooth harmonics (complex, one s.d.): what a
    #: cut's averaged harmonics keep after the equaliser (decision 1698)
    rel_error: float = 0.0

    @classmethod
    def from_function(
        cls,
        response: Callable[[np.ndarray, int], np.ndarray],
        top_hz: float,
        switch_rad_s: float = math.inf,
        step_hz: float = 2.0,
        rel_error: float = 0.0,
    ) -> TorqueResponse:
        """Tabulate ``response(f_hz, range)`` from 0 to ``top_hz``."""
        f = np.arange(0.0, top_hz + step_hz, step_hz)
        rows = [np.asarray(response(f, r), dtype=np.complex128) for r in (0, 1)]
        return cls(float(step_hz), float(switch_rad_s), np.ascontiguousarray(np.stack(rows)),
                   float(rel_error))  # fmt: skip


class EngagementBlock(Block):
    """Per-revolution engagement monitor on the spindle torque (module notes).

    Parameters
    ----------
    n_flutes, diameter_mm, helix_deg : the tool (field units).
    torque_channel, speed_channel : N·m and the spindle speed in ``speed_unit``.
    speed_unit : ``rad/s`` or ``rev/min``.
    angle_channel : the spindle's angle (rad, wrapped or not; a rotary encoder's, as Lee
        recorded beside the dynamometer) instead of a speed channel: the speed is its
        difference from sample to sample (wrapped into (−π, π]), so the angle the block
        integrates is the channel's (decision 1737).
    index_channel, index_threshold : a once-per-revolution index pulse (a keyphasor, an
        encoder's zero mark) instead of a speed channel, a mark where it rises through the
        threshold: the angle advances at the last revolution's speed between marks and is
        reset at each (:mod:`~millsense.monitoring.index_pulse`; decision 1737).
    angle_offset_rad : the tool's angle (flute 0's, in the feed's frame) where the spindle
        angle reads 0: at the stream's first sample with a speed, where the angle channel
        reads 0 or at the index mark with an angle or index channel (whose own angle starts
        the frame, decision 1694; :func:`~millsense.monitoring.angle_origin.tool_angle_offset`
        finds it from a cut, decision 1738).
    speed_rpm : a constant spindle speed (rev/min) instead of a speed channel (a laboratory
        cut at a set speed recorded with a dynamometer alone; decision 1737): the spindle
        angle is then that speed's, which must be the actual one to a few ppm (0.02 % off read
        a 2 mm depth as 2.10 mm); ``millsense monitor`` refines the set speed from the torque's
        own revolutions (:func:`~millsense.monitoring.revolution_period.refined_speed_rpm`).
    feed_channel : path feed, m/s (feed per tooth c = 2π v/(N Ω)); or give
        ``feed_per_tooth_mm``.
    n_harmonics : tooth-passing harmonics used.
    min_torque_nm : revolutions with a lower mean torque are not evaluated (air).
    air_torque_nm : the torque channel's mean torque with the tool out of the cut at the
        running speed (spindle friction the channel includes; 0 for a tared dynamometer or a
        friction-compensated observer). None: learnt from the air revolutions (mean torque
        below ``min_torque_nm``) at the running speed. Where the tooth-passing harmonics do
        not observe the edge coefficient K_e, the mean torque less this air torque gives it
        (decision 1806); with none known, K_e stays the harmonics' and the estimate is
        flagged (``EngagementEstimate.edge_source`` = 3).
    edge, max_depth_fraction : see :class:`~millsense.monitoring.torque_spectrum.
        SpectrumIdentifier`.
    cycle_revolutions : revolutions of one monitoring cycle (Lee's "one monitoring cycle for 3
        tool revolutions"; decision 1717): one estimate from the mean of the cycle's
        revolutions' harmonics (√n less noise, n times fewer fits); 1, the default, is one a
        revolution. Every "revolution" of :attr:`estimates` and
        :attr:`revolution_harmonics` is then a cycle.
    response : the torque channel's response to the cutting torque, as
        :class:`TorqueResponse` (an estimator's known frequency response, e.g. the spindle
        observer's from its machine file): each revolution's coefficients are divided by it
        at their frequencies before the fit (decision 1554). None: a flat channel (a
        dynamometer, Lee's case).
    name : block name (channel prefix).
    """

    def __init__(
        self,
        n_flutes: int,
        diameter_mm: float,
        helix_deg: float,
        torque_channel: str = "spindle/torque_est",
        speed_channel: str = "spindle/speed",
        speed_unit: str = "rad/s",
        speed_rpm: float | None = None,
        angle_channel: str | None = None,
        index_channel: str | None = None,
        index_threshold: float = 0.5,
        angle_offset_rad: float = 0.0,
        feed_channel: str | None = None,
        feed_per_tooth_mm: float | None = None,
        n_harmonics: int = DEFAULT_HARMONICS,
        min_torque_nm: float = 1e-4,
        air_torque_nm: float | None = None,
        edge: bool = True,
        max_depth_fraction: float = 0.5,
        response: TorqueResponse | None = None,
        cycle_revolutions: int = 1,
        name: str = "engagement",
    ) -> None:
        if int(n_flutes) != n_flutes or n_flutes < 1:
            raise ConfigError(f"engagement: n_flutes must be an integer ≥ 1, got {n_flutes!r}")
        if not (diameter_mm > 0 and math.isfinite(diameter_mm)):
            raise ConfigError(f"engagement: diameter_mm must be positive, got {diameter_mm!r}")
        if not (0 < helix_deg < 90):
            raise ConfigError(
                f"engagement: helix_deg must be in (0, 90) (the axial depth comes from the "
                f"helix), got {helix_deg!r}"
            )
        if (feed_channel is None) == (feed_per_tooth_mm is None):
            raise ConfigError("engagement: give exactly one of feed_channel or feed_per_tooth_mm")
        if feed_per_tooth_mm is not None and not feed_per_tooth_mm > 0:
            raise ConfigError(
                f"engagement: feed_per_tooth_mm must be positive, got {feed_per_tooth_mm!r}"
            )
        if n_harmonics < MIN_HARMONICS:
            raise ConfigError(
                f"engagement: n_harmonics must be ≥ {MIN_HARMONICS}, got {n_harmonics}"
            )
        if int(cycle_revolutions) != cycle_revolutions or cycle_revolutions < 1:
            raise ConfigError(
                f"engagement: cycle_revolutions must be an integer ≥ 1, got {cycle_revolutions!r}"
            )
        self.cycle_revolutions = int(cycle_revolutions)
        self.geom = ToolGeometry(int(n_flutes), 0.5e-3 * diameter_mm, math.radians(helix_deg))
        self.n_harmonics = int(n_harmonics)
        if not (0 < max_depth_fraction < 1):
            raise ConfigError(
                f"engagement: max_depth_fraction must be in (0, 1), got {max_depth_fraction!r}"
            )
        self.edge = bool(edge)
        self.max_depth_fraction = float(max_depth_fraction)
        self.torque_channel = torque_channel
        if speed_unit not in ("rad/s", "rev/min"):
            raise ConfigError(
                f"engagement: speed_unit must be rad/s or rev/min, got {speed_unit!r}"
            )
        if speed_rpm is not None and not (speed_rpm > 0 and math.isfinite(speed_rpm)):
            raise ConfigError(f"engagement: speed_rpm must be positive, got {speed_rpm!r}")
        if sum(v is not None for v in (speed_rpm, angle_channel, index_channel)) > 1:
            raise ConfigError(
                "engagement: give one of a set speed_rpm, an angle_channel or an index_channel"
            )
        if not math.isfinite(index_threshold):
            raise ConfigError(f"engagement: index_threshold must be finite, got {index_threshold}")
        if not math.isfinite(angle_offset_rad):
            raise ConfigError(
                f"engagement: angle_offset_rad must be finite, got {angle_offset_rad}"
            )
        self.angle_offset_rad = float(angle_offset_rad)
        self.index_channel = index_channel
        self.index_threshold = float(index_threshold)
        self._index_state = index_state()
        self.speed_channel = speed_channel
        self.speed_rpm = None if speed_rpm is None else float(speed_rpm)
        self.angle_channel = angle_channel
        self._last_angle = math.nan
        #: rad/s per unit of the speed channel
        self._speed_scale = 1.0 if speed_unit == "rad/s" else 2.0 * math.pi / 60.0
        self._constant_speed = np.empty(0)
        #: where a constant speed came from, for the summary (``millsense monitor`` sets it)
        self.speed_source = ""
        #: ``millsense monitor``'s finding that the record's zero is not flute 0's and no offset
        #: fixes the depths (an ``angle_origin.ToolAngle``; decision 1738): nothing is reported
        self.frame_unresolved: Any = None
        #: where ``angle_offset_rad`` came from, for the summary: "" (not set), "found" (the
        #: steady cut's harmonics, decision 1738) or "given" (``--flute0-deg``, decision 1694)
        self.offset_source = ""
        self.feed_channel = feed_channel
        self.c_m = None if feed_per_tooth_mm is None else 1e-3 * feed_per_tooth_mm
        self.min_torque_nm = float(min_torque_nm)
        if air_torque_nm is not None and not math.isfinite(air_torque_nm):
            raise ConfigError(f"engagement: air_torque_nm must be finite, got {air_torque_nm!r}")
        self.air_torque_nm = air_torque_nm
        self.response = response
        self.name = name
        if angle_channel is not None or index_channel is not None:
            ins = [torque_channel, str(angle_channel or index_channel)]
        elif self.speed_rpm is not None:
            ins = [torque_channel]
        else:
            ins = [torque_channel, speed_channel]
        if feed_channel is not None:
            ins.append(feed_channel)
        self.inputs = tuple(ins)
        self._names = [f"{name}/{f}" for f, _, _ in _FIELDS]
        n = self.geom.n_flutes
        self._k = np.concatenate([[1.0], n * np.arange(1, self.n_harmonics + 1, dtype=float)])
        self._log: list[tuple[float, np.ndarray | None]] = []
        #: per revolution of :attr:`_log`: its coefficients, feed per tooth, mean cutting torque
        #: and its variance factor (None: not evaluated)
        self._harm: list[tuple[np.ndarray, float, float, float] | None] = []
        self._made: list[tuple[float, EngagementEstimate | None]] = []
        self.fs = 0.0

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(nm, u, d) for nm, (_, u, d) in zip(self._names, _FIELDS, strict=True)]

    def reset(self, sample_rate_hz: float) -> None:
        if not (sample_rate_hz > 0 and math.isfinite(sample_rate_hz)):
            raise ConfigError(f"{self.name}: sample rate must be positive, got {sample_rate_hz}")
        self.fs = float(sample_rate_hz)
        self._last_angle = math.nan  # the angle channel's last sample (decision 1737)
        self._index_state = index_state()
        #: samples of the next chunk not to scan: until an angle or index channel's angle is
        #: first known (1 = not known yet; 0 once known, and always without such a channel)
        self._skip = 1 if (self.angle_channel or self.index_channel) else 0
        ident = self._ident = SpectrumIdentifier(
            self.geom, self.n_harmonics, self.edge, self.max_depth_fraction
        )
        acc = np.zeros(_sk.ACC_SIZE)
        acc[_sk.ACC_REV] = -1.0
        # the spindle angle starts at the tool's angle at the first sample (decision 1738)
        acc[_sk.ACC_FRAC] = (self.angle_offset_rad / (2.0 * math.pi)) % 1.0
        acc[_sk.ACC_STEP_SPEED] = math.nan  # no rotation cached yet
        g = self.geom
        fpar = [self.min_torque_nm, -1.0 if self.c_m is None else self.c_m, ident._kb]
        fpar += [ident.accept, g.radius_m, g.axial_pitch_m, RUNOUT_RCOND]
        fpar += [math.nan if self.air_torque_nm is None else float(self.air_torque_nm)]
        fpar += [self.fs, g.n_flutes, 1.0 if self.edge else 0.0]
        fpar += [float(self.cycle_revolutions)]  # layout: _sk.FPAR_*
        eq, eqp = self._equaliser()
        nk = self._k.size
        # the compiled scan's state, packed (parts in the order of _sk.PK_*), and the views of
        # its parts read and written here; the running mean of the cut's harmonics and its fit
        # are _anchor and _hmean (decision 1704)
        self._fst, self._cst, views = _sk.pack_state(
            [acc, np.zeros(3), np.array(fpar), ident.k, ident._lo, ident._hi, ident._scl,
             np.zeros((16, _sk.DONE_SIZE)), np.zeros((16, _sk.EST_SIZE)), self._k, eqp,
             np.zeros(_sk.AST_SIZE)],
            [np.zeros(nk, dtype=np.complex128), np.zeros((16, nk), dtype=np.complex128), eq,
             np.zeros(self.n_harmonics, dtype=np.complex128)],
        )  # fmt: skip
        v = views
        self._acc, self._prev, self._anchor = v[_sk.PK_ACC], v[_sk.PK_PREV], v[_sk.PK_ANCHOR]
        self._done, self._est, self._hmean = v[_sk.PK_DONE], v[_sk.PK_EST], v[_sk.PK_HMEAN]
        self._done_sums = v[_sk.PK_DONE_SUMS]
        self._mstate = ident._mstate
        self._held = np.full(len(_FIELDS), math.nan)
        self._held_views: HeldViews | None = None
        self._log = []
        self._harm = []
        self._made = []
        #: revolutions in the cut not evaluated because their highest tooth harmonic was not
        #: below the Nyquist frequency (decision 1734)
        self.aliased_revolutions = 0

    def _equaliser(self) -> tuple[np.ndarray, np.ndarray]:
        """The kernel's response table (rows: speed ranges) and (grid step Hz, switch speed
        rad/s); a 1-column table without a response (not applied)."""
        r = self.response
        if r is None:
            return np.ones((2, 1), dtype=np.complex128), np.array([1.0, math.inf])
        return r.table, np.array([r.step_hz, r.switch_rad_s])

    def _finish(self, t_end: float, row: int, done: list[float]) -> None:
        """The estimate of row ``row`` of the revolutions finished, ``done`` that row of
        :attr:`_done` as a list (module notes)."""
        self._held_views = None
        status = done[_sk.DONE_STATUS]
        if status == _sk.REV_NONE or status == _sk.REV_ALIASED:
            if status == _sk.REV_ALIASED:
                self.aliased_revolutions += 1
            self._log.append((t_end, None))
            self._harm.append(None)
            self._held = _NOT_EVALUATED
            return
        # the coefficients and what the fit took with them, for a cut's average (decision 1698)
        self._harm.append(
            (self._done_sums[row].copy(), done[_sk.DONE_FEED], done[_sk.DONE_T0_NET],
             done[_sk.DONE_MEAN_VAR])
        )  # fmt: skip
        out = self._est[row]
        ident = self._ident
        if status == _sk.REV_GRID:  # the grid search, then the next fits start from it
            has_prev = bool(self._acc[_sk.ACC_HAS_PREV])
            ident._prev = self._prev.copy() if has_prev else None
            coeff = self._done_sums[row]
            out[:] = ident.identify_array(
                coeff[1:],
                complex(coeff[0]),
                done[_sk.DONE_FEED],
                done[_sk.DONE_T0_NET],
                done[_sk.DONE_MEAN_VAR],
                # the scan's fit from the previous solution, which missed the accept misfit
                warm=(out[:3].copy(), float(out[_sk.EST_COST])) if has_prev else None,
            )
            self._prev[:] = out[[_sk.EST_AXIAL, _sk.EST_ENTRY, _sk.EST_EXIT]]
            self._acc[_sk.ACC_HAS_PREV] = 1.0
            self._search_mean()
        est = out.copy()
        self._held = est[: len(_FIELDS)]
        self._log.append((t_end, est))

    def _search_mean(self) -> None:
        """The fit of the running mean of the cut's harmonics, the second start of the next
        revolutions' fits (decision 1704), once the mean holds :data:`~._spectrum_kernels.
        ANCHOR_MIN_REVS` revolutions: refitted from its last point, and searched globally (the
        coarse grid's starts and that refit) where it has not been yet, where the refit's
        relative misfit is above :data:`~._spectrum_kernels.MISFIT_JUMP` × the last search's
        (a changed engagement) or after :data:`~._spectrum_kernels.ANCHOR_SEARCH_REVS`
        revolutions. Called with a revolution's grid search, i.e. only where the revolutions'
        fits miss the accept misfit (never on a clean stream after its first revolution)."""
        st = self._anchor
        if st[_sk.AST_COUNT] < _sk.ANCHOR_MIN_REVS:
            return
        ident = self._ident
        xn, norm = _sk.normalised(self._hmean)
        args = (ident._kb, ident.edge, ident._lo, ident._hi, ident._scl)
        best = None
        if st[_sk.AST_VALID]:
            last = st[_sk.AST_POINT : _sk.AST_POINT + 3].copy()
            best = _sk.lm_fit(last, xn, ident.k[: xn.size], *args, 60)
            if (st[_sk.AST_SINCE] < _sk.ANCHOR_SEARCH_REVS
                    and 2.0 * best[1] / norm <= _sk.MISFIT_JUMP * st[_sk.AST_MISFIT]):  # fmt: skip
                st[_sk.AST_POINT : _sk.AST_POINT + 3] = best[0]
                return
        p, cost = ident._grid_search(xn, norm, args, best)
        st[_sk.AST_POINT : _sk.AST_POINT + 3] = p
        st[_sk.AST_VALID] = 1.0
        st[_sk.AST_SINCE] = 0.0
        st[_sk.AST_MISFIT] = 2.0 * cost / norm

    @property
    def orders(self) -> np.ndarray:
        """The orders of the revolutions' coefficients: [1, N, 2N, …, KN]."""
        return self._k

    @property
    def revolution_harmonics(self) -> list[tuple[np.ndarray, float, float, float] | None]:
        """Per revolution so far: its coefficients (at :attr:`orders`), feed per tooth, mean
        cutting torque and variance factor (None: not evaluated)."""
        return self._harm

    @property
    def estimates(self) -> list[tuple[float, EngagementEstimate | None]]:
        """(end time of the revolution, its estimate or None) for every revolution so far."""
        made = self._made
        for t, est in self._log[len(made) :]:
            made.append((t, None if est is None else EngagementEstimate(*est.tolist())))
        return made

    def averaged(self, which: Sequence[int]) -> AveragedEstimate:
        """The engagement of the revolutions ``which`` (indices into :attr:`estimates`, each
        evaluated; at least :data:`~millsense.monitoring.torque_spectrum.AVERAGED_MIN_REVS`)
        from their averaged harmonics (decision 1698,
        :func:`~millsense.monitoring.torque_spectrum.identify_averaged`): for revolutions of
        one steady cut."""
        rows = [self._harm[i] for i in which]
        if any(r is None for r in rows):
            raise ValueError(f"{self.name}: a revolution averaged was not evaluated")
        kept = [r for r in rows if r is not None]
        ident = SpectrumIdentifier(self.geom, self.n_harmonics, self.edge,
                                   self.max_depth_fraction)  # fmt: skip
        return identify_averaged(
            ident,
            np.stack([r[0] for r in kept]),
            np.array([r[1] for r in kept]),
            np.array([r[2] for r in kept]),
            np.array([r[3] for r in kept]),
            0.0 if self.response is None else self.response.rel_error,
        )

    def _held_outputs(self, n: int) -> dict[str, np.ndarray]:
        """The held values for ``n`` samples (:func:`~millsense.streaming.block.held_views`;
        new views when the values change, once per revolution, or the chunk length does)."""
        self._held_views, out = held_views(self._names, self._held, self._held_views, n)
        return out

    def _speed(self, d: Any, n: int) -> np.ndarray:
        """The chunk's spindle speed in rad/s: the channel's, the angle channel's differences
        (the previous chunk's last angle carried; a stream's first sample repeats the next
        difference), or the constant ``speed_rpm`` (decision 1737)."""
        if self.index_channel is not None:
            a = np.empty(n)
            pulse = np.ascontiguousarray(d[self.index_channel], dtype=np.float64)
            index_angle(pulse, self.index_threshold, self._index_state, a)
            return self._angle_speed(a, n)
        if self.angle_channel is not None:
            return self._angle_speed(np.asarray(d[self.angle_channel], dtype=np.float64), n)
        if self.speed_rpm is None:
            sp = np.asarray(d[self.speed_channel], dtype=np.float64)
            return sp if self._speed_scale == 1.0 else sp * self._speed_scale
        if self._constant_speed.shape[0] != n:
            self._constant_speed = np.full(n, self.speed_rpm * 2.0 * math.pi / 60.0)
        return self._constant_speed

    def _angle_speed(self, a: np.ndarray, n: int) -> np.ndarray:
        """The speed (rad/s) of the angle's steps, wrapped into (−π, π] (a wrapped encoder
        angle's jump of 2π is no motion), the previous chunk's last angle carried; a step
        from or to an unknown (NaN) angle is no motion (decision 1737)."""
        if n == 0:
            return np.zeros(0)
        if self._skip > 0:
            # the samples before the angle is first known are not scanned (a first
            # revolution that holds the cut's torque without turning is no revolution)
            known = np.flatnonzero(np.isfinite(a))
            self._skip = n if known.size == 0 else int(known[0])
            if known.size and self._acc[_sk.ACC_REV] < 0:  # (the scan has not started)
                # the frame starts at the reference's own angle there, not at 0: flute 0 is
                # at ``angle_offset_rad`` where the reference reads 0 (its zero, the index
                # mark), in every record of the tool's clamping (decision 1694)
                start = (float(a[known[0]]) + self.angle_offset_rad) / (2.0 * math.pi)
                self._acc[_sk.ACC_FRAC] = start % 1.0
        step = np.diff(a, prepend=self._last_angle)
        self._last_angle = float(a[-1])
        step = step - 2.0 * math.pi * np.ceil((step - math.pi) / (2.0 * math.pi))
        step[~np.isfinite(step)] = 0.0
        return step * self.fs

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        x = np.asarray(d[self.torque_channel], dtype=np.float64)
        sp = self._speed(d, x.shape[0])
        fd = np.asarray(d[self.feed_channel], dtype=np.float64) if self.feed_channel else sp
        n = x.shape[0]
        # from the first sample whose angle is known (an angle or index channel; decision 1737)
        first = min(self._skip, n)
        if first >= n:
            return BlockOutput(self._held_outputs(n))
        nd, i = _sk.ingest_chunk(x, sp, fd, first, self._fst, self._cst, self._mstate)
        if nd == 0:  # no revolution ends in this chunk (the common case for short chunks)
            views = self._held_views
            if views is not None and views[0] == n:  # nothing ended since: the same views
                return BlockOutput(dict(views[1]))
            return BlockOutput(self._held_outputs(n))
        out = np.empty((len(_FIELDS), n))
        pos = 0
        t0, start, fs = chunk.t0_s, chunk.start, chunk.sample_rate_hz
        while True:
            for row, done in enumerate(self._done[:nd].tolist()):
                s = int(done[_sk.DONE_AT])
                out[:, pos:s] = self._held[:, None]
                self._finish(t0 + (start + s) / fs, row, done)
                pos = s
            if i >= n:
                break
            nd, i = _sk.ingest_chunk(x, sp, fd, i, self._fst, self._cst, self._mstate)
        out[:, pos:] = self._held[:, None]
        return BlockOutput(dict(zip(self._names, out, strict=True)))


# the identifier's output array holds the output channels' fields (:data:`_FIELDS`) first,
# then notch index, cost, edge coefficient and its source: :class:`EngagementEstimate`'s order
assert [_sk.EST_AXIAL, _sk.EST_RADIAL, _sk.EST_ENTRY, _sk.EST_EXIT, _sk.EST_KT, _sk.EST_RUNOUT,
        _sk.EST_RUNOUT_ANGLE, _sk.EST_RELIABILITY, _sk.EST_AXIAL_SD, _sk.EST_NOTCH, _sk.EST_COST,
        _sk.EST_EDGE, _sk.EST_EDGE_SOURCE] == list(range(_sk.EST_SIZE))  # fmt: skip


def make_engagement_block(**options: Any) -> Block:
    """Seed 004 ch. 2 monitor (needs ``n_flutes``, ``diameter_mm``, ``helix_deg`` and the feed)."""
    return EngagementBlock(**options)
