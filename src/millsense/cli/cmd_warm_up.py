"""``millsense warm-up``: compile the on-line system's kernels once after installing."""

from __future__ import annotations

from rich.console import Console

from millsense.cli.main import app
from millsense.cli.progress import progress_bar


@app.command("warm-up")
def warm_up() -> None:
    """Compile the kernels of the on-line system into numba's cache, once after installing
    (``make`` does it). Runs the first seconds of the demo's two sessions on the virtual
    machine. Without it the first live session of a fresh installation compiles them as it
    goes and falls behind the machine by about 20 s, its alarms with it (decision 1549)."""
    from millsense.warm_up import warm_up as run

    with progress_bar("compiling the on-line system", 1) as update:
        res = run(on_progress=update)
    Console().print(
        f"warm-up: {len(res.compiled)} kernels compiled in {res.seconds:.0f} s"
        if res.compiled
        else f"warm-up: nothing to compile (cache warm), {res.seconds:.1f} s"
    )
