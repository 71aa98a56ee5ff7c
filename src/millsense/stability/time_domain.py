"""Time-domain regenerative milling simulation (numba), resumable chunk by chunk.

The tool (flat or ball, any pitch, helix, runout) is flexible in x and y, each direction a sum
of modes (f_n, ζ, k). The workpiece surface left at every axial disc is stored at the angular
resolution of the time step; a flute whose edge does not reach that surface (h ≤ 0) does not
cut and leaves it unchanged, so the next flute meets the right surface. The modal equations
are integrated exactly for a force held constant over a step (zero-order-hold transition from
the matrix exponential).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from millsense.core.errors import ConfigError
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.geometry import EndMill
from millsense.stability._td_kernel import NEVER_CUT_M, td_run

FloatArray = NDArray[np.float64]

_TWO_PI = 2.0 * math.pi


#: Poincaré steps below this fraction of the RMS vibration count as converged (round-off level).
_NEGLIGIBLE_STEP = 1e-6


@dataclass(frozen=True)
class DirectionModes:
    """Modes of the tool in one direction: FRF = Σ 1 / (k_i (1 − r_i² + 2 i ζ_i r_i)).

    Parameters
    ----------
    natural_hz : (m,) float
        Natural frequencies [Hz] (m = 0 means rigid in that direction).
    damping_ratio : (m,) float
        Damping ratios ζ [-], 0 ≤ ζ < 1.
    stiffness_n_per_m : (m,) float
        Modal stiffnesses k [N/m].
    """

    natural_hz: FloatArray
    damping_ratio: FloatArray
    stiffness_n_per_m: FloatArray

    @classmethod
    def from_arrays(
        cls, natural_hz: ArrayLike, damping_ratio: ArrayLike, stiffness_n_per_m: ArrayLike
    ) -> DirectionModes:
        """Check and build from array-likes (one value per mode)."""
        fn = np.atleast_1d(np.asarray(natural_hz, dtype=float))
        ze = np.atleast_1d(np.asarray(damping_ratio, dtype=float))
        kk = np.atleast_1d(np.asarray(stiffness_n_per_m, dtype=float))
        if not (fn.shape == ze.shape == kk.shape) or fn.ndim != 1:
            raise ConfigError("modes: natural_hz, damping_ratio, stiffness need equal lengths")
        if np.any(fn <= 0) or np.any(kk <= 0) or np.any((ze < 0) | (ze >= 1)):
            raise ConfigError("modes: need f_n > 0, k > 0 and 0 ≤ ζ < 1 for every mode")
        return cls(fn, ze, kk)

    @classmethod
    def rigid(cls) -> DirectionModes:
        """No flexibility in this direction."""
        z = np.zeros(0)
        return cls(z, z, z)

    def discrete(self, dt_s: float) -> tuple[FloatArray, FloatArray]:
        """Exact zero-order-hold transition over ``dt_s``: s⁺ = A_d s + B_d F.

        Each mode q̈ + 2ζω q̇ + ω² q = (ω²/k) F with state s = [q, q̇]; A_d and B_d are the
        blocks of expm([[A, B], [0, 0]] dt).

        Returns
        -------
        ad : (m, 2, 2) float
        bd : (m, 2) float [m/N, m/(N s)]
        """
        m = self.natural_hz.size
        ad = np.zeros((m, 2, 2))
        bd = np.zeros((m, 2))
        for i in range(m):  # per mode, once per configuration
            w = _TWO_PI * self.natural_hz[i]
            big = np.zeros((3, 3))
            big[0, 1] = 1.0
            big[1, 0] = -(w**2)
            big[1, 1] = -2.0 * self.damping_ratio[i] * w
            big[1, 2] = w**2 / self.stiffness_n_per_m[i]
            e = expm(big * dt_s)
            ad[i] = e[:2, :2]
            bd[i] = e[:2, 2]
        return ad, bd


@dataclass
class TimeDomainChunk:
    """Outputs of one call of :meth:`TimeDomainMillingSim.run` (one entry per step).

    Forces are on the tool (see :mod:`millsense.process.forces`), evaluated at the middle of
    each step (``spindle_angle_rad``) and held over it; ``x_m``, ``y_m`` are the
    displacements at the start of the step, ``time_s`` the start time.
    """

    time_s: FloatArray
    spindle_angle_rad: FloatArray
    fx_n: FloatArray
    fy_n: FloatArray
    fz_n: FloatArray
    torque_nm: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    chip_m: FloatArray  #: (n, N) largest chip thickness of each flute over the discs [m]


@dataclass(frozen=True)
class StabilityVerdict:
    """Stable/unstable verdict from once-per-revolution (Poincaré) samples.

    Attributes
    ----------
    stable : bool
        Verdict (see :meth:`TimeDomainMillingSim.verdict`).
    decay_ratio : float
        Envelope of the Poincaré steps |P_k − P_{k−1}| in the last window over that in the
        first window.
    spread_ratio : float
        Envelope of the last window over the RMS displacement of the last revolution.
    multiplier_per_rev : float
        Growth factor per revolution of the envelope (log-linear fit over the windows).
    n_revolutions : int
        Number of Poincaré samples used.
    """

    stable: bool
    decay_ratio: float
    spread_ratio: float
    multiplier_per_rev: float
    n_revolutions: int


@dataclass
class TimeDomainMillingSim:
    """Regenerative milling simulation, resumable: ``run(a); run(b)`` equals ``run(a + b)``.

    Parameters
    ----------
    tool : EndMill
        Tool geometry with pitch, helix, shape and runout.
    coeffs : CuttingCoefficients
        Linear edge-force coefficients [N/m², N/m].
    engagement : Engagement
        Immersion intervals per axial layer.
    feed_per_tooth_m : float
        Feed per tooth c [m] (feed per revolution N c).
    axial_depth_m : float
        Axial depth of cut [m].
    spindle_speed_rad_s : float
        Spindle speed Ω [rad/s].
    modes_x, modes_y : DirectionModes
        Tool flexibility along x (feed) and y.
    n_discs : int
        Axial discs.
    steps_per_rev : int
        Time steps (and surface bins) per revolution; use a multiple of N for uniform pitch so
        the tooth delay is a whole number of steps.
    start_angle_rad : float
        Spindle angle at t = 0 [rad].

    Notes
    -----
    Chip thickness at flute j, disc d (regenerative, Altintas ch. 3 time-domain model):
    h = [(X + x) sin φ + y cos φ + r_jd − S_d(φ)] sin κ, S_d the radial coordinate of the
    surface at immersion bin φ, X = N c φ_s/(2π) the nominal feed position. A flute cuts
    only inside the engagement and where h > 0, and then S_d(φ) becomes its own position.
    Before t = 0 the tool turns rigidly for two revolutions to lay down the surface of the
    steady cut. The delay is resolved to one step (bins of 2π/steps_per_rev).
    """

    tool: EndMill
    coeffs: CuttingCoefficients
    engagement: Engagement
    feed_per_tooth_m: float
    axial_depth_m: float
    spindle_speed_rad_s: float
    modes_x: DirectionModes
    modes_y: DirectionModes
    n_discs: int = 20
    steps_per_rev: int = 200
    start_angle_rad: float = 0.0
    step: int = field(default=0, init=False)
    _poincare: list[tuple[float, float]] = field(default_factory=list, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.spindle_speed_rad_s > 0):
            raise ConfigError(
                f"simulation: spindle speed must be > 0, got {self.spindle_speed_rad_s!r}"
            )
        if self.steps_per_rev < 8:
            raise ConfigError(f"simulation: steps_per_rev must be ≥ 8, got {self.steps_per_rev!r}")
        if not (self.feed_per_tooth_m >= 0):
            raise ConfigError(
                f"simulation: feed_per_tooth_m must be ≥ 0, got {self.feed_per_tooth_m!r}"
            )
        discs = self.tool.discs(self.axial_depth_m, self.n_discs)
        self._dphi = _TWO_PI / self.steps_per_rev
        self._theta = self.tool.flute_angles_rad.copy()
        self._radii = self.tool.flute_radii_m(discs).copy()
        self._lag = discs.lag_rad.copy()
        self._axial_fraction = discs.axial_fraction.copy()
        self._bin_offset = np.rint(
            (self.start_angle_rad - self._theta[:, None] - self._lag[None, :]) / self._dphi
        ).astype(np.int64)
        self._sin_k = np.sin(discs.kappa_rad)
        self._cos_k = np.cos(discs.kappa_rad)
        self._edge = discs.edge_length_m.copy()
        self._eng = self.engagement.disc_table(self._axial_fraction)
        self._coeffs = np.array(self.coeffs.as_tuple(), dtype=float)
        self._sx = np.zeros((self.modes_x.natural_hz.size, 2))
        self._sy = np.zeros((self.modes_y.natural_hz.size, 2))
        self._discretise()
        self._feed_x0 = 0.0
        self._n_base = 0
        self._surface = np.full((self.n_discs, self.steps_per_rev), NEVER_CUT_M)
        self._advance(2 * self.steps_per_rev, -2 * self.steps_per_rev, rigid=True)

    @property
    def dt_s(self) -> float:
        """Time step [s] = 2π / (steps_per_rev Ω)."""
        return self._dphi / self.spindle_speed_rad_s

    @property
    def time_s(self) -> float:
        """Simulated time so far [s]."""
        return self.step * self.dt_s

    def _discretise(self) -> None:
        self._adx, self._bdx = self.modes_x.discrete(self.dt_s)
        self._ady, self._bdy = self.modes_y.discrete(self.dt_s)

    def _advance(
        self, n: int, step0: int, rigid: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        out_f = np.zeros((0 if rigid else n, 4))
        out_xy = np.zeros((0 if rigid else n, 2))
        out_h = np.zeros((0 if rigid else n, self.tool.n_flutes))
        td_run(
            n,
            step0,
            self.start_angle_rad,
            self._dphi,
            self.dt_s,
            self.tool.n_flutes * self.feed_per_tooth_m,
            self._feed_x0,
            self._n_base,
            self._theta,
            self._radii,
            self._lag,
            self._bin_offset,
            self._sin_k,
            self._cos_k,
            self._edge,
            self._eng,
            self._coeffs,
            self._adx,
            self._bdx,
            self._sx,
            self._ady,
            self._bdy,
            self._sy,
            self._surface,
            rigid,
            out_f,
            out_xy,
            out_h,
        )
        return out_f, out_xy, out_h

    def set_spindle_speed(self, spindle_speed_rad_s: float) -> None:
        """Change Ω from the next step on (the angular grid stays, the time step changes)."""
        if not (spindle_speed_rad_s > 0):
            raise ConfigError(f"simulation: spindle speed must be > 0, got {spindle_speed_rad_s!r}")
        self.spindle_speed_rad_s = float(spindle_speed_rad_s)
        self._discretise()

    def set_feed_per_tooth(self, feed_per_tooth_m: float) -> None:
        """Change the feed per tooth [m] from the next step on (feed position continuous)."""
        if not (feed_per_tooth_m >= 0):
            raise ConfigError(f"simulation: feed_per_tooth_m must be ≥ 0, got {feed_per_tooth_m!r}")
        self._feed_x0 = self._feed_position(self.step)
        self._n_base = self.step
        self.feed_per_tooth_m = float(feed_per_tooth_m)

    def _feed_position(self, n: int) -> float:
        f_rev = self.tool.n_flutes * self.feed_per_tooth_m
        return self._feed_x0 + f_rev * ((n - self._n_base) * self._dphi) / _TWO_PI

    def set_coefficients(self, coeffs: CuttingCoefficients) -> None:
        """Change the cutting coefficients from the next step on (a material change).

        With a straight-fluted tool on one disc and no edge forces, scaling K_tc and K_rc by s
        is a change of the axial depth by s; a slow ramp of it approaches a depth without the
        entry transient of a start at full depth (decision 0910).
        """
        self.coeffs = coeffs
        self._coeffs = np.array(coeffs.as_tuple(), dtype=float)

    def set_engagement(self, engagement: Engagement) -> None:
        """Change the immersion intervals from the next step on (same discs)."""
        self.engagement = engagement
        self._eng = engagement.disc_table(self._axial_fraction)

    def lay_surface(self, discs: NDArray[np.bool_], n_rev: int = 2) -> None:
        """Lay down the surface of the selected discs as a rigid tool would have cut it.

        Parameters
        ----------
        discs : (n_discs,) bool
            Discs whose surface is (re)laid with the current engagement.
        n_rev : int
            Revolutions of the rigid pass, ending at the current step.

        Notes
        -----
        The same rigid pass as the two revolutions before t = 0 (class Notes), run over the
        steps ``[step − n_rev·steps_per_rev, step)`` with the current feed, engagement and
        tool displacement, for the selected discs only. A disc that enters the material after
        t = 0 (first cut of a resumed simulation, a depth step up, the end of an air cut)
        otherwise meets a surface that was never cut (−1e30 m) or was left far behind, and the
        first flute would take that whole distance as its chip; the rigid pass gives it the
        nominal chip of the steady cut instead
        (docs/decisions/0077-simulator-regenerative-coupling.md).
        """
        mask = np.asarray(discs, dtype=bool)
        if mask.shape != (self.n_discs,):
            raise ConfigError(f"simulation: discs mask needs shape ({self.n_discs},)")
        if not mask.any():
            return
        full = self._eng
        sub = full.copy()
        sub[~mask, :, 1] = -1.0
        self._eng = sub
        try:
            n = int(n_rev) * self.steps_per_rev
            self._advance(n, self.step - n, rigid=True)
        finally:
            self._eng = full

    def run(self, n_steps: int) -> TimeDomainChunk:
        """Simulate ``n_steps`` more steps and return their outputs."""
        if n_steps < 0:
            raise ConfigError(f"simulation: n_steps must be ≥ 0, got {n_steps!r}")
        step0 = self.step
        out_f, out_xy, out_h = self._advance(int(n_steps), step0, rigid=False)
        steps = step0 + np.arange(n_steps, dtype=np.int64)
        t_start: FloatArray = (steps * self.dt_s).astype(np.float64)
        angle: FloatArray = (self.start_angle_rad + (steps + 0.5) * self._dphi).astype(np.float64)
        at_sample = np.nonzero(steps % self.poincare_period_steps == 0)[0]
        self._poincare.extend((float(out_xy[i, 0]), float(out_xy[i, 1])) for i in at_sample)
        self.step = step0 + int(n_steps)
        self._last = out_xy[-self.steps_per_rev :] if n_steps else getattr(self, "_last", None)
        return TimeDomainChunk(
            time_s=t_start,
            spindle_angle_rad=angle,
            fx_n=out_f[:, 0],
            fy_n=out_f[:, 1],
            fz_n=out_f[:, 2],
            torque_nm=out_f[:, 3],
            x_m=out_xy[:, 0],
            y_m=out_xy[:, 1],
            chip_m=out_h,
        )

    def run_revolutions(self, n_rev: float) -> TimeDomainChunk:
        """Simulate ``n_rev`` revolutions (rounded to whole steps)."""
        return self.run(round(n_rev * self.steps_per_rev))

    @property
    def poincare_period_steps(self) -> int:
        """Steps between Poincaré samples: one tooth period when the cut repeats every tooth
        (uniform pitch, no runout, steps_per_rev divisible by N), else one revolution.

        A period-doubling (flip) chatter of an N-flute tool with uniform pitch repeats every
        two tooth periods; for N = 2 that is once per revolution, where once-per-revolution
        samples would stand still and call a flip limit cycle stable
        (docs/decisions/0017-time-domain-stability-verdict.md).
        """
        n = self.tool.n_flutes
        uniform = np.allclose(self.tool.pitches_rad, 2.0 * math.pi / n, rtol=0, atol=1e-12)
        if uniform and self.tool.runout_offset_m == 0.0 and self.steps_per_rev % n == 0:
            return self.steps_per_rev // n
        return self.steps_per_rev

    @property
    def poincare_xy_m(self) -> FloatArray:
        """Displacement samples (x, y) [m] once per :attr:`poincare_period_steps`, (n, 2)."""
        return np.array(self._poincare, dtype=float).reshape(-1, 2)

    def verdict(
        self, last_revolutions: int = 80, n_windows: int = 4, decay_threshold: float = 0.5
    ) -> StabilityVerdict:
        """Stable/unstable from the once-per-revolution samples of the last revolutions.

        Parameters
        ----------
        last_revolutions : int
            Poincaré samples evaluated (at most those available; at least 2 n_windows + 1).
        n_windows : int
            The steps |P_k − P_{k−1}| are split into this many consecutive windows and the
            envelope (largest step) of each is taken.
        decay_threshold : float
            Stable if the envelope of the last window is below this fraction of the first.

        Notes
        -----
        A stable cut converges to vibration with the period of the revolution, so the
        Poincaré samples P_k = (x, y) at φ = φ_0 + 2πk converge to a point and their steps
        decay geometrically with the dominant Floquet multiplier. Chatter (Hopf or period
        doubling) keeps them moving: the envelope grows while the motion is linear and stays
        flat on the limit cycle once flutes leave the cut. Criterion: stable iff
        envelope(last window) < ``decay_threshold`` × envelope(first window) and below half the
        RMS vibration of the last revolution, or the steps are negligible (< 1e-6 of that RMS:
        a converged periodic solution leaves steps at the round-off level of the regenerative
        surface, measured at 2e-9 to 7e-9 of the RMS).
        A decaying transient with multiplier μ per revolution is called stable only when
        μ^(n(1−1/W)) is below the threshold (n revolutions, W windows): near the boundary run
        longer
        (docs/decisions/0017-time-domain-stability-verdict.md).
        """
        per_rev = self.steps_per_rev // self.poincare_period_steps
        p = self.poincare_xy_m[-(last_revolutions * per_rev + 1) :]
        steps = np.hypot(*np.diff(p, axis=0).T)
        per = steps.size // n_windows
        if per < 2:
            raise ConfigError(
                f"simulation: verdict needs ≥ {2 * n_windows + 1} revolutions, have {p.shape[0]}"
            )
        steps = steps[steps.size - per * n_windows :]
        env = steps.reshape(n_windows, per).max(axis=1)
        last = self._last
        amp = 0.0
        if last is not None and last.size:
            amp = float(np.sqrt(np.mean(np.sum((last - last.mean(axis=0)) ** 2, axis=1))))
        spread = float(env[-1] / amp) if amp > 0 else 0.0
        decay = float(env[-1] / env[0]) if env[0] > 0 else 0.0
        if np.all(env > 0):
            slope = float(np.polyfit(np.arange(n_windows) * per, np.log(env), 1)[0])
            mult = math.exp(slope * per_rev)
        else:
            mult = 0.0
        stable = (decay < decay_threshold and spread < 0.5) or spread < _NEGLIGIBLE_STEP
        return StabilityVerdict(stable, decay, spread, mult, int(p.shape[0]) // per_rev)

    def chatter_frequency_hz(self, x_m: ArrayLike, exclude_harmonics: bool = True) -> float:
        """Largest spectral peak of a displacement record, away from spindle harmonics [Hz].

        Parameters
        ----------
        x_m : (n,) float
            Displacement record from this simulation (consecutive steps) [m].
        exclude_harmonics : bool
            Ignore bins within two bins of multiples of the spindle frequency (forced
            vibration), so that the chatter frequency is found.
        """
        x = np.asarray(x_m, dtype=float)
        x = (x - x.mean()) * np.hanning(x.size)
        spec = np.abs(np.fft.rfft(x))
        freqs = np.fft.rfftfreq(x.size, self.dt_s)
        if exclude_harmonics:
            f_rev = self.spindle_speed_rad_s / _TWO_PI
            df = freqs[1]
            near = np.abs(freqs / f_rev - np.rint(freqs / f_rev)) * f_rev <= 2 * df
            spec = np.where(near, 0.0, spec)
        k = int(np.argmax(spec[1:])) + 1
        if 1 <= k < spec.size - 1:  # parabolic interpolation of the peak
            a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
            denom = a - 2 * b + c
            off = 0.5 * (a - c) / denom if denom != 0 else 0.0
            return float((k + off) * freqs[1])
        return float(freqs[k])
