"""Cutting forces from acceleration with İlme's angular-harmonic Kalman filter (seed 003).

The force of a helical end mill is the angular Fourier series of İlme Eq. 2.38, linear in the
four "temporal" coefficients q = [K_t, K_r, K_te, K_re]. Passing each tooth-passing harmonic
k·f_t through the accelerance G(f_k) gives an acceleration that is still linear in q
(Eq. 3.5), so a Kalman filter with random-walk states q and a measurement matrix H(φ_k)
rebuilt from the FRF at the tooth harmonics at every sample (Eq. 3.6–3.14) identifies q from
the acceleration. The force, DC included, is then rebuilt from q̂ with Eq. 2.38 (M11): the
acceleration carries no DC but the model structure does.

Pipeline (İlme §4.3.2, digest M9–M11):

1. reconstruction: FFT of the acceleration over a whole number of tooth periods, keep the bins
   of the first ``n_harmonics`` (20) tooth-passing orders, inverse FFT (a harmonic comb: it
   removes free vibration at the natural frequencies, noise and spindle-order content);
2. H(φ_k) from :func:`millsense.process.harmonic.measurement_matrix` with the FRF read at
   k·f_t (the measured FRF, interpolated; no modal fit, İlme M4);
3. :class:`~millsense.estimation.kalman.time_varying.TimeVaryingKalman` on q (Φ = I);
4. F̂(φ_k) = H_F(φ_k) q̂ with the force matrix (FRF = 1, DC included).

Units: the states are kept in İlme's units (N/mm² for K_t, K_r; N/mm for K_te, K_re) so that
the four have similar magnitudes and a scalar Q is meaningful (Table 3.3/4.3 give scalars);
everything else is SI (acceleration m/s², force N, angles rad).

Frame: forces are on the tool in the frame of :mod:`millsense.process.geometry` (decision
"Ilme Eq. 2.38 frame and Eq. 3.9 sign"). An accelerometer on the workpiece sees the reaction
−F; ``reaction=True`` (default) accounts for it, so the FRF passed is the accelerance of a tap
test on the workpiece (acceleration per hammer force).

Streaming (:class:`HarmonicKalmanBlock`): the reconstruction is a block operation, so the block
collects ``block_periods`` tooth periods (rounded to whole samples), reconstructs that block by
FFT, runs the filter over it and emits the results with a fixed delay of one block length
(``delay_samples``); the first block of the stream is NaN. Decision
docs/decisions/0090-ilme-reconstruction-streamed-in-whole-tooth-period-blocks.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.kalman.time_varying import TimeVaryingKalman
from millsense.process.harmonic import measurement_matrix
from millsense.streaming.block import Block, BlockOutput, Chunk

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Scale from İlme's state units (N/mm², N/mm) to SI (N/m², N/m).
STATE_SCALE = np.array([1e6, 1e6, 1e3, 1e3])

FrfSource = Callable[[FloatArray], ComplexArray] | tuple[ArrayLike, ArrayLike]

__all__ = [
    "STATE_SCALE",
    "CutSetup",
    "HarmonicKalmanBlock",
    "HarmonicKalmanResult",
    "effective_measurement_noise",
    "estimate_harmonic_kf",
    "find_angle_offset",
    "frf_at",
    "reconstruct_harmonics",
    "whole_period_length",
]


@dataclass(frozen=True)
class CutSetup:
    """Tool and cut known to the estimator (İlme Fig. 1.1, "known beforehand").

    Attributes
    ----------
    n_flutes : number of flutes N (uniform pitch).
    diameter_m : tool diameter D [m].
    helix_rad : helix angle α [rad].
    axial_depth_m : axial depth a_p [m].
    entry_rad, exit_rad : immersion θ_st, θ_ex [rad] (process.geometry convention).
    feed_per_tooth_m : feed per tooth t_x [m].
    """

    n_flutes: int
    diameter_m: float
    helix_rad: float
    axial_depth_m: float
    entry_rad: float
    exit_rad: float
    feed_per_tooth_m: float

    def __post_init__(self) -> None:
        if self.n_flutes < 1 or not (self.diameter_m > 0 and self.axial_depth_m > 0):
            raise ConfigError("harmonic KF cut: n_flutes ≥ 1, diameter_m > 0, axial_depth_m > 0")
        if not (self.feed_per_tooth_m > 0):
            raise ConfigError("harmonic KF cut: feed_per_tooth_m must be > 0")

    def geometry(self) -> dict[str, float | int]:
        """Keyword arguments of :func:`millsense.process.harmonic.harmonic_basis`."""
        return {
            "n_flutes": self.n_flutes,
            "diameter_m": self.diameter_m,
            "helix_rad": self.helix_rad,
            "axial_depth_m": self.axial_depth_m,
            "entry_rad": self.entry_rad,
            "exit_rad": self.exit_rad,
        }


def frf_at(frf: FrfSource, freq_hz: ArrayLike) -> ComplexArray:
    """The FRF at given frequencies: a callable, or measured samples interpolated linearly.

    Parameters
    ----------
    frf : callable ``f_hz → G`` or a pair ``(freq_hz, G)`` of measured samples [Hz, any unit].
    freq_hz : query frequencies [Hz].

    Raises
    ------
    InputDataError
        A query outside the measured frequency range (İlme reads the FRF only where measured).
    """
    f = np.atleast_1d(np.asarray(freq_hz, dtype=float))
    if callable(frf):
        return np.asarray(frf(f), dtype=complex)
    fm = np.asarray(frf[0], dtype=float)
    hm = np.asarray(frf[1], dtype=complex)
    if f.min() < fm[0] or f.max() > fm[-1]:
        raise InputDataError(
            f"harmonic KF: FRF measured over {fm[0]:g}-{fm[-1]:g} Hz, tooth harmonics need "
            f"{f.min():g}-{f.max():g} Hz"
        )
    return np.interp(f, fm, hm.real) + 1j * np.interp(f, fm, hm.imag)


def whole_period_length(sample_rate_hz: float, tooth_frequency_hz: float, n_periods: int) -> int:
    """Samples in ``n_periods`` tooth periods, rounded to a whole sample."""
    return max(1, round(n_periods * sample_rate_hz / tooth_frequency_hz))


def reconstruct_harmonics(
    x: ArrayLike, sample_rate_hz: float, tooth_frequency_hz: float, n_harmonics: int = 20
) -> FloatArray:
    """İlme's acceleration reconstruction: FFT, keep the first tooth harmonics, inverse FFT.

    Parameters
    ----------
    x : (n,) signal [any unit]; for exact bins it should span whole tooth periods
        (:func:`whole_period_length`).
    sample_rate_hz : sampling rate [Hz].
    tooth_frequency_hz : tooth-passing frequency f_t = N·n/60 [Hz].
    n_harmonics : orders k = 1 … n_harmonics kept (20 in İlme, "chosen empirically").

    Returns
    -------
    (n,) the signal rebuilt from the bins nearest k·f_t (DC and everything else zeroed).

    Notes
    -----
    İlme §4.3.2 step 3 and digest M9. Orders at or above the Nyquist frequency are skipped.
    """
    xa = np.asarray(x, dtype=float)
    n = xa.size
    if n < 2:
        return np.zeros(n)
    spec = np.fft.rfft(xa)
    keep = np.zeros(spec.size, dtype=bool)
    k = np.arange(1, n_harmonics + 1)
    bins = np.rint(k * tooth_frequency_hz * n / sample_rate_hz).astype(int)
    bins = bins[(bins > 0) & (bins < spec.size) & (2 * bins != n)]
    keep[bins] = True
    spec[~keep] = 0.0
    return np.fft.irfft(spec, n)


def effective_measurement_noise(z: ArrayLike, r: float, model_error: float) -> FloatArray:
    """Per-sample R of the filter: sensor noise plus a persistent, relative model error.

    Parameters
    ----------
    z : (n,) or (n, m) reconstructed acceleration of the record (or block) [m/s²].
    r : sensor-noise variance per sample [(m/s²)²] (İlme: free-state variance).
    model_error : relative rms ε of the model error of z [-].

    Returns
    -------
    (m, m) diagonal R_eff = r + n·ε²·mean(z_j²) [(m/s²)²].

    Notes
    -----
    The reconstructed acceleration differs from b_h H(φ) q by a model error e (FRF error,
    position drift, runout, cross accelerance) that repeats every revolution: averaging n
    samples does not shrink it. Treating it as white noise of variance ε² var(z) would credit
    the filter with n independent looks at it; the record is worth one, so the white-noise
    variance that gives the filter the right information is n·ε²·var(z) (a batch filter with
    Φ = I, Q = 0 then weighs the data by (Σ Hᵀ H / n)/(ε² var z), the information of one
    revolution-averaged look). Decision "İlme filter: persistent model error in R".
    """
    za = np.asarray(z, dtype=float)
    za = za.reshape(-1, 1) if za.ndim == 1 else za
    n = za.shape[0]
    return np.diag(r + n * model_error**2 * np.mean(za**2, axis=0))


@dataclass(frozen=True)
class HarmonicKalmanResult:
    """Outputs of :func:`estimate_harmonic_kf` (one row per sample used).

    Attributes
    ----------
    coefficients : (n, 4) q̂ history [N/m², N/m², N/m, N/m] (SI).
    acceleration_reconstructed : (n, m) reconstructed measurement [m/s²].
    acceleration_estimated : (n, m) H q̂ (İlme's â) [m/s²].
    force_x, force_y : (n,) force on the tool from the running q̂ [N].
    force_x_converged, force_y_converged : (n,) force from the final q̂ [N] (İlme M11).
    n_used : samples used (a whole number of tooth periods from the start).
    """

    coefficients: FloatArray
    acceleration_reconstructed: FloatArray
    acceleration_estimated: FloatArray
    force_x: FloatArray
    force_y: FloatArray
    force_x_converged: FloatArray
    force_y_converged: FloatArray
    n_used: int

    @property
    def final_coefficients(self) -> FloatArray:
        """Converged q̂ [N/m², N/m², N/m, N/m]."""
        return self.coefficients[-1].copy()


class _HarmonicModel:
    """H(φ) of the acceleration and of the force for one cut, in scaled state units."""

    def __init__(
        self,
        cut: CutSetup,
        frfs: Mapping[str, FrfSource],
        tooth_frequency_hz: float,
        n_harmonics: int,
        reaction: bool,
        n_harmonics_force: int,
    ) -> None:
        if not frfs or any(d not in ("x", "y") for d in frfs):
            raise ConfigError("harmonic KF: frfs needs keys among 'x', 'y'")
        self.cut = cut
        self.directions = tuple(sorted(frfs))
        fk = tooth_frequency_hz * np.arange(1, n_harmonics + 1)
        self.g = {d: frf_at(frfs[d], fk) for d in self.directions}
        self.sign = -1.0 if reaction else 1.0
        self.n_harmonics = n_harmonics
        self.n_harmonics_force = n_harmonics_force

    def h_meas(self, phi: FloatArray) -> FloatArray:
        rows = []
        for d in self.directions:
            h = measurement_matrix(
                phi,
                self.cut.feed_per_tooth_m,
                n_harmonics=self.n_harmonics,
                frf=self.g[d],
                **self.cut.geometry(),
            )
            rows.append(h[:, 0 if d == "x" else 1, :])
        return self.sign * np.stack(rows, axis=1) * STATE_SCALE  # (n, m, 4)

    def h_force(self, phi: FloatArray) -> FloatArray:
        h = measurement_matrix(
            phi,
            self.cut.feed_per_tooth_m,
            n_harmonics=self.n_harmonics_force,
            **self.cut.geometry(),
        )
        return h * STATE_SCALE  # (n, 2, 4)


def _check_settings(q: float, r: float, n_harmonics: int, model_error: float, who: str) -> None:
    if not (q >= 0 and r > 0 and n_harmonics >= 1):
        raise ConfigError(f"{who}: q ≥ 0, r > 0 and n_harmonics ≥ 1 are required")
    if not model_error >= 0:
        raise ConfigError(f"{who}: model_error must be ≥ 0")


def estimate_harmonic_kf(
    acceleration: Mapping[str, ArrayLike],
    spindle_angle_rad: ArrayLike,
    sample_rate_hz: float,
    spindle_speed_rpm: float,
    cut: CutSetup,
    frfs: Mapping[str, FrfSource],
    *,
    q: float = 0.1,
    r: float = 0.28,
    p0: ArrayLike = 1e6,
    x0: ArrayLike | None = None,
    n_harmonics: int = 20,
    n_harmonics_force: int = 100,
    reaction: bool = True,
    model_error: float = 0.0,
) -> HarmonicKalmanResult:
    """İlme's offline estimator over one record (§4.3.2 steps 2–5).

    Parameters
    ----------
    acceleration : {"x"|"y": (n,)} measured acceleration per direction [m/s²] (İlme uses "y").
    spindle_angle_rad : (n,) spindle angle φ_k [rad], synchronised with the acceleration
        (İlme M10; :func:`find_angle_offset` estimates a constant offset).
    sample_rate_hz : sampling rate [Hz].
    spindle_speed_rpm : nominal spindle speed [rev/min] (İlme assumption 5).
    cut : tool and cut (t_x, a_p, θ_st, θ_ex, …).
    frfs : {"x"|"y": FRF} accelerance per direction [(m/s²)/N], a callable or measured
        ``(freq_hz, G)`` samples (no modal fit, İlme M4).
    q : process noise per sample, in (N/mm²)² for K_t, K_r and (N/mm)² for K_te, K_re (one
        scalar for all states, Q·I₄; İlme Table 4.3 uses 0.10).
    r : measurement noise variance [(m/s²)²] (İlme: variance of the acceleration in free
        state, Table 4.3: 0.28).
    p0 : initial covariance in the scaled units, scalar (→ p0·I₄) or (4, 4); uninformative
        by default.
    x0 : initial q in SI [N/m², N/m², N/m, N/m] (default zeros).
    n_harmonics : tooth harmonics in the reconstruction and in H (20).
    n_harmonics_force : harmonics of the force rebuilt from q̂ (Eq. 2.38; 100 keeps Gibbs
        ripple small).
    reaction : the sensor is on the workpiece (loaded by −F); False for a sensor loaded by F.
    model_error : relative rms ε [-] of the persistent model error of the reconstructed
        acceleration (FRF error and its drift along the pass, runout, cross accelerance). It
        repeats every revolution, so it does not average out: the record is worth one
        independent look at it, and the filter uses R_eff = r + n·ε²·var(z) per sample
        (:func:`effective_measurement_noise`). 0 gives İlme's R = r. İlme reports the FRF
        gain varying by up to 25 % along the pass (§4.1); the validation uses 0.2.

    Returns
    -------
    HarmonicKalmanResult over the longest whole number of tooth periods from the start.

    Notes
    -----
    İlme Eq. 3.5 (acceleration harmonics), Eq. 3.6–3.14 (Kalman filter, Φ = I), Eq. 3.9 row y
    derived from K_4 (digest erratum 1), Eq. 2.38 for the force (DC included).

    With ``model_error`` > 0 the data move q̂ away from the prior (x0, p0) only along the
    directions whose acceleration signature is larger than the model error; where H carries
    no such information (the 4-flute half-immersion cuts: smallest singular value ~4e-4 of
    the largest) q̂ stays at the prior and the force error is the prior's. Decision
    docs/decisions/0105-ilme-filter-persistent-model-error-in-r.md.
    """
    _check_settings(q, r, n_harmonics, model_error, "harmonic KF")
    phi = np.asarray(spindle_angle_rad, dtype=float)
    f_t = cut.n_flutes * spindle_speed_rpm / 60.0
    if not f_t > 0:
        raise ConfigError("harmonic KF: spindle_speed_rpm must be > 0")
    f_rev = spindle_speed_rpm / 60.0
    n_revs = math.floor(phi.size * f_rev / sample_rate_hz)
    if n_revs < 1:
        raise InputDataError(f"harmonic KF: record shorter than one revolution ({phi.size})")
    n = min(whole_period_length(sample_rate_hz, f_rev, n_revs), phi.size)
    model = _HarmonicModel(cut, frfs, f_t, n_harmonics, reaction, n_harmonics_force)
    z = np.column_stack(
        [
            reconstruct_harmonics(
                np.asarray(acceleration[d], dtype=float)[:n], sample_rate_hz, f_t, n_harmonics
            )
            for d in model.directions
        ]
    )
    x0s = None if x0 is None else np.asarray(x0, dtype=float) / STATE_SCALE
    r_eff = effective_measurement_noise(z, r, model_error)
    kf = TimeVaryingKalman(4, q, r_eff, x0=x0s, p0=p0, n_measurements=len(model.directions))
    out = kf.process(z, model.h_meas(phi[:n]))
    hf = model.h_force(phi[:n])
    f_run = np.einsum("nij,nj->ni", hf, out.x)
    f_conv = hf @ out.x[-1]
    return HarmonicKalmanResult(
        coefficients=out.x * STATE_SCALE,
        acceleration_reconstructed=z,
        acceleration_estimated=out.z_est,
        force_x=f_run[:, 0],
        force_y=f_run[:, 1],
        force_x_converged=f_conv[:, 0],
        force_y_converged=f_conv[:, 1],
        n_used=n,
    )


def find_angle_offset(
    acceleration: Mapping[str, ArrayLike],
    spindle_angle_rad: ArrayLike,
    sample_rate_hz: float,
    spindle_speed_rpm: float,
    cut: CutSetup,
    frfs: Mapping[str, FrfSource],
    *,
    n_harmonics: int = 20,
    n_grid: int = 180,
    reaction: bool = True,
) -> float:
    """Constant spindle-angle offset φ_0 [rad] that best explains the acceleration.

    İlme tuned φ_0 by hand from dynamometer landmarks (§4.3.1, digest M10). Here (an addition,
    digest §8): for offsets on a grid over one tooth pitch 2π/N the reconstructed acceleration
    is fitted by least squares in q (it is linear in q) and the offset with the smallest
    residual wins, refined by a parabola through the three best grid points. The record must
    span whole tooth periods for an exact reconstruction (it is trimmed like
    :func:`estimate_harmonic_kf`). Add the result to the angle channel.
    """
    phi = np.asarray(spindle_angle_rad, dtype=float)
    f_t = cut.n_flutes * spindle_speed_rpm / 60.0
    f_rev = spindle_speed_rpm / 60.0
    n_revs = math.floor(phi.size * f_rev / sample_rate_hz)
    if n_revs < 1:
        raise InputDataError("angle offset: record shorter than one revolution")
    n = min(whole_period_length(sample_rate_hz, f_rev, n_revs), phi.size)
    model = _HarmonicModel(cut, frfs, f_t, n_harmonics, reaction, 1)
    z = np.concatenate(
        [
            reconstruct_harmonics(
                np.asarray(acceleration[d], dtype=float)[:n], sample_rate_hz, f_t, n_harmonics
            )
            for d in model.directions
        ]
    )
    pitch = 2.0 * math.pi / cut.n_flutes
    grid = np.arange(n_grid) * pitch / n_grid
    res = np.empty(n_grid)
    for i, d0 in enumerate(grid):
        h = model.h_meas(phi[:n] + d0)  # (n, m, 4)
        a = np.concatenate([h[:, j, :] for j in range(h.shape[1])])
        sol, *_ = np.linalg.lstsq(a, z, rcond=None)
        res[i] = float(np.sum((z - a @ sol) ** 2))
    i0 = int(np.argmin(res))
    rm, r0, rp = res[(i0 - 1) % n_grid], res[i0], res[(i0 + 1) % n_grid]
    den = rm - 2.0 * r0 + rp
    frac = 0.5 * (rm - rp) / den if den > 0 else 0.0
    return float(((i0 + frac) * pitch / n_grid) % pitch)


class HarmonicKalmanBlock(Block):
    """Streaming İlme estimator: block reconstruction, time-varying Kalman filter, force.

    Parameters
    ----------
    name : block name.
    acceleration_channels : {"x"|"y": channel} measured acceleration channels [m/s²].
    angle_channel : spindle angle channel [rad] (encoder, synchronised).
    spindle_speed_rpm : nominal spindle speed [rev/min] (sets f_t and the block length).
    cut, frfs, q, r, p0, x0, n_harmonics, n_harmonics_force, reaction, model_error :
        as in :func:`estimate_harmonic_kf`; with ``model_error`` each block is one independent
        look at the model error (R_eff from the block's length and variance), so over many
        blocks the data gain weight: the FRF changes along the pass, so the error of
        successive blocks is not the same one.
    block_periods : tooth periods per reconstruction block.
    prefix : prefix of the output channel names.

    Notes
    -----
    Outputs ``{prefix}fx``, ``{prefix}fy`` [N] (force on the tool from the running q̂) and
    ``{prefix}ktc``, ``{prefix}krc`` [N/m²], ``{prefix}kte``, ``{prefix}kre`` [N/m]. Output
    sample k belongs to input sample k − ``delay_samples`` (one block); the first block is
    NaN. The filter state carries across blocks, so a stream cut into blocks gives the offline
    result on each block (reconstructed block by block).
    """

    def __init__(
        self,
        name: str,
        acceleration_channels: Mapping[str, str],
        angle_channel: str,
        spindle_speed_rpm: float,
        cut: CutSetup,
        frfs: Mapping[str, FrfSource],
        *,
        q: float = 0.1,
        r: float = 0.28,
        p0: ArrayLike = 1e6,
        x0: ArrayLike | None = None,
        n_harmonics: int = 20,
        n_harmonics_force: int = 100,
        reaction: bool = True,
        block_periods: int = 16,
        prefix: str = "ilme_",
        model_error: float = 0.0,
    ) -> None:
        _check_settings(q, r, n_harmonics, model_error, f"block {name}")
        self.model_error = float(model_error)
        if set(acceleration_channels) != set(frfs):
            raise ConfigError(f"block {name}: acceleration channels and FRFs name other axes")
        if block_periods < 1:
            raise ConfigError(f"block {name}: block_periods must be ≥ 1")
        self.name = name
        self.cut = cut
        self.f_t = cut.n_flutes * spindle_speed_rpm / 60.0
        if not self.f_t > 0:
            raise ConfigError(f"block {name}: spindle_speed_rpm must be > 0")
        self._model = _HarmonicModel(cut, frfs, self.f_t, n_harmonics, reaction, n_harmonics_force)
        self._acc = {d: acceleration_channels[d] for d in self._model.directions}
        self.inputs = (*self._acc.values(), angle_channel)
        self._angle = angle_channel
        self.block_periods = block_periods
        self._kf_args = (q, r, p0, None if x0 is None else np.asarray(x0, float) / STATE_SCALE)
        self._r = float(r)
        self.n_harmonics = n_harmonics
        self.prefix = prefix
        self._names = [f"{prefix}{s}" for s in ("fx", "fy", "ktc", "krc", "kte", "kre")]
        self.block_length = 0
        self.sample_rate_hz = 0.0

    @property
    def delay_samples(self) -> int:
        """Output delay [samples]: one reconstruction block (set by :meth:`reset`)."""
        return self.block_length

    def output_channels(self) -> list[ChannelInfo]:
        units = ["N", "N", "N/m^2", "N/m^2", "N/m", "N/m"]
        return [ChannelInfo(n, u) for n, u in zip(self._names, units, strict=True)]

    def reset(self, sample_rate_hz: float) -> None:
        self.sample_rate_hz = float(sample_rate_hz)
        self.block_length = whole_period_length(sample_rate_hz, self.f_t, self.block_periods)
        q, r, p0, x0 = self._kf_args
        self._kf = TimeVaryingKalman(
            4, q, r, x0=x0, p0=p0, n_measurements=len(self._model.directions)
        )
        m = len(self._model.directions)
        self._pending = np.zeros((0, m + 1))
        self._ready = np.full((self.block_length, 6), np.nan)

    def _run_block(self, blk: FloatArray) -> FloatArray:
        phi = blk[:, -1]
        z = np.column_stack(
            [
                reconstruct_harmonics(blk[:, j], self.sample_rate_hz, self.f_t, self.n_harmonics)
                for j in range(blk.shape[1] - 1)
            ]
        )
        self._kf.r = effective_measurement_noise(z, self._r, self.model_error)
        out = self._kf.process(z, self._model.h_meas(phi))
        f = np.einsum("nij,nj->ni", self._model.h_force(phi), out.x)
        return np.column_stack([f, out.x * STATE_SCALE])

    def process(self, chunk: Chunk) -> BlockOutput:
        cols = [np.asarray(chunk.data[c], dtype=float) for c in self.inputs]
        n = len(cols[0])
        self._pending = np.vstack([self._pending, np.column_stack(cols)])
        done = []
        while self._pending.shape[0] >= self.block_length:
            done.append(self._run_block(self._pending[: self.block_length]))
            self._pending = self._pending[self.block_length :]
        if done:
            self._ready = np.vstack([self._ready, *done])
        out, self._ready = self._ready[:n], self._ready[n:]
        return BlockOutput({name: out[:, i].copy() for i, name in enumerate(self._names)})
