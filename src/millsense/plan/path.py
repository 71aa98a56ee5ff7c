"""Toolpath representation (one row per programmed move) and fixed arc-length sampling.

A :class:`Toolpath` is what :mod:`millsense.plan.gcode` produces: a structure of numpy arrays
with one row per move (rapid, feed line, circular/helical arc, dwell), SI units inside. The
sampler :func:`sample_path` walks it at a fixed arc length (0.4 mm by default, the spacing of
Aslan's virtual feedback file, seed 000 §0 and §6) and returns a :class:`SampledPath`.

Coordinates are the tool tip (controlled point) in the machine frame: program coordinates plus
the active work offset (G54-G59). Rotary axes A and C are in radians; they are carried through
(interpolated linearly along each move) and do not add to the path length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from millsense.core.budget import check_path_points, check_path_steps
from millsense.core.units import MM, MM_PER_MIN

#: Move kinds (``Toolpath.kind``).
RAPID = 0
LINE = 1
ARC = 2
DWELL = 3

#: Planes (``Toolpath.plane``): index triples (u, v, w) into (x, y, z), right-handed so that a
#: positive (counter-clockwise, G3) rotation is about +w. XY for G17, ZX for G18, YZ for G19.
PLANE_XY = 0
PLANE_ZX = 1
PLANE_YZ = 2
PLANE_AXES = np.array([[0, 1, 2], [2, 0, 1], [1, 2, 0]], dtype=np.intp)

DEFAULT_STEP = 0.4 * MM  #: m, Aslan's virtual-file spacing (seed 000 §0)
DEFAULT_RAPID_RATE = 20_000.0 * MM_PER_MIN  #: m/s (20 m/min); machines differ, configurable
DEFAULT_RAPID_ROTARY_RATE = 2.0 * math.pi * 20.0 / 60.0  #: rad/s (20 rev/min), configurable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class Toolpath:
    """Programmed moves of a part program, one row per move, SI units.

    Attributes
    ----------
    kind : (n,) int8
        :data:`RAPID` (G0), :data:`LINE` (G1), :data:`ARC` (G2/G3) or :data:`DWELL` (G4).
    start, end : (n, 5) float64
        Start and end of each move, ``[x, y, z, a, c]`` in m (x, y, z) and rad (a, c).
        ``start[i] == end[i-1]``.
    centre : (n, 3) float64
        Arc centre in m (its coordinate along the arc axis is the start's); NaN for non-arcs.
    plane : (n,) int8
        :data:`PLANE_XY`, :data:`PLANE_ZX` or :data:`PLANE_YZ` for arcs, -1 otherwise.
    direction : (n,) int8
        +1 counter-clockwise (G3), -1 clockwise (G2) seen from the positive arc axis; 0 else.
    sweep : (n,) float64
        Swept angle of an arc, rad, positive (2π for a full circle, more with a P word).
    radius_start, radius_end : (n,) float64
        Distance from the centre to the start and end in the arc plane, m. They differ by at
        most the arc tolerance; the arc is then a spiral (see ``gcode`` Notes). 0 for non-arcs.
    feed : (n,) float64
        Programmed feed along the path, m/s (G94 feed per minute converted); NaN for rapids
        and dwells.
    rotary_feed : (n,) float64
        For a feed move with rotary motion only, the F word read as deg/min, in rad/s; NaN else.
    spindle_speed : (n,) float64
        Programmed spindle speed while the spindle turns, rad/s; 0 when it is stopped (M5).
    spindle_dir : (n,) int8
        +1 for M3 (clockwise), -1 for M4, 0 stopped.
    tool : (n,) int32
        Tool in the spindle (last M6; 0 before any tool change).
    nc_line : (n,) int64
        N number of the block, -1 if the block had none.
    source_line : (n,) int64
        1-based line of the source file.
    dwell : (n,) float64
        Dwell time of a :data:`DWELL` row, s; 0 otherwise.
    source : str
        File name (or label) the program was read from.
    notes : tuple of str
        Things the interpreter accepted but ignored (M0/M1, M2 missing...), one line each.
    tool_changes : tuple of (line, tool)
        1-based source line and tool number of every M6, in program order.
    """

    kind: NDArray[np.int8]
    start: FloatArray
    end: FloatArray
    centre: FloatArray
    plane: NDArray[np.int8]
    direction: NDArray[np.int8]
    sweep: FloatArray
    radius_start: FloatArray
    radius_end: FloatArray
    feed: FloatArray
    rotary_feed: FloatArray
    spindle_speed: FloatArray
    spindle_dir: NDArray[np.int8]
    tool: NDArray[np.int32]
    nc_line: IntArray
    source_line: IntArray
    dwell: FloatArray
    source: str = "<string>"
    notes: tuple[str, ...] = field(default_factory=tuple)
    tool_changes: tuple[tuple[int, int], ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    def lengths(self) -> FloatArray:
        """Exact length of each move in x, y, z, m.

        Notes
        -----
        Lines: ``|end - start|``. Arcs (helical included): ``sqrt((r̄·Θ)² + Δw²)`` with Θ the
        sweep, Δw the travel along the arc axis and ``r̄ = (r_start + r_end)/2``; this is exact
        for a circular or helical arc (r_start = r_end) and second-order accurate in the radius
        mismatch (≤ 2 µm) of a spiral arc. Dwells: 0.
        """
        d = self.end[:, :3] - self.start[:, :3]
        out = np.sqrt(np.einsum("ij,ij->i", d, d))
        arc = self.kind == ARC
        if np.any(arc):
            ax = PLANE_AXES[self.plane[arc]][:, 2]
            dw = np.take_along_axis(d[arc], ax[:, None], axis=1)[:, 0]
            rbar = 0.5 * (self.radius_start[arc] + self.radius_end[arc])
            out[arc] = np.hypot(rbar * self.sweep[arc], dw)
        out[self.kind == DWELL] = 0.0
        return out

    def durations(
        self,
        rapid_rate: float = DEFAULT_RAPID_RATE,
        rapid_rotary_rate: float = DEFAULT_RAPID_ROTARY_RATE,
    ) -> FloatArray:
        """Time of each move at programmed feed, s (no acceleration limits).

        Parameters
        ----------
        rapid_rate : float
            Speed of G0 moves along the path, m/s.
        rapid_rotary_rate : float
            Speed of the faster rotary axis in a G0 move without x, y, z motion, rad/s.

        Notes
        -----
        Feed moves take ``L/F``. A move with rotary motion only takes ``max(|ΔA|, |ΔC|)/F``
        with F read in deg/min (LinuxCNC semantics). Dwells take their P time.
        """
        lengths = self.lengths()
        speed = np.where(self.kind == RAPID, rapid_rate, self.feed)
        out = np.zeros(len(self))
        moving = lengths > 0.0
        out[moving] = lengths[moving] / speed[moving]
        rot = np.max(np.abs(self.end[:, 3:] - self.start[:, 3:]), axis=1)
        rot_only = (~moving) & (rot > 0.0) & (self.kind != DWELL)
        rrate = np.where(self.kind == RAPID, rapid_rotary_rate, self.rotary_feed)
        out[rot_only] = rot[rot_only] / rrate[rot_only]
        dw = self.kind == DWELL
        out[dw] = self.dwell[dw]
        return out


def cnc_line(nc_line: IntArray, source_line: IntArray) -> IntArray:
    """The line a CNC names a block by: its N number, else (``nc_line`` < 0: none) its line in
    the program, as the virtual machine's ``cnc/nc_line`` reports it (decision 1739)."""
    nc = np.asarray(nc_line, dtype=np.int64)
    return np.where(nc >= 0, nc, np.asarray(source_line, dtype=np.int64))


@dataclass(frozen=True)
class SampledPath:
    """The toolpath sampled at a fixed arc length, one entry per sample, SI units.

    Attributes
    ----------
    s : (m,) float64
        Arc length along the path (x, y, z) from the program start, m. ``diff(s)`` equals the
        step everywhere except possibly the last interval.
    t : (m,) float64
        Time at programmed feed (rapids at the rapid rate, dwells included), s.
    x, y, z, a, c : (m,) float64
        Tool tip position, m, and rotary axes, rad.
    tangent : (m, 3) float64
        Unit direction of motion (feed direction) at the sample.
    feed : (m,) float64
        Path speed, m/s (the rapid rate on rapids).
    rapid : (m,) bool
        True on G0 moves.
    spindle_speed : (m,) float64
        rad/s, 0 while the spindle is stopped.
    spindle_dir : (m,) int8
        +1 M3, -1 M4, 0 stopped.
    tool, nc_line, source_line, move : (m,) int
        Tool number, N number (-1 if none), source line and row of the :class:`Toolpath`.
    step : float
        The sampling step, m.
    """

    s: FloatArray
    t: FloatArray
    x: FloatArray
    y: FloatArray
    z: FloatArray
    a: FloatArray
    c: FloatArray
    tangent: FloatArray
    feed: FloatArray
    rapid: NDArray[np.bool_]
    spindle_speed: FloatArray
    spindle_dir: NDArray[np.int8]
    tool: NDArray[np.int32]
    nc_line: IntArray
    source_line: IntArray
    move: IntArray
    step: float

    def __len__(self) -> int:
        return int(self.s.shape[0])

    @property
    def xyz(self) -> FloatArray:
        """(m, 3) tool tip positions, m."""
        return np.column_stack((self.x, self.y, self.z))


def sample_path(
    path: Toolpath,
    step: float = DEFAULT_STEP,
    *,
    rapid_rate: float = DEFAULT_RAPID_RATE,
    rapid_rotary_rate: float = DEFAULT_RAPID_ROTARY_RATE,
) -> SampledPath:
    """Sample a toolpath every ``step`` of arc length across lines and arcs.

    Parameters
    ----------
    path : Toolpath
        Moves from :func:`millsense.plan.gcode.interpret`.
    step : float
        Arc-length spacing, m (default 0.4 mm, Aslan's virtual-file spacing).
    rapid_rate : float
        Speed along G0 moves, m/s (default 20 m/min).
    rapid_rotary_rate : float
        Speed of G0 moves that turn rotary axes only, rad/s (default 20 rev/min).

    Returns
    -------
    SampledPath
        Samples at ``s = 0, step, 2·step, ...`` and at the path end ``s = L``.

    Notes
    -----
    Sample k lies at ``s_k = k·h`` (h the step) on the move whose arc-length interval
    ``[S_i, S_i + L_i)`` contains it; zero-length moves (dwells, rotary-only moves) hold no
    sample but add their time. On a line ``p = p0 + u·(p1 - p0)``, on an arc
    ``θ = θ0 + d·u·Θ``, ``r = r0 + u·(r1 - r0)``, ``w = w0 + u·Δw`` with ``u = (s_k - S_i)/L_i``
    (arc-length parameter of a helix; exact for circular arcs). Rotary axes are linear in u.
    Time is ``T_i + (s_k - S_i)/F_i`` with ``T_i`` the summed durations of the earlier moves.
    Vectorised over samples; no Python loop per sample.
    """
    if not step > 0.0:
        raise ValueError(f"sampling step must be positive, got {step!r} m")
    lengths = path.lengths()
    durations = path.durations(rapid_rate, rapid_rotary_rate)
    s_end = np.cumsum(lengths)
    s_start = s_end - lengths
    t_start = np.cumsum(durations) - durations
    total = float(s_end[-1]) if len(path) else 0.0
    positive = np.flatnonzero(lengths > 0.0)
    if positive.size == 0:
        return _empty(step)
    check_path_steps(total, step, path.source, _longest(path, lengths))

    n_full = math.floor(total / step + 1e-9)
    s = np.arange(n_full + 1, dtype=np.float64) * step
    s = s[s <= total]
    if total - s[-1] > 1e-9 * step:
        s = np.append(s, total)
    idx = np.searchsorted(s_end, s, side="right")
    idx = np.minimum(idx, positive[-1])
    u = (s - s_start[idx]) / lengths[idx]
    np.clip(u, 0.0, 1.0, out=u)

    p0 = path.start[idx]
    p1 = path.end[idx]
    pos = p0 + u[:, None] * (p1 - p0)  # lines, and rotary axes of every move
    tangent = p1[:, :3] - p0[:, :3]
    arc = path.kind[idx] == ARC
    if np.any(arc):
        _arc_points(path, idx[arc], u[arc], pos, tangent, arc)
    norm = np.sqrt(np.einsum("ij,ij->i", tangent, tangent))
    tangent = tangent / np.where(norm > 0.0, norm, 1.0)[:, None]

    kind = path.kind[idx]
    rapid = kind == RAPID
    feed = np.where(rapid, rapid_rate, path.feed[idx])
    t = t_start[idx] + (s - s_start[idx]) / feed
    return _sampled(path, idx, s, t, pos, tangent, feed, rapid, step)


#: Largest chord error of :func:`vertex_path` on arcs [m] by default.
DEFAULT_CHORD_TOLERANCE = 1e-6


def vertex_path(
    path: Toolpath,
    chord_tol_m: float = DEFAULT_CHORD_TOLERANCE,
    *,
    rapid_rate: float = DEFAULT_RAPID_RATE,
    rapid_rotary_rate: float = DEFAULT_RAPID_ROTARY_RATE,
) -> SampledPath:
    """The toolpath at its programmed vertices (exact corners), arcs split by chord error.

    Parameters
    ----------
    path : Toolpath
        Moves from :func:`millsense.plan.gcode.interpret`.
    chord_tol_m : float
        Largest distance between an arc (or helix) and its chords, m (1 µm).
    rapid_rate, rapid_rotary_rate : float
        As :func:`sample_path`.

    Returns
    -------
    SampledPath
        Point 0 is the start of the first move; then the end of every move that moves
        (x, y, z or a rotary axis), arcs preceded by their interior points. Every point
        carries the feed, spindle, tool, NC line and rapid flag of the move that *leads to*
        it (the convention of the simulator's ``Job.from_sampled_path``: a segment takes the
        state of the point it moves to); the first point those of the first move. ``step``
        is the chord tolerance.

    Notes
    -----
    An arc of radius r and sweep Θ gets ``n = ⌈Θ / (2 arccos(1 − δ/r))⌉`` chords (δ the
    tolerance), equal in parameter u; its points are those of :func:`sample_path`'s arc
    formula at ``u = i/n`` (helix and spiral included). Lines keep their end points only, so
    the machine's interpolator sees the programmed corners rather than the chords of 0.4 mm
    samples. Rotary-only moves (5-axis) are points too, with the F word as rad/s
    (``rotary_feed``) or the rapid rotary rate. Dwells add time only.
    """
    if not chord_tol_m > 0.0:
        raise ValueError(f"chord tolerance must be positive, got {chord_tol_m!r} m")
    n_mv = len(path)
    if n_mv == 0:
        return _empty(chord_tol_m)
    lengths = path.lengths()
    durations = path.durations(rapid_rate, rapid_rotary_rate)
    rot = np.max(np.abs(path.end[:, 3:] - path.start[:, 3:]), axis=1)
    moving = ((lengths > 0.0) | (rot > 0.0)) & (path.kind != DWELL)
    if not np.any(moving):
        return _empty(chord_tol_m)
    arc = (path.kind == ARC) & moving
    r_max = np.maximum(path.radius_start, path.radius_end)
    pieces = np.ones(n_mv, dtype=np.int64)
    if np.any(arc):
        ratio = np.clip(1.0 - chord_tol_m / np.maximum(r_max[arc], 1e-300), -1.0, 1.0)
        dphi = 2.0 * np.arccos(ratio)
        pieces[arc] = np.maximum(np.ceil(path.sweep[arc] / np.maximum(dphi, 1e-12)), 1)
    pieces[~moving] = 0
    check_path_points(float(pieces.sum()), path.source, _longest(path, lengths))
    idx = np.repeat(np.arange(n_mv), pieces)
    first = np.cumsum(pieces) - pieces
    u = (np.arange(idx.size) - first[idx] + 1) / pieces[idx]
    first_move = int(np.argmax(moving))
    idx = np.concatenate([[first_move], idx])
    u = np.concatenate([[0.0], u])
    p0 = path.start[idx]
    p1 = path.end[idx]
    pos = p0 + u[:, None] * (p1 - p0)
    tangent = p1[:, :3] - p0[:, :3]
    on_arc = path.kind[idx] == ARC
    if np.any(on_arc):
        _arc_points(path, idx[on_arc], u[on_arc], pos, tangent, on_arc)
    norm = np.sqrt(np.einsum("ij,ij->i", tangent, tangent))
    tangent = tangent / np.where(norm > 0.0, norm, 1.0)[:, None]
    s_start = np.cumsum(lengths) - lengths
    t_start = np.cumsum(durations) - durations
    s = s_start[idx] + u * lengths[idx]
    t = t_start[idx] + u * durations[idx]
    rapid = path.kind[idx] == RAPID
    rot_only = lengths[idx] <= 0.0
    feed = np.where(
        rapid,
        np.where(rot_only, rapid_rotary_rate, rapid_rate),
        np.where(rot_only, path.rotary_feed[idx], path.feed[idx]),
    )
    return _sampled(path, idx, s, t, pos, tangent, feed, rapid, chord_tol_m)


def _longest(path: Toolpath, lengths: FloatArray) -> str:
    """The longest move of ``path`` as ``line N, L m`` for a work-ceiling message."""
    k = int(np.argmax(np.where(np.isfinite(lengths), lengths, np.inf)))
    return f"line {int(path.source_line[k])}, {float(lengths[k]):.4g} m"


def _arc_points(
    path: Toolpath,
    idx: IntArray,
    u: FloatArray,
    pos: FloatArray,
    tangent: FloatArray,
    mask: NDArray[np.bool_],
) -> None:
    """Fill positions and tangents of the samples on arcs (in place, rows ``mask``)."""
    axes = PLANE_AXES[path.plane[idx]]  # (k, 3): u, v, w indices into x, y, z
    start = path.start[idx, :3]
    end = path.end[idx, :3]
    centre = path.centre[idx]
    su = np.take_along_axis(start, axes, axis=1)
    eu = np.take_along_axis(end, axes, axis=1)
    cu = np.take_along_axis(centre, axes, axis=1)
    theta0 = np.arctan2(su[:, 1] - cu[:, 1], su[:, 0] - cu[:, 0])
    d = path.direction[idx].astype(np.float64)
    sweep = path.sweep[idx]
    r0 = path.radius_start[idx]
    dr = path.radius_end[idx] - r0
    dw = eu[:, 2] - su[:, 2]
    theta = theta0 + d * u * sweep
    r = r0 + u * dr
    cos, sin = np.cos(theta), np.sin(theta)
    local = np.column_stack((cu[:, 0] + r * cos, cu[:, 1] + r * sin, su[:, 2] + u * dw))
    dlocal = np.column_stack(
        (
            -d * sweep * r * sin + dr * cos,
            d * sweep * r * cos + dr * sin,
            dw,
        )
    )
    xyz = np.empty_like(local)
    dxyz = np.empty_like(dlocal)
    np.put_along_axis(xyz, axes, local, axis=1)
    np.put_along_axis(dxyz, axes, dlocal, axis=1)
    pos[mask, :3] = xyz
    tangent[mask] = dxyz


def _empty(step: float) -> SampledPath:
    f = np.zeros(0)
    i = np.zeros(0, dtype=np.int64)
    return SampledPath(
        s=f,
        t=f,
        x=f,
        y=f,
        z=f,
        a=f,
        c=f,
        tangent=np.zeros((0, 3)),
        feed=f,
        rapid=np.zeros(0, dtype=bool),
        spindle_speed=f,
        spindle_dir=np.zeros(0, dtype=np.int8),
        tool=np.zeros(0, dtype=np.int32),
        nc_line=i,
        source_line=i,
        move=i,
        step=float(step),
    )


def _sampled(
    path: Toolpath,
    idx: NDArray[np.int64],
    s: NDArray[np.float64],
    t: NDArray[np.float64],
    pos: NDArray[np.float64],
    tangent: NDArray[np.float64],
    feed: NDArray[np.float64],
    rapid: NDArray[np.bool_],
    step: float,
) -> SampledPath:
    """A :class:`SampledPath` from sample positions and the move index of every sample."""
    return SampledPath(
        s=s,
        t=t,
        x=np.ascontiguousarray(pos[:, 0]),
        y=np.ascontiguousarray(pos[:, 1]),
        z=np.ascontiguousarray(pos[:, 2]),
        a=np.ascontiguousarray(pos[:, 3]),
        c=np.ascontiguousarray(pos[:, 4]),
        tangent=tangent,
        feed=feed,
        rapid=rapid,
        spindle_speed=path.spindle_speed[idx],
        spindle_dir=path.spindle_dir[idx],
        tool=path.tool[idx],
        nc_line=path.nc_line[idx],
        source_line=path.source_line[idx],
        move=idx.astype(np.int64),
        step=float(step),
    )
