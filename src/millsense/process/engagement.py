"""Cutter–workpiece engagement as immersion intervals per axial layer.

Angles follow :mod:`millsense.process.geometry`: φ clockwise from +y, feed along +x
(Altintas, *Manufacturing Automation* ch. 2). Slotting is φ ∈ [0, π]; down milling with
radial depth a_e enters at φ_st = arccos(2 a_e/D − 1) and leaves at π; up milling enters at 0
and leaves at φ_ex = arccos(1 − 2 a_e/D) (benchmarks.md §1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError

_TWO_PI = 2.0 * math.pi

Interval = tuple[float, float]


def _check_intervals(intervals: Sequence[Sequence[float]], where: str) -> tuple[Interval, ...]:
    out: list[Interval] = []
    for iv in intervals:
        if len(iv) != 2:
            raise ConfigError(f"engagement{where}: an interval needs (entry, exit), got {iv!r}")
        a, b = float(iv[0]), float(iv[1])
        if not (math.isfinite(a) and math.isfinite(b)) or b <= a or b - a > _TWO_PI + 1e-12:
            raise ConfigError(
                f"engagement{where}: interval ({a!r}, {b!r}) needs entry < exit ≤ entry + 2π"
            )
        out.append((a, b))
    return tuple(out)


@dataclass(frozen=True)
class Engagement:
    """Immersion intervals (entry, exit) [rad] per axial layer.

    Attributes
    ----------
    layers : tuple of tuple of (entry, exit)
        ``layers[k]`` holds the intervals of layer k; the layers split the axial depth of cut
        into equal slices from the tool tip upwards. One layer = same engagement at every
        height. A layer with no interval is out of cut. An interval may wrap past 2π
        (entry < exit ≤ entry + 2π); an angle φ is inside if (φ − entry) mod 2π ≤ exit − entry.

    Notes
    -----
    The disc at relative height s ∈ (0, 1) of the axial depth uses layer ⌊s L⌋ (L layers), so
    an engagement computed on its own axial grid can be passed unchanged to a force model
    with a different number of discs.
    """

    layers: tuple[tuple[Interval, ...], ...]

    @classmethod
    def slot(cls) -> Engagement:
        """Full immersion (slotting), φ ∈ [0, π]."""
        return cls(layers=(((0.0, math.pi),),))

    @classmethod
    def radial(
        cls, radial_depth_m: float, diameter_m: float, mode: Literal["down", "up"] = "down"
    ) -> Engagement:
        """Straight cut with radial depth a_e [m] in down or up milling.

        Parameters
        ----------
        radial_depth_m : float
            Radial depth of cut a_e [m], 0 < a_e ≤ D.
        diameter_m : float
            Tool diameter D [m].
        mode : {"down", "up"}
            Down (climb) milling exits at π; up (conventional) milling enters at 0.
        """
        if not (0.0 < radial_depth_m <= diameter_m * (1 + 1e-12)):
            raise ConfigError(
                f"engagement: radial_depth_m must be in (0, D={diameter_m!r}], "
                f"got {radial_depth_m!r}"
            )
        ratio = min(radial_depth_m / diameter_m, 1.0)
        if mode == "down":
            iv = (math.acos(2.0 * ratio - 1.0), math.pi)
        elif mode == "up":
            iv = (0.0, math.acos(1.0 - 2.0 * ratio))
        else:
            raise ConfigError(f"engagement: mode must be 'down' or 'up', got {mode!r}")
        return cls(layers=((iv,),))

    @classmethod
    def from_intervals(
        cls, intervals: Sequence[Sequence[float]] | Sequence[Sequence[Sequence[float]]]
    ) -> Engagement:
        """Build from intervals for all heights, or one list of intervals per layer.

        Parameters
        ----------
        intervals : [(entry, exit), ...] or [[(entry, exit), ...], ...]
            Angles in rad. A flat list applies to every height; a nested list gives the
            layers from the tool tip upwards (see class notes).
        """
        seq = list(intervals)
        if not seq:
            return cls(layers=((),))
        first = seq[0]
        nested = len(first) == 0 or isinstance(first[0], Sequence | np.ndarray)
        if not nested:
            return cls(layers=(_check_intervals(seq, ""),))  # type: ignore[arg-type]
        return cls(
            layers=tuple(
                _check_intervals(layer, f" layer {k}")  # type: ignore[arg-type]
                for k, layer in enumerate(seq)
            )
        )

    @property
    def n_layers(self) -> int:
        """Number of axial layers."""
        return len(self.layers)

    def layer_index(self, axial_fraction: NDArray[np.float64]) -> NDArray[np.int64]:
        """Layer used by discs at relative heights ``axial_fraction`` ∈ (0, 1)."""
        k = np.floor(np.asarray(axial_fraction) * self.n_layers).astype(np.int64)
        return np.clip(k, 0, self.n_layers - 1)

    def max_intervals(self) -> int:
        """Largest number of intervals in one layer."""
        return max((len(layer) for layer in self.layers), default=0)

    def disc_table(self, axial_fraction: NDArray[np.float64]) -> NDArray[np.float64]:
        """Intervals per disc as an array (n_discs, max_intervals, 2) of (entry, width).

        Missing intervals are padded with width −1 (never inside). Used by compiled kernels.
        """
        idx = self.layer_index(axial_fraction)
        m = max(self.max_intervals(), 1)
        table = np.zeros((idx.size, m, 2))
        table[:, :, 1] = -1.0
        for d, k in enumerate(idx):
            for i, (a, b) in enumerate(self.layers[int(k)]):
                table[d, i, 0] = a
                table[d, i, 1] = b - a
        return table

    def inside(
        self, immersion_rad: NDArray[np.float64], axial_fraction: NDArray[np.float64]
    ) -> NDArray[np.bool_]:
        """Whether each edge point is inside the engagement.

        Parameters
        ----------
        immersion_rad : (..., n_discs) float
            Immersion angles [rad], last axis over discs.
        axial_fraction : (n_discs,) float
            Relative disc heights, from :class:`~millsense.process.geometry.Discs`.

        Returns
        -------
        (..., n_discs) bool
        """
        phi = np.asarray(immersion_rad, dtype=float)
        table = self.disc_table(axial_fraction)
        out = np.zeros(phi.shape, dtype=bool)
        for i in range(table.shape[1]):
            entry = table[:, i, 0]
            width = table[:, i, 1]
            out |= np.mod(phi - entry, _TWO_PI) <= width
        return out
