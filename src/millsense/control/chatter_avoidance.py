"""Chatter avoidance by a spindle-speed change (issue 16 item 3; seed 000 C13, Fig. 6.16).

Aslan names the spindle override as the remedy for chatter but gives no rule (digest C13); the
rule here is the classical one of Smith and Tlusty, which the digests of seeds 000 and 002 list
(Munasinghe §2.6, ref. [46] Smith & Delio): put the tooth-passing frequency on a whole
fraction of the chatter frequency,

    f_t = N Ω / 60 = f_c / j   ⇒   Ω_j = 60 f_c / (N j),   j = 1, 2, ...

so that the phase between the inner and the outer wave of the cut surface (f_c / f_t − j)
vanishes, which puts the speed near the top of lobe j of the stability chart (decision 1508
gave the event the data: ``chatter_hz``, ``flutes``, ``spindle_rpm``).

:func:`choose_spindle_speed` forms the candidates Ω_j for j = 1..``max_lobe`` inside the
limits (override range of the CNC, e.g. 50-150 %, and the machine's speed range). With a
:class:`StabilityModel` (the case's modal tool/machine FRF, cutting coefficients, radial
immersion and the current axial depth) every candidate is checked on the case's lobes: the
lowest unstable depth at Ω_j (:mod:`millsense.stability.robust`); the speed commanded is the
geometric centre of the widest stable pocket holding a stable Ω_j, where the relative error of
the model's modes it tolerates is largest (:func:`stable_pocket_rpm`, decision 1635), else the
candidate whose lowest unstable depth exceeds the current depth by the largest margin.
Without a model the nearest faster lobe is taken (Smith-Tlusty, j = ⌊f_c / f_t⌋), and the
recommendation says that it was not checked.

:class:`ChatterAvoidanceBlock` wraps a chatter monitor and turns its ``chatter`` alarms into
``spindle_override`` commands (decision 1631).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.stability.cases import MillingStabilityCase
from millsense.streaming.block import (
    Block,
    BlockOutput,
    Chunk,
    Event,
    EventKind,
    HeldViews,
    Severity,
    held_views,
)

#: Candidates closer than this fraction to the current speed are no change.
SAME_SPEED = 0.01


@dataclass(frozen=True)
class SpeedLimits:
    """What the CNC and the machine allow.

    Attributes
    ----------
    override_min_pct, override_max_pct : spindle override range, % of the programmed speed
        (Aslan: overrides are written at 10 Hz; 50-150 % is a common CNC range).
    min_rpm, max_rpm : the machine's spindle speed range, rev/min.
    """

    override_min_pct: float = 50.0
    override_max_pct: float = 150.0
    min_rpm: float = 0.0
    max_rpm: float = math.inf

    def __post_init__(self) -> None:
        if not 0 < self.override_min_pct <= 100.0 <= self.override_max_pct:
            raise ConfigError(
                f"chatter avoidance: override range {self.override_min_pct:g}-"
                f"{self.override_max_pct:g} % must satisfy 0 < min ≤ 100 ≤ max"
            )
        if not 0 <= self.min_rpm < self.max_rpm:
            raise ConfigError(
                f"chatter avoidance: speed range {self.min_rpm:g}-{self.max_rpm:g} rev/min "
                "must satisfy 0 ≤ min < max"
            )

    def allows(self, rpm: float, programmed_rpm: float) -> bool:
        """True if ``rpm`` is inside the speed range and its override inside the range."""
        pct = 100.0 * rpm / programmed_rpm
        return (
            self.min_rpm <= rpm <= self.max_rpm
            and self.override_min_pct - 1e-9 <= pct <= self.override_max_pct + 1e-9
        )


@dataclass
class StabilityModel:
    """The stability lobes of the cut in progress.

    Parameters
    ----------
    case : the structure (modal tool/machine FRF), flutes, cutting coefficients and radial
        immersion (:class:`~millsense.stability.cases.MillingStabilityCase`; its speed grid is
        not used).
    depth_mm : current axial depth of cut, mm.
    """

    case: MillingStabilityCase
    depth_mm: float
    _cache: dict[float, float] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not self.depth_mm > 0:
            raise ConfigError(f"chatter avoidance: depth {self.depth_mm!r} mm must be > 0")

    def at_depth(self, depth_mm: float) -> StabilityModel:
        """The same lobes for another cut depth (the computed speeds are shared)."""
        return StabilityModel(self.case, depth_mm, self._cache)

    def lowest_unstable_depth_mm(self, rpm: Sequence[float] | np.ndarray) -> np.ndarray:
        """Lowest unstable axial depth at each speed, mm (inf: stable up to the case's
        ``depth_max``), from :func:`millsense.stability.robust.robust_lobes` (first unstable
        band only; results cached per 0.01 rev/min)."""
        from millsense.stability.cases import compute_lobes

        speeds = [round(float(n), 2) for n in np.atleast_1d(np.asarray(rpm, dtype=float))]
        todo = sorted({n for n in speeds if n not in self._cache})
        if todo:
            res = compute_lobes(self.case, rpm=np.array(todo), refine_minima=False, bands_up_to=1.0)
            for n, d in zip(todo, res.critical_depth_m, strict=True):
                self._cache[n] = float(d) * 1e3
        return np.array([self._cache[n] for n in speeds])

    def scan_depths_mm(self, rpm: np.ndarray) -> np.ndarray:
        """Critical depth at many speeds for the pocket search, mm: the zero-order
        (Altintas–Budak) limit for a uniform pitch (analytical, milliseconds for a scan; within
        a few per cent of SDM at high immersion, no flip lobes), else the SDM of
        :meth:`lowest_unstable_depth_mm`. Where it matters, the chosen speed is checked on SDM."""
        if self.case.pitch is not None:
            return self.lowest_unstable_depth_mm(rpm)
        from millsense.stability.zoa import zoa_lobes

        c = self.case
        res = zoa_lobes(c.structure, c.flutes, c.kt, c.kr, c.phi_st, c.phi_ex, rpm)
        return np.asarray(res.critical_depth_m, dtype=float) * 1e3


#: Pocket search around a lobe speed: ±this fraction, in steps of :data:`POCKET_STEP`.
POCKET_SPAN = 0.3
POCKET_STEP = 0.005


def stable_pocket_rpm(
    model: StabilityModel, rpm: float, lo_rpm: float, hi_rpm: float
) -> tuple[float, float] | None:
    """The speeds around ``rpm`` stable at the model's depth, as (lowest, highest) rev/min on a
    log grid of :data:`POCKET_STEP` within ±:data:`POCKET_SPAN` and [``lo_rpm``, ``hi_rpm``]
    (a pocket cut by a limit ends there); None if ``rpm`` itself is not stable
    (:meth:`StabilityModel.scan_depths_mm`; decision 1635)."""
    lo = max(lo_rpm, rpm * (1.0 - POCKET_SPAN))
    hi = min(hi_rpm, rpm * (1.0 + POCKET_SPAN))
    if not lo <= rpm <= hi:
        return None
    k_lo = math.floor(math.log(lo / rpm) / math.log1p(POCKET_STEP))
    k_hi = math.ceil(math.log(hi / rpm) / math.log1p(POCKET_STEP))
    grid = rpm * (1.0 + POCKET_STEP) ** np.arange(k_lo, k_hi + 1)
    grid = np.clip(grid, lo, hi)
    ok = model.scan_depths_mm(grid) > model.depth_mm
    i0 = -k_lo  # the index of rpm itself
    if not ok[i0]:
        return None
    bad_below = np.flatnonzero(~ok[:i0])
    bad_above = np.flatnonzero(~ok[i0:])
    first = int(bad_below[-1]) + 1 if bad_below.size else 0
    last = i0 + int(bad_above[0]) - 1 if bad_above.size else len(grid) - 1
    return float(grid[first]), float(grid[last])


@dataclass(frozen=True)
class Candidate:
    """One lobe's speed: Ω_j = 60 f_c / (N j) [rev/min], its lowest unstable depth [mm] (NaN
    without a model)."""

    lobe: int
    spindle_rpm: float
    override_pct: float
    lowest_unstable_depth_mm: float = math.nan


@dataclass(frozen=True)
class SpeedRecommendation:
    """A new spindle speed against chatter.

    Attributes
    ----------
    spindle_rpm : new speed, rev/min.
    override_pct : new override, % of the programmed speed.
    lobe_number : j of Ω = 60 f_c / (N j).
    chatter_hz : chatter frequency it was chosen for, Hz.
    previous_rpm : speed while chattering, rev/min.
    lowest_unstable_depth_mm : lowest unstable depth at the new speed, mm (NaN: no model).
    margin_mm : that depth minus the current depth, mm (NaN: no model); > 0 predicted stable.
    checked : True if checked against a stability model.
    reason : one line saying why.
    candidates : every candidate inside the limits.
    """

    spindle_rpm: float
    override_pct: float
    lobe_number: int
    chatter_hz: float
    previous_rpm: float
    lowest_unstable_depth_mm: float
    margin_mm: float
    checked: bool
    reason: str
    candidates: tuple[Candidate, ...] = ()
    #: the stable pocket the speed was centred in, rev/min (NaN: not centred) and the
    #: relative speed margin to its edges (a lobe shift the speed tolerates; decision 1635)
    pocket_rpm: tuple[float, float] = (math.nan, math.nan)
    speed_margin: float = math.nan

    @property
    def predicted_stable(self) -> bool:
        """True if a model predicts the new speed stable at the current depth."""
        return self.checked and self.margin_mm > 0


def lobe_speeds_rpm(chatter_hz: float, flutes: int, lobes: Sequence[int]) -> np.ndarray:
    """Ω_j = 60 f_c / (N j), rev/min: the tooth-passing frequency on f_c / j (Smith-Tlusty).

    Parameters
    ----------
    chatter_hz : chatter frequency f_c, Hz.
    flutes : teeth N.
    lobes : lobe numbers j ≥ 1.
    """
    j = np.asarray(lobes, dtype=float)
    return 60.0 * chatter_hz / (flutes * j)


def choose_spindle_speed(
    chatter_hz: float,
    flutes: int,
    spindle_rpm: float,
    programmed_rpm: float | None = None,
    limits: SpeedLimits | None = None,
    model: StabilityModel | None = None,
    max_lobe: int = 20,
) -> SpeedRecommendation | None:
    """A new spindle speed against chatter at ``chatter_hz`` (module notes).

    Parameters
    ----------
    chatter_hz : detected chatter frequency f_c, Hz.
    flutes : teeth N.
    spindle_rpm : current speed, rev/min.
    programmed_rpm : the program's speed (the override's 100 %), rev/min; default the
        current speed.
    limits : override and speed ranges (default 50-150 %, no speed range).
    model : the case's stability model; None: nearest faster lobe, unchecked.
    max_lobe : largest j tried.

    Returns
    -------
    The recommendation, or None if no candidate lies inside the limits.

    Notes
    -----
    Ω_j = 60 f_c / (N j) (Smith & Tlusty; seed 002 §2.6 lobe relation, Eq. 2.16). With a model
    the candidate with the largest margin ``a_lim(Ω_j) − a`` wins (ties: the one nearest the
    current speed); without, the smallest Ω_j above the current speed (j = ⌊f_c / f_t⌋ when
    inside the limits), else the largest below it.
    """
    if not (chatter_hz > 0 and math.isfinite(chatter_hz)):
        raise ConfigError(f"chatter avoidance: chatter frequency {chatter_hz!r} Hz must be > 0")
    if flutes < 1:
        raise ConfigError(f"chatter avoidance: flutes {flutes} must be ≥ 1")
    if not spindle_rpm > 0:
        raise ConfigError(f"chatter avoidance: spindle speed {spindle_rpm!r} rev/min must be > 0")
    lim = limits or SpeedLimits()
    prog = float(programmed_rpm) if programmed_rpm else float(spindle_rpm)
    js = list(range(1, max_lobe + 1))
    speeds = lobe_speeds_rpm(chatter_hz, flutes, js)
    inside = [
        (j, float(n))
        for j, n in zip(js, speeds, strict=True)
        if lim.allows(float(n), prog) and abs(n / spindle_rpm - 1.0) > SAME_SPEED
    ]
    if not inside:
        return None
    if model is not None:
        depth_lim = model.lowest_unstable_depth_mm([n for _, n in inside])
        cands = tuple(
            Candidate(j, n, 100.0 * n / prog, float(d))
            for (j, n), d in zip(inside, depth_lim, strict=True)
        )
        best = max(
            cands, key=lambda c: (c.lowest_unstable_depth_mm, -abs(c.spindle_rpm - spindle_rpm))
        )
        centred = _centred(model, cands, spindle_rpm, lim, prog)
        if centred is not None:
            best, pocket, delta = centred
        margin = best.lowest_unstable_depth_mm - model.depth_mm
        if centred is not None:
            reason = (
                f"centre of lobe {best.lobe}'s stable pocket {pocket[0]:.0f}-{pocket[1]:.0f} "
                f"rev/min (±{100 * delta:.1f} % of speed to its edges): lowest unstable depth "
                f"{best.lowest_unstable_depth_mm:.3g} mm > cut {model.depth_mm:.3g} mm "
                f"(margin {margin:.3g} mm)"
            )
            return SpeedRecommendation(
                best.spindle_rpm, best.override_pct, best.lobe, chatter_hz, spindle_rpm,
                best.lowest_unstable_depth_mm, margin, True, reason, cands, pocket, delta,
            )  # fmt: skip
        if margin > 0:
            reason = (
                f"lobe {best.lobe} of {len(cands)} candidates: lowest unstable depth "
                f"{best.lowest_unstable_depth_mm:.3g} mm > cut {model.depth_mm:.3g} mm "
                f"(margin {margin:.3g} mm)"
            )
        else:
            reason = (
                f"no candidate predicted stable at {model.depth_mm:.3g} mm: best lobe "
                f"{best.lobe} is stable only to {best.lowest_unstable_depth_mm:.3g} mm; "
                "reduce the depth (seed 002)"
            )
        return SpeedRecommendation(
            best.spindle_rpm,
            best.override_pct,
            best.lobe,
            chatter_hz,
            spindle_rpm,
            best.lowest_unstable_depth_mm,
            margin,
            True,
            reason,
            cands,
        )
    cands = tuple(Candidate(j, n, 100.0 * n / prog) for j, n in inside)
    faster = [c for c in cands if c.spindle_rpm > spindle_rpm]
    if faster:
        best = min(faster, key=lambda c: c.spindle_rpm)
        how = "nearest faster lobe"
    else:
        best = max(cands, key=lambda c: c.spindle_rpm)
        how = "no faster lobe inside the limits: nearest slower lobe"
    reason = f"no stability model: {how} (Smith-Tlusty, j = {best.lobe}), not checked"
    return SpeedRecommendation(
        best.spindle_rpm,
        best.override_pct,
        best.lobe,
        chatter_hz,
        spindle_rpm,
        math.nan,
        math.nan,
        False,
        reason,
        cands,
    )


def _centred(
    model: StabilityModel,
    cands: Sequence[Candidate],
    spindle_rpm: float,
    lim: SpeedLimits,
    programmed_rpm: float,
) -> tuple[Candidate, tuple[float, float], float] | None:
    """The centre (in log speed) of the widest stable pocket holding a stable lobe speed, as a
    candidate checked on the model's lobes, its pocket and relative speed margin; None if no
    lobe speed is stable or no centre is (decision 1635).

    Smith–Tlusty's Ω_j = 60 f_c/(N j) lies right of the lobe's top when f_c is above the mode
    (the usual case), on the steep flank: a mode a few per cent softer than the model's (under
    load, with wear or another holder) moves the flank over it. Lobes move in proportion to
    the mode frequencies, so the speed that tolerates the largest error either way is the
    geometric centre of the pocket, where the margin sqrt(Ω_hi/Ω_lo) − 1 is the same to both
    edges."""
    lo_rpm = max(lim.min_rpm, programmed_rpm * lim.override_min_pct / 100.0)
    hi_rpm = min(lim.max_rpm, programmed_rpm * lim.override_max_pct / 100.0)
    found = []
    for c in cands:
        if not c.lowest_unstable_depth_mm > model.depth_mm:
            continue
        pocket = stable_pocket_rpm(model, c.spindle_rpm, lo_rpm, hi_rpm)
        if pocket is None:
            continue
        centre = math.sqrt(pocket[0] * pocket[1])
        if abs(centre / spindle_rpm - 1.0) <= SAME_SPEED:
            continue  # the model holds the chattering speed stable: no centring on it
        found.append((math.sqrt(pocket[1] / pocket[0]) - 1.0, c, pocket, centre))
    for delta, c, pocket, centre in sorted(found, key=lambda f: -f[0]):
        depth = float(model.lowest_unstable_depth_mm([centre])[0])
        if depth > model.depth_mm:
            pct = 100.0 * centre / programmed_rpm
            return Candidate(c.lobe, centre, pct, depth), pocket, delta
    return None


# ------------------------------------------------------------------------------------------
# the streaming block
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AvoidanceSettings:
    """Settings of a :class:`ChatterAvoidanceBlock`.

    Attributes
    ----------
    act : True: command the new speed (OVERRIDE ``spindle_override``); False: recommend it
        (NOTE ``spindle_recommendation``, severity WARNING).
    limits : override and speed ranges.
    settle_s : after a speed change, no further action for this long, s (the monitor needs a
        steady window after the change; decision 1631).
    override_channel : channel with the effective spindle override as a fraction (the
        simulator's ``cnc/spindle_override``), or None: the block's own last command.
    max_lobe : largest lobe number tried.
    require_stable : with a model, act only on a candidate predicted stable (else a WARNING
        ``no_stable_speed`` advising a depth reduction).
    depth_channel : channel with the current axial depth of cut, m (the virtual plan's, e.g.
        ``plan/axial_depth``): the model's lobes are judged at that depth when the chatter is
        acted on; None: the model's own depth.
    """

    act: bool = True
    limits: SpeedLimits = field(default_factory=SpeedLimits)
    settle_s: float = 0.8
    override_channel: str | None = None
    max_lobe: int = 20
    require_stable: bool = True
    depth_channel: str | None = None

    def __post_init__(self) -> None:
        if not self.settle_s >= 0:
            raise ConfigError(f"chatter avoidance: settle time {self.settle_s!r} s must be ≥ 0")
        if self.max_lobe < 1:
            raise ConfigError(f"chatter avoidance: max_lobe {self.max_lobe} must be ≥ 1")


class ChatterAvoidanceBlock(Block):
    """A chatter monitor (child) and the spindle-speed rule on its alarms.

    Each chunk goes to the child; its channels and events are passed on unchanged (the
    ``chatter`` ALARM included, for an arbiter). On a ``chatter`` alarm, and on a new decision
    of the child that still finds chatter once ``settle_s`` has passed since the last change,
    :func:`choose_spindle_speed` picks the speed; the block emits an OVERRIDE
    ``spindle_override`` (value: % of the programmed speed; message with the new rev/min) when
    ``act``, else a NOTE ``spindle_recommendation``. Events carry the child event's NC line and
    position. Output ``{name}/spindle_override_pct``: the override the block last asked for.

    Parameters
    ----------
    monitor : chatter monitor block (any method; it must emit ``chatter`` alarms carrying
        ``chatter_hz``, ``flutes`` and ``spindle_rpm``, and output ``{its name}/chatter_hz``).
    settings : what to do.
    model : stability model of the cut, or None.
    name : block name.
    """

    def __init__(
        self,
        monitor: Block,
        settings: AvoidanceSettings | None = None,
        model: StabilityModel | None = None,
        name: str = "chatter_avoidance",
    ) -> None:
        self.monitor = monitor
        self.settings = s = settings or AvoidanceSettings()
        self.model = model
        self.name = name
        ins = list(monitor.inputs)
        if s.override_channel is not None and s.override_channel not in ins:
            ins.append(s.override_channel)
        if s.depth_channel is not None and s.depth_channel not in ins:
            ins.append(s.depth_channel)
        self.inputs = tuple(ins)
        self._hz_channel = f"{monitor.name}/chatter_hz"
        self._out = f"{name}/spindle_override_pct"

    def output_channels(self) -> list[ChannelInfo]:
        return [
            *self.monitor.output_channels(),
            ChannelInfo(self._out, "%", "spindle override last asked for by chatter avoidance"),
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self.monitor.reset(sample_rate_hz)
        self._fs = float(sample_rate_hz)
        self._pct = 100.0  # the override last asked for
        self._last_action = -math.inf
        self._last_hz = math.nan  # child's chatter_hz at the previous sample
        self._flutes = 0
        self._programmed = math.nan
        self._changed = False  # the last action changed the speed
        self._changed_at = np.empty(0, dtype=np.int64)
        self._pct_key = math.nan
        self._pct_views: HeldViews | None = None
        self.recommendations: list[SpeedRecommendation] = []

    # ------------------------------------------------------------------ per chunk
    def process(self, chunk: Chunk) -> BlockOutput:
        out = self.monitor.process(chunk.restricted(self.monitor.inputs))
        events = list(out.events)
        n = chunk.n
        pct_before = self._pct
        changes: list[tuple[int, float]] = []  # (sample, override asked for from there)
        triggers: list[tuple[int, Event | None, float]] = []
        alarm_at = set()
        for e in out.events:
            if e.kind is EventKind.ALARM and e.name == "chatter":
                if e.sample >= 0:
                    k = e.sample - chunk.start
                else:
                    k = round((e.time_s - chunk.t0_s) * chunk.sample_rate_hz) - chunk.start
                k = min(max(k, 0), max(n - 1, 0))
                triggers.append((k, e, float(e.values.get("chatter_hz", e.value or math.nan))))
                alarm_at.add(k)
        hz = out.channels.get(self._hz_channel)
        if hz is not None and n:
            hz = np.ascontiguousarray(hz, dtype=np.float64)
            if self._changed_at.shape[0] < n:  # scratch kept from chunk to chunk
                self._changed_at = np.empty(2 * n, dtype=np.int64)
            changed = self._changed_at
            for i in changed[: _changes(hz, self._last_hz, changed)].tolist():
                if i not in alarm_at:
                    triggers.append((i, None, float(hz[i])))
            self._last_hz = float(hz[-1])
        triggers.sort(key=lambda tr: tr[0])
        for k, ev, f_c in triggers:
            t = chunk.t0_s + (chunk.start + k) / chunk.sample_rate_hz
            if t - self._last_action < self.settings.settle_s - 1e-12:
                continue
            if ev is None and not self._changed:
                continue  # persisting chatter is acted on only after a speed change of ours
            new = self._act(chunk, k, t, ev, f_c)
            if new is not None:
                events.append(new)
                if new.kind is EventKind.OVERRIDE:
                    changes.append((k, self._pct))
        if changes:
            pct = np.full(n, pct_before)
            for k, v in changes:
                pct[k:] = v
        else:  # held: views of one array never written again
            views = self._pct_views
            if views is None or views[0] != n or self._pct_key != pct_before:
                self._pct_key = pct_before
                views, _ = held_views((self._out,), np.array([pct_before]), None, n)
                self._pct_views = views
            pct = views[1][self._out]
        channels = dict(out.channels)
        channels[self._out] = pct
        return BlockOutput(channels, events)

    def _override_at(self, chunk: Chunk, k: int) -> float:
        ch = self.settings.override_channel
        if ch is not None:
            v = float(np.asarray(chunk.data[ch])[k])
            if v > 0 and math.isfinite(v):
                return v
        return self._pct / 100.0

    def _act(self, chunk: Chunk, k: int, t: float, ev: Event | None, f_c: float) -> Event | None:
        s = self.settings
        if not (f_c > 0 and math.isfinite(f_c)):
            return None
        ovr = self._override_at(chunk, k)
        if ev is not None:
            self._flutes = round(float(ev.values.get("flutes", 0.0)))
            rpm = float(ev.values.get("spindle_rpm", math.nan))
            self._programmed = rpm / ovr if rpm > 0 else math.nan
        if self._flutes < 1 or not self._programmed > 0:
            return None
        rpm_now = self._programmed * ovr
        model = self.model
        if model is not None and s.depth_channel is not None:
            depth = float(np.asarray(chunk.data[s.depth_channel])[k])
            if depth > 0 and math.isfinite(depth):
                model = model.at_depth(depth * 1e3)  # the cut's depth where it chatters
        rec = choose_spindle_speed(
            f_c, self._flutes, rpm_now, self._programmed, s.limits, model, s.max_lobe
        )
        sample = chunk.start + k
        self._last_action = t  # one decision per settle time, whatever it was
        self._changed = False
        if rec is None:
            return _located(ev, Event(
                t, EventKind.NOTE, self.name,
                f"chatter at {f_c:.1f} Hz: no lobe speed inside {s.limits.override_min_pct:g}-"
                f"{s.limits.override_max_pct:g} % of {self._programmed:.0f} rev/min",
                name="no_stable_speed", sample=sample, severity=Severity.WARNING,
                values={"chatter_hz": f_c, "spindle_rpm": rpm_now},
            ))  # fmt: skip
        self.recommendations.append(rec)
        values = {
            "chatter_hz": f_c,
            "spindle_rpm": rec.spindle_rpm,
            "previous_spindle_rpm": rpm_now,
            "programmed_spindle_rpm": self._programmed,
            "override_pct": rec.override_pct,
            "lobe_number": float(rec.lobe_number),
            "lowest_unstable_depth_mm": rec.lowest_unstable_depth_mm,
            "margin_mm": rec.margin_mm,
            "speed_margin_pct": (
                100.0 * rec.speed_margin if math.isfinite(rec.speed_margin) else math.nan
            ),
        }
        text = (
            f"chatter at {f_c:.1f} Hz: spindle {rpm_now:.0f} → {rec.spindle_rpm:.0f} rev/min "
            f"(override {rec.override_pct:.1f} %); {rec.reason}"
        )
        if rec.checked and not rec.predicted_stable and s.require_stable:
            return _located(ev, Event(
                t, EventKind.NOTE, self.name, text, name="no_stable_speed", sample=sample,
                severity=Severity.WARNING, values=values,
            ))  # fmt: skip
        if not s.act:
            return _located(ev, Event(
                t, EventKind.NOTE, self.name, "recommended: " + text,
                name="spindle_recommendation", value=rec.override_pct, sample=sample,
                severity=Severity.WARNING, values=values,
            ))  # fmt: skip
        if not s.limits.allows(rec.spindle_rpm, self._programmed):  # never outside the limits
            return None
        self._pct = rec.override_pct
        self._changed = True
        return _located(ev, Event(
            t, EventKind.OVERRIDE, self.name, text, name="spindle_override",
            value=rec.override_pct, sample=sample, severity=Severity.WARNING, values=values,
        ))  # fmt: skip


def _located(src: Event | None, e: Event) -> Event:
    """``e`` with the NC line and tool-tip position of the monitor's event ``src``."""
    if src is None:
        return e
    return replace(e, nc_line=src.nc_line, x_mm=src.x_mm, y_mm=src.y_mm, z_mm=src.z_mm)


@numba.njit(cache=True)
def _changes(
    hz: NDArray[np.float64], last: float, out: NDArray[np.int64]
) -> int:  # pragma: no cover - compiled
    """Samples where the monitor's chatter frequency changes to a finite value (from ``last``
    before the chunk; NaN to NaN is no change), written to ``out``; returns how many (the
    numpy form's comparisons in one loop, decision 1654)."""
    m = 0
    prev = last
    for k in range(hz.shape[0]):
        h = hz[k]
        same = h == prev or (math.isnan(h) and math.isnan(prev))
        if not same and math.isfinite(h):
            out[m] = k
            m += 1
        prev = h
    return m
