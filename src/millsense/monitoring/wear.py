"""Tool wear from what a CNC has: the cutting torque at engagement matched by the virtual plan
(issue 20, item 2; decision 2002).

A deeper or wider cut raises the spindle torque as much as a worn tool does; the virtual plan
removes that ambiguity. Along a run, :class:`WearBlock` accumulates, over the samples where the
plan is steady and in cut (``plan/judged_torque`` > 0 — calibrated, steady, not a transient,
seed 000 C15/C16 and decision 1622) and the spindle is at speed, the normal equations of

    T_meas = s u T_shear + T_edge + VB (s g u T_shear + (μ σ / K_te) T_edge),

the plan's predicted mean torque split into its shear part T_shear (× the feed override u:
linear in the chip) and edge part T_edge (:mod:`millsense.online.plan_sync`), with the wear
terms of a **linear flank-land model** believed by the monitor (:class:`WearBelief`): a land
of width VB adds μσ·VB to the tangential edge coefficient K_te (Smithey, Kapoor & DeVor 2001)
and the blunter edge scales the shear coefficients by (1 + g VB). The tool's first run (a new
tool, VB = 0) is the reference (:func:`fresh_fit`): T_meas = s u T_shear + e T_edge gives s,
the ratio of the real K_tc to the plan's, and e, the ratio of the real K_te to the plan's —
both by least squares when the run's regressors are independent enough that a plan mismatch
of :data:`PLAN_MISMATCH` moves e by at most :data:`EDGE_TOLERANCE` (:func:`edge_scale_error`),
else s alone with the plan's K_te (e = 1): in a cut of constant width the edge torque is a
fixed fraction of the shear torque and the two scales cannot be told apart (decision 1760).
Every later run gives VB by least squares (:func:`vb_from_sums`), independent of the depths
and widths cut.

The belief's σ, μ, g are generic values for aluminium alloys, not the virtual machine's
(:mod:`millsense.simulator.wear` is a different, piecewise model with other numbers): the
estimate is judged on a plant it does not share (decision 2002).

:func:`wear_trend` fits the per-run estimates against the tool's cutting time and gives the
remaining cutting time to a VB limit (ISO 8688-2: 0.3 mm uniform flank wear).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.plan.virtual_plan import VirtualPlan
from millsense.streaming.block import Block, BlockOutput, Chunk

__all__ = [
    "EDGE_TOLERANCE",
    "PLAN_MISMATCH",
    "VB_LIMIT_M",
    "FreshFit",
    "ToolRun",
    "ToolRunWear",
    "WearBelief",
    "WearBlock",
    "WearSums",
    "WearTrend",
    "assess_tool",
    "edge_scale_error",
    "fresh_fit",
    "fresh_scale",
    "vb_from_sums",
    "wear_trend",
]

#: ISO 8688-2 end-of-life criterion: uniform flank wear VB = 0.3 mm.
VB_LIMIT_M = 0.3e-3
#: Plan torques below this fraction of the plan's largest are not used (an observer's offset
#: and noise would weigh more than the wear there; the same rule as the K_tc calibration).
MIN_USED = 0.3
#: Relative mismatch of the plan's torque between cuts of different engagement that the
#: reference fit must survive: ±2 % (the fleet's four programs on the virtual machine read shear
#: scales 0.98–1.02 with exact coefficients, decision 1760: z-map and runout the plan lacks).
PLAN_MISMATCH = 0.02
#: Largest error of the edge scale at which it is identified: 15 %, about what a preset's
#: K_te may be off for another lot or grind (decision 1760); beyond it the plan's K_te is the
#: better guess.
EDGE_TOLERANCE = 0.15


@dataclass(frozen=True)
class WearBelief:
    """The monitor's linear flank-land model (SI; decision 2002).

    contact_stress_n_m2 : σ on the land (120 N/mm², generic for aluminium alloys).
    flank_friction : μ on the land (0.5).
    shear_growth_per_mm : g, fractional growth of K_tc per mm of VB (0.2).
    """

    contact_stress_n_m2: float = 120e6
    flank_friction: float = 0.5
    shear_growth_per_mm: float = 0.2

    def __post_init__(self) -> None:
        for name in ("contact_stress_n_m2", "flank_friction", "shear_growth_per_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"wear belief: {name} must be ≥ 0, got {v!r}")


@dataclass
class WearSums:
    """Sums over the used samples of one run (m: measured torque, s: u·T_shear, e: T_edge).

    ``raw_sum_nm`` / ``raw_n``: the measured cutting torque over every in-cut sample, without
    engagement normalisation (the "raw torque" indicator the plan-based one is compared with).
    """

    n: int = 0
    m: float = 0.0
    s: float = 0.0
    e: float = 0.0
    mm: float = 0.0
    ms: float = 0.0
    me: float = 0.0
    ss: float = 0.0
    se: float = 0.0
    ee: float = 0.0
    raw_sum_nm: float = 0.0
    raw_n: int = 0

    def add(self, tm: np.ndarray, xs: np.ndarray, xe: np.ndarray) -> None:
        """Accumulate used samples."""
        self.n += int(tm.size)
        self.m += float(tm.sum())
        self.s += float(xs.sum())
        self.e += float(xe.sum())
        self.mm += float(tm @ tm)
        self.ms += float(tm @ xs)
        self.me += float(tm @ xe)
        self.ss += float(xs @ xs)
        self.se += float(xs @ xe)
        self.ee += float(xe @ xe)

    @property
    def raw_torque_nm(self) -> float:
        """Mean measured cutting torque in cut (NaN: never in cut)."""
        return self.raw_sum_nm / self.raw_n if self.raw_n else math.nan

    @property
    def ratio(self) -> float:
        """Measured over predicted torque on the used samples (NaN: none used)."""
        pred = self.s + self.e
        return self.m / pred if self.n and pred > 0 else math.nan

    def as_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class FreshFit:
    """The new tool's reference (:func:`fresh_fit`): shear scale s = K_tc,real / K_tc,plan,
    edge scale e = K_te,real / K_te,plan (1: the plan's K_te kept), the condition number of
    the normalised normal matrix, the edge-scale error a plan mismatch could cause
    (:func:`edge_scale_error`) and whether e was identified."""

    scale: float
    edge_scale: float
    condition: float
    edge_error: float
    edge_identified: bool


def fresh_fit(sums: WearSums, tolerance: float = EDGE_TOLERANCE) -> FreshFit:
    """The shear and edge scales from a new tool's run (VB = 0), module docstring: least
    squares of T_meas = s u T_shear + e T_edge when :func:`edge_scale_error` is at most
    ``tolerance``, else of T_meas − T_edge = s u T_shear (e = 1)."""
    if sums.n == 0 or sums.ss <= 0:
        raise InputDataError("wear: the new tool's run has no steady cut to calibrate on")
    cond = _condition(sums)
    err = edge_scale_error(sums)
    if err <= tolerance:
        det = sums.ss * sums.ee - sums.se * sums.se
        s = (sums.ms * sums.ee - sums.me * sums.se) / det
        e = (sums.me * sums.ss - sums.ms * sums.se) / det
        return FreshFit(s, e, cond, err, True)
    return FreshFit((sums.ms - sums.se) / sums.ss, 1.0, cond, err, False)


def _condition(sums: WearSums) -> float:
    """Condition number κ of the normal matrix of (u T_shear, T_edge), columns normalised:
    (1 + r) / (1 − r), r their uncentred correlation (inf: collinear or no edge torque)."""
    if sums.ss <= 0 or sums.ee <= 0:
        return math.inf
    r = abs(sums.se) / math.sqrt(sums.ss * sums.ee)
    return (1.0 + r) / (1.0 - r) if r < 1.0 else math.inf


def edge_scale_error(sums: WearSums, mismatch: float = PLAN_MISMATCH) -> float:
    """The error of the edge scale e that a relative torque mismatch ``mismatch`` of the plan,
    different between the samples, can cause in the reference fit (decision 1760).

    Divided by x_s = u T_shear, the fit is T_meas / x_s = s + e c with c = T_edge / x_s: e is
    the slope over c, so a mismatch δ of the torque s + e c̄ moves it by δ (1 + c̄) / σ_c, with
    c̄ = Σ x_s x_e / Σ x_s² and σ_c the spread of c (both weighted by x_s²); σ_c = c̄ √(1/r² − 1)
    with r the uncentred correlation of x_s and x_e (:func:`_condition`: κ ≈ 4 / (1 − r²))."""
    if sums.ss <= 0 or sums.ee <= 0 or sums.se <= 0:
        return math.inf
    cbar = sums.se / sums.ss
    r2 = sums.se * sums.se / (sums.ss * sums.ee)
    spread = cbar * math.sqrt(max(1.0 / r2 - 1.0, 0.0))
    return mismatch * (1.0 + cbar) / spread if spread > 0 else math.inf


def fresh_scale(sums: WearSums) -> float:
    """s = K_tc,real / K_tc,plan from a new tool's run (VB = 0) with the plan's K_te: least
    squares of T_meas − T_edge = s u T_shear (module docstring; :func:`fresh_fit` also
    identifies the edge scale where the run allows it)."""
    return fresh_fit(sums, tolerance=-math.inf).scale


def vb_from_sums(
    sums: WearSums, scale: float, kte_n_m: float, belief: WearBelief, edge_scale: float = 1.0
) -> float:
    """VB [m] of one run by least squares on the belief's wear terms (module docstring):
    y = T_meas − s u T_shear − e T_edge, z = s g u T_shear + (μσ/K_te) T_edge, VB = Σyz / Σz²
    (K_te the plan's: the land adds μσ VB to the real K_te, so its torque is μσ VB T_edge /
    K_te,plan whatever e)."""
    if sums.n == 0:
        return math.nan
    if not (kte_n_m > 0):
        raise ConfigError("wear: the plan's K_te must be > 0 to weigh the edge torque")
    a = scale * belief.shear_growth_per_mm * 1e3  # per metre of VB, on u·T_shear
    c = belief.flank_friction * belief.contact_stress_n_m2 / kte_n_m  # on T_edge
    e = edge_scale
    # Σ y z and Σ z² from the run's sums (y = m − s·x_s − e·x_e, z = a·x_s + c·x_e)
    syz = a * (sums.ms - scale * sums.ss - e * sums.se) + c * (
        sums.me - scale * sums.se - e * sums.ee
    )
    szz = a * a * sums.ss + 2 * a * c * sums.se + c * c * sums.ee
    return syz / szz if szz > 0 else math.nan


class WearBlock(Block):
    """Accumulates a run's :class:`WearSums` (module docstring); emits ``wear/used`` (1 on
    the samples used).

    Parameters
    ----------
    plan : the virtual plan being run (its ``torque_avg_nm`` and ``torque_avg_shear_nm``).
    row_channel, judged_channel, in_cut_channel : :class:`~millsense.online.plan_sync.
        PlanSync`'s row, judged torque and in-cut flag.
    torque_channel : measured cutting torque (N·m; air reference removed).
    override_channel : effective feed override (fraction), or None (1).
    at_speed_channel : 1 where the spindle is settled at speed, or None.
    """

    def __init__(
        self,
        plan: VirtualPlan,
        *,
        row_channel: str = "plan/row",
        judged_channel: str = "plan/judged_torque",
        in_cut_channel: str = "plan/in_cut",
        torque_channel: str = "plan/cutting_torque",
        override_channel: str | None = "cnc/feed_override",
        at_speed_channel: str | None = "spindle/at_speed",
        name: str = "wear",
    ) -> None:
        tq = np.nan_to_num(np.asarray(plan["torque_avg_nm"], dtype=np.float64))
        sh = np.nan_to_num(np.asarray(plan["torque_avg_shear_nm"], dtype=np.float64))
        self._shear = sh
        self._edge = tq - sh
        self._min = MIN_USED * float(np.max(np.abs(tq), initial=0.0))
        self.row_channel = row_channel
        self.judged_channel = judged_channel
        self.in_cut_channel = in_cut_channel
        self.torque_channel = torque_channel
        self.override_channel = override_channel
        self.at_speed_channel = at_speed_channel
        self.name = name
        ins = [row_channel, judged_channel, in_cut_channel, torque_channel]
        ins += [c for c in (override_channel, at_speed_channel) if c is not None]
        self.inputs = tuple(ins)
        self.sums = WearSums()

    def output_channels(self) -> list[ChannelInfo]:
        return [ChannelInfo(f"{self.name}/used", "1", "1 on the samples the wear fit uses")]

    def reset(self, sample_rate_hz: float) -> None:
        self.sums = WearSums()

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        rows = np.asarray(d[self.row_channel], dtype=np.float64)
        tm = np.asarray(d[self.torque_channel], dtype=np.float64)
        ok = (rows >= 0) & np.isfinite(tm)
        if self.at_speed_channel is not None:
            ok &= np.asarray(d[self.at_speed_channel]) > 0.5
        r = np.where(ok, rows, 0).astype(np.int64)
        in_cut = ok & (np.asarray(d[self.in_cut_channel]) > 0.5)
        self.sums.raw_sum_nm += float(tm[in_cut].sum())
        self.sums.raw_n += int(in_cut.sum())
        u = (
            np.asarray(d[self.override_channel], dtype=np.float64)
            if self.override_channel is not None
            else np.ones(chunk.n)
        )
        xs = self._shear[r] * u
        xe = self._edge[r]
        use = in_cut & (np.asarray(d[self.judged_channel]) > 0) & ((xs + xe) >= self._min)
        self.sums.add(tm[use], xs[use], xe[use])
        return BlockOutput({f"{self.name}/used": use.astype(np.float64)})


@dataclass(frozen=True)
class WearTrend:
    """A tool's wear against its cutting time and the remaining life to ``limit_m``.

    rate_m_s : slope of the line fitted through the last runs (m of VB per s of cutting).
    remaining_s : cutting time left to the limit at that rate (0: reached; inf: no growth).
    """

    limit_m: float
    rate_m_s: float
    remaining_s: float
    last_vb_m: float
    points: int = 0
    notes: list[str] = field(default_factory=list)


def wear_trend(
    cutting_time_s: Sequence[float],
    vb_m: Sequence[float],
    *,
    limit_m: float = VB_LIMIT_M,
    last: int = 5,
) -> WearTrend:
    """Fit VB against cutting time over the last ``last`` runs (the steady, then accelerated
    stage: the recent slope is the one that predicts the end) and extrapolate to ``limit_m``."""
    t = np.asarray(cutting_time_s, dtype=np.float64)
    v = np.asarray(vb_m, dtype=np.float64)
    if t.shape != v.shape:
        raise InputDataError("wear trend: cutting times and VB differ in length")
    ok = np.isfinite(t) & np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size == 0:
        return WearTrend(limit_m, math.nan, math.nan, math.nan, 0, ["no run with a VB estimate"])
    order = np.argsort(t, kind="stable")
    t, v = t[order][-last:], v[order][-last:]
    current = float(v[-1])
    if t.size < 2 or np.ptp(t) <= 0:
        return WearTrend(limit_m, math.nan, math.nan, current, int(t.size),
                         ["one run: no trend yet"])  # fmt: skip
    rate, icpt = np.polyfit(t, v, 1)
    now = float(t[-1])
    fitted = float(icpt + rate * now)
    if fitted >= limit_m or current >= limit_m:
        remaining = 0.0
    elif rate <= 0:
        remaining = math.inf
    else:
        remaining = (limit_m - fitted) / rate
    return WearTrend(limit_m, float(rate), float(remaining), current, int(t.size))


@dataclass(frozen=True)
class ToolRun:
    """One run of a tool as the fleet assessment sees it.

    run : its name; order : position in the tool's life (cutting time before the run, s, or
    any increasing key); cut_s : time in cut during the run; sums : its :class:`WearSums`;
    kte_n_m : the plan's K_te.
    """

    run: str
    order: float
    cut_s: float
    sums: WearSums
    kte_n_m: float


@dataclass(frozen=True)
class ToolRunWear:
    """The assessment of one run: VB estimate, the flag against the limit, the tool's trend at
    that run (rate, remaining cutting time) and the tool's reference (:class:`FreshFit`: shear
    and edge scale, condition number, edge-scale error)."""

    run: str
    run_index: int
    cutting_time_s: float
    vb_m: float
    worn: bool
    rate_m_s: float
    remaining_s: float
    reference: bool
    shear_scale: float = 1.0
    edge_scale: float = 1.0
    condition: float = math.nan
    edge_error: float = math.nan


def assess_tool(
    runs: Sequence[ToolRun],
    *,
    belief: WearBelief | None = None,
    limit_m: float = VB_LIMIT_M,
    cutting_time_known: bool = False,
) -> list[ToolRunWear]:
    """VB per run of one tool, its flag and the trend (module docstring).

    The runs are taken in ``order``; the first is the new tool's (VB = 0, the reference
    :func:`fresh_fit` of the shear and, where identifiable, the edge scale; decisions 2002,
    1760; every row carries the reference's scales, condition number and edge-scale error).
    ``cutting_time_known``: ``order`` is the tool's
    cutting time before each run (a CNC's tool-life counter); else the time is accumulated
    from the runs' own time in cut.
    """
    b = belief if belief is not None else WearBelief()
    ordered = sorted(runs, key=lambda r: r.order)
    if not ordered:
        return []
    ref = next((r for r in ordered if r.sums.n > 0), None)
    if ref is None:
        raise InputDataError(
            f"wear: no run of the tool ({ordered[0].run}, ...) has a steady cut to judge"
        )
    fit = fresh_fit(ref.sums)
    out: list[ToolRunWear] = []
    times: list[float] = []
    vbs: list[float] = []
    clock = 0.0
    for i, r in enumerate(ordered):
        t = r.order if cutting_time_known else clock
        clock += max(r.cut_s, 0.0)
        vb = 0.0 if r is ref else vb_from_sums(r.sums, fit.scale, r.kte_n_m, b, fit.edge_scale)
        times.append(t)
        vbs.append(vb)
        tr = wear_trend(times, vbs, limit_m=limit_m)
        worn = bool(vb >= limit_m)
        out.append(ToolRunWear(r.run, i, t, vb, worn, tr.rate_m_s, tr.remaining_s, r is ref,
                               fit.scale, fit.edge_scale, fit.condition,
                               fit.edge_error))  # fmt: skip
    return out
