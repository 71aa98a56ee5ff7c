"""Chatter remedy by depth reduction: a part program rewritten into shallower passes (seed 002).

Munasinghe (digest M6, V5) stops the axes on chatter, reduces the axial depth by a preset step
(1.0 mm) and **rewrites the NC program so that the full programmed depth is removed in several
passes at the reduced depth**, then runs the new program. :func:`split_deep_passes` is that
rewriting: given a program and a stable depth limit (e.g. the lowest unstable depth of the
lobes at the programmed speed, :class:`~millsense.control.chatter_avoidance.StabilityModel`),
every cutting pass deeper than the limit below the stock top is replaced by k = ⌈D / a_lim⌉
passes: k − 1 copies whose Z is clamped at ``top − i·D/k`` (i = 1 … k − 1), each followed by a
retract to the pass's start height and a rapid back to its start, then the original pass. The
last pass is the programmed one, so the geometry finally reached is the programmed geometry.
A pass entered below the top (a rapid down beside the part, in air) has each copy start at
its level and the last at the programmed height (rapids on the vertical the program came
down).

A *pass* is a run of blocks in which the tool stays below the stock top: it starts with the
feed move that takes the tool below ``top_z_mm`` and ends before the move that brings it back
to or above it (or before a rapid). Its depth D is ``top − lowest Z`` of the pass. Clamping
each move's end point keeps a straight or helical move above the level (both ends are); for a
ramp the clamped copy reaches the level later than the true clamped ramp would, so an
intermediate pass of a ramp is at most as deep as the step (constant-Z passes are exact).

Supported: absolute (G90) metric (G21) programs in the subset of
:mod:`millsense.plan.gcode`, with its ``%`` demarcation lines (lines after the closing one
are copied untouched); G91 and G20 are refused with a one-line error. The program is read as
the interpreter reads it (UTF-8, else latin-1) and written back in the same encoding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from millsense.core.errors import ConfigError, ProgramError
from millsense.plan.gcode_lexer import program_error, strip_block, words

#: Tolerance on heights, mm.
EPS_MM = 1e-6


@dataclass(frozen=True)
class CuttingPass:
    """A run of blocks below the stock top (module notes).

    Attributes
    ----------
    first_line, last_line : 1-based source lines of its first and last block.
    depth_mm : stock top minus the lowest Z of the pass, mm.
    start_mm : tool position (x, y, z) before the pass, mm.
    """

    first_line: int
    last_line: int
    depth_mm: float
    start_mm: tuple[float, float, float]


@dataclass(frozen=True)
class DepthRewrite:
    """A program rewritten by :func:`split_deep_passes`.

    Attributes
    ----------
    text : the new program.
    passes_before, passes_after : cutting passes of the original and of the new program.
    split : (original pass, number of passes it became) for every pass that was split.
    """

    text: str
    passes_before: list[CuttingPass]
    passes_after: list[CuttingPass]
    split: list[tuple[CuttingPass, int]] = field(default_factory=list)


@dataclass
class _Line:
    raw: str
    words: list[tuple[str, str]]
    motion: int | None  # motion mode in effect after the block if it moves, else None
    start: tuple[float, float, float]
    end: tuple[float, float, float]
    explicit_motion: bool


def _fmt(v: float) -> str:
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _parse(text: str, source: str) -> list[_Line]:
    """Blocks with their modal motion and the tool position before and after them, mm."""
    pos = [0.0, 0.0, 0.0]
    mode = 0
    out: list[_Line] = []
    opened = closed = False  # '%' demarcation, as the interpreter reads it
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if closed:
            block = ""  # after the closing '%': not part of the program, copied as it is
        elif raw.strip() == "%" and (opened or not any(ln.raw.strip() for ln in out)):
            closed, opened, block = opened, True, ""
        else:
            block = strip_block(raw, source, lineno)
        ws = words(block.lstrip("/"), raw, source, lineno) if block else []
        explicit = False
        for letter, num in ws:
            if letter != "G":
                continue
            g = round(float(num) * 10)
            if g in (0, 10, 20, 30):
                mode, explicit = g // 10, True
            elif g == 910:
                raise program_error(source, lineno, raw, "depth rewriting needs G90 (absolute)")
            elif g == 200:
                raise program_error(source, lineno, raw, "depth rewriting needs G21 (mm)")
            elif g in (280, 300, 530):
                raise program_error(
                    source, lineno, raw, "depth rewriting: G28/G30/G53 moves are not supported"
                )
        start = (pos[0], pos[1], pos[2])
        axes = {k: float(v) for k, v in ws if k in "XYZ"}
        moves = bool(axes)
        for i, k in enumerate("XYZ"):
            if k in axes:
                pos[i] = axes[k]
        out.append(
            _Line(raw, ws, mode if moves else None, start, (pos[0], pos[1], pos[2]), explicit)
        )
    return out


def _passes(lines: list[_Line], top: float) -> list[tuple[int, int]]:
    """(first, end) block indices (end exclusive) of the cutting passes."""
    res: list[tuple[int, int]] = []
    first: int | None = None
    for i, ln in enumerate(lines):
        if ln.motion is None:
            continue
        below = ln.end[2] < top - EPS_MM
        if first is None:
            if below and ln.motion != 0:
                first = i
        elif not below or ln.motion == 0:
            res.append((first, i))
            first = i if (below and ln.motion != 0) else None
    if first is not None:
        res.append((first, len(lines)))
    return res


def _trim(lines: list[_Line], a: int, b: int) -> int:
    """End of the pass ``a:b`` without trailing blocks that do not move."""
    while b > a + 1 and lines[b - 1].motion is None:
        b -= 1
    return b


def cutting_passes(text: str, top_z_mm: float = 0.0, source: str = "<string>") -> list[CuttingPass]:
    """The cutting passes of a program (module notes) with their depths below ``top_z_mm``."""
    lines = _parse(text, source)
    out = []
    for a, b in _passes(lines, top_z_mm):
        b = _trim(lines, a, b)
        zmin = min(ln.end[2] for ln in lines[a:b] if ln.motion is not None)
        out.append(CuttingPass(a + 1, b, top_z_mm - zmin, lines[a].start))
    return out


def _clamped(ln: _Line, level: float, need_motion: int | None) -> str:
    """The block with Z = max(its end Z, ``level``), N words and comments dropped."""
    ws = [(k, v) for k, v in ln.words if k not in ("N", "Z")]
    head = f"G{need_motion} " if need_motion is not None else ""
    body = " ".join(f"{k}{v}" for k, v in ws)
    return f"{head}{body} Z{_fmt(max(ln.end[2], level))}".strip()


def split_deep_passes(
    text: str, max_depth_mm: float, top_z_mm: float = 0.0, source: str = "<string>"
) -> DepthRewrite:
    """Rewrite ``text`` so that no cutting pass is deeper than ``max_depth_mm`` (module notes).

    Parameters
    ----------
    text : the part program (G90, G21).
    max_depth_mm : the stable depth limit a_lim, mm.
    top_z_mm : Z of the stock top, mm.
    source : file name for messages.

    Returns
    -------
    The new program and the passes before and after.

    Notes
    -----
    Seed 002 (Munasinghe, ch. 3.3 / 5.2 V5): "rewrite the NC program so that the full
    programmed depth is removed in several passes at the reduced depth". A pass of depth D
    becomes k = ⌈D / a_lim⌉ passes of depth D / k ≤ a_lim each.
    """
    if not (max_depth_mm > 0 and math.isfinite(max_depth_mm)):
        raise ConfigError(f"depth rewriting: depth limit {max_depth_mm!r} mm must be > 0")
    lines = _parse(text, source)
    if not any(ln.motion is not None for ln in lines):
        # as `plan` refuses it: an empty output would pass for a rewritten program
        raise ProgramError(f"{source}: program has no motion to split")
    before = cutting_passes(text, top_z_mm, source)
    spans = {a: _trim(lines, a, b) for a, b in _passes(lines, top_z_mm)}
    out: list[str] = []
    split: list[tuple[CuttingPass, int]] = []
    i = 0
    mode_before = 0  # modal motion before block i
    while i < len(lines):
        if i not in spans:
            out.append(lines[i].raw)
            if lines[i].motion is not None or lines[i].explicit_motion:
                mode_before = _mode_after(lines[i], mode_before)
            i += 1
            continue
        b = spans[i]
        body = lines[i:b]
        zmin = min(ln.end[2] for ln in body if ln.motion is not None)
        depth = top_z_mm - zmin
        k = math.ceil(depth / max_depth_mm - 1e-9)
        if k <= 1:
            for ln in body:
                out.append(ln.raw)
                mode_before = _mode_after(ln, mode_before)
            i = b
            continue
        x0, y0, z0 = lines[i].start
        safe = z0 if z0 >= top_z_mm - EPS_MM else top_z_mm + 2.0
        split.append((CuttingPass(i + 1, b, depth, (x0, y0, z0)), k))
        z = z0  # the tool's height at (x0, y0) before each copy
        for p in range(1, k):
            level = top_z_mm - depth * p / k
            out.append(f"(chatter: depth pass {p}/{k} at Z{_fmt(level)}, seed 002)")
            # a pass entered below the top (a rapid beside the part, in air) starts at its level
            if max(z0, level) != z:
                out.append(f"G0 Z{_fmt(max(z0, level))}")
            mode = mode_before
            first = True
            for ln in body:
                if ln.motion is None:
                    out.append(ln.raw)  # feed, coolant...: no motion, harmless to repeat
                    mode = _mode_after(ln, mode)
                    continue
                need = mode if (first and not ln.explicit_motion) else None
                out.append(_clamped(ln, level, need))
                mode = ln.motion
                first = False
            out.append(f"G0 Z{_fmt(safe)}")
            out.append(f"G0 X{_fmt(x0)} Y{_fmt(y0)}")
            z = safe
        out.append(f"(chatter: depth pass {k}/{k}, as programmed)")
        if z != z0:
            out.append(f"G0 Z{_fmt(z0)}")  # back down where the program entered the pass
        first_move = next(j for j, ln in enumerate(body) if ln.motion is not None)
        for j, ln in enumerate(body):
            if j == first_move and not ln.explicit_motion:
                out.append(f"G{mode_before} {ln.raw.strip()}")
            else:
                out.append(ln.raw)
            mode_before = _mode_after(ln, mode_before)
        i = b
    new = "\n".join(out) + ("\n" if text.endswith("\n") else "")
    return DepthRewrite(new, before, cutting_passes(new, top_z_mm, source), split)


def _mode_after(ln: _Line, mode: int) -> int:
    if ln.motion is not None:
        return ln.motion
    for k, v in ln.words:
        if k == "G" and round(float(v) * 10) in (0, 10, 20, 30):
            mode = round(float(v) * 10) // 10
    return mode


def write_split_program(
    program: str | Path,
    output: str | Path,
    max_depth_mm: float,
    top_z_mm: float = 0.0,
) -> DepthRewrite:
    """Read ``program``, split its deep passes (:func:`split_deep_passes`) and write the new
    program to ``output`` atomically (never onto the input; :mod:`millsense.io.safe_output`)."""
    from millsense.io.safe_output import check_outputs, write_text
    from millsense.plan.gcode import read_program

    check_outputs({"program": program}, {"output": output})
    text, encoding = read_program(program)
    res = split_deep_passes(text, max_depth_mm, top_z_mm, source=str(program))
    write_text(output, res.text, encoding)
    return res
