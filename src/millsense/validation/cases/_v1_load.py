"""The V1 cut's load (seed 000 V1, Aslan Ch. 3.5) with the realism of a real cut (issue 12).

Ø20 mm 2-flute end mill (30° helix), full-immersion slot, 4 mm deep, 0.2 mm/tooth, Al7050,
the table feeding along +X; Aslan measured the forces with a table dynamometer. Before
2026-11-28 the simulated cut was a constant-speed, runout-free slot switched on at full
engagement: exactly periodic with the tooth period. It now has, as a real cut has (decision
1710):

- **radial runout** of the cutter, ρ = :data:`V1_RUNOUT_M` = 37 µm at
  λ = :data:`V1_RUNOUT_ANGLE_RAD` (seed 000 Ch. 4.5: "the runout at the tool tip which is
  measured as 35-40 micron" on Aslan's Ø20 mm 2-flute end mill; the same value the Ch. 4
  replica uses, decision 0096; the angle is that replica's, a choice). The two flutes cut
  unequal chips, so the force repeats once per revolution, not once per tooth;
- **the spindle's speed variation**: the tool turns at the angle of the preset's truth spindle
  (:class:`~millsense.simulator.truth_spindle.TruthSpindleSim`, torsional structure, velocity
  and current PI, ripple, bearing drag) under the cut's own torque, run up to speed before the
  record: the speed dips at the entry and ripples at the tooth frequency. The torque depends on
  the angle and the angle on the torque; :data:`SPINDLE_PASSES` fixed-point passes solve it
  (the change of the last pass is returned);
- **the entry**: the cutter enters the workpiece's edge (perpendicular to the feed) at the
  feed, so the engaged arc grows from nothing to the half circle over R/v_f (1.5 s at
  1000 rev/min, 0.27 s at 5500 rev/min): immersion ``[asin(e/R), π − asin(e/R)]`` for the edge
  a distance ``e`` ahead of the tool's centre, quantised in :data:`ENTRY_STEPS` steps.

Forces are those on the table along +X/+Y in the frames of :mod:`millsense.simulator.slot_cut`
(the table moves along +X; the drive's load is their opposite).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from millsense.process.geometry import EndMill

#: radial runout of the V1 cutter, m, and its direction (see the module docstring)
V1_RUNOUT_M = 37e-6
V1_RUNOUT_ANGLE_RAD = 0.4
#: feed per tooth, axial depth (m), flutes of the V1 cut
V1_FEED_PER_TOOTH_M = 0.2e-3
V1_DEPTH_M = 4e-3
#: the machine whose truth spindle turns the tool
V1_MACHINE = "quaser-ux600"
#: spindle run-up before the record: ramp and hold, s
SPINUP_RAMP_S, SPINUP_HOLD_S = 1.0, 1.0
#: fixed-point passes of torque → spindle angle → torque
SPINDLE_PASSES = 3
#: steps of the entry's engaged arc (edge distance quantised in R/ENTRY_STEPS)
ENTRY_STEPS = 200
#: axial discs of the force model
N_DISCS = 20


@dataclass(frozen=True)
class V1Load:
    """One V1 cut: air, entry, steady slot, sampled at ``fs`` (SI).

    ``table_x``/``table_y``: force on the table, N; ``torque``: cutting torque at the tool,
    N·m; ``tool_speed``: the truth spindle's tool speed, rad/s; ``n_air``: samples before the
    first contact; ``n_full``: first sample at full engagement; ``feed``: m/s; ``tooth_hz``:
    nominal tooth frequency; ``pass_change``: largest |ΔF| of the last fixed-point pass, N.
    """

    table_x: np.ndarray
    table_y: np.ndarray
    torque: np.ndarray
    tool_speed: np.ndarray
    n_air: int
    n_full: int
    feed: float
    tooth_hz: float
    pass_change: float


def v1_feed(rpm: float, n_flutes: int = 2) -> float:
    """Table feed of the V1 cut at ``rpm``, m/s (0.2 mm/tooth)."""
    return V1_FEED_PER_TOOTH_M * n_flutes * rpm / 60.0


def v1_tool(runout_m: float = V1_RUNOUT_M) -> EndMill:
    """The V1 end mill (preset ``aslan-d20-2flute``) with radial runout ``runout_m``."""
    import dataclasses

    from millsense.core.config import ToolConfig
    from millsense.core.presets import load_preset

    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    return dataclasses.replace(tool, runout_offset_m=runout_m, runout_angle_rad=V1_RUNOUT_ANGLE_RAD)


def entry_immersion(edge_ahead_m: float, radius_m: float) -> tuple[float, float] | None:
    """Engaged arc of a slotting cutter whose centre is ``edge_ahead_m`` behind the edge.

    The workpiece lies beyond the edge (a plane normal to the feed); behind the edge the slot
    is already cut. A flute at immersion φ sits ``R·sin φ`` ahead of the centre along the feed
    (:mod:`millsense.process.geometry`), so it is in the material for ``R sin φ ≥ e``:
    ``[asin(e/R), π − asin(e/R)]``; None before the first contact (e ≥ R), the half circle
    once the centre has passed the edge (e ≤ 0).
    """
    if edge_ahead_m >= radius_m:
        return None
    a = math.asin(max(edge_ahead_m, 0.0) / radius_m)
    return a, math.pi - a


def _forces(
    tool: EndMill, angle: np.ndarray, n_air: int, n_entry: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table forces X/Y and tool torque along the record, the entry by its quantised arcs."""
    from millsense.core.config import MaterialConfig
    from millsense.core.presets import load_preset
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.engagement import Engagement
    from millsense.process.forces import milling_forces

    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    n = len(angle)
    fx, fy, tq = np.zeros(n), np.zeros(n), np.zeros(n)
    r = tool.radius_m
    # entry: the edge moves from R to 0 ahead of the centre over n_entry samples, one
    # engagement per step of R/ENTRY_STEPS (its arc at the step's middle)
    edges = np.linspace(n_air, n_air + n_entry, ENTRY_STEPS + 1).round().astype(int)
    spans = [
        (int(a), int(b), r * (1 - (k + 0.5) / ENTRY_STEPS))
        for k, (a, b) in enumerate(itertools.pairwise(edges))
    ]
    spans.append((n_air + n_entry, n, 0.0))
    for a, b, e in spans:
        arc = entry_immersion(e, r)
        if b <= a or arc is None:
            continue
        eng = Engagement.slot() if e <= 0 else Engagement.from_intervals([arc])
        cut = milling_forces(
            tool, coeffs, eng, V1_FEED_PER_TOOTH_M, V1_DEPTH_M, angle[a:b], n_discs=N_DISCS
        )
        # force on the table along +X / +Y (the frames of simulator.slot_cut: the table moves
        # along +X, the tool feeds along -X relative to the workpiece)
        fx[a:b], fy[a:b], tq[a:b] = cut.fx_n, cut.fy_n, cut.torque_nm
    return fx, fy, tq


@cache
def v1_load(
    rpm: float,
    n_air: int,
    n_steady: int,
    fs: float = 10_000.0,
    runout_m: float = V1_RUNOUT_M,
    spindle: bool = True,
    entry: bool = True,
) -> V1Load:
    """The V1 cut at ``rpm``: ``n_air`` samples of air, the entry, ``n_steady`` samples of
    full slot (see the module docstring; ``spindle=False`` turns at the constant commanded
    speed, ``entry=False`` engages the full slot at once, ``runout_m=0`` removes the runout:
    the load of before, for comparison)."""
    from millsense.simulator.truth_spindle import TruthSpindleSim, load_truth_spindle

    tool = v1_tool(runout_m)
    w = rpm * 2 * math.pi / 60.0
    feed = v1_feed(rpm, tool.n_flutes)
    n_entry = round(tool.radius_m / feed * fs) if entry else 0
    n = n_air + n_entry + n_steady
    angle = w * np.arange(n) / fs
    fx, fy, tq = _forces(tool, angle, n_air, n_entry)
    speed = np.full(n, w)
    change = 0.0
    if spindle:
        n_ramp, n_hold = round(SPINUP_RAMP_S * fs), round(SPINUP_HOLD_S * fs)
        ref = np.concatenate([np.arange(n_ramp) / n_ramp * w, np.full(n_hold + n, w)])
        for _ in range(SPINDLE_PASSES):
            sim = TruthSpindleSim(load_truth_spindle(V1_MACHINE), fs)
            out = sim.advance(ref, np.concatenate([np.zeros(n_ramp + n_hold), tq]))
            rec = slice(n_ramp + n_hold, None)
            angle = out["angle"][rec] - out["angle"][n_ramp + n_hold]
            speed = out["true_speed"][rec]
            fx_new, fy_new, tq = _forces(tool, angle, n_air, n_entry)
            change = float(max(np.max(np.abs(fx_new - fx)), np.max(np.abs(fy_new - fy))))
            fx, fy = fx_new, fy_new
    return V1Load(fx, fy, tq, speed, n_air, n_air + n_entry, feed, rpm / 60 * tool.n_flutes, change)
