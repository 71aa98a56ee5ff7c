"""A virtual plan as the engagement and the job of the virtual machine.

:class:`PlanEngagement` implements the engagement-source protocol of
:mod:`millsense.simulator.process_coupling` (``table``, ``at(s_m, t_s)``) from the rows of a
:class:`~millsense.plan.virtual_plan.VirtualPlan`: row k's engagement (all layers, the exact
intervals of the CWE) and axial depth hold while the tool travels from row k to row k+1
(the engagement criterion of :mod:`millsense.plan.cwe`: the material met on the way from
P_k to P_{k+1}). :func:`plan_path` gives the polyline, feed, spindle speed and NC line of the
rows, from which the CLI builds the simulator's ``Job`` (``virtual`` does not import
``machine``; both sit on ``process``).

Arc length is measured the way the simulator's interpolator measures the job path: the
cumulative chord length between consecutive rows (x, y, z), so the engagement is looked up on
the same polyline the machine follows (the plan's own ``s_mm`` is the arc length along exact
arcs; the two differ by 4·10⁻⁵ mm per 0.4 mm step on an R 8 mm arc).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError
from millsense.core.units import MM, MM_PER_MIN, RPM
from millsense.plan.path import cnc_line
from millsense.plan.virtual_plan import VirtualPlan
from millsense.process.engagement import Engagement

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class PlanPath:
    """The rows of a plan as a polyline the virtual machine runs (arguments of ``Job``).

    Attributes
    ----------
    path : (N, 3) tool tip, m, or (N, 5) with A and C, rad.
    feed_m_s : (N−1,) programmed feed per segment, m/s (the feed of the row it moves to).
    spindle_rad_s : (N−1,) programmed spindle speed per segment, rad/s.
    nc_line : (N−1,) N number (source line where the block had none) per segment.
    rapid : (N−1,) True on rapid segments.
    rows : (N,) plan row of every path point (rows that do not move are dropped).
    """

    path: FloatArray
    feed_m_s: FloatArray
    spindle_rad_s: FloatArray
    nc_line: IntArray
    rapid: NDArray[np.bool_]
    rows: IntArray


def _chord_arc_length(xyz: FloatArray) -> FloatArray:
    seg = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def plan_path(plan: VirtualPlan, five_axis: bool = False) -> PlanPath:
    """Polyline through the plan rows with their feed, spindle speed and NC line.

    Parameters
    ----------
    plan : the virtual plan.
    five_axis : include the A and C columns (5-axis trunnion machine).

    Notes
    -----
    Segment k → k+1 takes the feed, spindle speed, NC line and rapid flag of row k+1 (the
    convention of ``Job.from_sampled_path``); rows that do not move from the previous kept
    row (less than 1 pm, and no rotary motion on a 5-axis machine) are dropped. The rows are
    the path: corners between 0.4 mm rows are cut by the chord (at most step/2 · sin(θ/2)
    from the programmed vertex), which the plan's engagement shares.

    A rotary-only move (``G0 A30 C90`` of a 3+2 set-up, ``G1 C90 F3600``) holds no row of the
    plan (:func:`~millsense.plan.path.sample_path`): its rotation falls into the segment to
    the next row, whose plan time (``t_s``) includes the rotation's at its rate. On a 5-axis
    machine a segment that turns the rotary axes takes at least that time: its feed is lowered
    to its length over the plan's time (decision 1743; at the row's feed the rotation came in
    a few milliseconds, and the virtual machine's C axis ran at 100 rad/s and diverged).
    """
    xyz = plan.xyz_m
    cols = [xyz]
    if five_axis:
        cols.append(np.radians(np.column_stack([plan["a_deg"], plan["c_deg"]])))
    pts = np.column_stack(cols).astype(np.float64)
    if len(pts) < 2:
        raise InputDataError("plan: fewer than two rows, nothing to run")
    seg = np.diff(pts, axis=0)
    length = np.linalg.norm(seg[:, :3], axis=1)
    if five_axis:
        length = np.where(length > 1e-12, length, np.linalg.norm(seg[:, 3:], axis=1))
    keep = np.concatenate([[True], length > 1e-12])
    idx = np.nonzero(keep)[0]
    if len(idx) < 2:
        raise InputDataError("plan: the rows do not move, nothing to run")
    nc = cnc_line(plan["nc_line"], plan["source_line"])
    nxt = idx[1:]
    feed = np.maximum(np.asarray(plan["feed_mm_min"], dtype=np.float64)[nxt], 1e-6) * MM_PER_MIN
    if five_axis:
        # a segment that turns the rotary axes lasts at least the plan's time (decision 1743)
        kept = np.diff(pts[idx], axis=0)
        rot = np.linalg.norm(kept[:, 3:], axis=1)
        lin = np.linalg.norm(kept[:, :3], axis=1)
        turns = rot > 1e-12
        dt = np.diff(np.asarray(plan["t_s"], dtype=np.float64)[idx])
        size = np.where(lin > 1e-12, lin, rot)  # the interpolator's length (m, else rad)
        slow = turns & (dt > 0.0) & (size < (1.0 - 1e-9) * feed * dt)
        feed = np.where(slow, size / np.where(slow, dt, 1.0), feed)
    return PlanPath(
        path=pts[idx],
        feed_m_s=feed,
        spindle_rad_s=np.asarray(plan["spindle_rpm"], dtype=np.float64)[nxt] * RPM,
        nc_line=nc[nxt],
        rapid=np.asarray(plan["rapid"], dtype=np.bool_)[nxt],
        rows=idx.astype(np.int64),
    )


@dataclass
class PlanEngagement:
    """Engagement source of the virtual machine from a virtual plan, by arc length.

    Parameters
    ----------
    plan : the virtual plan (format 2 for the full per-layer engagement).

    Attributes
    ----------
    table : distinct engagements of the rows in cut (index = ``engagement_index``).
    row_index : (n,) index into ``table`` per row (−1 out of cut, on rapids or at depth 0).
    row_depth_m : (n,) axial depth per row, m (0 where ``row_index`` is −1).
    row_s_m : (n,) chord arc length of every row along the rows' polyline, m.
    exact : True when the per-layer intervals were used, False for the version-1 fallback.
    notes : things the user should know (the fallback), one line each.

    Notes
    -----
    ``at(s)`` returns the state of row k for ``row_s_m[k] ≤ s < row_s_m[k+1]`` and air before
    the first and from the last row on. Distinct engagements: rows with equal interval counts
    and float32 intervals in every layer share one table entry (the CWE quantises the angles
    to its 0.5° bins, so the demo part's 3 821 rows in cut need a few hundred). Without the
    layer columns (format 1) every row in cut uses its widest interval (``entry_deg``,
    ``exit_deg``) at all heights — exact for a slot or a straight radial cut, not where
    layers differ (a depth step inside the tool, a floor with walls).
    """

    plan: VirtualPlan
    table: tuple[Engagement, ...] = field(init=False)
    row_index: IntArray = field(init=False)
    row_depth_m: FloatArray = field(init=False)
    row_s_m: FloatArray = field(init=False)
    exact: bool = field(init=False)
    notes: list[str] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        p = self.plan
        n = len(p)
        self.row_s_m = _chord_arc_length(p.xyz_m)
        depth = np.asarray(p["axial_depth_mm"], dtype=np.float64) * MM
        active = np.asarray(p["in_cut"], bool) & ~np.asarray(p["rapid"], bool) & (depth > 0)
        index = np.full(n, -1, dtype=np.int64)
        table: list[Engagement] = []
        lay = p.layers
        if lay is not None:
            self.exact = True
            active &= lay.counts.sum(axis=1) > 0
            key = np.concatenate(
                [
                    lay.counts.astype(np.float32),
                    lay.intervals_rad.reshape(n, -1).astype(np.float32),
                ],
                axis=1,
            )[active]
            uniq, inv = np.unique(key, axis=0, return_inverse=True)
            n_layers, m = lay.counts.shape[1], lay.intervals_rad.shape[2]
            for u in uniq:
                cnt = u[:n_layers].astype(np.int64)
                iv = u[n_layers:].reshape(n_layers, m, 2).astype(np.float64)
                table.append(
                    Engagement.from_intervals(
                        [
                            [(float(a), float(b)) for a, b in iv[k, : cnt[k]]]
                            for k in range(n_layers)
                        ]
                    )
                )
            index[active] = inv.reshape(-1)
        else:
            self.exact = False
            entry = np.radians(np.asarray(p["entry_deg"], dtype=np.float64))
            exit_ = np.radians(np.asarray(p["exit_deg"], dtype=np.float64))
            active &= (np.asarray(p["n_intervals"]) > 0) & (exit_ > entry)
            pairs = np.column_stack([entry, exit_])[active]
            uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
            table = [Engagement(layers=(((float(a), float(b)),),)) for a, b in uniq]
            index[active] = inv.reshape(-1)
            self.notes.append(
                "plan without per-layer intervals (format 1): the engagement of every row is "
                "its widest interval at all heights (re-plan for the exact engagement)"
            )
        self.table = tuple(table)
        self.row_index = index
        self.row_depth_m = np.where(index >= 0, depth, 0.0)
        # lookup arrays of at(): one past the last row is air
        self._idx = np.concatenate([self.row_index[:-1], [-1, -1]]) if n else np.array([-1])
        self._dep = np.concatenate([self.row_depth_m[:-1], [0.0, 0.0]]) if n else np.zeros(1)

    @property
    def max_depth_m(self) -> float:
        """Largest axial depth of the plan, m (the chatter simulation's disc span)."""
        return float(self.row_depth_m.max(initial=0.0))

    def at(self, s_m: FloatArray, t_s: FloatArray | None = None) -> tuple[IntArray, FloatArray]:
        """Engagement index (−1 in air) and axial depth (m) per sample at arc length ``s_m``.

        ``t_s`` is not used (the plan is indexed by arc length).
        """
        s = np.asarray(s_m, dtype=np.float64)
        k = np.searchsorted(self.row_s_m, s, side="right") - 1
        k = np.where(k < 0, len(self._idx) - 1, k)  # before the first row: air
        k = np.minimum(k, len(self._idx) - 1)
        return self._idx[k], self._dep[k]

    def row_at(self, s_m: FloatArray) -> IntArray:
        """Plan row per arc length (−1 before the first row)."""
        k = np.searchsorted(self.row_s_m, np.asarray(s_m, dtype=np.float64), side="right") - 1
        return np.asarray(np.minimum(k, len(self.row_s_m) - 1), dtype=np.int64)

    def summary(self) -> str:
        """One line: rows in cut, distinct engagements, exact or fallback."""
        kind = "per-layer intervals" if self.exact else "widest interval (format 1)"
        return (
            f"{int((self.row_index >= 0).sum())} rows in cut, {len(self.table)} distinct "
            f"engagements ({kind}), max depth {self.max_depth_m * 1e3:.2f} mm"
        )
