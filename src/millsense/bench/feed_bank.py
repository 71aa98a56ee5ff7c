"""Position-scheduled feed estimator bank identified from simulated table-load sweeps at N
positions along the stroke (the bench for :mod:`millsense.estimation.feed.schedule`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from itertools import pairwise
from typing import Literal

from millsense.bench.feed_commissioning import (
    SWEEP_SPEED_RAD_S,
    disturbance_sweep,
    identify_feed_axis,
)
from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError
from millsense.estimation.feed.estimator import FeedAxisModel
from millsense.estimation.feed.path_fit import SweepResult
from millsense.estimation.feed.schedule import (
    DEFAULT_CROSSFADE,
    SWEEP_LEAD_S,
    SWEEP_PERIODS,
    Design,
    DesignChoice,
    FeedModelBank,
    design_member,
    interval_worst_db,
    relative_shift,
)
from millsense.simulator.commissioning import ramp_move
from millsense.simulator.feed_drive import FeedDriveParams


def sweep_travel(transmission: float, speed_rad_s: float, sample_rate_hz: float) -> float:
    """Load travel of a moving bank sweep (lead-in + :data:`SWEEP_PERIODS` 1 s periods), m/rad;
    ``transmission`` r_g, m/rad (rad/rad rotary)."""
    n = round((SWEEP_LEAD_S + SWEEP_PERIODS) * sample_rate_hz)
    pos, _ = ramp_move(speed_rad_s, n, sample_rate_hz)
    return float(pos[-1] * transmission)


def identify_feed_bank(
    params: FeedDriveParams,
    axis: str,
    kind: Literal["linear", "rotary"],
    positions: Sequence[float],
    *,
    sample_rate_hz: float = 10_000.0,
    sweep_speed_rad_s: float = SWEEP_SPEED_RAD_S,
    sweep_force_rms: float | None = None,
    design: DesignChoice = "auto",
    crossfade: float = DEFAULT_CROSSFADE,
    seed: int = 0,
    nameplate: FeedAxisConfig,
) -> tuple[FeedModelBank, list[SweepResult]]:
    """Identify Φ_d at each position (friction, J_e, LuGre and R shared) → a model bank.

    Parameters
    ----------
    params : the simulated drive at commissioning (only its CNC channels are used).
    axis, kind : axis name and ``linear``/``rotary``.
    nameplate : the nameplate axis table (K_t, lead, η, encoder counts the estimator is given).
    positions : identification positions, load position m (rad rotary), ascending; each sweep
        is a constant-velocity move centred on its position (travel :func:`sweep_travel`).
    sample_rate_hz : CNC rate, Hz.
    sweep_speed_rad_s : motor speed of the sweeps, rad/s.
    sweep_force_rms : RMS of the sweep load, N (N·m rotary); default 3 N·m of τ_a at the motor.
    design : ``robust`` (each member by :func:`design_member` for half its measured neighbour
        shift), ``nominal``, or ``auto``: the one with the smaller analytic worst deviation
        over an interval (:func:`interval_worst_db` on the middle member with its half shift).
    crossfade : see :class:`FeedModelBank`.
    seed : base seed of the simulated tests.

    Returns
    -------
    (bank, sweeps): the bank and the sweep (FRF and fit) of each position.

    Notes
    -----
    The first position runs
    :func:`~millsense.bench.feed_commissioning.identify_feed_axis` (all commissioning
    tests); the others only :func:`~millsense.bench.feed_commissioning.disturbance_sweep`
    from their start position, with
    the first position's drive model, LuGre and R (friction, inertia and noise do not depend on
    the position). The neighbour shift is measured from the sweeps (:func:`relative_shift`), not
    taken from the simulator.
    """
    pos = [float(p) for p in positions]
    if len(pos) == 0 or any(b <= a for a, b in pairwise(pos)):
        raise ConfigError(f"identify bank {axis}: positions must be ascending and non-empty")
    fs = sample_rate_hz
    half = 0.5 * sweep_travel(nameplate.transmission_m_rad, sweep_speed_rad_s, fs)
    lg = nameplate.transmission_m_rad / nameplate.efficiency
    f_rms = sweep_force_rms if sweep_force_rms is not None else 3.0 / lg
    first, sweep0 = identify_feed_axis(
        params,
        axis,
        kind,
        sample_rate_hz=fs,
        sweep_force_rms=f_rms,
        tune=False,
        seed=seed,
        start_position=pos[0] - half,
        sweep_speed_rad_s=sweep_speed_rad_s,
        nameplate=nameplate,
    )
    raw: list[FeedAxisModel] = [first]
    sweeps = [sweep0]
    for k, x in enumerate(pos[1:], start=1):
        sw = disturbance_sweep(
            params,
            first.drive,
            fs,
            first.lowpass_hz,
            force_rms=f_rms,
            seed=seed + 2 + 10 * k,
            lugre=first.lugre,
            speed_rad_s=sweep_speed_rad_s,
            start_position=x - half,
        )
        raw.append(replace(first, disturbance=sw.fit))
        sweeps.append(sw)
    band = (3.0, 260.0)
    shifts = [
        abs(relative_shift(raw[i].disturbance, sweeps[i + 1], band)) for i in range(len(raw) - 1)
    ]
    halves = []
    for i in range(len(raw)):
        nb = [shifts[j] for j in (i - 1, i) if 0 <= j < len(shifts)]
        halves.append(0.5 * max(nb) if nb else 0.0)
    chosen: Design
    analytic = (math.nan, math.nan)
    if design == "auto":
        mid = len(raw) // 2
        if halves[mid] > 0:
            worst = {
                d: interval_worst_db(raw[mid], halves[mid], design=d, crossfade=crossfade)[
                    "worst_db"
                ]
                for d in ("nominal", "robust")
            }
            chosen = "robust" if worst["robust"] < worst["nominal"] else "nominal"
            analytic = (worst["nominal"], worst["robust"])
        else:
            chosen = "nominal"
    else:
        chosen = design
    models = tuple(design_member(m, chosen, h) for m, h in zip(raw, halves, strict=True))
    return FeedModelBank(tuple(pos), models, tuple(halves), crossfade, chosen, analytic), sweeps
