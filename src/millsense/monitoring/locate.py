"""Where an event happened on the tool path, from the virtual plan.

The CNC's NC-line channel (when the recording has one) names the block being executed (its N
number, or its line in the program where it has none); the plan's rows of that line closest in
planned time give the tool-tip position. Without an
NC-line channel the planned time alone is used. Planned and actual time differ by overrides
and the spindle run-up, so with overrides the position is that of the nearest row of the
right NC line (decision 1505).
"""

from __future__ import annotations

import numpy as np

from millsense.plan.path import cnc_line
from millsense.plan.virtual_plan import VirtualPlan


class PlanLocator:
    """(time s, NC line or None) → (NC line, x, y, z in mm) on the plan's path."""

    def __init__(self, plan: VirtualPlan) -> None:
        self.t = np.asarray(plan["t_s"], dtype=float)
        # the line the CNC names: the N number, else the source line (decision 1739)
        nc = np.asarray(plan["nc_line"], dtype=np.int64)
        self.nc = cnc_line(nc, plan["source_line"]) if "source_line" in plan.columns else nc
        self.xyz = np.column_stack(
            [np.asarray(plan[c], dtype=float) for c in ("x_mm", "y_mm", "z_mm")]
        )

    def __call__(
        self, time_s: float, nc_line: int | None = None
    ) -> tuple[int | None, float | None, float | None, float | None]:
        if len(self.t) == 0:
            return nc_line, None, None, None
        rows = np.flatnonzero(self.nc == nc_line) if nc_line is not None else np.zeros(0, int)
        if len(rows) == 0:
            rows = np.arange(len(self.t))
        r = int(rows[np.argmin(np.abs(self.t[rows] - time_s))])
        x, y, z = (float(v) for v in self.xyz[r])
        return int(self.nc[r]), x, y, z
