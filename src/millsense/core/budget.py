"""Bounded work: the size of what a command will compute, checked before it allocates.

Every command estimates its work from its inputs (path samples of a plan, vertices of a
simulated path, samples of a simulation) and refuses beyond a documented ceiling with one line
that names the input that caused it and how to proceed (decision 0943 "Work ceilings"). A
program with ``G1 X30000000`` is then a one-line error, not a 33 GiB allocation.

Ceilings (each with the memory or time it stands for):

- :data:`MAX_PATH_STEPS` — path samples of a plan: 4 million (1600 m of path at the 0.4 mm
  step; ~40 float columns per step make ~1.3 GB with the engagement and force statistics).
- :data:`MAX_PATH_POINTS` — vertices and arc chords of a simulated path: 4 million (~0.5 GB).
- :data:`MAX_SIGNAL_S` — signal a simulation writes: 4 h (a long shift's part at 10 kHz, ~40 GB
  of HDF5 and ~1.5 h of wall time at ~10× real time).
- Z-map cells of a stock: :data:`millsense.plan.stock.MAX_CELLS`.
"""

from __future__ import annotations

import math

from millsense.core.errors import ProgramError, UserError

#: Largest number of path samples a plan computes.
MAX_PATH_STEPS = 4_000_000
#: Largest number of points (vertices, arc chords) of a simulated path.
MAX_PATH_POINTS = 4_000_000
#: Longest signal a simulation writes, s.
MAX_SIGNAL_S = 4 * 3600.0


def check_path_steps(total_m: float, step_m: float, where: str, longest: str) -> None:
    """A plan of a ``total_m`` path at ``step_m``: refuse beyond :data:`MAX_PATH_STEPS`.

    ``where`` names the program, ``longest`` its longest move (``line 3, 30000 m``).
    """
    if not math.isfinite(total_m):
        raise ProgramError(f"{where}: the path length is not finite ({longest})")
    steps = total_m / step_m
    if steps > MAX_PATH_STEPS:
        raise ProgramError(
            f"{where}: {total_m:.4g} m of path at a {step_m * 1e3:g} mm step is {steps:.3g} "
            f"steps, beyond the ceiling of {MAX_PATH_STEPS:.3g} (longest move: {longest}); "
            "check the program's coordinates and units, split it, or give a larger --step-mm"
        )


def check_path_points(points: float, where: str, longest: str) -> None:
    """A simulated path of ``points`` vertices/chords: refuse beyond :data:`MAX_PATH_POINTS`."""
    if not points <= MAX_PATH_POINTS:
        raise ProgramError(
            f"{where}: the path needs {points:.3g} points (vertices and arc chords), beyond the "
            f"ceiling of {MAX_PATH_POINTS:.3g} (longest move: {longest}); check the program's "
            "arcs and coordinates, or split it"
        )


def check_signal(seconds: float, where: str, how: str, error: type[UserError]) -> None:
    """A simulation of ``seconds`` of signal: refuse beyond :data:`MAX_SIGNAL_S`.

    ``how`` says how to proceed (``give --duration-s``).
    """
    if not seconds <= MAX_SIGNAL_S:
        raise error(
            f"{where}: {seconds:.4g} s of signal to simulate, beyond the ceiling of "
            f"{MAX_SIGNAL_S:g} s; {how}"
        )
