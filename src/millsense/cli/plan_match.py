"""The check that a virtual plan belongs to a recording (``monitor``, ``replay``,
``report``, ``batch --plan``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def check_plan_matches(vp: Any, plan: Path, rec: Any, recording: Path | str) -> None:
    """A plan of another program is refused: the plan's and the recording's ``program``
    metadata name different files, or files of one name whose contents differ (both sides'
    ``program_sha256``, written by ``plan`` and ``run`` since the qa4 helper found two
    ``program.nc`` of different folders accepted).

    A plan longer than the recording is accepted: a run stopped by a feed hold, an operator or
    the end of a recording covers only the start of its program (the README's run with a
    broken tooth stops at 12.6 s of a 30.5 s plan). Where either side carries no program
    name there is nothing to compare.

    Raises
    ------
    InputDataError
        Naming both files and both programs.
    """
    from millsense.core.errors import InputDataError

    p_prog = str(vp.metadata.get("program", "") or "")
    r_prog = str(rec.metadata.get("program", "") or "")
    if p_prog and r_prog and Path(p_prog).name != Path(r_prog).name:
        raise InputDataError(
            f"{plan}: plan of program '{Path(p_prog).name}', but {recording} was recorded "
            f"running '{Path(r_prog).name}'"
        )
    p_sha = str(vp.metadata.get("program_sha256", "") or "")
    r_sha = str(rec.metadata.get("program_sha256", "") or "")
    if p_sha and r_sha and p_sha != r_sha:
        raise InputDataError(
            f"{plan}: plan of program '{p_prog}' (SHA-256 {p_sha[:12]}…), but {recording} was "
            f"recorded running another program of that name, '{r_prog}' (SHA-256 "
            f"{r_sha[:12]}…)"
        )
