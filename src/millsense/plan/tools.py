"""A part program with tool changes as one segment per tool (decision 1683).

A virtual plan covers one tool (one :class:`~millsense.process.geometry.EndMill`, one force
basis, one tool in the virtual machine). A shop's program changes tools (``T2 M6``); its
moves are split at every change of the tool in the spindle: a segment is the run of moves
from one tool change to the next, and moves before the first change (the preamble's rapids,
tool 0) belong to the first tool. Each segment is planned with its tool, in program order,
on one stock, so that what an earlier tool removed is gone for the later ones.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from millsense.core.errors import ConfigError, ProgramError
from millsense.plan.path import Toolpath

__all__ = ["ToolSegment", "assign_tools", "tool_segments"]


@dataclass(frozen=True)
class ToolSegment:
    """The moves of one tool.

    Attributes
    ----------
    tool : tool number (T word of its M6; 0 for a program without tool change).
    path : its moves (a :class:`Toolpath` of their own, the source's name and notes kept).
    first_line : 1-based source line of its tool change (M6), else of its first move.
    """

    tool: int
    path: Toolpath
    first_line: int


def _rows(path: Toolpath, lo: int, hi: int) -> Toolpath:
    arrays = {
        f.name: getattr(path, f.name)[lo:hi]
        for f in dataclasses.fields(path)
        if isinstance(getattr(path, f.name), np.ndarray)
    }
    return dataclasses.replace(path, **arrays)


def tool_segments(path: Toolpath) -> list[ToolSegment]:
    """The program's moves split where the tool in the spindle changes (module notes)."""
    n = len(path)
    if n == 0:
        return [ToolSegment(0, path, 0)]
    tool = path.tool.astype(np.int64)
    named = np.flatnonzero(tool != 0)
    if named.size:
        # the moves before the first tool change run with the first tool
        tool = tool.copy()
        tool[: named[0]] = tool[named[0]]
    cuts = np.flatnonzero(np.diff(tool) != 0) + 1
    bounds = [0, *cuts.tolist(), n]
    out = []
    for lo, hi in itertools.pairwise(bounds):
        line = int(path.source_line[lo])
        # the last M6 to this tool before its first move (the program's own line)
        changes = [ln for ln, t in path.tool_changes if t == tool[lo] and ln <= line]
        out.append(ToolSegment(int(tool[lo]), _rows(path, lo, hi), max(changes, default=line)))
    return out


def assign_tools(
    segments: list[ToolSegment], specs: list[str], source: str, one_tool: bool = False
) -> list[str]:
    """The tool (preset or file) of every segment from the ``--tool`` options.

    ``specs``: one tool for a program with one tool (``--tool aslan-d20-2flute``), or one
    ``Tn=TOOL`` per tool of the program (``--tool T1=aslan-d20-2flute --tool T2=t2.toml``).
    ``one_tool``: the command takes one tool (``run --program``, ``schedule``): a program with
    several is refused with the per-tool plan as remedy in whichever form the tool was given
    (decision 1683; a ``Tn=TOOL`` form there would otherwise ask for the other tools, which
    the command cannot take).

    Raises
    ------
    ProgramError
        One tool given for a program with several, or a tool of the program not given: one
        line naming the program's line of that tool's change and the remedy.
    ConfigError
        A malformed ``Tn=TOOL``, a tool given twice or not used by the program, the two forms
        mixed.
    """
    used = sorted({s.tool for s in segments})
    shown = ", ".join(f"T{t}" for t in used)
    first: dict[int, int] = {}
    for s in segments:
        first.setdefault(s.tool, s.first_line)
    pairs = [spec for spec in specs if "=" in spec]
    if not pairs and len(specs) != 1:
        raise ConfigError(
            f"--tool given {len(specs)} times: one tool, or one Tn=TOOL per tool change"
        )
    if (not pairs or one_tool) and len(used) > 1:
        t = segments[1].tool
        what = f"--tool {specs[0]} is one tool" if not one_tool else "this command runs one tool"
        raise ProgramError(
            f"{source}:{first[t]}: tool change to T{t} (the program uses {shown}); {what}: "
            "`millsense plan` plans each with its own ("
            + " ".join(f"--tool T{u}=TOOL" for u in used)
            + ": one plan per tool, on one stock; simulate and run take each with --plan)"
        )
    if not pairs:
        return [specs[0]] * len(segments)
    if len(pairs) != len(specs):
        raise ConfigError("--tool: give one tool, or Tn=TOOL for every tool (not both)")
    given: dict[int, str] = {}
    for spec in pairs:
        key, _, name = spec.partition("=")
        key = key.strip().upper()
        if not (key.startswith("T") and key[1:].isdigit() and name.strip()):
            raise ConfigError(f"--tool {spec!r}: expected Tn=TOOL (T1=aslan-d20-2flute)")
        t = int(key[1:])
        if t in given:
            raise ConfigError(f"--tool T{t} given twice")
        given[t] = name.strip()
    if used == [0] and len(given) == 1:  # no tool change in the program: the one given
        return [next(iter(given.values()))] * len(segments)
    for t in used:
        if t not in given:
            raise ProgramError(
                f"{source}:{first[t]}: tool change to T{t}: no --tool T{t}=TOOL given "
                f"(the program uses {shown})"
            )
    extra = sorted(set(given) - set(used))
    if extra:
        raise ConfigError(f"--tool T{extra[0]}=...: the program uses {shown}, not T{extra[0]}")
    return [given[s.tool] for s in segments]
