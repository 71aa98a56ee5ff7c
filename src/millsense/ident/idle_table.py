"""Position-indexed idling disturbance table (Yamada §2.9, seed 001 C8).

The position-dependent part of a ball-screw drive's disturbance (lead-periodic friction, ball
circulation, torque ripple, screw runout) repeats with position. Air cuts with the same
trajectory and feed as the cut (three in Yamada) give the estimator's output in idling; its
average over the runs, indexed by the table position, is subtracted from the estimate during
the cut at the same position (:meth:`IdleTable.compensate`).

Storage (decision docs/decisions/0076-idling-table-storage-and-indexing-issue-6-item-6.md): a CSV
file (``position_mm,value``) next to the machine file, referenced from the axis' TOML table
``[axes.<name>.idle_table]`` with the file name, the quantity and unit of the values, the
feed (mm/min) and the number of runs. A table holds thousands of bins (tens of µm over the
stroke): too many for readable TOML, trivial as CSV.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millsense.core.errors import ConfigError, InputDataError


@dataclass(frozen=True)
class IdleTable:
    """An averaged disturbance as a function of table position.

    Attributes
    ----------
    position_m : bin centres, m (ascending, equally spaced).
    value : averaged estimator output per bin (unit ``unit``).
    quantity : what the values are (e.g. ``thrust``, ``torque``, ``relative_displacement``).
    unit : SI unit of the values (e.g. ``N``).
    feed_m_s : feed of the air cuts, m/s (signed by the direction of travel).
    n_runs : number of air cuts averaged.
    """

    position_m: np.ndarray
    value: np.ndarray
    quantity: str
    unit: str
    feed_m_s: float
    n_runs: int

    def covers(self, position_m: np.ndarray) -> np.ndarray:
        """Mask of the positions inside the table's range (± one bin)."""
        x = np.asarray(position_m, dtype=float)
        step = float(self.position_m[1] - self.position_m[0]) if len(self.position_m) > 1 else 0
        return np.asarray((x >= self.position_m[0] - step) & (x <= self.position_m[-1] + step))

    def __call__(self, position_m: np.ndarray, outside: str = "error") -> np.ndarray:
        """The table at the given positions (linear interpolation), estimate units.

        Parameters
        ----------
        position_m : positions, m.
        outside : ``error`` — a position outside the table's range (± one bin) is an error;
            ``hold`` — the edge values are held there.

        Raises
        ------
        InputDataError if a position lies outside the range and ``outside`` is ``error``.
        """
        x = np.asarray(position_m, dtype=float)
        if outside == "hold":
            return np.asarray(np.interp(x, self.position_m, self.value))
        step = float(self.position_m[1] - self.position_m[0]) if len(self.position_m) > 1 else 0
        lo, hi = self.position_m[0] - step, self.position_m[-1] + step
        if x.size and (float(np.min(x)) < lo or float(np.max(x)) > hi):
            raise InputDataError(
                f"idle table covers {lo * 1e3:.3f}-{hi * 1e3:.3f} mm; positions "
                f"{float(np.min(x)) * 1e3:.3f}-{float(np.max(x)) * 1e3:.3f} mm fall outside"
            )
        return np.asarray(np.interp(x, self.position_m, self.value))

    def compensate(
        self, position_m: np.ndarray, estimate: np.ndarray, outside: str = "error"
    ) -> np.ndarray:
        """``estimate − table(position)``: the estimate with the idling disturbance removed.

        Parameters
        ----------
        position_m : table position per sample, m.
        estimate : the estimator's output per sample (the table's unit).
        outside : see :meth:`__call__`.
        """
        est = np.asarray(estimate, dtype=float)
        if est.shape != np.shape(position_m):
            raise InputDataError(
                f"idle compensation: estimate {est.shape} and position {np.shape(position_m)} "
                "differ in shape"
            )
        return np.asarray(est - self(position_m, outside))

    # ------------------------------------------------------------------ storage
    def to_csv(self, path: str | Path) -> None:
        """Write ``position_mm,value`` rows (header names the quantity and unit)."""
        p = Path(path)
        data = np.column_stack([self.position_m * 1e3, self.value])
        header = f"position_mm,{self.quantity}_{self.unit}"
        from millsense.io.safe_output import atomic_path

        with atomic_path(p) as tmp:  # an existing table is replaced whole or not at all
            np.savetxt(tmp, data, delimiter=",", header=header, comments="", fmt="%.9g")

    def config_table(self, csv_name: str) -> dict[str, object]:
        """Keys of ``[axes.<name>.idle_table]`` referencing the CSV (field units)."""
        return {
            "file": csv_name,
            "quantity": self.quantity,
            "unit": self.unit,
            "feed_mm_min": self.feed_m_s * 60e3,
            "runs": self.n_runs,
            "bin_mm": float(self.position_m[1] - self.position_m[0]) * 1e3,
        }

    @classmethod
    def from_config(cls, table: dict[str, object], base_dir: str | Path) -> IdleTable:
        """Load from an ``[axes.<name>.idle_table]`` table and the CSV it references.

        Parameters
        ----------
        table : the TOML table (``file``, ``quantity``, ``unit``, ``feed_mm_min``, ``runs``).
        base_dir : directory the ``file`` is relative to (the TOML file's directory).

        Raises
        ------
        ConfigError naming the key or the file.
        """
        for key in ("file", "quantity", "unit", "feed_mm_min", "runs"):
            if key not in table:
                raise ConfigError(f"idle_table: missing key '{key}'")
        path = Path(base_dir) / str(table["file"])
        try:
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"idle_table file {path}: {exc}") from None
        if data.shape[1] != 2 or data.shape[0] < 2:
            raise ConfigError(f"idle_table file {path}: needs two columns and two rows or more")
        if not np.all(np.diff(data[:, 0]) > 0):
            raise ConfigError(f"idle_table file {path}: position_mm must be ascending")
        feed = table["feed_mm_min"]
        runs = table["runs"]
        assert isinstance(feed, (int, float)) and isinstance(runs, int)
        return cls(
            data[:, 0] * 1e-3,
            data[:, 1],
            str(table["quantity"]),
            str(table["unit"]),
            float(feed) / 60e3,
            runs,
        )


def build_idle_table(
    runs: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    bin_m: float,
    feed_m_s: float,
    quantity: str = "thrust",
    unit: str = "N",
    min_runs: int = 2,
) -> IdleTable:
    """Average the estimator output of repeated air cuts per position bin (Yamada §2.9).

    Parameters
    ----------
    runs : per air cut, (table position per sample m, estimator output per sample); only the
        samples to use (the constant-feed part) should be passed.
    bin_m : bin width, m (a twentieth of the shortest wavelength to be removed, or finer).
    feed_m_s : feed of the runs, m/s (stored with the table: it applies to cuts at this feed).
    quantity, unit : what the estimate is and its SI unit.
    min_runs : fewest runs accepted (Yamada uses three).

    Returns
    -------
    IdleTable over the range every run covers.

    Notes
    -----
    Per run and bin the mean of the samples in the bin; the table is the mean over the runs
    (each run weighs equally, whatever its sample count). Bins no run reached in the common
    range are filled by linear interpolation. Averaging over runs removes the noise that does
    not repeat with position; what repeats (the idling disturbance) stays.
    """
    if len(runs) < min_runs:
        raise InputDataError(f"idle table: {len(runs)} air cuts given, needs {min_runs} or more")
    if not bin_m > 0:
        raise InputDataError(f"idle table: bin width must be positive, got {bin_m} m")
    lo, hi = -math.inf, math.inf
    for k, (x, y) in enumerate(runs):
        x = np.asarray(x, dtype=float)
        if x.shape != np.shape(y) or x.ndim != 1 or len(x) < 2:
            raise InputDataError(f"idle table: run {k}: position and estimate must be equal 1-D")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise InputDataError(f"idle table: run {k} has non-finite samples")
        lo, hi = max(lo, float(x.min())), min(hi, float(x.max()))
    if not hi - lo >= 2 * bin_m:
        raise InputDataError(
            f"idle table: the runs share {max(hi - lo, 0) * 1e3:.3f} mm of travel, less than two "
            f"bins of {bin_m * 1e3:g} mm"
        )
    n_bins = int((hi - lo) // bin_m)
    edges = lo + bin_m * np.arange(n_bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    per_run = np.full((len(runs), n_bins), np.nan)
    for k, (x, y) in enumerate(runs):
        xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        idx = np.floor((xa - lo) / bin_m).astype(np.int64)
        ok = (idx >= 0) & (idx < n_bins)
        sums = np.bincount(idx[ok], weights=ya[ok], minlength=n_bins)
        counts = np.bincount(idx[ok], minlength=n_bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            per_run[k] = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    with np.errstate(invalid="ignore"):
        table = np.nanmean(np.where(np.isnan(per_run), np.nan, per_run), axis=0)
    good = np.isfinite(table)
    if good.sum() < 2:
        raise InputDataError("idle table: fewer than two bins hold samples")
    table = np.interp(centres, centres[good], table[good])
    return IdleTable(centres, table, quantity, unit, float(feed_m_s), len(runs))


def periodic_amplitude(position_m: np.ndarray, signal: np.ndarray, wavelength_m: float) -> float:
    """Amplitude of the component of ``signal`` periodic in position with ``wavelength_m``.

    Least-squares fit of ``a·sin(2πx/λ) + b·cos(2πx/λ) + c`` (the constant absorbs the mean);
    returns ``√(a² + b²)`` in the signal's unit.
    """
    x = np.asarray(position_m, dtype=float)
    k = 2.0 * math.pi / wavelength_m
    basis = np.column_stack([np.sin(k * x), np.cos(k * x), np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(basis, np.asarray(signal, dtype=float), rcond=None)
    return float(math.hypot(coef[0], coef[1]))


#: Bins of :class:`DirectionIdle`: motion in −direction, at rest, in +direction.
DIRECTIONS = ("negative", "rest", "positive")


@dataclass(frozen=True)
class DirectionIdle:
    """Idle load of an estimate per direction of motion: the velocity-indexed idle table.

    An air phase at one cutting feed samples the idle (friction) load at one speed per
    direction, so the velocity index reduces to the sign of the commanded velocity: negative,
    at rest (|v| ≤ ``deadband``), positive (Aslan C2: friction depends on direction; Yamada §2.9:
    "observer output in idling = disturbance", constant in Ch. 6).

    Attributes
    ----------
    value : mean estimate in air per bin of :data:`DIRECTIONS` (estimate unit), NaN where the
        air phase holds no sample of that bin.
    variance : variance of the estimate about that mean per bin (unit²), NaN where unseen.
    samples : air samples per bin.
    deadband : |v| at or below which the axis is at rest (axis unit/s: m/s or rad/s).
    unit : unit of the estimate (``N``, ``N*m``).
    """

    value: tuple[float, float, float]
    variance: tuple[float, float, float]
    samples: tuple[int, int, int]
    deadband: float
    unit: str

    def bins(self, velocity: np.ndarray) -> np.ndarray:
        """Bin index (0 −, 1 rest, 2 +) per velocity sample."""
        v = np.asarray(velocity, dtype=float)
        return np.asarray(
            np.where(v > self.deadband, 2, np.where(v < -self.deadband, 0, 1)), dtype=np.int64
        )

    def __call__(self, velocity: np.ndarray) -> np.ndarray:
        """Idle load per sample (0 in a bin the air phase did not see), estimate unit."""
        table = np.nan_to_num(np.asarray(self.value, dtype=float), nan=0.0)
        return np.asarray(table[self.bins(velocity)])

    def compensate(self, velocity: np.ndarray, estimate: np.ndarray) -> np.ndarray:
        """``estimate − idle(velocity)``, sample by sample."""
        est = np.asarray(estimate, dtype=float)
        if est.shape != np.shape(velocity):
            raise InputDataError(
                f"idle compensation: estimate {est.shape} and velocity {np.shape(velocity)} "
                "differ in shape"
            )
        return np.asarray(est - self(velocity))

    def seen(self) -> list[str]:
        """Names of the bins the air phase saw."""
        return [d for d, n in zip(DIRECTIONS, self.samples, strict=True) if n > 0]


def build_direction_idle(
    velocity: np.ndarray,
    estimate: np.ndarray,
    *,
    deadband: float,
    unit: str = "N",
    min_samples: int = 100,
) -> DirectionIdle:
    """Mean and variance of an estimate in air per direction of the commanded velocity.

    Parameters
    ----------
    velocity : commanded axis velocity per air sample, m/s or rad/s.
    estimate : the estimator's output per air sample (aligned with ``velocity``).
    deadband : |v| at or below which the axis counts as at rest, m/s or rad/s.
    unit : unit of the estimate.
    min_samples : fewest samples for a bin to count as seen (fewer: NaN, not compensated).

    Notes
    -----
    Per bin b: ``value_b = mean(est | bin b)`` and ``variance_b = var(est | bin b)`` (Aslan
    Eq. 3.30: R is the fluctuation of the torque in an air cut); bins with fewer than
    ``min_samples`` samples are left NaN (the compensation leaves them untouched).
    """
    v = np.asarray(velocity, dtype=float)
    y = np.asarray(estimate, dtype=float)
    if v.shape != y.shape or v.ndim != 1:
        raise InputDataError("idle: velocity and estimate must be equal 1-D arrays")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(y))):
        raise InputDataError("idle: the air phase has non-finite samples")
    probe = DirectionIdle((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, 0, 0), deadband, unit)
    b = probe.bins(v)
    vals, vars_, counts = [], [], []
    for k in range(3):
        sel = y[b == k]
        ok = len(sel) >= min_samples
        vals.append(float(sel.mean()) if ok else math.nan)
        vars_.append(float(sel.var()) if ok else math.nan)
        counts.append(len(sel) if ok else 0)
    return DirectionIdle(
        (vals[0], vals[1], vals[2]),
        (vars_[0], vars_[1], vars_[2]),
        (counts[0], counts[1], counts[2]),
        float(deadband),
        unit,
    )
