"""``millsense monitor``'s account of the engagement monitor (seed 004 ch. 2, Lee Fig. 2.9):
which of its revolutions count, the record's steady cuts among them (decision 1739), what each
cut's revolutions say (decisions 1807, 1558, 1698, 1738), the summary's lines, the event log's
rows and the figure's depth panel of it.

A part program's record holds several cuts: a slot and a shallower pass, a step in depth. Their
revolutions were pooled into one verdict, whose median or averaged harmonics mixed the cuts (a
3 mm slot followed by a 1.5 mm half-immersion pass read "not determined" over the 139
revolutions of both, where each alone reads its own depth). Each steady cut
(:func:`~millsense.monitoring.steady_cuts.steady_cuts`) now has its own verdict, line and event.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from millsense.streaming.block import Event, EventKind, Severity


def reliable(e: Any) -> bool:
    """A revolution's estimate is reported: σ ≥ RELIABLE_SIGMA and physical coefficients
    (K_t > 0, K_e ≥ 0: a cutting force never pulls the tool along; decision 1807), on a side
    cut's window (decision 1738)."""
    from millsense.monitoring.engagement import RELIABLE_SIGMA, side_cut_window

    return bool(e.reliability >= RELIABLE_SIGMA and e.kt_n_m2 > 0 and e.edge_n_m >= 0
                and side_cut_window(e.entry_rad, e.exit_rad))  # fmt: skip


def steady_cut_mask(rec: Any) -> np.ndarray | None:
    """Where a session's recording says the plan is steady in the cut (``plan/judged_torque``
    > 0: in cut, at speed, away from entries, steps and exits; decision 1622), or None."""
    if "plan/judged_torque" not in rec.channel_names:
        return None
    return np.asarray(rec.channel("plan/judged_torque"), dtype=np.float64) > 0


@dataclass(frozen=True)
class EngagementVerdict:
    """What :func:`engagement_summary` reports of an engagement block's revolutions
    (decisions 1807, 1558, 1698): the evaluated revolutions it counts (index into the block's
    estimates, end time s, estimate), the reliable ones among them, the averaged harmonics'
    estimate (None: fewer than AVERAGED_MIN_REVS revolutions), and ``kind``: ``"medians"``
    (the reliable revolutions' medians), ``"averaged"`` (the averaged fit, determined),
    ``"undetermined"`` or ``"none"`` (no revolution evaluated); ``where`` qualifies the
    counts (the plan's steady cut)."""

    timed: list[tuple[int, float, Any]]
    reliable: list[Any]
    avg: Any
    kind: str
    where: str


def engagement_verdict(
    block: Any,
    steady: np.ndarray | None = None,
    fs: float = 1.0,
    rows: Sequence[int] | None = None,
) -> EngagementVerdict:
    """:class:`EngagementVerdict` of ``block``. With ``steady`` (per sample,
    :func:`steady_cut_mask`) only the revolutions that end where the plan is steady count: an
    entry's or an exit's revolutions are a changing engagement, not the cut's (decision 1558);
    with ``rows`` (indices into the block's estimates: one steady cut, decision 1739) only
    those.

    The medians of the reliable revolutions (:func:`reliable`) where at least half are and
    the revolutions' averaged harmonics (√n less noise than one revolution's) allow their
    median depth: within their depth interval (one interval: no second basin) widened by three
    standard errors of the median; else the averaged harmonics' estimate where they determine
    the depth; else not determined (a few revolutions of noise can pass the test by chance;
    decision 1807)."""
    from millsense.monitoring.engagement import depth_summary, determined
    from millsense.monitoring.torque_spectrum import AVERAGED_MIN_REVS

    timed, where = _counted(block, steady, fs)
    if rows is not None:
        keep = set(rows)
        timed = [r for r in timed if r[0] in keep]
    every = [e for _, _, e in timed]
    if not every:
        return EngagementVerdict(timed, [], None, "none", where)
    if getattr(block, "frame_unresolved", None) is not None:
        # the record's zero is not flute 0's and no offset fixes the depths (decision 1738)
        return EngagementVerdict(timed, [], None, "misaligned", where)
    est = [e for e in every if reliable(e)]
    avg = block.averaged([i for i, _, _ in timed]) if len(every) >= AVERAGED_MIN_REVS else None
    if 2 * len(est) >= len(every):
        if avg is None:
            return EngagementVerdict(timed, est, avg, "medians", where)
        depth = depth_summary(est)
        se3 = 3 * depth.standard_error_m
        if avg.connected and (
            (not math.isfinite(avg.depth_low_m) or avg.depth_low_m - se3 <= depth.median_m)
            and depth.median_m <= avg.depth_high_m + se3
        ):  # fmt: skip
            return EngagementVerdict(timed, est, avg, "medians", where)
    kind = "averaged" if avg is not None and determined(avg) else "undetermined"
    return EngagementVerdict(timed, est, avg, kind, where)


def _counted(
    block: Any, steady: np.ndarray | None, fs: float
) -> tuple[list[tuple[int, float, Any]], str]:
    """The evaluated revolutions that count (index into the block's estimates, end time s,
    estimate): those ending where the plan is steady, with ``steady`` (decision 1558); and the
    words that say so ("" without)."""
    timed = [(i, t, e) for i, (t, e) in enumerate(getattr(block, "estimates", []))
             if e is not None]  # fmt: skip
    if steady is None or not steady.any():
        return timed, ""
    n = steady.size
    timed = [(i, t, e) for i, t, e in timed if steady[min(max(round(t * fs), 0), n - 1)]]
    return timed, " in the plan's steady cut"


#: A median engagement window narrower than this (degrees) is the fits' collapse in noise, not
#: a window (decision 1739).
COLLAPSED_WINDOW_DEG = 5.0

#: Where a cut lies: (NC line, x, y, z mm) at a stream sample, each None where unknown.
Place = Callable[[int], tuple[int | None, float | None, float | None, float | None]]


@dataclass(frozen=True)
class EngagementCut:
    """One steady cut of the record (decision 1739): the end times of its first and last
    revolution (s from the stream's first sample) and the verdict on its revolutions."""

    first_s: float
    last_s: float
    verdict: EngagementVerdict


def _as_cut(v: EngagementVerdict) -> EngagementCut:
    times = [t for _, t, _ in v.timed]
    return EngagementCut(times[0] if times else math.nan, times[-1] if times else math.nan, v)


def engagement_cuts(
    block: Any, steady: np.ndarray | None = None, fs: float = 1.0
) -> list[EngagementCut]:
    """The record's steady cuts and the verdict on each (decision 1739). The revolutions that
    count (:func:`engagement_verdict`'s: evaluated, and in the plan's steady cut where the
    recording says where that is) are split by
    :func:`~millsense.monitoring.steady_cuts.steady_cuts` into runs at one level of the first
    tooth harmonic and of the mean cutting torque, each of at least
    :data:`~millsense.monitoring.torque_spectrum.AVERAGED_MIN_REVS` revolutions (what the
    averaged harmonics need); revolutions in none of them (an entry, an exit, air, an
    engagement that keeps changing) are not reported. Where no run is that long, or the
    record's frame is unresolved (decision 1738: the record has one verdict), the one verdict
    over every revolution that counts, as before."""
    from millsense.monitoring.steady_cuts import steady_cuts
    from millsense.monitoring.torque_spectrum import AVERAGED_MIN_REVS

    timed, _ = _counted(block, steady, fs)
    harm = list(getattr(block, "revolution_harmonics", []))
    runs: list[list[int]] = []
    if timed and harm and getattr(block, "frame_unresolved", None) is None:
        counted = {i for i, _, _ in timed}
        coeffs = [h[0] if h is not None and i in counted else None for i, h in enumerate(harm)]
        means = [h[2] if h is not None else math.nan for h in harm]
        runs = steady_cuts(coeffs, means, AVERAGED_MIN_REVS)
    if not runs:  # the one verdict over every revolution that counts
        return [_as_cut(engagement_verdict(block, steady, fs))]
    return [_as_cut(engagement_verdict(block, steady, fs, rows=r)) for r in runs]


def engagement_lines(
    block: Any, cuts: Sequence[EngagementCut], fs: float, t0_s: float = 0.0,
    place: Place | None = None,
) -> list[str]:  # fmt: skip
    """The summary's lines on the engagement (decision 1739): one line, as before, where the
    record has one cut; else a line counting the cuts, then one per cut: the end times of its
    revolutions, the NC line and the plan's position at its middle (``place``, where known),
    and its verdict."""
    if len(cuts) == 1:
        return [engagement_summary(block, fs=fs, verdict=cuts[0].verdict)]
    lines = [f"  {block.name}: {len(cuts)} steady cuts, each judged apart (decision 1739)"
             f"{_harmonics_note(block, fs)}"]  # fmt: skip
    for k, c in enumerate(cuts, 1):
        lines.append(f"    cut {k} (revolutions ending {t0_s + c.first_s:.2f}-"
                     f"{t0_s + c.last_s:.2f} s{_place_words(c, fs, place)}): "
                     f"{_verdict_text(block, c.verdict)}")  # fmt: skip
    return lines


def _middle_sample(c: EngagementCut, fs: float) -> int:
    return max(round(0.5 * (c.first_s + c.last_s) * fs), 0)


def _place_words(c: EngagementCut, fs: float, place: Place | None) -> str:
    """", NC line L at x … y … z … mm" at the cut's middle, as far as ``place`` knows it."""
    if place is None:
        return ""
    nc, x, y, z = place(_middle_sample(c, fs))
    out = "" if nc is None else f", NC line {nc}"
    if x is not None and y is not None and z is not None:
        out += f" at x {x:.1f} y {y:.1f} z {z:.1f} mm"
    return out


def cut_result(c: EngagementCut) -> dict[str, float]:
    """A cut's engagement as the event log's values (units in the names; NaN where the verdict
    gives none): the reliable revolutions' medians (``medians``) or the averaged harmonics'
    estimate (``averaged``); counts and the span of the revolutions' end times always."""
    v = c.verdict
    nan = math.nan
    out = {"revolutions": float(len(v.timed)), "reliable_revolutions": float(len(v.reliable)),
           "first_s": c.first_s, "last_s": c.last_s, "axial_depth_mm": nan,
           "radial_depth_mm": nan, "kt_n_mm2": nan, "runout_um": nan,
           "reliability": nan}  # fmt: skip
    if v.kind == "medians":
        est = v.reliable
        rows = [[e.axial_depth_m, e.radial_depth_m, e.kt_n_m2, e.runout_m, e.reliability]
                for e in est]  # fmt: skip
    elif v.kind == "averaged":
        a = v.avg.estimate
        rows = [[a.axial_depth_m, a.radial_depth_m, a.kt_n_m2, a.runout_m, a.reliability]]
    else:
        return out
    da, dr, kt, ro, sig = np.median(np.asarray(rows, dtype=np.float64), axis=0)
    out.update(axial_depth_mm=1e3 * da, radial_depth_mm=1e3 * dr, kt_n_mm2=1e-6 * kt,
               runout_um=1e6 * ro, reliability=sig)  # fmt: skip
    return out


def engagement_events(
    block: Any, cuts: Sequence[EngagementCut], fs: float, t0_s: float = 0.0,
    place: Place | None = None,
) -> list[Event]:  # fmt: skip
    """One NOTE ``engagement`` per cut with revolutions (decision 1739), at the end of its last
    revolution: the axial depth (mm, NaN where not determined) as the value, :func:`cut_result`
    as the values, the NC line and the plan's position at the cut's middle, the summary's words
    as the message."""
    out = []
    for k, c in enumerate(cuts, 1):
        if c.verdict.kind == "none":
            continue
        sample = max(round(c.last_s * fs), 0)
        nc, x, y, z = place(_middle_sample(c, fs)) if place is not None else (None,) * 4
        values = cut_result(c)
        out.append(Event(
            time_s=t0_s + c.last_s, kind=EventKind.NOTE, source=block.name,
            message=f"cut {k}: {_verdict_text(block, c.verdict)}", name="engagement",
            value=values["axial_depth_mm"], sample=sample, severity=Severity.INFO,
            values=values, nc_line=nc, x_mm=x, y_mm=y, z_mm=z,
        ))  # fmt: skip
    return out


def depth_panel_of_cuts(
    block: Any, cuts: Sequence[EngagementCut], n_steps: int, step: int, fs: float
) -> dict[str, np.ndarray]:
    """:func:`depth_panel` of every cut, merged: a step is reported where one cut reports it,
    and the averaged values are each cut's over the steps its revolutions hold."""
    out: dict[str, np.ndarray] = {}
    for c in cuts:
        for key, val in depth_panel(block, c.verdict, n_steps, step, fs).items():
            if key not in out:
                out[key] = val
            elif val.dtype == bool:
                out[key] = out[key] | val
            else:
                out[key] = np.where(np.isnan(out[key]), val, out[key])
    return out


def depth_panel(
    block: Any, verdict: EngagementVerdict, n_steps: int, step: int, fs: float
) -> dict[str, np.ndarray]:
    """Per plotted step (every ``step`` samples), what the depth panel marks as the summary's
    result (decision 1704): ``{name}/reported``, whether the revolution held there is one whose
    value the summary's medians take (``verdict.kind`` "medians": counted and
    :func:`reliable`); where the summary reports the averaged harmonics (``"averaged"``) or
    the depths they allow (``"undetermined"``), no revolution is reported alone and
    ``{name}/averaged_depth`` and ``{name}/averaged_radial`` (the averaged fit's axial and
    radial depth; NaN where not determined), ``{name}/averaged_low`` and
    ``{name}/averaged_high`` (m; NaN/inf at the search range's ends) are given over the steps
    the averaged revolutions hold."""
    name = block.name
    out = {f"{name}/reported": np.zeros(n_steps, dtype=bool)}
    revs = list(getattr(block, "estimates", []))
    if not verdict.timed or not revs:
        return out
    t_end = np.array([t for t, _ in revs], dtype=np.float64)
    counted = np.zeros(t_end.size, dtype=bool)
    counted[[i for i, _, _ in verdict.timed]] = True
    held = np.searchsorted(t_end, np.arange(n_steps) * step / fs, side="right") - 1
    at = np.maximum(held, 0)
    if verdict.kind == "medians":
        ok = counted & np.array([e is not None and reliable(e) for _, e in revs], dtype=bool)
        out[f"{name}/reported"] = (held >= 0) & ok[at]
        return out
    avg = verdict.avg
    if avg is None:
        return out
    span = (held >= 0) & counted[at]
    ok = verdict.kind == "averaged"
    depth = avg.estimate.axial_depth_m if ok else math.nan
    radial = avg.estimate.radial_depth_m if ok else math.nan
    for key, val in (("averaged_depth", depth), ("averaged_low", avg.depth_low_m),
                     ("averaged_high", avg.depth_high_m), ("averaged_radial", radial)):  # fmt: skip
        out[f"{name}/{key}"] = np.where(span, val, np.nan)
    return out


def engagement_summary(
    block: Any,
    steady: np.ndarray | None = None,
    fs: float = 1.0,
    verdict: EngagementVerdict | None = None,
) -> str:
    """One line: revolutions evaluated and the engagement over them (decisions 1807, 1558,
    1698), as :func:`engagement_verdict` decides (``verdict``: already decided)."""
    v = verdict if verdict is not None else engagement_verdict(block, steady, fs)
    return _engagement_line(block, v) + _harmonics_note(block, fs)


def _harmonics_note(block: Any, fs: float) -> str:
    """What the summary adds where the harmonics were limited by the Nyquist frequency
    (decision 1734): the harmonics fitted where fewer than the default, and the revolutions
    left unevaluated because theirs reached it; the monitoring cycle where it is longer than a
    revolution (decision 1717); flute 0's angle where it was found (decision
    1738); and where the spindle angle came from (decision 1737)."""
    from millsense.monitoring.engagement import DEFAULT_HARMONICS

    note = ""
    k = int(getattr(block, "n_harmonics", DEFAULT_HARMONICS))
    if k < DEFAULT_HARMONICS:
        note += (f"; fitted on {k} tooth harmonics, those below the Nyquist frequency "
                 f"({0.5 * fs:g} Hz) at the recording's top speed")  # fmt: skip
    cycle = int(getattr(block, "cycle_revolutions", 1))
    if cycle > 1:
        note += (f"; one estimate per monitoring cycle of {cycle} revolutions, the whole number "
                 "nearest Lee's 50 ms at the running speed: the revolutions counted are cycles "
                 "(decision 1717)")  # fmt: skip
    offset = float(getattr(block, "angle_offset_rad", 0.0))
    source = getattr(block, "offset_source", "")
    angle = getattr(block, "angle_channel", None)
    index = getattr(block, "index_channel", None)
    where = ("at the record's first sample" if angle is None and index is None
             else "where the spindle angle reads 0")  # fmt: skip
    if source == "given":
        note += f"; flute 0 at {np.degrees(offset):.1f}° {where}, as given (--flute0-deg)"
    elif offset != 0.0:
        note += (f"; flute 0 at {np.degrees(offset):.1f}° {where}, from the steady cut's "
                 "harmonics (decision 1738)")  # fmt: skip
        if angle is not None or index is not None:
            # the reference's zero is the clamping's: the angle serves its other records
            note += (f": --flute0-deg {np.degrees(offset):.1f} gives it to the tool's other "
                     "records in this clamping (decision 1694)")  # fmt: skip
    if angle is not None:
        note += f"; the spindle angle from the channel {angle}"
    elif index is not None:
        note += (f"; the spindle angle from the index pulse {index} (the line through its "
                 "last 8 marks)")  # fmt: skip
    rpm = getattr(block, "speed_rpm", None)
    if rpm is not None:
        source = getattr(block, "speed_source", "") or f"the set speed of {rpm:g} rev/min"
        note += f"; no speed channel: the spindle angle from {source}"
    aliased = int(getattr(block, "aliased_revolutions", 0))
    if aliased:
        note += (f"; {aliased} revolutions in the cut not evaluated: their tooth harmonics "
                 f"reach the Nyquist frequency ({0.5 * fs:g} Hz)")  # fmt: skip
    return note


def _times_words(ratio: float) -> str:
    """A misfit ratio in the summary's words."""
    return f"{ratio:.0f} times" if ratio < 1000 else "over 1000 times"


def _notch_words(index: float) -> str:
    """A notch index in the summary's words (the fit caps a depth too small to place it)."""
    return f"{index:.0f}" if index < 100 else "above 100"


def _engagement_line(block: Any, v: EngagementVerdict) -> str:
    """The summary's line on the engagement as ``v`` decides it."""
    return f"  {block.name}: {_verdict_text(block, v)}"


def _verdict_text(block: Any, v: EngagementVerdict) -> str:
    """What ``v`` says of the engagement, in words (the summary line after the block's name)."""
    from millsense.monitoring.engagement import RELIABLE_SIGMA, depth_summary, side_cut_window

    where, est, avg = v.where, v.reliable, v.avg
    every = [e for _, _, e in v.timed]
    if v.kind == "misaligned":
        found = block.frame_unresolved
        return (
            f"engagement not determined: the record's spindle-angle zero is not "
            f"flute 0's (the steady cut's harmonics fit {np.degrees(found.offset_rad):.0f}° "
            f"further on {_times_words(found.misfit_at_zero / max(found.misfit, 1e-300))} "
            "better), "
            f"and the depth's notch (harmonic {_notch_words(found.notch_index)}) lies beyond the "
            f"{block.n_harmonics} fitted, where an angle offset and a depth trade phase: only a "
            "spindle angle whose zero is flute 0, or an angle or index channel with flute 0's "
            "angle given (--flute0-deg, decision 1694), fixes the depths here (decision 1738)"
        )
    if v.kind == "none":
        if getattr(block, "aliased_revolutions", 0):
            return f"no revolution evaluated{where}"
        return f"no revolution evaluated{where} (no cut, or the torque is too low)"

    def med(v: list[float]) -> float:
        return float(np.median(v))

    head = f"{len(est)} of {len(every)} revolutions{where} reliable"
    if v.kind == "medians":
        depth = depth_summary(est)
        return (
            f"{head} (σ ≥ {RELIABLE_SIGMA}): median axial depth "
            f"{1e3 * depth.median_m:.3f} mm (standard error "
            f"{1e3 * depth.standard_error_m:.3f} mm, a revolution's scatter "
            f"{1e3 * depth.scatter_m:.3f} mm), "
            + _engagement_values([e.radial_depth_m for e in est], [e.kt_n_m2 for e in est],
                                 [e.runout_m for e in est], [e.reliability for e in est],
                                 [e.edge_n_m for e in est], [e.edge_source for e in est])
        )  # fmt: skip
    if v.kind == "averaged":
        a = avg.estimate
        return (
            f"{head} alone; the {avg.n} revolutions' harmonics averaged: axial depth "
            f"{1e3 * a.axial_depth_m:.3f} mm "
            f"(profile interval {1e3 * avg.depth_low_m:.3f}–{1e3 * avg.depth_high_m:.3f} mm), "
            + _engagement_values([a.radial_depth_m], [a.kt_n_m2], [a.runout_m],
                                 [a.reliability], [a.edge_n_m], [a.edge_source])
        )  # fmt: skip
    allowed = ""
    if avg is not None:
        lo, hi = avg.depth_low_m, avg.depth_high_m
        basin = "" if avg.connected else " or in another basin"
        allowed = (f"; averaged over the {avg.n} revolutions the axial depth lies anywhere "
                   f"{depth_span(lo, hi)}{basin}")  # fmt: skip
    inside = [e for e in every if not side_cut_window(e.entry_rad, e.exit_rad)]
    why = ("the torque's tooth harmonics do not fix the engagement here (e.g. a full slot with 3 "
           "or more flutes, or a light cut in the signal's noise)")  # fmt: skip
    width = float(np.degrees(med([e.exit_rad - e.entry_rad for e in every])))
    if width < COLLAPSED_WINDOW_DEG:
        # the fits shrink the window to nothing: no engagement explains the harmonics better
        # than their noise (decision 1739)
        why = (f"the revolutions' fits collapse to no engagement window (median width "
               f"{width:.1f}°): the torque's tooth harmonics are in its noise here (a light cut, "
               "or an estimate's noise at these frequencies)")  # fmt: skip
    elif 2 * len(inside) > len(every):
        # decision 1738: most windows inside the half-turn
        entry = float(np.degrees(med([e.entry_rad for e in inside])))
        exit_ = float(np.degrees(med([e.exit_rad for e in inside])))
        why = (f"most revolutions' engagement window lies inside the half-turn (median "
               f"{entry:.0f}° to {exit_:.0f}°), which no steady side cut gives: a transient, "
               "or a spindle angle whose zero is not the tool's reference (decision 1738)")
    return (
        f"engagement not determined: {len(est)} of {len(every)} "
        f"revolutions{where} reliable (σ ≥ {RELIABLE_SIGMA}, K_t > 0, K_e ≥ 0, a side cut's "
        f"window; median σ {med([e.reliability for e in every]):.2f}){allowed}; {why}"
    )


def depth_span(low_m: float, high_m: float) -> str:
    """The depths an undetermined engagement allows, in words (an infinite bound: the search's
    own end)."""
    if math.isfinite(low_m) and math.isfinite(high_m):
        return f"from {1e3 * low_m:.2f} to {1e3 * high_m:.2f} mm"
    if math.isfinite(low_m):
        return f"from {1e3 * low_m:.2f} mm to the largest depth searched"
    if math.isfinite(high_m):
        return f"from the smallest depth searched to {1e3 * high_m:.2f} mm"
    return "in the whole range searched"


def _engagement_values(
    dr: list[float], kt: list[float], runout: list[float], sigma: list[float],
    ke: list[float], source: list[float],
) -> str:  # fmt: skip
    """The summary's radial depth, K_t, runout, reliability and K_e (medians), in words."""

    def med(v: list[float]) -> float:
        return float(np.median(v))

    return (
        f"radial depth {1e3 * med(dr):.3f} mm, K_t {1e-6 * med(kt):.0f} N/mm², runout "
        f"{1e6 * med(runout):.1f} µm, reliability {med(sigma):.3f}, K_e "
        f"{1e-3 * med(ke):.1f} N/mm ({_edge_source(source)})"
    )


#: Where the engagement monitor's K_e came from (``EngagementEstimate.edge_source``, decision
#: 1806), as the summary line says it.
_EDGE_SOURCES = {
    0: "not fitted",
    1: "from the tooth harmonics",
    2: "from the mean torque",
    3: "harmonics only, no air torque known: less reliable",
}


def _edge_source(sources: list[float]) -> str:
    """The most frequent source of K_e over the revolutions, in words."""
    vals, counts = np.unique(np.asarray(sources, dtype=int), return_counts=True)
    return _EDGE_SOURCES.get(int(vals[np.argmax(counts)]), "unknown")


