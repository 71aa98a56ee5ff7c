"""Process coupling of the virtual machine: cutting forces at the actual tool motion.

The simulator hands this module, per block of samples, the tool motion it estimates for that
block (spindle angle and speed, tool-centre speed across the tool axis, arc length along the
path, time). It returns the force on the tool in the process frame (x along the feed, y normal
to it, z along the tool axis, :mod:`millsense.process.forces`), the cutting torque, and the
ground truth of the cut (engagement, depth, chip load, chatter state, breakage).

Engagement comes from an :class:`EngagementSource`: a table of :class:`Engagement` objects
and, per sample, an index into it and an axial depth. :class:`EngagementSchedule` gives simple
unit cases (slot, radial immersion, depth steps, air cuts) as functions of arc length or time;
the virtual plan of issue 4 will implement the same interface.

Injectable events (:class:`ToothBreak`, :class:`DepthStep`, :class:`AirCut`) act from a given
time on. Without tool modes the forces are the static mechanistic model evaluated for every
sample with its own feed per tooth (:func:`block_forces`); with tool modes the regenerative
time-domain simulation (:class:`~millsense.stability.time_domain.TimeDomainMillingSim`)
replaces them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol

import numba
import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError
from millsense.core.plausibility import Findings
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import previous_flute_table
from millsense.process.geometry import EndMill
from millsense.stability.time_domain import DirectionModes, TimeDomainMillingSim

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TWO_PI = 2.0 * math.pi


class EngagementSource(Protocol):
    """Where the tool is in the material, per sample.

    Attributes
    ----------
    table : the distinct engagements (immersion intervals per layer) the source refers to.
    """

    @property
    def table(self) -> Sequence[Engagement]: ...

    def at(self, s_m: FloatArray, t_s: FloatArray | None = None) -> tuple[IntArray, FloatArray]:
        """Engagement index into :attr:`table` and axial depth (m, 0 = air) per sample.

        Parameters
        ----------
        s_m : arc length of the tool along the programmed path, m.
        t_s : sample times, s (needed by time-based schedules).
        """
        ...


@dataclass(frozen=True)
class EngagementSegment:
    """From ``start`` (m of arc length, or s) on: engagement ``table[index]`` at ``depth_m``."""

    start: float
    index: int
    depth_m: float


@dataclass(frozen=True)
class EngagementSchedule:
    """Piecewise-constant engagement and axial depth along arc length or time.

    Parameters
    ----------
    table : distinct engagements.
    segments : ordered by ``start``; before the first segment the tool is in air.
    basis : ``arc_length`` (starts in m of path) or ``time`` (starts in s).
    """

    table: tuple[Engagement, ...]
    segments: tuple[EngagementSegment, ...]
    basis: Literal["arc_length", "time"] = "arc_length"
    _starts: FloatArray = field(init=False, repr=False, compare=False)
    _idx: IntArray = field(init=False, repr=False, compare=False)
    _dep: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        starts = [s.start for s in self.segments]
        if starts != sorted(starts):
            raise ConfigError("engagement schedule: segment starts must be increasing")
        for seg in self.segments:
            if not (0 <= seg.index < len(self.table)):
                raise ConfigError(f"engagement schedule: index {seg.index} outside the table")
            if not (seg.depth_m >= 0 and math.isfinite(seg.depth_m)):
                raise ConfigError(f"engagement schedule: depth {seg.depth_m!r} m must be ≥ 0")
        # lookup tables of :meth:`at` (built once; the simulator calls it every block)
        object.__setattr__(self, "_starts", np.array(starts, dtype=np.float64))
        object.__setattr__(
            self, "_idx", np.array([s.index for s in self.segments] + [0], dtype=np.int64)
        )
        object.__setattr__(self, "_dep", np.array([s.depth_m for s in self.segments] + [0.0]))

    @classmethod
    def constant(
        cls, engagement: Engagement, depth_m: float, start: float = 0.0
    ) -> EngagementSchedule:
        """One engagement at one depth from ``start`` (m of arc length) on."""
        return cls((engagement,), (EngagementSegment(start, 0, depth_m),))

    @classmethod
    def from_spec(
        cls, spec: str, diameter_m: float, depth_m: float, start_m: float = 0.0
    ) -> EngagementSchedule:
        """From a CLI text: ``slot``, ``ae_mm=5`` (down milling) or ``ae_mm=5,up``.

        Raises
        ------
        ConfigError
            For any other text (one line naming the option).
        """
        text = spec.strip().lower()
        if text == "slot":
            return cls.constant(Engagement.slot(), depth_m, start_m)
        if text.startswith("ae_mm="):
            parts = text.removeprefix("ae_mm=").split(",")
            try:
                ae = float(parts[0]) * 1e-3
            except ValueError:
                raise ConfigError(f"--engagement: '{spec}': ae_mm needs a number") from None
            mode = parts[1] if len(parts) > 1 else "down"
            if mode not in ("down", "up"):
                raise ConfigError(f"--engagement: '{spec}': mode must be 'down' or 'up'")
            return cls.constant(Engagement.radial(ae, diameter_m, mode), depth_m, start_m)  # type: ignore[arg-type]
        raise ConfigError(f"--engagement: '{spec}' (use slot, ae_mm=VALUE or ae_mm=VALUE,up)")

    @classmethod
    def along_cutting_moves(
        cls,
        engagement: Engagement,
        depth_m: float,
        arc_length_m: FloatArray,
        rapid: NDArray[np.bool_],
    ) -> EngagementSchedule:
        """``engagement`` at ``depth_m`` on feed moves, air on rapids.

        Parameters
        ----------
        arc_length_m : (N,) arc length at the path points, m.
        rapid : (N−1,) True on rapid segments.
        """
        segs: list[EngagementSegment] = []
        cut_prev: bool | None = None
        for i, r in enumerate(np.asarray(rapid, dtype=bool)):
            cut = not r
            if cut != cut_prev:
                segs.append(EngagementSegment(float(arc_length_m[i]), 0, depth_m if cut else 0.0))
                cut_prev = cut
        return cls((engagement,), tuple(segs))

    @property
    def max_depth_m(self) -> float:
        return max((s.depth_m for s in self.segments), default=0.0)

    def at(self, s_m: FloatArray, t_s: FloatArray | None = None) -> tuple[IntArray, FloatArray]:
        """Engagement index and axial depth per sample (see :class:`EngagementSource`), new
        arrays."""
        x = np.asarray(s_m if self.basis == "arc_length" else t_s, dtype=np.float64)
        if self.basis == "time" and t_s is None:
            raise ConfigError("engagement schedule: a time-based schedule needs t_s")
        idx = np.empty(x.shape, dtype=np.int64)
        dep = np.empty(x.shape)
        if x.ndim == 1:
            _segment_lookup(self._starts, self._idx, self._dep, x, idx, dep)
        else:
            _segment_lookup(self._starts, self._idx, self._dep, x.ravel(), idx.ravel(), dep.ravel())
        return idx, dep


# --------------------------------------------------------------------------------------------
# Injectable events
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ToothBreak:
    """From ``time_s`` on, flute ``flute`` is shorter by ``radius_loss_m`` (chipped), or gone
    (``radius_loss_m=None``: broken, modelled as a loss of 1 mm + the tool radius)."""

    time_s: float
    flute: int = 0
    radius_loss_m: float | None = None


@dataclass(frozen=True)
class DepthStep:
    """From ``time_s`` on, the axial depth is ``depth_m`` wherever the tool is in material."""

    time_s: float
    depth_m: float


@dataclass(frozen=True)
class AirCut:
    """Between ``start_s`` and ``end_s`` the tool is in air (no engagement)."""

    start_s: float
    end_s: float


ProcessEvent = ToothBreak | DepthStep | AirCut


# --------------------------------------------------------------------------------------------
# Static forces with a feed per tooth per sample
# --------------------------------------------------------------------------------------------


def block_forces(
    tool: EndMill,
    coeffs: CuttingCoefficients,
    engagement: Engagement,
    feed_per_tooth_m: FloatArray,
    axial_depth_m: float,
    spindle_angle_rad: FloatArray,
    radius_loss_m: FloatArray | None = None,
    n_discs: int = 10,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Static milling forces with a feed per tooth and flute radius loss per sample.

    Parameters
    ----------
    tool, coeffs, engagement : as :func:`millsense.process.forces.milling_forces`.
    feed_per_tooth_m : (n,) feed per tooth c per sample, m (≥ 0).
    axial_depth_m : axial depth, m (> 0).
    spindle_angle_rad : (n,) spindle angle φ, rad.
    radius_loss_m : (n, N) radius lost by each flute at each sample, m (chipped/broken tooth),
        or None.
    n_discs : axial discs.

    Returns
    -------
    fx, fy, fz, torque : (n,) forces on the tool (feed frame), N, and cutting torque, N·m.

    Notes
    -----
    The chip thickness of :func:`millsense.process.forces.chip_thickness` (Lee Eq. 2.4
    generalised) with c and the flute radii r_j taken per sample:
    ``h_j = sin κ · max(0, min_m [N c Δθ_jm/(2π) sin φ_j + r_j − r_{j−m}])``, then the linear
    edge-force model and projections of :func:`~millsense.process.forces.milling_forces`
    (Altintas ch. 2; Aslan Eq. 5.32). For a constant c and no radius loss it equals
    ``milling_forces`` (tested). A flute that lost radius leaves its chip to the next flute
    (Munasinghe digest, simulator item 3).
    """
    phi_s = np.asarray(spindle_angle_rad, dtype=np.float64)
    c = np.asarray(feed_per_tooth_m, dtype=np.float64)
    discs = tool.discs(axial_depth_m, n_discs)
    phi = tool.immersion_angles(phi_s, discs)  # (n, N, d)
    radii = tool.flute_radii_m(discs)[None, :, :]
    if radius_loss_m is not None:
        radii = radii - np.asarray(radius_loss_m)[:, :, None]
    prev, angle = previous_flute_table(tool)
    f_rev = tool.n_flutes * c
    sin_phi = np.sin(phi)
    h: FloatArray | None = None
    for m in range(tool.n_flutes):
        dr = radii - radii[:, prev[:, m], :]
        cand = (f_rev[:, None] * (angle[:, m] / _TWO_PI)[None, :])[:, :, None] * sin_phi + dr
        h = cand if h is None else np.minimum(h, cand)
    assert h is not None
    sk = np.sin(discs.kappa_rad)[None, None, :]
    ck = np.cos(discs.kappa_rad)[None, None, :]
    h = np.maximum(h, 0.0) * sk
    h = np.where(engagement.inside(phi, discs.axial_fraction), h, 0.0)
    cutting = h > 0.0
    db = discs.edge_length_m[None, None, :]
    hb = h * db
    eb = np.where(cutting, db, 0.0)
    dft = coeffs.ktc * hb + coeffs.kte * eb
    dfr = coeffs.krc * hb + coeffs.kre * eb
    dfa = coeffs.kac * hb + coeffs.kae * eb
    cphi = np.cos(phi)
    radial_out = dfa * ck - dfr * sk
    fx = np.sum(-dft * cphi + radial_out * sin_phi, axis=(1, 2))
    fy = np.sum(dft * sin_phi + radial_out * cphi, axis=(1, 2))
    fz = np.sum(dfr * ck + dfa * sk, axis=(1, 2))
    torque = np.sum(dft * radii, axis=(1, 2))
    return fx, fy, fz, torque


@numba.njit(cache=True)
def _feed_per_tooth(feed: np.ndarray, speed: np.ndarray, n_flutes: float, out: np.ndarray) -> None:
    """Feed per tooth ``c = 2π·|v| / (N·max(|Ω|, 1e-9))``, 0 where ``|Ω| ≤ 1e-6`` rad/s."""
    for k in range(feed.shape[0]):
        s = abs(speed[k])
        if s > 1e-6:
            om = s if s > 1e-9 else 1e-9
            out[k] = _TWO_PI * abs(feed[k]) / (n_flutes * om)
        else:
            out[k] = 0.0


@numba.njit(cache=True)
def _segment_lookup(
    starts: np.ndarray,
    idx_tab: np.ndarray,
    dep_tab: np.ndarray,
    x: np.ndarray,
    idx: np.ndarray,
    dep: np.ndarray,
) -> None:
    """Per sample the last segment with ``start ≤ x`` (``searchsorted(starts, x, 'right') −
    1``; before the first, the air entry after the segments): its index and depth."""
    n_seg = starts.shape[0]
    for k in range(x.shape[0]):
        lo, hi = 0, n_seg  # first start > x by bisection
        while lo < hi:
            mid = (lo + hi) // 2
            if starts[mid] <= x[k]:
                lo = mid + 1
            else:
                hi = mid
        j = lo - 1 if lo > 0 else n_seg
        idx[k] = idx_tab[j]
        dep[k] = dep_tab[j]


@numba.njit(cache=True)
def _air_index(idx: np.ndarray, depth: np.ndarray) -> None:
    """Engagement index −1 wherever the depth is ≤ 0 (in air)."""
    for k in range(idx.shape[0]):
        if depth[k] <= 0.0:
            idx[k] = -1


@numba.njit(cache=True)
def _uniform(idx: np.ndarray, depth: np.ndarray) -> bool:
    """True when every sample has the first sample's engagement index and depth."""
    for k in range(1, idx.shape[0]):
        if idx[k] != idx[0] or depth[k] != depth[0]:
            return False
    return True


@numba.njit(cache=True)
def _forces_kernel(
    phi_s: np.ndarray,
    c: np.ndarray,
    loss: np.ndarray,
    theta: np.ndarray,
    lag: np.ndarray,
    radii: np.ndarray,
    prev: np.ndarray,
    dtheta: np.ndarray,
    sin_k: np.ndarray,
    cos_k: np.ndarray,
    edge: np.ndarray,
    eng: np.ndarray,
    k6: np.ndarray,
    sin_a: np.ndarray,
    cos_a: np.ndarray,
    force: np.ndarray,
    torque: np.ndarray,
) -> None:
    """Per-sample loop of :func:`block_forces` (same equations, compiled).

    The edge angle ``φ = φ_s − θ_j − ψ_d`` enters the engagement test reduced by floor; its sine
    and cosine come from one sine–cosine pair of ``φ_s`` per sample and the fixed ``α = θ_j + ψ_d``
    (``sin_a``, ``cos_a`` (flutes, discs)) by the angle-difference formulas, to round-off the
    same values (no per-edge sine and cosine).
    """
    n_fl = theta.shape[0]
    n_d = lag.shape[0]
    r = np.empty((n_fl, n_d))
    for k in range(phi_s.shape[0]):
        for j in range(n_fl):
            for d in range(n_d):
                r[j, d] = radii[j, d] - loss[k, j]
        f_rev = n_fl * c[k]
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tq = 0.0
        s_s = math.sin(phi_s[k])
        c_s = math.cos(phi_s[k])
        for j in range(n_fl):
            for d in range(n_d):
                phi = phi_s[k] - theta[j] - lag[d]
                inside = False
                for i in range(eng.shape[1]):
                    w = eng[d, i, 1]
                    if w >= 0.0:
                        # (φ − start) mod 2π by floor (libm's exact fmod costs more than the
                        # rest of the edge; the two differ by round-off of φ)
                        x = phi - eng[d, i, 0]
                        x -= _TWO_PI * math.floor(x / _TWO_PI)
                        if x < 0.0:
                            x += _TWO_PI
                        if x <= w:
                            inside = True
                if not inside:
                    continue
                sp = s_s * cos_a[j, d] - c_s * sin_a[j, d]
                h = 1e300
                for m in range(n_fl):
                    cand = f_rev * dtheta[j, m] / _TWO_PI * sp + r[j, d] - r[prev[j, m], d]
                    if cand < h:
                        h = cand
                if h <= 0.0:
                    continue
                h *= sin_k[d]
                db = edge[d]
                dft = k6[0] * h * db + k6[3] * db
                dfr = k6[1] * h * db + k6[4] * db
                dfa = k6[2] * h * db + k6[5] * db
                cp = c_s * cos_a[j, d] + s_s * sin_a[j, d]
                radial_out = dfa * cos_k[d] - dfr * sin_k[d]
                fx += -dft * cp + radial_out * sp
                fy += dft * sp + radial_out * cp
                fz += dfr * cos_k[d] + dfa * sin_k[d]
                tq += dft * r[j, d]
        force[k, 0] = fx
        force[k, 1] = fy
        force[k, 2] = fz
        torque[k] = tq


class StaticForceModel:
    """Compiled static force model with cached discs per (engagement, depth).

    Evaluates the equations of :func:`block_forces` in :func:`_forces_kernel`; the disc
    geometry and engagement tables are built once per distinct (engagement, depth).
    """

    def __init__(self, tool: EndMill, coeffs: CuttingCoefficients, n_discs: int = 10) -> None:
        self.tool = tool
        self.n_discs = n_discs
        self._k6 = np.array(
            [coeffs.ktc, coeffs.krc, coeffs.kac, coeffs.kte, coeffs.kre, coeffs.kae]
        )
        prev, angle = previous_flute_table(tool)
        self._prev = np.ascontiguousarray(prev)
        self._dtheta = np.ascontiguousarray(angle)
        self._theta = np.ascontiguousarray(tool.flute_angles_rad, dtype=np.float64)
        self._cache: dict[tuple[int, float], tuple[np.ndarray, ...]] = {}

    def _geometry(self, key: tuple[int, float], engagement: Engagement) -> tuple[np.ndarray, ...]:
        g = self._cache.get(key)
        if g is None:
            discs = self.tool.discs(key[1], self.n_discs)
            alpha = self._theta[:, None] + np.asarray(discs.lag_rad)[None, :]
            g = (
                np.ascontiguousarray(discs.lag_rad),
                np.ascontiguousarray(self.tool.flute_radii_m(discs)),
                np.ascontiguousarray(np.sin(discs.kappa_rad)),
                np.ascontiguousarray(np.cos(discs.kappa_rad)),
                np.ascontiguousarray(discs.edge_length_m),
                np.ascontiguousarray(engagement.disc_table(discs.axial_fraction)),
                np.ascontiguousarray(np.sin(alpha)),
                np.ascontiguousarray(np.cos(alpha)),
            )
            self._cache[key] = g
        return g

    def forces(
        self,
        key: int,
        engagement: Engagement,
        depth_m: float,
        spindle_angle_rad: FloatArray,
        feed_per_tooth_m: FloatArray,
        radius_loss_m: FloatArray,
    ) -> FloatArray:
        """(n, 4) [F_x, F_y, F_z (N, feed frame), torque (N·m)] per sample."""
        n = len(spindle_angle_rad)
        force, torque = np.empty((n, 3)), np.empty(n)
        angle, c, loss = spindle_angle_rad, feed_per_tooth_m, radius_loss_m
        self.forces_into(key, engagement, depth_m, angle, c, loss, force, torque)
        return np.column_stack([force, torque])

    def forces_into(
        self,
        key: int,
        engagement: Engagement,
        depth_m: float,
        spindle_angle_rad: FloatArray,
        feed_per_tooth_m: FloatArray,
        radius_loss_m: FloatArray,
        force: FloatArray,
        torque: FloatArray,
    ) -> None:
        """:meth:`forces` into ``force`` ((n, 3) C-contiguous, N, feed frame) and ``torque``
        ((n,), N·m)."""
        lag, radii, sk, ck, edge, eng, sin_a, cos_a = self._geometry((key, depth_m), engagement)
        _forces_kernel(
            np.ascontiguousarray(spindle_angle_rad, dtype=np.float64),
            np.ascontiguousarray(feed_per_tooth_m, dtype=np.float64),
            np.ascontiguousarray(radius_loss_m, dtype=np.float64),
            self._theta,
            lag,
            radii,
            self._prev,
            self._dtheta,
            sk,
            ck,
            edge,
            eng,
            self._k6,
            sin_a,
            cos_a,
            force,
            torque,
        )


# --------------------------------------------------------------------------------------------
# The coupling object
# --------------------------------------------------------------------------------------------


@dataclass
class ToolModes:
    """Tool flexibility for regenerative chatter (process frame x = feed, y = normal)."""

    x: DirectionModes
    y: DirectionModes
    steps_per_rev: int = 0  #: 0 = choose from the sample rate (≥ 2 steps per sample)

    @classmethod
    def from_toml(cls, path: str | Path, findings: Findings | None = None) -> ToolModes:
        """The ``[[structure.x]]``/``[[structure.y]]`` modes of a TOML file (a stability case
        file works: only its ``[structure]`` table is read).

        Each mode gives ``natural_frequency_hz``, ``damping_ratio`` and ``stiffness_n_m`` (or
        ``residue_alpha_m_n_s2`` with ``residue_beta_m_n_s`` = 0, stiffness ω²/α); x is along
        the feed, y normal to it, as in the stability cases. A direction without modes is
        rigid. Every mode passes :func:`millsense.core.plausibility.check_modes` (damping and
        stiffness > 0; over-damped modes are warnings added to ``findings``).

        Raises
        ------
        ConfigError
            Missing ``[structure]``, a bad mode (one line naming file and key), a velocity
            residue (the time-domain tool model has none), or no mode at all.
        """
        from millsense.core.config import parse_config, read_toml
        from millsense.core.plausibility import check_modes
        from millsense.stability.cases import StructureSpec

        data = read_toml(path)
        if not isinstance(data.get("structure"), dict):
            raise ConfigError(f"{path}: missing table [structure] ([[structure.x]] modes)")
        spec = parse_config(StructureSpec, data["structure"], f"{path} [structure]")
        if not spec.x and not spec.y:
            raise ConfigError(f"{path}: [structure] has no [[structure.x]] or [[structure.y]] mode")
        out = []
        for d, modes in (("x", spec.x), ("y", spec.y)):
            if not modes:
                out.append(DirectionModes.rigid())
                continue
            f, z, k = [], [], []
            for i, m in enumerate(modes):
                if m.residue_beta_m_n_s != 0.0:
                    raise ConfigError(
                        f"{path}: structure.{d}[{i}]: residue_beta_m_n_s must be 0 for the "
                        "simulated tool (give stiffness_n_m)"
                    )
                f.append(m.natural_frequency_hz)
                z.append(m.damping_ratio)
                k.append(m.stiffness_n_m if m.stiffness_n_m is not None else m.to_mode().stiffness)
            check_modes(f, z, k, f"{path} [structure] {d}", findings or Findings())
            out.append(DirectionModes.from_arrays(f, z, k))
        return cls(out[0], out[1])


@dataclass
class ProcessOutput:
    """Per-sample process quantities of one block (SI)."""

    force: FloatArray  #: (n, 3) force on the tool in the process frame [feed, normal, axis], N
    torque: FloatArray  #: (n,) cutting torque, N·m
    engagement_index: IntArray  #: (n,) index into the engagement table (−1 in air)
    depth_m: FloatArray  #: (n,) axial depth, m
    feed_per_tooth_m: FloatArray  #: (n,) chip load, m
    vibration_m: FloatArray  #: (n, 2) tool displacement x, y, m (0 without modes)
    vibration_acc: FloatArray  #: (n, 2) tool acceleration x, y, m/s² (0 without modes)
    chatter: FloatArray  #: (n,) 1 while the vibration is not periodic with the revolution
    broken: FloatArray  #: (n,) 1 after a tooth break / chip


@dataclass
class ProcessCoupling:
    """Cutting process of the virtual machine, evaluated block by block (resumable).

    Parameters
    ----------
    tool, coeffs : tool geometry and cutting coefficients.
    engagement : engagement source (arc length / time → engagement, depth).
    events : injectable events.
    n_discs : axial discs of the force model.
    modes : tool modes for regenerative chatter, or None for static forces.
    sample_rate_hz : rate of the blocks, Hz.
    chatter_ratio : a sample is flagged as chatter when the RMS change of the tool vibration
        over one revolution exceeds this fraction of its RMS (and 1 µm).
    """

    tool: EndMill
    coeffs: CuttingCoefficients
    engagement: EngagementSource
    events: Sequence[ProcessEvent] = ()
    n_discs: int = 10
    modes: ToolModes | None = None
    sample_rate_hz: float = 10000.0
    chatter_ratio: float = 0.25
    _td: TimeDomainMillingSim | None = field(default=None, init=False, repr=False)
    _td_t0: float = field(default=0.0, init=False, repr=False)
    _td_hist: FloatArray = field(default_factory=lambda: np.zeros((0, 2)), init=False)
    _td_speed: float = field(default=0.0, init=False, repr=False)
    _td_break_done: set[int] = field(default_factory=set, init=False, repr=False)
    _last2: FloatArray = field(default_factory=lambda: np.zeros((2, 2)), init=False)
    _td_disc_eng: list[tuple[tuple[float, float], ...]] = field(
        default_factory=list, init=False, repr=False
    )

    def __post_init__(self) -> None:
        if self.n_discs < 1:
            raise ConfigError(f"process: n_discs must be ≥ 1, got {self.n_discs}")
        for ev in self.events:
            if isinstance(ev, ToothBreak) and not (0 <= ev.flute < self.tool.n_flutes):
                raise ConfigError(
                    f"process: tooth break flute {ev.flute} (tool has {self.tool.n_flutes})"
                )
            if isinstance(ev, AirCut) and not ev.end_s > ev.start_s:
                raise ConfigError(f"process: air cut end {ev.end_s} s ≤ start {ev.start_s} s")
            if isinstance(ev, DepthStep) and not ev.depth_m >= 0:
                raise ConfigError(f"process: depth step {ev.depth_m} m must be ≥ 0")
        self._table = list(self.engagement.table)
        # the events by kind, once (evaluated every block)
        self._depth_steps = sorted(
            (e for e in self.events if isinstance(e, DepthStep)), key=lambda e: e.time_s
        )
        self._air_cuts = [e for e in self.events if isinstance(e, AirCut)]
        self._breaks = [e for e in self.events if isinstance(e, ToothBreak)]
        self._static = StaticForceModel(self.tool, self.coeffs, self.n_discs)
        self._max_depth = max(
            [getattr(self.engagement, "max_depth_m", 0.0)]
            + [e.depth_m for e in self.events if isinstance(e, DepthStep)]
        )

    @property
    def breakage_time_s(self) -> float | None:
        """Earliest tooth break or chip, s (None if none is injected)."""
        times = [e.time_s for e in self.events if isinstance(e, ToothBreak)]
        return min(times) if times else None

    def _loss(self, ev: ToothBreak) -> float:
        return ev.radius_loss_m if ev.radius_loss_m is not None else self.tool.radius_m + 1e-3

    def engagement_at(self, s_m: FloatArray, t_s: FloatArray) -> tuple[IntArray, FloatArray]:
        """Engagement index (−1 in air) and depth per sample, after the events."""
        idx, depth = self.engagement.at(s_m, t_s)
        if not isinstance(self.engagement, EngagementSchedule):  # its arrays are new: no copy
            idx = np.array(idx, dtype=np.int64)
            depth = np.array(depth, dtype=np.float64)
        for ev in self._depth_steps:
            sel = (t_s >= ev.time_s) & (depth > 0)
            depth[sel] = ev.depth_m
        for ev_a in self._air_cuts:
            depth[(t_s >= ev_a.start_s) & (t_s < ev_a.end_s)] = 0.0
        _air_index(idx, depth)
        return idx, depth

    def radius_loss(self, t_s: FloatArray) -> FloatArray:
        """(n, N) radius lost per flute at times ``t_s``, m."""
        loss = np.zeros((len(t_s), self.tool.n_flutes))
        for ev in self._breaks:
            loss[t_s >= ev.time_s, ev.flute] += self._loss(ev)
        return loss

    def evaluate(
        self,
        t_s: FloatArray,
        s_m: FloatArray,
        spindle_angle_rad: FloatArray,
        spindle_speed_rad_s: FloatArray,
        feed_speed_m_s: FloatArray,
    ) -> ProcessOutput:
        """Process quantities of one block of consecutive samples.

        Parameters
        ----------
        t_s : sample times, s.
        s_m : arc length of the tool along the path, m.
        spindle_angle_rad, spindle_speed_rad_s : spindle angle (rad) and speed (rad/s).
        feed_speed_m_s : tool-centre speed relative to the workpiece across the tool axis,
            m/s (feed per tooth ``c = 2π v / (N Ω)``).
        """
        n = len(t_s)
        c = np.empty(n)
        _feed_per_tooth(
            np.asarray(feed_speed_m_s, dtype=np.float64),
            np.asarray(spindle_speed_rad_s, dtype=np.float64),
            float(self.tool.n_flutes),
            c,
        )
        idx, depth = self.engagement_at(s_m, t_s)
        loss = self.radius_loss(t_s)
        broken = (loss.sum(axis=1) > 0).astype(np.float64) if self._breaks else np.zeros(n)
        force = np.zeros((n, 3))
        torque = np.zeros(n)
        vib = np.zeros((n, 2))
        acc = np.zeros((n, 2))
        chatter = np.zeros(n)
        if self.modes is None:
            if n and _uniform(idx, depth):
                k, d = int(idx[0]), float(depth[0])
                if k >= 0 and d > 0:  # one engagement over the block: straight into the arrays
                    self._static.forces_into(
                        k, self._table[k], d, spindle_angle_rad, c, loss, force, torque
                    )
            else:
                keys = np.stack([idx.astype(np.float64), depth], axis=1)
                for kk in np.unique(keys, axis=0):
                    k, d = int(kk[0]), float(kk[1])
                    if k < 0 or d <= 0:
                        continue
                    sel = (idx == k) & (depth == kk[1])
                    res = self._static.forces(
                        k, self._table[k], d, spindle_angle_rad[sel], c[sel], loss[sel]
                    )
                    force[sel] = res[:, :3]
                    torque[sel] = res[:, 3]
        else:
            self._regenerative(
                t_s, idx, depth, c, spindle_speed_rad_s, force, torque, vib, acc, chatter
            )
        return ProcessOutput(force, torque, idx, depth, c, vib, acc, chatter, broken)

    # ---------------------------------------------------------------- regenerative path
    def _layered(self, idx: int, depth: float) -> Engagement:
        """Engagement ``idx`` restricted to the lowest ``depth`` of the maximum depth (layers
        of the n_discs discs of the time-domain simulation)."""
        n = self.n_discs
        if idx < 0 or depth <= 0:
            return Engagement(layers=tuple(() for _ in range(n)))
        base = self._table[idx]
        layers = []
        for j in range(n):
            frac = (j + 0.5) / n
            if frac * self._max_depth <= depth + 1e-12:
                k = int(base.layer_index(np.array([frac]))[0])
                layers.append(base.layers[k])
            else:
                layers.append(())
        return Engagement(layers=tuple(layers))

    def _make_td(self, t0: float, speed: float, c: float) -> TimeDomainMillingSim:
        assert self.modes is not None
        spr = self.modes.steps_per_rev
        if spr <= 0:
            per_rev = _TWO_PI / speed * self.sample_rate_hz
            spr = min(max(2 * math.ceil(per_rev), 64), 4096)
        spr = int(math.ceil(spr / self.tool.n_flutes) * self.tool.n_flutes)
        if self._max_depth <= 0:
            raise ConfigError("process: chatter simulation needs a positive axial depth")
        td = TimeDomainMillingSim(
            self.tool,
            self.coeffs,
            self._layered(-1, 0.0),
            c,
            self._max_depth,
            speed,
            self.modes.x,
            self.modes.y,
            n_discs=self.n_discs,
            steps_per_rev=spr,
        )
        self._td_t0 = t0
        self._td_speed = speed
        return td

    def _regenerative(
        self,
        t_s: FloatArray,
        idx: IntArray,
        depth: FloatArray,
        c: FloatArray,
        speed: FloatArray,
        force: FloatArray,
        torque: FloatArray,
        vib: FloatArray,
        acc: FloatArray,
        chatter: FloatArray,
    ) -> None:
        """Run the time-domain simulation over the block; engagement, depth, feed per tooth
        and spindle speed are taken at the block's first sample (block = 3 ms)."""
        om = float(abs(speed[0]))
        if om < 1e-3:
            if self._td is not None:
                self._td = None  # spindle stopped: the surface is forgotten
            return
        if self._td is None and (idx[0] < 0 or depth[0] <= 0):
            return  # not in the material yet: the surface starts with the first cut
        if self._td is None:
            self._td = self._make_td(float(t_s[0]), om, float(c[0]))
            self._td_disc_eng = [()] * self.n_discs
        td = self._td
        if abs(om - td.spindle_speed_rad_s) > 1e-9 * om:
            # keep the time base: the steps so far ran at the old speed
            self._td_t0 += td.step * (td.dt_s - _TWO_PI / td.steps_per_rev / om)
            td.set_spindle_speed(om)
        td.set_feed_per_tooth(float(c[0]))
        eng = self._layered(int(idx[0]), float(depth[0]))
        td.set_engagement(eng)
        # discs entering the material (first cut, depth step up, end of an air cut, new
        # immersion) get the surface a rigid tool would have left: never a stale surface
        layers = list(eng.layers)
        fresh = np.array(
            [bool(new) and new != old for new, old in zip(layers, self._td_disc_eng, strict=True)]
        )
        td.lay_surface(fresh)
        self._td_disc_eng = layers
        dt = 1.0 / self.sample_rate_hz
        t_end = float(t_s[-1]) + 0.5 * dt
        n_needed = math.floor((t_end - self._td_t0) / td.dt_s) + 1 - td.step
        rows_f = []
        rows_x = []
        # tooth breaks inside the block split the run at their step
        pending = sorted(
            (
                e
                for e in self.events
                if isinstance(e, ToothBreak) and id(e) not in self._td_break_done
            ),
            key=lambda e: e.time_s,
        )
        done = 0
        for ev in pending:
            k_ev = math.ceil((ev.time_s - self._td_t0) / td.dt_s) - td.step
            if k_ev > n_needed:
                break
            k_ev = max(k_ev, 0)
            if k_ev > done:
                ch = td.run(k_ev - done)
                rows_f.append(np.column_stack([ch.fx_n, ch.fy_n, ch.fz_n, ch.torque_nm]))
                rows_x.append(np.column_stack([ch.x_m, ch.y_m]))
                done = k_ev
            # the simulator's own flute radii: a chipped flute cuts less from here on
            td._radii[ev.flute, :] -= self._loss(ev)
            self._td_break_done.add(id(ev))
        if n_needed > done:
            ch = td.run(n_needed - done)
            rows_f.append(np.column_stack([ch.fx_n, ch.fy_n, ch.fz_n, ch.torque_nm]))
            rows_x.append(np.column_stack([ch.x_m, ch.y_m]))
        f_new = np.concatenate(rows_f) if rows_f else np.zeros((0, 4))
        x_new = np.concatenate(rows_x) if rows_x else np.zeros((0, 2))
        spr = td.steps_per_rev
        hist = np.concatenate([self._td_hist, x_new])
        first = td.step - len(x_new)
        if len(x_new):
            # zero-order hold: each sample takes the step that contains its time
            k = np.floor((t_s - self._td_t0) / td.dt_s).astype(np.int64) - first
            k = np.clip(k, 0, len(x_new) - 1)
            force[:, :3] = f_new[k, :3]
            torque[:] = f_new[k, 3]
            vib[:] = x_new[k]
            if len(hist) >= 2 * spr:
                # chatter: the vibration does not repeat after one revolution
                win = hist[-2 * spr :]
                d = win[spr:] - win[:spr]
                rms_d = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
                cur = win[spr:]
                rms_v = float(np.sqrt(np.mean(np.sum((cur - cur.mean(axis=0)) ** 2, axis=1))))
                if rms_d > self.chatter_ratio * rms_v and rms_d > 1e-6:
                    chatter[:] = 1.0
        self._td_hist = hist[-2 * spr :]
        # tool acceleration at the sample rate: second difference of the displacement
        seq = np.vstack([self._last2, vib])
        acc[:] = np.diff(seq, n=2, axis=0) * self.sample_rate_hz**2
        self._last2 = seq[-2:].copy()
