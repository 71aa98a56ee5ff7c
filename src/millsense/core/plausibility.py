"""Physical plausibility: one validation layer every command calls before and after it computes.

A configuration or program can be valid (every key in range, every block legal) and still
describe something no machine can do: a 500 mm axial depth with a Ø20 mm end mill, a feed of
1e9 mm/min, a cut with the spindle stopped, a tool mode without damping, a force beyond what the
axis drives can push. This module holds those physical ranges in one place (decision 0941
"One plausibility layer"):

- **errors** — impossible input — raise a one-line :class:`~millsense.core.errors.UserError`
  naming the file, line, option or key (the CLI exits with status 2, nothing written);
- **warnings** — implausible but possible input — are collected in a :class:`Findings`; the CLI
  prints each as ``millsense: warning: ...`` and JSON outputs carry them as ``warnings``.

The ranges (all documented in decision 0941):

======================  ==============================  =======================================
quantity                error                           warning
======================  ==============================  =======================================
axial depth a_p         > 5 D, or > the tool stickout   > 3 D
radial width a_e        ≤ 0 or > D                      —
feed per tooth f_z      > R (tool radius)               > 0.5 mm or < 0.5 µm
path feed               > machine max (else 100 m/min)  —
spindle while cutting   |n| < 1 rev/min                 —
spindle speed           > the machine's max_rpm         —
tool mode               ζ ≤ 0, k < 1 N/mm, f ≤ 0     ζ ≥ 1, k < 0.1 N/µm
force, power            —                               > the machine's ``[limits]``
======================  ==============================  =======================================
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from millsense.core.config import MachineLimitsConfig
from millsense.core.errors import ConfigError, UserError

#: Axial depth beyond this many tool diameters is an error: no solid end mill has flutes that
#: long (long-series end mills reach ~4 D of flute length).
DEPTH_ERROR_DIAMETERS = 5.0
#: Axial depth beyond this many diameters is a warning (beyond regular/long series).
DEPTH_WARN_DIAMETERS = 3.0
#: Feed per tooth above this is a warning, mm (solid end-mill catalogues stay below ~0.3 mm).
FZ_WARN_MAX_MM = 0.5
#: Feed per tooth below this is a warning, mm (below an edge radius: rubbing, not cutting).
FZ_WARN_MIN_MM = 0.5e-3
#: Without a machine limit, a path feed above this is an error, mm/min (no machine tool axis
#: moves at 100 m/min while cutting).
FEED_ERROR_MM_MIN = 100_000.0
#: A mode stiffer than this is required, N/m (1 N/mm; tool-tip stiffnesses are ~1e6–1e8 N/m).
STIFFNESS_ERROR_N_M = 1e3
#: A mode softer than this is a warning, N/m (0.1 N/µm).
STIFFNESS_WARN_N_M = 1e5
#: A spindle slower than this counts as stopped, rev/min.
SPINDLE_STOPPED_RPM = 1.0

_RPM = 2.0 * math.pi / 60.0  # rad/s per rev/min


@dataclass
class Findings:
    """Warnings collected by the checks (errors are raised at once)."""

    warnings: list[str] = field(default_factory=list)

    def warn(self, message: str) -> None:
        """Add one warning (kept on one line, duplicates dropped)."""
        line = " ".join(str(message).split())
        if line not in self.warnings:
            self.warnings.append(line)

    def extend(self, messages: Iterable[str]) -> None:
        for m in messages:
            self.warn(m)


def _first(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


def check_depth(
    depth_mm: float,
    diameter_mm: float,
    where: str,
    findings: Findings,
    *,
    stickout_mm: float | None = None,
    error: type[UserError] = ConfigError,
) -> None:
    """Axial depth of cut against the tool: error beyond 5 D or the stickout, warning beyond 3 D.

    ``where`` names the input (``--depth-mm``, ``plan.nc:12``).
    """
    if not (math.isfinite(depth_mm) and depth_mm > 0):
        raise error(f"{where}: axial depth {depth_mm!r} mm must be > 0")
    if stickout_mm is not None and depth_mm > stickout_mm:
        raise error(
            f"{where}: axial depth {depth_mm:g} mm exceeds the tool's stickout "
            f"{stickout_mm:g} mm (the holder would cut)"
        )
    if depth_mm > DEPTH_ERROR_DIAMETERS * diameter_mm:
        raise error(
            f"{where}: axial depth {depth_mm:g} mm is more than {DEPTH_ERROR_DIAMETERS:g} times "
            f"the tool diameter {diameter_mm:g} mm: no end mill cuts that deep"
        )
    if depth_mm > DEPTH_WARN_DIAMETERS * diameter_mm:
        findings.warn(
            f"{where}: axial depth {depth_mm:g} mm is more than {DEPTH_WARN_DIAMETERS:g} times "
            f"the tool diameter {diameter_mm:g} mm (a long-series tool at least)"
        )


def check_width(
    width_mm: float, diameter_mm: float, where: str, *, error: type[UserError] = ConfigError
) -> None:
    """Radial width of cut: 0 < a_e ≤ D."""
    if not (math.isfinite(width_mm) and width_mm > 0):
        raise error(f"{where}: radial width {width_mm!r} mm must be > 0")
    if width_mm > diameter_mm * (1 + 1e-9):
        raise error(
            f"{where}: radial width {width_mm:g} mm exceeds the tool diameter {diameter_mm:g} mm"
        )


def check_feed_limit(
    feed_mm_min: ArrayLike,
    label: Callable[[int], str],
    limits: MachineLimitsConfig | None,
    *,
    error: type[UserError] = ConfigError,
) -> None:
    """Path feeds against the machine's ``max_feed_mm_min`` (or 100 m/min without one).

    ``label(i)`` names the input of ``feed_mm_min[i]`` (``prog.nc:7``); NaN feeds (rapids,
    dwells) are skipped.
    """
    feed = np.asarray(feed_mm_min, dtype=np.float64)
    cap = FEED_ERROR_MM_MIN
    what = "no machine tool feeds that fast"
    if limits is not None and limits.max_feed_mm_min is not None:
        cap = limits.max_feed_mm_min
        what = "the machine's max_feed_mm_min"
    bad = np.isfinite(feed) & (feed > cap)
    bad |= np.isinf(feed)
    if bad.any():
        k = _first(bad)
        raise error(f"{label(k)}: feed {feed[k]:g} mm/min exceeds {cap:g} mm/min ({what})")


def check_cutting_moves(
    feed_mm_min: ArrayLike,
    spindle_rpm: ArrayLike,
    flutes: int,
    diameter_mm: float,
    label: Callable[[int], str],
    findings: Findings,
    *,
    max_rpm: float | None = None,
    error: type[UserError] = ConfigError,
) -> None:
    """Moves that cut: spindle running, feed per tooth f_z = F / (N n) in range.

    Errors: spindle stopped (|n| < 1 rev/min), spindle above ``max_rpm``, f_z above the tool
    radius (the teeth would leave uncut ridges higher than the tool: no continuous chip).
    Warnings: f_z above 0.5 mm or below 0.5 µm (first offending move named, with the count).
    """
    feed = np.asarray(feed_mm_min, dtype=np.float64)
    rpm = np.abs(np.asarray(spindle_rpm, dtype=np.float64))
    if feed.size == 0:
        return
    stopped = rpm < SPINDLE_STOPPED_RPM
    if stopped.any():
        k = _first(stopped)
        raise error(
            f"{label(k)}: the tool cuts with the spindle stopped (on a machine that is a crash): "
            "start it with S and M3 before the cut"
        )
    if max_rpm is not None and (rpm > max_rpm * (1 + 1e-9)).any():
        k = _first(rpm > max_rpm * (1 + 1e-9))
        raise error(
            f"{label(k)}: spindle speed {rpm[k]:g} rev/min exceeds the machine's max_rpm "
            f"{max_rpm:g}"
        )
    fz = feed / (flutes * rpm)
    radius = 0.5 * diameter_mm
    impossible = ~np.isfinite(fz) | (fz > radius)
    if impossible.any():
        k = _first(impossible)
        raise error(
            f"{label(k)}: feed {feed[k]:g} mm/min at {rpm[k]:g} rev/min with {flutes} teeth "
            f"is {fz[k]:.4g} mm per tooth, more than the tool radius {radius:g} mm: impossible"
        )
    for mask, text in (
        (fz > FZ_WARN_MAX_MM, f"above {FZ_WARN_MAX_MM:g} mm (implausibly coarse)"),
        (fz < FZ_WARN_MIN_MM, f"below {FZ_WARN_MIN_MM * 1e3:g} µm (the edge rubs, no chip)"),
    ):
        if mask.any():
            k = _first(mask)
            more = f" ({int(mask.sum())} cutting moves/steps)" if mask.sum() > 1 else ""
            findings.warn(f"{label(k)}: feed per tooth {fz[k]:.4g} mm is {text}{more}")


def check_modes(
    natural_frequency_hz: ArrayLike,
    damping_ratio: ArrayLike,
    stiffness_n_m: ArrayLike,
    where: str,
    findings: Findings,
) -> None:
    """Structural modes: f > 0, ζ > 0, k ≥ 1e3 N/m, all finite (errors); ζ ≥ 1 or
    k < 1e5 N/m (warnings).

    A mode without damping never decays (the simulated vibration grows without bound, the
    stability limit is 0 everywhere and its lobes are NaN); a stiffness ≤ 0 is not a structure.
    ``where`` names the file and table (``tool.toml [structure] x[0]``).
    """
    f = np.atleast_1d(np.asarray(natural_frequency_hz, dtype=np.float64))
    z = np.atleast_1d(np.asarray(damping_ratio, dtype=np.float64))
    k = np.atleast_1d(np.asarray(stiffness_n_m, dtype=np.float64))
    for i in range(f.size):  # a handful of modes, not a signal
        tag = f"{where}[{i}]"
        if not (math.isfinite(f[i]) and f[i] > 0):
            raise ConfigError(f"{tag}: natural_frequency_hz = {f[i]:g} must be > 0")
        if not (math.isfinite(z[i]) and z[i] > 0):
            raise ConfigError(
                f"{tag}: damping_ratio = {z[i]:g} must be > 0 (an undamped mode never decays)"
            )
        if not (math.isfinite(k[i]) and k[i] >= STIFFNESS_ERROR_N_M):
            raise ConfigError(
                f"{tag}: stiffness_n_m = {k[i]:g} must be ≥ {STIFFNESS_ERROR_N_M:g} N/m "
                "(1 N/mm: softer is no machine-tool structure)"
            )
        if k[i] < STIFFNESS_WARN_N_M:
            findings.warn(
                f"{tag}: stiffness_n_m = {k[i]:g} N/m is below {STIFFNESS_WARN_N_M:g} N/m "
                "(0.1 N/µm): an implausibly soft tool"
            )
        if z[i] >= 1.0:
            findings.warn(f"{tag}: damping_ratio = {z[i]:g} ≥ 1: an over-damped mode")


class HeldLoad:
    """The largest |mean| of a stream over consecutive windows of 10 ms from its start, and
    the window's middle sample (decision 1690): what a drive holds, not a sample's spike (an
    estimator's ringing at an axis's stop, ±11 kN for 3 ms on a 160 N cut, averages out; a
    wrong K_t or lead scales every window)."""

    WINDOW_S = 0.01

    def __init__(self, sample_rate_hz: float) -> None:
        self.width = max(1, round(self.WINDOW_S * sample_rate_hz))
        self.peak = 0.0
        self.at = -1  # the largest window's middle sample (−1: none complete)
        self._sum = 0.0
        self._count = 0
        self._start = 0  # the open window's first sample

    def _close(self, mean: float, first: int) -> None:
        if abs(mean) > self.peak or self.at < 0:
            self.peak = abs(mean)
            self.at = first + self.width // 2

    def add(self, start: int, v: np.ndarray) -> None:
        """The chunk ``v`` (finite) starting at sample ``start``, following the last one."""
        w = self.width
        if self._count == 0:
            self._start = start
        take = min(w - self._count, v.size)
        self._sum += float(np.sum(v[:take]))
        self._count += take
        if self._count < w:
            return
        self._close(self._sum / w, self._start)
        rest = v[take:]
        whole = rest.size // w
        if whole:
            means = rest[: whole * w].reshape(whole, w).mean(axis=1)
            k = int(np.argmax(np.abs(means)))
            self._close(float(means[k]), start + take + k * w)
        tail = rest[whole * w :]
        self._sum = float(np.sum(tail))
        self._count = tail.size
        self._start = start + take + whole * w


def check_against_limits(
    limits: MachineLimitsConfig | None,
    where: str,
    findings: Findings,
    *,
    peak_force_n: float | None = None,
    power_w: float | None = None,
) -> None:
    """Predicted or estimated force and power against the machine's ``[limits]`` (warnings).

    ``peak_force_n`` is compared with ``axis_force_n`` (every component a linear axis carries
    is at most the resultant), ``power_w`` (mean cutting power) with ``spindle_power_kw``.
    """
    if limits is None:
        return
    if (
        peak_force_n is not None
        and limits.axis_force_n is not None
        and peak_force_n > limits.axis_force_n
    ):
        findings.warn(
            f"{where}: peak force {peak_force_n:.4g} N exceeds the machine's axis_force_n "
            f"{limits.axis_force_n:g} N (the drives cannot hold it)"
        )
    if (
        power_w is not None
        and limits.spindle_power_kw is not None
        and power_w > limits.spindle_power_kw * 1e3
    ):
        findings.warn(
            f"{where}: cutting power {power_w / 1e3:.4g} kW exceeds the machine's "
            f"spindle_power_kw {limits.spindle_power_kw:g} kW (the spindle would stall)"
        )
