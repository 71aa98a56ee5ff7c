"""A rich progress bar for long CLI work (shown only on a terminal or when asked)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


@contextmanager
def progress_bar(
    description: str, total: float, live: Callable[[float], str] | None = None
) -> Iterator[Callable[[float], None]]:
    """Yield ``update(done)``; the bar disappears when the work ends. ``live(done)``: a line of
    live figures shown beside the bar at every update (e.g. the overrides of an on-line run)."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[live]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        transient=True,
    ) as prog:
        task = prog.add_task(description, total=total, live="")

        def update(done: float) -> None:
            text = live(done) if live is not None else ""
            prog.update(task, completed=min(done, total), live=text)

        yield update
