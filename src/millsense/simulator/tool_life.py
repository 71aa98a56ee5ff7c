"""A simulated tool life: which runs a fleet of tools makes and how worn each tool is at each
run (issue 20 acceptance: the wear monitor over varying depths and widths; decision 2001).

Each tool makes ``runs`` runs; each run machines one part with one of the programs (cycled
with a per-tool offset, so consecutive runs change depth and width) and represents
``part_cut_s`` of cutting — the short plan the virtual machine simulates is a sample of the
part, and the tool's wear between runs comes from the whole part. The tool's VB before the run
follows :class:`~millsense.simulator.wear.FlankWearModel`'s growth at the tool's cutting speed,
with a per-tool life factor (tools of one type do not wear alike: ±30 % is common in tool-life
tests) drawn from a seeded generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millsense.core.errors import ConfigError
from millsense.simulator.wear import FlankWearModel

__all__ = ["ToolLifeRun", "tool_life_runs"]


@dataclass(frozen=True)
class ToolLifeRun:
    """One run of the schedule: tool, run number, program index, the tool's cutting time
    before the run (s, what the CNC's tool-life counter shows) and its true VB (m)."""

    tool_id: str
    run_index: int
    program: int
    cutting_time_s: float
    vb_m: float


def tool_life_runs(
    n_tools: int,
    runs: int,
    n_programs: int,
    *,
    part_cut_s: float,
    cutting_speed_m_s: float,
    model: FlankWearModel | None = None,
    life_spread: float = 0.3,
    seed: int = 0,
    max_vb_m: float = 0.6e-3,
) -> list[ToolLifeRun]:
    """The runs of ``n_tools`` tools × ``runs`` each (module docstring), VB capped at
    ``max_vb_m`` (a tool is replaced long before)."""
    if n_tools < 1 or runs < 1 or n_programs < 1:
        raise ConfigError("tool life: n_tools, runs and n_programs must be ≥ 1")
    if not (math.isfinite(part_cut_s) and part_cut_s > 0):
        raise ConfigError(f"tool life: part_cut_s must be > 0, got {part_cut_s!r}")
    m = model if model is not None else FlankWearModel()
    rng = np.random.default_rng(seed)
    factors = rng.uniform(1 - life_spread, 1 + life_spread, n_tools)
    out: list[ToolLifeRun] = []
    for k in range(n_tools):
        t = np.arange(runs) * part_cut_s
        teq = m.equivalent_time_s(t, cutting_speed_m_s) * factors[k]
        vb = np.minimum(m.vb_at(teq), max_vb_m)
        for i in range(runs):
            prog = (i + k) % n_programs
            out.append(ToolLifeRun(f"T{k + 1}", i, prog, float(t[i]), float(vb[i])))
    return out
