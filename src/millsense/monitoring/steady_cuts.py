"""The steady cuts among a record's revolutions, from the engagement monitor's harmonics.

Lee's fit (seed 004 ch. 2) gives one engagement per revolution. A record of a part program
holds several cuts (a slot, then a shallower pass, a step in depth), with entries, exits and
air between them. What a revolution's estimate is judged against, and what is averaged or
summarised, is one cut: consecutive evaluated revolutions whose first tooth harmonic and mean
cutting torque stay within :data:`STEADY_BAND` of the run's mean.

- :func:`steady_rows`: the longest such run (decision 1738: the cut whose averaged harmonics
  place flute 0 in the record's frame);
- :func:`steady_cuts`: every run of at least ``min_revolutions``, runs a gap of at most
  :data:`MERGE_GAP` revolutions apart at the same level joined (one revolution outside the band
  in a long cut, a noise spike, does not split it in two; decision 1739).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

#: Consecutive revolutions whose first tooth harmonic (and mean cutting torque, where given)
#: stays within this fraction of the run's mean count as one steady cut.
STEADY_BAND = 0.15
#: Runs at most this many revolutions apart whose levels agree within :data:`STEADY_BAND` are
#: one cut (decision 1739).
MERGE_GAP = 2
#: In :func:`steady_cuts` a revolution also stays in its cut within this many standard
#: deviations of a revolution's level (from the record's revolution-to-revolution changes): a
#: noisy torque's revolutions scatter beyond the band without the cut changing (decision 1739).
NOISE_K = 4.0


def _levels(
    coeffs: Sequence[NDArray[np.complex128] | None], means: Sequence[float] | None
) -> list[tuple[float, float]]:
    """Per revolution: the first tooth harmonic's magnitude (NaN: not evaluated) and the mean
    cutting torque (NaN: not given or not finite, which the band then does not test)."""
    out = []
    for i, c in enumerate(coeffs):
        m = abs(c[1]) if c is not None else math.nan
        t = float(means[i]) if means is not None and c is not None else math.nan
        out.append((m, t if math.isfinite(t) else math.nan))
    return out


def _within(value: float, total: float, count: int, noise: float = 0.0) -> bool:
    """``value`` within :data:`STEADY_BAND` of the mean ``total / count``, or within ``noise``
    of it (NaN: not tested)."""
    if not math.isfinite(value) or not math.isfinite(total):
        return True
    mean = total / count
    return abs(value - mean) <= max(STEADY_BAND * abs(mean), noise)


def level_noise(values: Sequence[float]) -> float:
    """The standard deviation of one revolution's level from the changes between consecutive
    finite ``values`` (their median absolute change over 0.6745·√2: a change of cut among
    many revolutions moves it little); 0 with fewer than two."""
    x = np.asarray(values, dtype=np.float64)
    d = np.diff(x)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return 0.0
    return float(np.median(np.abs(d)) / (0.6745 * math.sqrt(2.0)))


def steady_runs(
    coeffs: Sequence[NDArray[np.complex128] | None],
    means: Sequence[float] | None = None,
    noise_k: float = 0.0,
) -> list[list[int]]:
    """Every run of consecutive evaluated revolutions (None: not evaluated, which ends a run)
    whose first tooth harmonic's magnitude, and mean cutting torque ``means`` where given,
    stay within :data:`STEADY_BAND` of the run's means (or within ``noise_k`` standard
    deviations of a revolution's level, :func:`level_noise`), in order."""
    levels = _levels(coeffs, means)
    return _runs(levels, *_tolerances(levels, noise_k))


def _tolerances(levels: list[tuple[float, float]], noise_k: float) -> tuple[float, float]:
    """``noise_k`` standard deviations of a revolution's tooth harmonic and mean torque
    (:func:`level_noise`), 0 with ``noise_k`` = 0."""
    if noise_k == 0.0:
        return 0.0, 0.0
    return (noise_k * level_noise([m for m, _ in levels]),
            noise_k * level_noise([t for _, t in levels]))  # fmt: skip


def _runs(levels: list[tuple[float, float]], nm: float, nt: float) -> list[list[int]]:
    """:func:`steady_runs` of the revolutions' ``levels`` with the tolerances ``nm``, ``nt``."""
    runs: list[list[int]] = []
    run: list[int] = []
    total_m = total_t = 0.0
    for i, (m, t) in enumerate(levels):
        if run and math.isfinite(m) and _within(m, total_m, len(run), nm) and _within(
            t, total_t, len(run), nt
        ):
            run.append(i)
            total_m += m
            total_t += t
            continue
        if run:
            runs.append(run)
        if math.isfinite(m) and m > 0:
            run, total_m, total_t = [i], m, t
        else:
            run, total_m, total_t = [], 0.0, 0.0
    if run:
        runs.append(run)
    return runs


def steady_rows(coeffs: Sequence[NDArray[np.complex128] | None]) -> list[int]:
    """The longest of :func:`steady_runs` on the first tooth harmonic alone (the first of
    equal length): one steady cut, whose windows share one frame (decision 1738)."""
    best: list[int] = []
    for run in steady_runs(coeffs):
        if len(run) > len(best):
            best = run
    return best


def steady_cuts(
    coeffs: Sequence[NDArray[np.complex128] | None],
    means: Sequence[float] | None = None,
    min_revolutions: int = 1,
) -> list[list[int]]:
    """The record's steady cuts (decision 1739): :func:`steady_runs` on the first tooth
    harmonic and the mean cutting torque (each within :data:`NOISE_K` standard deviations of a
    revolution's level where the band is narrower), a run joined to the one before where at most
    :data:`MERGE_GAP` revolutions lie between them and its mean levels are within
    :data:`STEADY_BAND` of that one's (runs of :data:`MERGE_GAP` revolutions or fewer between
    them, a spike, are passed over); the cuts of at least ``min_revolutions`` revolutions, in
    order. The revolutions between joined runs are not part of the cut."""
    levels = _levels(coeffs, means)
    nm, nt = _tolerances(levels, NOISE_K)
    cuts: list[list[int]] = []
    short: list[list[int]] = []  # runs of MERGE_GAP revolutions or fewer since the last cut
    for run in _runs(levels, nm, nt):
        if len(run) <= MERGE_GAP:
            short.append(run)
            continue
        if cuts and run[0] - cuts[-1][-1] - 1 <= MERGE_GAP:
            prev = cuts[-1]
            pm = [levels[i][0] for i in prev]
            pt = [levels[i][1] for i in prev]
            rm = float(np.mean([levels[i][0] for i in run]))
            rt = float(np.mean([levels[i][1] for i in run]))
            if _within(rm, float(np.sum(pm)), len(pm), nm) and _within(
                rt, float(np.sum(pt)), len(pt), nt
            ):
                prev.extend(run)
                short = []
                continue
        cuts += [*short, list(run)]
        short = []
    cuts += short
    return [c for c in cuts if len(c) >= min_revolutions]
