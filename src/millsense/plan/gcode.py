"""Modal interpreter for the RS274/NGC subset that CAM post-processors emit for milling.

:func:`interpret` (a string) and :func:`interpret_file` turn a part program into a
:class:`~millsense.plan.path.Toolpath` (one row per move, SI units). Field units come in
(mm or inch per G21/G20, mm/min or inch/min, rev/min, degrees) and are converted once.

Supported
---------
- Motion: G0, G1, G2, G3 (centre IJK and radius R forms, full circles, helical arcs, P turns),
  G4 dwell (P in seconds), G28 (via an intermediate point to the caller's reference position),
  G53 (machine coordinates for one G0/G1 block).
- Modes: G17/G18/G19, G20/G21, G90/G91, G90.1/G91.1, G94, G54-G59 (translations given by the
  caller, default zero), G40, G43 H / G49 (accepted; the programmed point is the tool tip),
  G80, G15, G69, G97, G98/G99, G61/G61.1/G64 (accepted, no effect on the programmed path).
- F, S, T; M3/M4/M5, M6, M7/M8/M9, M0/M1 (ignored with a note), M2/M30 (end of program).
- Comments ``( )`` and ``;``, N numbers, block delete ``/``, ``%`` demarcation lines, an ``O``
  program number alone on a line, A and C rotary words in degrees.

Refused with a :class:`~millsense.core.errors.ProgramError` (one line: file, line, text):
cutter compensation G41/G42, inverse-time G93 and feed per revolution G95, canned cycles,
G92/G10 and other unknown G or M codes, two words of one modal group, a repeated letter,
G1/G2/G3 without a feed, an arc whose end is off its radius beyond the tolerance, an R arc
without end point or ending at its start, words no command uses, garbage.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from millsense.core.errors import ProgramError
from millsense.core.units import DEG, MM, MM_PER_MIN, RPM
from millsense.plan.gcode_lexer import (
    KNOWN_LETTERS,
    garbage_error,
    program_error,
    strip_block,
    tokens,
)
from millsense.plan.path import ARC, DWELL, LINE, PLANE_XY, PLANE_YZ, PLANE_ZX, RAPID, Toolpath

INCH_MM = 25.4
#: Arc end-point tolerance of RS274/NGC v3 (Kramer et al. 2000, §3.5.3.2): the distances from
#: the centre to the start and to the end may differ by 0.002 mm (0.0002 inch under G20).
ARC_TOL_MM = 0.002
ARC_TOL_INCH = 0.0002
_FULL_CIRCLE_MM = 1e-9  # an end this close to the start (mm, in the plane) closes the circle
_TWO_PI = 2.0 * math.pi

# Modal groups of G codes (key: code x 10, so G90.1 -> 901). Group 0 = non-modal.
_G_GROUP: dict[int, int] = {
    0: 1, 10: 1, 20: 1, 30: 1,
    800: 9,
    170: 2, 180: 2, 190: 2,
    900: 3, 910: 3,
    901: 4, 911: 4,
    940: 5,
    200: 6, 210: 6,
    400: 7,
    430: 8, 490: 8,
    980: 10, 990: 10,
    540: 12, 550: 12, 560: 12, 570: 12, 580: 12, 590: 12,
    610: 13, 611: 13, 640: 13,
    150: 15, 690: 16, 970: 14,
    40: 0, 280: 0, 530: 0,
}  # fmt: skip
_G_REFUSED: dict[int, str] = {
    410: "cutter radius compensation G41 is not supported (program the tool centre path)",
    420: "cutter radius compensation G42 is not supported (program the tool centre path)",
    411: "dynamic cutter compensation G41.1 is not supported",
    421: "dynamic cutter compensation G42.1 is not supported",
    930: "inverse-time feed G93 is not supported (use G94)",
    950: "feed per revolution G95 is not supported (use G94)",
    960: "constant surface speed G96 is not supported (use G97)",
    920: "G92 coordinate offsets are not supported (use G54-G59)",
    100: "G10 data setting is not supported",
    160: "polar coordinates G16 are not supported",
    680: "coordinate rotation G68 is not supported",
    431: "dynamic tool length offset G43.1 is not supported",
    591: "G59.1 is not supported (G54-G59 only)",
    592: "G59.2 is not supported (G54-G59 only)",
    593: "G59.3 is not supported (G54-G59 only)",
}
for _c in (730, 740, 760, 810, 820, 830, 840, 850, 860, 870, 880, 890):
    _G_REFUSED[_c] = f"canned cycle G{_c // 10} is not supported (post the cycle as moves)"
_GROUP_NAMES = {
    1: "motion",
    2: "plane",
    3: "distance mode",
    4: "arc distance mode",
    5: "feed mode",
    6: "units",
    7: "cutter compensation",
    8: "tool length",
    9: "canned cycle",
    10: "return mode",
    12: "work offset",
    13: "path control",
    14: "spindle mode",
    15: "polar",
    16: "rotation",
    0: "non-modal",
}
# M codes: group (4 stop, 6 tool change, 7 spindle, 8 coolant).
_M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 6: 6, 3: 7, 4: 7, 5: 7, 7: 8, 8: 8, 9: 8}
_AXES = ("X", "Y", "Z")
_XYZ = frozenset(_AXES)
_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}
# Plane -> (u, v, w) axis indices and the centre-offset letters of u and v, and of w (refused).
_PLANE_INFO = {
    PLANE_XY: ((0, 1, 2), ("I", "J"), "K"),
    PLANE_ZX: ((2, 0, 1), ("K", "I"), "J"),
    PLANE_YZ: ((1, 2, 0), ("J", "K"), "I"),
}
_PLANE_OF_G = {170: PLANE_XY, 180: PLANE_ZX, 190: PLANE_YZ}
_NCOL = 14  # columns of the per-move record, see _Machine.emit
_ACOL = 9  # columns of the per-arc record


def _gkey(number: str) -> int:
    return round(float(number) * 10.0)


def _gname(key: int) -> str:
    return f"G{key // 10}" if key % 10 == 0 else f"G{key / 10:g}"


class _Machine:
    """Modal state and output buffers of one interpretation (positions in machine-frame mm)."""

    def __init__(
        self,
        source: str,
        offsets: dict[int, tuple[float, float, float]],
        home: tuple[float, float, float] | None,
        initial: Sequence[float],
        block_delete: bool,
    ) -> None:
        self.source = source
        self.offsets = offsets
        self.home = home
        self.block_delete = block_delete
        self.pos = [float(v) for v in initial] + [0.0, 0.0]  # x y z mm, a c deg
        self.start = tuple(self.pos)
        self.scale = 1.0  # mm per program unit
        self.arc_tol = ARC_TOL_MM
        self.incremental = False
        self.arc_incremental = True  # G91.1 is the default (IJK relative to the start)
        self.plane = PLANE_XY
        self.motion: int | None = None  # G80: no motion mode until G0..G3
        self.offset = offsets.get(540, (0.0, 0.0, 0.0))
        self.feed: float | None = None  # mm/min (already scaled)
        self.feed_word = math.nan  # F as written (deg/min for rotary-only moves)
        self.speed = 0.0  # rev/min
        self.spindle_dir = 0
        self.selected_tool = 0
        self.tool = 0
        self.moves = array("d")
        self.arcs = array("d")
        self.n_moves = 0
        self.notes: list[str] = []
        self.tool_changes: list[tuple[int, int]] = []
        self.ended = False

    # ------------------------------------------------------------------ output
    def emit(
        self, kind: int, end: Sequence[float], feed: float, nc: int, lineno: int, dwell: float
    ) -> None:
        spindle = self.speed if self.spindle_dir else 0.0
        self.moves.extend(
            (kind, end[0], end[1], end[2], end[3], end[4], feed, spindle,
             self.spindle_dir, self.tool, nc, lineno, dwell, self.feed_word)
        )  # fmt: skip
        self.n_moves += 1

    # ------------------------------------------------------------------ one block
    def block(self, raw: str, lineno: int) -> None:
        src = self.source
        s = strip_block(raw, src, lineno)
        if not s:
            return
        if s[0] == "O" and s[1:].isdigit():
            return  # program number (Fanuc "O1001"), no effect
        if s[0] == "/":
            if self.block_delete:
                return
            s = s[1:]
        gcodes: list[int] = []
        mcodes: list[int] = []
        vals: dict[str, float] = {}
        nc = -1
        for letter, number, bad in tokens(s):
            if bad:
                raise garbage_error(s, bad, raw, src, lineno)
            if letter == "G":
                gcodes.append(_gkey(number))
            elif letter == "M":
                m = float(number)
                if m != int(m):
                    raise program_error(src, lineno, raw, f"unknown M code M{number}")
                mcodes.append(int(m))
            elif letter == "N":
                nc = int(float(number))
            elif letter in vals:
                raise program_error(src, lineno, raw, f"word {letter} appears twice")
            elif letter not in KNOWN_LETTERS:
                if letter == "O":
                    raise program_error(src, lineno, raw, "O-words (subroutines) not supported")
                raise program_error(src, lineno, raw, f"word {letter} is not supported")
            else:
                vals[letter] = float(number)
        motion = self.motion
        if not gcodes and not mcodes and motion is not None and vals and vals.keys() <= _XYZ:
            # Fast path for the commonest CAM block: x, y, z words continuing G0 or G1.
            if motion == 10 or motion == 0:
                pos = self.pos
                tgt = pos.copy()
                k = self.scale
                if self.incremental:
                    for ax, v in vals.items():
                        i = _AXIS_INDEX[ax]
                        tgt[i] = pos[i] + v * k
                else:
                    off = self.offset
                    for ax, v in vals.items():
                        i = _AXIS_INDEX[ax]
                        tgt[i] = v * k + off[i]
                if motion == 0:
                    self.emit(RAPID, tgt, math.nan, nc, lineno, 0.0)
                else:
                    if not self.feed:
                        self.move_block(motion, vals, nc, raw, lineno, explicit=False)
                    self.emit(LINE, tgt, self.feed, nc, lineno, 0.0)  # type: ignore[arg-type]
                self.pos = tgt
                return
            self.move_block(motion, vals, nc, raw, lineno, explicit=False)
            return
        self.full_block(gcodes, mcodes, vals, nc, raw, lineno)

    def full_block(
        self,
        gcodes: list[int],
        mcodes: list[int],
        vals: dict[str, float],
        nc: int,
        raw: str,
        lineno: int,
    ) -> None:
        src = self.source
        seen: dict[int, int] = {}
        motion: int | None = None
        nonmodal: list[int] = []
        for g in gcodes:
            group = _G_GROUP.get(g)
            if group is None:
                reason = _G_REFUSED.get(g, f"unknown G code {_gname(g)}")
                raise program_error(src, lineno, raw, reason)
            if group in seen and group != 0:
                raise program_error(
                    src, lineno, raw,
                    f"{_gname(seen[group])} and {_gname(g)} are both in the "
                    f"{_GROUP_NAMES[group]} group",
                )  # fmt: skip
            seen[group] = g
            if group == 0:
                nonmodal.append(g)
            elif group == 1:
                motion = g
        if len(nonmodal) > 1:
            raise program_error(
                src, lineno, raw, "two non-modal G codes in one block: "
                + " and ".join(_gname(g) for g in nonmodal),
            )  # fmt: skip
        mseen: dict[int, int] = {}
        for m in mcodes:
            mg = _M_GROUP.get(m)
            if mg is None:
                raise program_error(src, lineno, raw, f"unknown M code M{m}")
            if mg in mseen and mg != 8:
                raise program_error(
                    src, lineno, raw, f"M{mseen[mg]} and M{m} are in the same modal group"
                )
            mseen[mg] = m

        # RS274/NGC order of execution (v3 Table 8).
        if 6 in seen:  # units first: G20/G21 applies to every word of its own block
            inch = seen[6] == 200
            self.scale = INCH_MM if inch else 1.0
            self.arc_tol = ARC_TOL_INCH * INCH_MM if inch else ARC_TOL_MM
        if "F" in vals:
            f = vals.pop("F")
            if f < 0:
                raise program_error(src, lineno, raw, "negative feed rate")
            self.feed = f * self.scale
            self.feed_word = f
        if "S" in vals:
            sval = vals.pop("S")
            if sval < 0:
                raise program_error(src, lineno, raw, "negative spindle speed")
            self.speed = sval
        if "T" in vals:
            t = vals.pop("T")
            if t < 0 or t != int(t):
                raise program_error(src, lineno, raw, "tool number must be a whole number ≥ 0")
            self.selected_tool = int(t)
        if 6 in mcodes:
            self.tool = self.selected_tool
            self.tool_changes.append((lineno, self.tool))
        for m in mcodes:
            if m == 3:
                self.spindle_dir = 1
            elif m == 4:
                self.spindle_dir = -1
            elif m == 5:
                self.spindle_dir = 0
        if 40 in nonmodal:
            p = vals.pop("P", None)
            if p is None or p < 0:
                raise program_error(src, lineno, raw, "G4 dwell needs a time P ≥ 0 (seconds)")
            self.emit(DWELL, self.pos, math.nan, nc, lineno, p)
        if 2 in seen:
            self.plane = _PLANE_OF_G[seen[2]]
        if 8 in seen:
            h = vals.pop("H", None)
            if seen[8] == 430 and (h is None or h < 0 or h != int(h)):
                raise program_error(src, lineno, raw, "G43 needs a tool length offset number H")
        if 12 in seen:
            self.offset = self.offsets.get(seen[12], (0.0, 0.0, 0.0))
        if 3 in seen:
            self.incremental = seen[3] == 910
        if 4 in seen:
            self.arc_incremental = seen[4] == 911
        if motion is not None:
            self.motion = motion
        if 13 in seen:  # path control: blending tolerances P/Q do not change the path
            vals.pop("P", None)
            vals.pop("Q", None)

        has_axes = any(k in vals for k in ("X", "Y", "Z", "A", "C"))
        if 280 in nonmodal:
            if motion is not None and has_axes:
                raise program_error(src, lineno, raw, "G28 and a motion code both use axis words")
            self.g28(vals, nc, raw, lineno)
        elif 530 in nonmodal:
            if self.motion not in (0, 10) or self.incremental:
                raise program_error(src, lineno, raw, "G53 needs G0 or G1 and G90")
            self.move_block(self.motion, vals, nc, raw, lineno, explicit=True, machine=True)
        elif has_axes or motion in (20, 30):
            if self.motion is None:
                raise program_error(src, lineno, raw, "axis words without a motion mode (G0-G3)")
            self.move_block(self.motion, vals, nc, raw, lineno, explicit=motion is not None)
        leftover = [k for k in vals if k not in ("X", "Y", "Z", "A", "C")]
        if leftover:
            raise program_error(src, lineno, raw, f"word {leftover[0]} is not used by any command")
        for m in mcodes:
            if m in (0, 1):
                what = "program stop M0" if m == 0 else "optional stop M1"
                self.notes.append(f"{src}:{lineno}: {what} ignored")
            elif m in (2, 30):
                self.ended = True

    # ------------------------------------------------------------------ motion
    def target(self, vals: dict[str, float], machine: bool = False) -> list[float]:
        """End point (machine-frame mm, degrees) from the axis words; pops them from vals."""
        pos = self.pos
        tgt = pos.copy()
        k = self.scale
        for i, ax in enumerate(_AXES):
            if ax in vals:
                v = vals.pop(ax) * k
                if self.incremental:
                    tgt[i] = pos[i] + v
                elif machine:
                    tgt[i] = v
                else:
                    tgt[i] = v + self.offset[i]
        for i, ax in ((3, "A"), (4, "C")):
            if ax in vals:
                v = vals.pop(ax)
                tgt[i] = pos[i] + v if self.incremental else v
        return tgt

    def move_block(
        self,
        motion: int,
        vals: dict[str, float],
        nc: int,
        raw: str,
        lineno: int,
        *,
        explicit: bool,
        machine: bool = False,
    ) -> None:
        if motion == 0:
            tgt = self.target(vals, machine)
            self.emit(RAPID, tgt, math.nan, nc, lineno, 0.0)
            self.pos = tgt
            return
        feed = self.feed
        if not feed:
            what = "no feed rate programmed (F)" if feed is None else "feed rate F is zero"
            raise program_error(self.source, lineno, raw, f"{_gname(motion)} with {what}")
        if motion == 10:
            tgt = self.target(vals, machine)
            self.emit(LINE, tgt, feed, nc, lineno, 0.0)
            self.pos = tgt
            return
        self.arc(motion, vals, nc, raw, lineno, feed)

    def arc(
        self, motion: int, vals: dict[str, float], nc: int, raw: str, lineno: int, feed: float
    ) -> None:
        src = self.source
        (iu, iv, _iw), (lu, lv), lw = _PLANE_INFO[self.plane]
        in_plane = _AXES[iu] in vals or _AXES[iv] in vals
        tgt = self.target(vals)
        if lw in vals:
            raise program_error(
                src,
                lineno,
                raw,
                f"{lw} word on an arc in the {('XY', 'ZX', 'YZ')[self.plane]} plane",
            )
        turns = 1
        if "P" in vals:
            p = vals.pop("P")
            if p < 1 or p != int(p):
                raise program_error(src, lineno, raw, "arc P (turns) must be a whole number ≥ 1")
            turns = int(p)
        pos = self.pos
        su, sv = pos[iu], pos[iv]
        eu, ev = tgt[iu], tgt[iv]
        ccw = motion == 30
        k = self.scale
        if "R" in vals:
            if lu in vals or lv in vals:
                raise program_error(src, lineno, raw, "arc with both R and centre offsets")
            rr = vals.pop("R") * k
            if not in_plane:
                raise program_error(src, lineno, raw, "R arc without an end point in its plane")
            du, dv = eu - su, ev - sv
            chord = math.hypot(du, dv)
            if chord < _FULL_CIRCLE_MM:
                raise program_error(
                    src, lineno, raw, "R arc ending at its start (a full circle needs I/J/K)"
                )
            r = abs(rr)
            half = 0.5 * chord
            h2 = r * r - half * half
            if h2 < 0.0:
                if half - r > self.arc_tol:
                    raise program_error(
                        src, lineno, raw,
                        f"arc radius {r / k:g} is smaller than half the chord {half / k:g}",
                    )  # fmt: skip
                h2 = 0.0
            h = math.sqrt(h2)
            # Centre left of the chord for G3 with R > 0 (≤ 180°), right for G2; R < 0 flips.
            side = (1.0 if ccw else -1.0) * (1.0 if rr > 0 else -1.0)
            cu = su + 0.5 * du - side * h * dv / chord
            cv = sv + 0.5 * dv + side * h * du / chord
            rs = re = math.hypot(su - cu, sv - cv)
        else:
            if lu not in vals and lv not in vals:
                raise program_error(src, lineno, raw, f"arc needs {lu}/{lv} centre offsets or R")
            ou = vals.pop(lu, 0.0) * k
            ov = vals.pop(lv, 0.0) * k
            if self.arc_incremental:
                cu, cv = su + ou, sv + ov
            else:
                cu = ou + self.offset[iu]
                cv = ov + self.offset[iv]
            rs = math.hypot(su - cu, sv - cv)
            re = math.hypot(eu - cu, ev - cv)
            if abs(rs - re) > self.arc_tol:
                raise program_error(
                    src, lineno, raw,
                    f"arc end point is {abs(rs - re) / k:.4g} {'inch' if k != 1.0 else 'mm'} off "
                    f"its radius (tolerance {self.arc_tol / k:g})",
                )  # fmt: skip
            if rs < self.arc_tol:
                raise program_error(src, lineno, raw, "arc with zero radius")
        t0 = math.atan2(sv - cv, su - cu)
        t1 = math.atan2(ev - cv, eu - cu)
        if math.hypot(eu - su, ev - sv) < _FULL_CIRCLE_MM:
            sweep = _TWO_PI
        else:
            sweep = (t1 - t0) % _TWO_PI if ccw else (t0 - t1) % _TWO_PI
        sweep += _TWO_PI * (turns - 1)
        centre = pos[:3]
        centre[iu] = cu
        centre[iv] = cv
        self.arcs.extend(
            (self.n_moves, centre[0], centre[1], centre[2], self.plane,
             1.0 if ccw else -1.0, sweep, rs, re)
        )  # fmt: skip
        self.emit(ARC, tgt, feed, nc, lineno, 0.0)
        self.pos = tgt

    def g28(self, vals: dict[str, float], nc: int, raw: str, lineno: int) -> None:
        if self.home is None:
            raise program_error(
                self.source, lineno, raw,
                "G28 needs the machine reference position (--home-mm X,Y,Z on the command line, "
                "home_mm in the interpreter)",
            )  # fmt: skip
        named = [i for i, ax in enumerate(("X", "Y", "Z", "A", "C")) if ax in vals]
        mid = self.target(vals)
        if mid != self.pos:
            self.emit(RAPID, mid, math.nan, nc, lineno, 0.0)
            self.pos = mid
        home = self.pos.copy()
        ref = (*self.home, 0.0, 0.0)  # rotary axes home at 0 deg
        for i in named if named else range(5):
            home[i] = ref[i]
        self.emit(RAPID, home, math.nan, nc, lineno, 0.0)
        self.pos = home

    # ------------------------------------------------------------------ result
    def toolpath(self) -> Toolpath:
        n = self.n_moves
        rec = np.frombuffer(self.moves, dtype=np.float64).reshape(n, _NCOL)
        end = rec[:, 1:6].copy()
        start = np.empty_like(end)
        start[0] = self.start
        start[1:] = end[:-1]
        for arr in (start, end):
            arr[:, :3] *= MM
            arr[:, 3:] *= DEG
        kind = rec[:, 0].astype(np.int8)
        centre = np.full((n, 3), np.nan)
        plane = np.full(n, -1, dtype=np.int8)
        direction = np.zeros(n, dtype=np.int8)
        sweep = np.zeros(n)
        r0 = np.zeros(n)
        r1 = np.zeros(n)
        if len(self.arcs):
            arc = np.frombuffer(self.arcs, dtype=np.float64).reshape(-1, _ACOL)
            ia = arc[:, 0].astype(np.intp)
            centre[ia] = arc[:, 1:4] * MM
            plane[ia] = arc[:, 4].astype(np.int8)
            direction[ia] = arc[:, 5].astype(np.int8)
            sweep[ia] = arc[:, 6]
            r0[ia] = arc[:, 7] * MM
            r1[ia] = arc[:, 8] * MM
        feed_mm_min = rec[:, 6]
        rot_only = (kind == LINE) & np.all(end[:, :3] == start[:, :3], axis=1)
        rot_only &= np.any(end[:, 3:] != start[:, 3:], axis=1)
        rotary_feed = np.where(rot_only, rec[:, 13] / 60.0 * DEG, np.nan)
        return Toolpath(
            kind=kind,
            start=start,
            end=end,
            centre=centre,
            plane=plane,
            direction=direction,
            sweep=sweep,
            radius_start=r0,
            radius_end=r1,
            feed=feed_mm_min * MM_PER_MIN,
            rotary_feed=rotary_feed,
            spindle_speed=rec[:, 7] * RPM,
            spindle_dir=rec[:, 8].astype(np.int8),
            tool=rec[:, 9].astype(np.int32),
            nc_line=rec[:, 10].astype(np.int64),
            source_line=rec[:, 11].astype(np.int64),
            dwell=rec[:, 12].copy(),
            source=self.source,
            notes=tuple(self.notes),
            tool_changes=tuple(self.tool_changes),
        )


def _offsets(
    work_offsets_mm: Mapping[str, Sequence[float]] | None,
) -> dict[int, tuple[float, float, float]]:
    out: dict[int, tuple[float, float, float]] = {}
    for name, xyz in (work_offsets_mm or {}).items():
        key = name.strip().upper()
        if key not in {f"G5{i}" for i in range(4, 10)}:
            raise ValueError(f"work offset {name!r}: expected one of G54..G59")
        vals = tuple(float(v) for v in xyz)
        if len(vals) != 3:
            raise ValueError(f"work offset {name}: expected (x, y, z) in mm, got {xyz!r}")
        out[int(key[1:]) * 10] = (vals[0], vals[1], vals[2])
    return out


def interpret(
    text: str,
    *,
    source: str = "<string>",
    work_offsets_mm: Mapping[str, Sequence[float]] | None = None,
    home_mm: Sequence[float] | None = None,
    initial_position_mm: Sequence[float] = (0.0, 0.0, 0.0),
    block_delete: bool = True,
) -> Toolpath:
    """Interpret an RS274/NGC milling program into a toolpath.

    Parameters
    ----------
    text : str
        The program.
    source : str
        File name or label used in error messages and kept in ``Toolpath.source``.
    work_offsets_mm : mapping, optional
        ``{"G54": (x, y, z), ...}``: origin of each work coordinate system in the machine
        frame, mm. Missing systems are at the machine origin (zero offset).
    home_mm : sequence of 3 floats, optional
        Machine reference position for G28, mm in the machine frame. Without it, G28 is an
        error (the position is the machine's, not the program's).
    initial_position_mm : sequence of 3 floats
        Tool tip before the first block, machine frame, mm (A = C = 0).
    block_delete : bool
        True (switch on): lines starting with ``/`` are skipped; False: they run.

    Returns
    -------
    Toolpath
        One row per move, SI units, machine frame (program coordinates + work offset).

    Raises
    ------
    ProgramError
        For any unsupported or inconsistent block; the message is one line
        ``file:line: reason: 'text'``.

    Notes
    -----
    RS274/NGC v3 (Kramer, Proctor, Messina 2000) semantics as implemented by LinuxCNC; the
    decisions where posts differ are in
    ``docs/decisions/0035-g-code-interpreter-dialect-choices-issue-4-item-1.md``. Arcs: with IJK the
    distances centre-start and centre-end may differ by the tolerance (0.002 mm, 0.0002 inch); the
    move is then a spiral whose radius changes linearly with the angle, so it still ends exactly on
    the programmed point. R arcs take the centre left of the chord for G3 and right for G2 when
    R > 0 (sweep ≤ 180°), the other side for R < 0. A feed move of rotary axes only reads F as
    deg/min.
    """
    offsets = _offsets(work_offsets_mm)
    home = None
    if home_mm is not None:
        hx, hy, hz = (float(v) for v in home_mm)
        home = (hx, hy, hz)
    init = [float(v) for v in initial_position_mm]
    if len(init) != 3:
        raise ValueError("initial_position_mm must be (x, y, z)")
    m = _Machine(source, offsets, home, init, block_delete)
    lines = text.splitlines()
    first = 0
    while first < len(lines) and not lines[first].strip():
        first += 1
    percent = first < len(lines) and lines[first].strip() == "%"
    if percent:
        first += 1
    closed = False
    for i in range(first, len(lines)):
        raw = lines[i]
        if percent and raw.strip() == "%":
            closed = True
            break
        m.block(raw, i + 1)
        if m.ended:
            break
    if percent and not closed and not m.ended:
        raise ProgramError(f"{source}: program opened with % has no closing % line")
    if not percent and not m.ended:
        m.notes.append(f"{source}: no M2/M30 or % at the end; interpreted to the last line")
    if m.n_moves == 0:
        raise ProgramError(f"{source}: program contains no moves")
    return m.toolpath()


def read_program(path: str | Path) -> tuple[str, str]:
    """The text of a program file and the encoding it was read with, to write a rewritten
    program back in it: UTF-8 (a byte-order mark, which Windows editors write, is not text:
    ``utf-8-sig`` writes it back), else latin-1 (every byte a character, so a Windows
    editor's cp1252 comments are kept byte for byte).

    Raises
    ------
    ProgramError
        If the file cannot be read (message names the file).
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ProgramError(f"{p}: cannot read program: {exc.strerror or exc}") from exc
    encoding = "utf-8-sig" if raw.startswith(b"\xef\xbb\xbf") else "utf-8"
    try:
        return raw.decode(encoding), encoding
    except UnicodeDecodeError:
        return raw.decode("latin-1"), "latin-1"


def interpret_file(path: str | Path, **kwargs: object) -> Toolpath:
    """Read (:func:`read_program`) and interpret a G-code file; see :func:`interpret` for the
    keyword arguments.

    Raises
    ------
    ProgramError
        If the file cannot be read, or for any bad block (message names the file).
    """
    text, _ = read_program(path)
    return interpret(text, source=str(path), **kwargs)  # type: ignore[arg-type]
