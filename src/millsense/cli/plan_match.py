"""The check that a virtual plan belongs to a recording (``monitor``, ``replay``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def check_plan_matches(vp: Any, plan: Path, rec: Any, recording: Path) -> None:
    """A plan of another program, or one much longer than the recording, is refused.

    Raises
    ------
    InputDataError
        Naming both files: the programs differ (the plan's and the recording's ``program``
        metadata), or the plan lasts more than twice the recording (+1 s).
    """
    from millsense.core.errors import InputDataError

    p_prog = str(vp.metadata.get("program", "") or "")
    r_prog = str(rec.metadata.get("program", "") or "")
    if p_prog and r_prog and Path(p_prog).name != Path(r_prog).name:
        raise InputDataError(
            f"{plan}: plan of program '{Path(p_prog).name}', but {recording} was recorded "
            f"running '{Path(r_prog).name}'"
        )
    t = np.asarray(vp["t_s"], dtype=float)
    plan_s = float(t[-1] - t[0]) if len(t) else 0.0
    rec_s = rec.n_samples / rec.sample_rate_hz
    # overrides up to 150 % shorten the run by a third at most; 2× leaves room for a run
    # recorded at the highest override
    if plan_s > 2.0 * rec_s + 1.0:
        raise InputDataError(
            f"{plan}: the plan lasts {plan_s:.1f} s but {recording} only {rec_s:.1f} s "
            "(a plan of another program?)"
        )
