"""Feed scheduling: a feed per step that holds a predicted peak force, torque or power at a
limit, and an optimised G-code program with the new F words (beyond the seeds).

Per engagement signature s the force at feed per tooth c is c/c_ref F_shear + F_edge
(:mod:`millsense.plan.predict`), so the limit defines one feed per tooth per signature:

- ``force``: the largest c with max_φ |c/c_ref S_xy(φ) + E_xy(φ)| ≤ F_lim (XY resultant,
  rotation invariant, so the feed direction does not matter);
- ``torque``: the same with the torque series;
- ``power``: mean torque × Ω ≤ P_lim, closed form per step.

The peak is convex and increasing in c (a maximum of convex functions, ≥ the edge part at
c = 0), so a vectorised bisection over all signatures finds it (60 halvings). The feed
v = c N Ω / 2π is clipped to [min, max] (out of cut: the programmed feed), consecutive steps
within ``merge_tolerance`` form runs at their minimum feed, and the v² rule limits the change
between steps to the axis acceleration: v_{k+1}² ≤ v_k² + 2 a Δs forwards and
v_k² ≤ v_{k+1}² + 2 a Δs backwards (both passes only lower feeds, so the limit holds).
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError, ProgramError
from millsense.core.units import MM, MM_PER_MIN
from millsense.plan.gcode import INCH_MM
from millsense.plan.path import ARC, LINE, PLANE_XY, Toolpath
from millsense.plan.virtual_plan import VirtualPlan

FloatArray = NDArray[np.float64]

#: Status per step (``FeedSchedule.status``).
AT_LIMIT = 0
AT_MAX = 1
AT_MIN = 2
PROGRAMMED = 3
ACCEL_LIMITED = 4

_KINDS = ("force", "torque", "power")
#: A feed change is written this far [mm] before the row where it applies.
SPLIT_BEFORE_MM = 1e-3
_COMMENTS = re.compile(r"\([^()]*\)|;.*")
_MOTION = re.compile(r"G0*[0123](?![\d.])", re.IGNORECASE)
_G20 = r"G0*20(?![\d.])"
_G21 = r"G0*21(?![\d.])"
#: F words of a block in inches (G20) are inch/min, rounded down to this [inch/min].
FEED_QUANTUM_INCH_MIN = 0.01
_GEOM = re.compile(r"([XYZIJKRF])\s*[-+]?(?:\d+\.?\d*|\.\d+)", re.IGNORECASE)


@dataclass
class FeedSchedule:
    """Scheduled feed per plan row.

    Attributes
    ----------
    feed_m_s : (n,) float
        Scheduled feed [m/s] (programmed feed on rapids and out of cut).
    target_m_s : (n,) float
        Feed holding the limit exactly, before bounds and smoothing [m/s] (inf if the limit
        is never reached, 0 if the edge forces alone exceed it).
    status : (n,) int8
        AT_LIMIT, AT_MAX, AT_MIN, PROGRAMMED or ACCEL_LIMITED.
    kind : str
        "force", "torque" or "power".
    limit : float
        The limit [N, N·m or W].
    """

    feed_m_s: FloatArray
    target_m_s: FloatArray
    status: NDArray[np.int8]
    kind: str
    limit: float


def _peak_solve(shear: FloatArray, edge: FloatArray, limit: float) -> FloatArray:
    """Largest x ≥ 0 with max_a g(x S_a + E_a) ≤ limit per signature (g = |.| or value)."""
    vector = shear.ndim == 3

    def peak(x: FloatArray) -> FloatArray:
        v = x[:, None, None] * shear + edge if vector else x[:, None] * shear + edge
        return np.sqrt((v**2).sum(axis=2)).max(axis=1) if vector else v.max(axis=1)

    s_max = np.sqrt((shear**2).sum(axis=2)).max(axis=1) if vector else np.abs(shear).max(axis=1)
    e_max = np.sqrt((edge**2).sum(axis=2)).max(axis=1) if vector else np.abs(edge).max(axis=1)
    lo = np.zeros(shear.shape[0])
    hi = (limit + e_max) / np.maximum(s_max, 1e-300)
    out = np.zeros_like(lo)
    ok = peak(lo) <= limit
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = peak(mid) <= limit
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    out[ok] = lo[ok]
    return out


@numba.njit(cache=True)
def _smooth(v: np.ndarray, ds: np.ndarray, chain: np.ndarray, accel: float) -> None:
    n = v.shape[0]
    for k in range(n - 1):
        if chain[k + 1]:
            cap = math.sqrt(v[k] * v[k] + 2.0 * accel * ds[k])
            if v[k + 1] > cap:
                v[k + 1] = cap
    for k in range(n - 2, -1, -1):
        if chain[k + 1]:
            cap = math.sqrt(v[k + 1] * v[k + 1] + 2.0 * accel * ds[k])
            if v[k] > cap:
                v[k] = cap


def _hold_to_the_move_end(
    plan: VirtualPlan, feed: FloatArray, status: NDArray[np.int8], rapid: NDArray[np.bool_]
) -> None:
    """The last row of a move faces the next move (its engagement is the chord's to the next
    row, decision 0066), but its feed runs from it to the move's end first, through the cut
    of the rows before it: it takes at most their feed (decision 1744). A slot's last row
    0.095 mm before an arc that turns back read out of the cut, and its piece of the slot
    was written at the programmed feed, 5 × the scheduled one."""
    line = np.asarray(plan["source_line"])
    if line.size < 3:
        return
    k = np.flatnonzero(line[1:-1] != line[2:]) + 1  # rows whose next row is another line
    k = k[(line[k] == line[k - 1]) & ~rapid[k] & ~rapid[k - 1] & (feed[k - 1] < feed[k])]
    feed[k] = feed[k - 1]
    status[k] = status[k - 1]


def schedule_feed(
    plan: VirtualPlan,
    limit: float,
    *,
    kind: str = "force",
    max_feed_m_s: float | None = None,
    min_feed_m_s: float | None = None,
    accel_m_s2: float = 1.0,
    merge_tolerance: float = 0.02,
) -> FeedSchedule:
    """Feed per row that keeps the predicted peak force (torque, power) at ``limit``.

    Parameters
    ----------
    plan : VirtualPlan
        A plan built in memory (with its force basis).
    limit : float
        Peak XY resultant [N], peak torque [N·m] or mean power [W].
    kind : {"force", "torque", "power"}
        Quantity limited.
    max_feed_m_s : float, optional
        Upper bound [m/s] (default: the programmed feed of each step; give it to speed up
        light cuts).
    min_feed_m_s : float, optional
        Lower bound [m/s] (default: 10 % of the programmed feed).
    accel_m_s2 : float
        Path acceleration for the v² rule [m/s²].
    merge_tolerance : float
        Consecutive steps whose targets differ by less than this fraction share one feed
        (the smallest), to keep the number of F changes down.

    Returns
    -------
    FeedSchedule
    """
    if kind not in _KINDS:
        raise InputDataError(f"schedule: kind must be one of {_KINDS}, got {kind!r}")
    if not (math.isfinite(limit) and limit > 0):
        raise InputDataError(f"schedule: limit must be > 0, got {limit!r}")
    if not accel_m_s2 > 0:
        raise InputDataError(f"schedule: accel_m_s2 must be > 0, got {accel_m_s2!r}")
    basis = plan.basis
    if basis is None:
        raise InputDataError("schedule: the plan has no force basis (plan the program in memory)")
    prog = plan["feed_mm_min"] * MM_PER_MIN
    rapid = plan["rapid"].astype(bool)
    sig = basis.signature
    act = sig >= 0
    omega = plan["spindle_rpm"] * (2 * math.pi / 60.0)
    flutes = int(plan.metadata["tool"]["flutes"])
    scale = (
        float(plan["ktc_n_mm2"][act][0] / plan.metadata["material"]["ktc_n_mm2"])
        if (act.any())
        else 1.0
    )
    target = np.full(len(plan), np.inf)
    if kind == "power":
        s_bar = basis.shear[:, :, 3].mean(axis=1) * scale
        e_bar = basis.edge[:, :, 3].mean(axis=1)
        w = np.where(act, omega, 1.0)
        x = (limit / w - e_bar[sig]) / np.maximum(s_bar[sig], 1e-300)
        c_star = np.maximum(x, 0.0) * basis.c_ref_m[sig]
    else:
        if kind == "force":
            x_sig = _peak_solve(basis.shear[:, :, :2] * scale, basis.edge[:, :, :2], limit)
        else:
            x_sig = _peak_solve(basis.shear[:, :, 3] * scale, basis.edge[:, :, 3], limit)
        c_star = x_sig[sig] * basis.c_ref_m[sig]
    target[act] = (c_star * flutes * omega / (2 * math.pi))[act]
    hi = np.full(len(plan), max_feed_m_s) if max_feed_m_s is not None else prog.copy()
    lo = np.full(len(plan), min_feed_m_s) if min_feed_m_s is not None else 0.1 * prog
    if np.any(lo[~rapid] > hi[~rapid]):
        raise InputDataError("schedule: minimum feed exceeds the maximum feed")
    feed = prog.copy()
    status = np.full(len(plan), PROGRAMMED, dtype=np.int8)
    sched = act & ~rapid
    feed[sched] = np.clip(target[sched], lo[sched], hi[sched])
    status[sched] = np.where(
        target[sched] >= hi[sched], AT_MAX, np.where(target[sched] <= lo[sched], AT_MIN, AT_LIMIT)
    )
    _hold_to_the_move_end(plan, feed, status, rapid)
    # runs of nearly equal feed share the smallest value
    run_start = 0
    n = len(plan)
    idx = np.flatnonzero(~rapid)
    if idx.size:
        f = feed[idx]
        starts = [0]
        ref = f[0]
        for i in range(1, idx.size):  # one pass over steps, offline (not a signal loop)
            contiguous = idx[i] == idx[i - 1] + 1
            if not contiguous or abs(f[i] - ref) > merge_tolerance * ref:
                starts.append(i)
                ref = f[i]
        bounds = [*starts, idx.size]
        for a, b in itertools.pairwise(bounds):
            run_start = a
            f[run_start:b] = f[run_start:b].min()
        before = feed.copy()
        feed[idx] = f
        chain = np.zeros(n, dtype=np.bool_)
        chain[1:] = ~rapid[1:] & ~rapid[:-1]
        ds = np.diff(plan["s_mm"]) * MM
        v = feed.copy()
        _smooth(v, np.append(ds, 0.0), chain, float(accel_m_s2))
        limited = (v < before * (1 - 1e-9)) & ~rapid
        feed = np.where(rapid, prog, v)
        status[limited & (status != AT_MIN)] = ACCEL_LIMITED
        status[(feed < before * (1 - merge_tolerance - 1e-9)) & ~rapid] = ACCEL_LIMITED
    return FeedSchedule(feed, target, status, kind, float(limit))


def _fmt(v: float) -> str:
    text = f"{v:.5f}".rstrip("0")
    return "0." if text in ("-0.", "0.") else text


def _strip_words(line: str, letters: str) -> str:
    """Remove words with the given letters outside comments."""
    out = []
    last = 0
    for m in _COMMENTS.finditer(line):
        out.append(
            _GEOM.sub(
                lambda w: "" if w.group(1).upper() in letters else w.group(0),
                line[last : m.start()],
            )
        )
        out.append(m.group(0))
        last = m.end()
    out.append(
        _GEOM.sub(lambda w: "" if w.group(1).upper() in letters else w.group(0), line[last:])
    )
    return re.sub(r"[ \t]+", " ", "".join(out)).rstrip()


def _with_words(line: str, words: str) -> str:
    """``line`` with ``words`` added to its block: before a ``;`` comment, which runs to the
    end of the line (after it they would be comment text)."""
    for m in _COMMENTS.finditer(line):
        if m.group(0).startswith(";"):
            head = line[: m.start()].rstrip()
            return f"{head} {words} {m.group(0)}" if head else f"{words} {m.group(0)}"
    # (an arc's last block keeps no word of its line but its words: no leading blank)
    return f"{line} {words}" if line.strip() else words


def _inch_blocks(lines: list[str]) -> list[bool]:
    """For every line, whether its words are in inches: G20 in effect, its own G20/G21
    included (units come first in a block, RS274/NGC v3 Table 8)."""
    inch = False
    out = []
    for raw in lines:
        body = _COMMENTS.sub("", raw).upper().replace(" ", "")
        if re.search(_G20, body):
            inch = True
        elif re.search(_G21, body):
            inch = False
        out.append(inch)
    return out


def _splittable(text: str) -> str | None:
    """Reason a program cannot be split in place (None if it can).

    The plan is interpreted without work offsets, so G54-G59 are zero translations and the
    plan's coordinates are the program's (in G21, G90, G91.1).
    """
    body = _COMMENTS.sub("", text).upper().replace(" ", "")
    for code, why in (
        (_G20, "inch units (G20)"),
        (r"G91(?![.\d])", "incremental distances (G91)"),
        (r"G90\.1", "absolute arc centres (G90.1)"),
    ):
        if re.search(code, body):
            return why
    return None


def write_scheduled_program(
    program_text: str,
    toolpath: Toolpath,
    plan: VirtualPlan,
    schedule: FeedSchedule,
    path: str | Path,
    *,
    feed_quantum_mm_min: float = 0.1,
    encoding: str = "utf-8",
) -> int:
    """Write the program with scheduled F words; split long blocks where the feed changes.

    Parameters
    ----------
    program_text : str
        The original program (the one ``toolpath`` and ``plan`` were made from, without
        work offsets).
    toolpath : Toolpath
        Its moves.
    plan : VirtualPlan
        Its plan.
    schedule : FeedSchedule
        From :func:`schedule_feed`.
    path : path
        Output file (written atomically).
    feed_quantum_mm_min : float
        F words are rounded down to this [mm/min]; in a G20 block they are inch/min, rounded
        down to :data:`FEED_QUANTUM_INCH_MIN`.
    encoding : str
        The program's (:func:`millsense.plan.gcode.read_program`), to write it back in.

    Returns
    -------
    int
        Number of blocks added by splitting.

    Notes
    -----
    Every feed block with plan rows gets the F of its first run; where the feed changes
    inside a line or an XY arc, the block is split at the row positions into blocks with
    explicit G1/G2/G3 and end points (arcs with incremental I, J); the original line (its N
    number and other words) ends the block. Programs in G20, G91, G90.1 or with a non-zero
    work offset are not split: each block then takes the lowest feed of its rows.
    """
    lines = program_text.splitlines()
    why = _splittable(program_text)
    q = feed_quantum_mm_min
    feed_mm = np.floor(schedule.feed_m_s / MM_PER_MIN / q + 1e-9) * q
    feed_mm = np.maximum(feed_mm, q)
    qi = FEED_QUANTUM_INCH_MIN
    feed_inch = np.floor(schedule.feed_m_s / MM_PER_MIN / INCH_MM / qi + 1e-9) * qi
    feed_inch = np.maximum(feed_inch, qi)
    inch = _inch_blocks(lines)
    src = plan["source_line"]
    rapid = plan["rapid"].astype(bool)
    moves_of: dict[int, list[int]] = {}
    for i, ln in enumerate(toolpath.source_line):
        moves_of.setdefault(int(ln), []).append(i)
    rows_of: dict[int, NDArray[np.int64]] = {}
    feed_rows = np.flatnonzero(~rapid)
    if feed_rows.size:
        order = src[feed_rows]
        brk = np.flatnonzero(np.diff(order)) + 1
        for grp in np.split(feed_rows, brk):
            rows_of.setdefault(int(src[grp[0]]), grp)
    out: list[str] = []
    added = 0
    for lineno, raw in enumerate(lines, start=1):
        rows = rows_of.get(lineno)
        if rows is None:
            out.append(raw)
            continue
        f = feed_inch[rows] if inch[lineno - 1] else feed_mm[rows]
        moves = moves_of.get(lineno, [])
        kinds = {int(toolpath.kind[m]) for m in moves}
        single = len(moves) == 1 and kinds <= {LINE, ARC}
        mv = moves[0] if moves else -1
        arc_ok = single and (int(toolpath.kind[mv]) == LINE or int(toolpath.plane[mv]) == PLANE_XY)
        change = np.flatnonzero(np.diff(f) != 0) + 1
        if change.size == 0 or why is not None or not arc_ok:
            out.append(_with_words(_strip_words(raw, "F"), f"F{_fmt(float(f.min()))}"))
            continue
        start = toolpath.start[mv, :3] / MM
        centre = toolpath.centre[mv] / MM
        is_arc = int(toolpath.kind[mv]) == ARC
        gcode = "G1" if not is_arc else ("G3" if toolpath.direction[mv] > 0 else "G2")
        cur = start
        cur_feed = float(f[0])
        for k in change:
            r = int(rows[k])
            pt = np.array([plan["x_mm"][r], plan["y_mm"][r], plan["z_mm"][r]])
            back = np.array([plan["x_mm"][r - 1], plan["y_mm"][r - 1], plan["z_mm"][r - 1]])
            # split SPLIT_BEFORE_MM ahead of row r so that the re-sampled row r falls in the
            # next block (with its feed) despite the rounding of the written coordinates
            d = back - pt
            pt = pt + d * (SPLIT_BEFORE_MM / max(float(np.linalg.norm(d)), 1e-12))
            words = [gcode]
            for ax, a, b in zip("XYZ", cur, pt, strict=True):
                if abs(b - a) > 1e-9 or (is_arc and ax != "Z"):
                    words.append(f"{ax}{_fmt(float(b))}")
            if is_arc:
                words.append(f"I{_fmt(float(centre[0] - cur[0]))}")
                words.append(f"J{_fmt(float(centre[1] - cur[1]))}")
            words.append(f"F{_fmt(cur_feed)}")
            out.append(" ".join(words))
            added += 1
            cur = pt
            cur_feed = float(f[k])
        end = toolpath.end[mv, :3] / MM
        if is_arc:
            tail = f"{gcode} X{_fmt(float(end[0]))} Y{_fmt(float(end[1]))}"
            if abs(end[2] - start[2]) > 1e-9:
                tail += f" Z{_fmt(float(end[2]))}"
            tail += f" I{_fmt(float(centre[0] - cur[0]))} J{_fmt(float(centre[1] - cur[1]))}"
            rest = _MOTION.sub("", _strip_words(raw, "XYZIJKRF")).rstrip()
            out.append(_with_words(rest, f"{tail} F{_fmt(cur_feed)}"))
        else:
            out.append(_with_words(_strip_words(raw, "F"), f"F{_fmt(cur_feed)}"))
    text = "\n".join(out) + "\n"
    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp")
    try:
        tmp.write_text(text, encoding=encoding)
        tmp.replace(p)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise ProgramError(f"{p}: cannot write program: {exc.strerror or exc}") from exc
    return added
