"""Predictive notch filter bank: encoder interpolation errors that move with the feed, and
fixed structural modes (Yamada C10, Table 4-5).

An encoder's interpolation error is periodic in position with the signal period λ, so at feed
speed v it appears at ``f_k = k·v/λ`` (k = 1, 2, …; Yamada §2.8: λ = ℓ/512 = 9.77 µm for a
512-period rotary encoder on a 5 mm lead). Its amplitude is unpredictable but its frequency is
known (digest §5), so the force estimate is notched at those frequencies, re-tuned every sample
from the measured feed speed, plus fixed notches at structural modes the observer does not
model (the screw torsional mode, 778.5 Hz).

Each notch is the biquad ``g·(1 − 2cos ω₀ z⁻¹ + z⁻²)/(1 − 2r cos ω₀ z⁻¹ + r² z⁻²)`` with pole
radius ``r = e^{−π·B/f_s}`` (−3 dB width ≈ B Hz) and ``g`` making the DC gain 1, run in
transposed direct form II with coefficients recomputed per sample in numba (decision
docs/decisions/0072-predictive-notch-bank.md). A notch whose frequency is below ``min_hz`` or above
``max_hz`` (or 0.45 f_s) passes the signal unchanged but keeps its state, so a notch fades in and
out without a switch transient beyond the filter's own. The feed speed is the backward difference of
the motor angle times R, low-passed by a first-order filter (``speed_cutoff_hz``), inside the same
kernel; state is carried, so the output is identical whatever the chunking.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.streaming.block import Block, BlockOutput, Chunk

FloatArray = NDArray[np.float64]


def encoder_notch_frequencies(
    feed_m_s: ArrayLike, wavelength_m: float, harmonics: Sequence[int]
) -> FloatArray:
    """``f_k = k·|v|/λ`` (Hz) for each feed speed (rows) and harmonic k (columns)."""
    v = np.abs(np.atleast_1d(np.asarray(feed_m_s, dtype=float)))
    k = np.asarray(harmonics, dtype=float)
    return np.asarray(v[:, None] * k[None, :] / wavelength_m, dtype=float)


@dataclass(frozen=True)
class NotchBankSpec:
    """What to notch.

    Attributes
    ----------
    wavelength_m : encoder signal period in travel, m (ℓ/512 for Yamada's rotary encoders).
    harmonics : tracked harmonics k of ``v/λ``.
    fixed_hz : fixed notch frequencies, Hz (e.g. 778.5, the screw torsional mode).
    bandwidth_hz : −3 dB width of every notch, Hz.
    min_hz, max_hz : tracked notches outside this range pass through.
    speed_cutoff_hz : first-order low-pass of the feed speed, Hz.
    """

    wavelength_m: float
    harmonics: tuple[int, ...] = (1, 2, 3, 4)
    fixed_hz: tuple[float, ...] = ()
    bandwidth_hz: float = 20.0
    min_hz: float = 20.0
    max_hz: float = 2000.0
    speed_cutoff_hz: float = 20.0

    def __post_init__(self) -> None:
        if not self.wavelength_m > 0.0:
            raise ConfigError(f"notch bank: wavelength_m must be > 0, got {self.wavelength_m}")
        if not self.bandwidth_hz > 0.0:
            raise ConfigError(f"notch bank: bandwidth_hz must be > 0, got {self.bandwidth_hz}")
        if any(k < 1 for k in self.harmonics):
            raise ConfigError(f"notch bank: harmonics must be ≥ 1, got {self.harmonics}")


@numba.njit(cache=True)
def _notch_kernel(
    x: np.ndarray,
    pos: np.ndarray,
    harmonics: np.ndarray,
    fixed: np.ndarray,
    prm: np.ndarray,
    st: np.ndarray,
    sp: np.ndarray,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """prm = [fs, wavelength, r, min_hz, max_hz, speed_alpha]; st (nsec, 2) DF2T states;
    sp = [previous position, filtered speed, started flag]."""
    fs = prm[0]
    lam = prm[1]
    r = prm[2]
    fmin = prm[3]
    fmax = min(prm[4], 0.45 * fs)
    alpha = prm[5]
    nh = harmonics.shape[0]
    nf = fixed.shape[0]
    for k in range(x.shape[0]):
        if sp[2] == 0.0:
            sp[0] = pos[k]
            sp[2] = 1.0
        v = (pos[k] - sp[0]) * fs
        sp[0] = pos[k]
        sp[1] += alpha * (v - sp[1])
        fv = abs(sp[1]) / lam
        y = x[k]
        for j in range(nh + nf):
            if j < nh:
                f0 = harmonics[j] * fv
                active = f0 >= fmin and f0 <= fmax
            else:
                f0 = fixed[j - nh]
                active = f0 > 0.0 and f0 <= 0.45 * fs
            if active:
                c = math.cos(2.0 * math.pi * f0 / fs)
                g = (1.0 - 2.0 * r * c + r * r) / (2.0 - 2.0 * c)
                b0 = g
                b1 = -2.0 * c * g
                b2 = g
                a1 = -2.0 * r * c
                a2 = r * r
            else:
                b0 = 1.0
                b1 = 0.0
                b2 = 0.0
                a1 = 0.0
                a2 = 0.0
            yo = b0 * y + st[j, 0]
            st[j, 0] = b1 * y - a1 * yo + st[j, 1]
            st[j, 1] = b2 * y - a2 * yo
            y = yo
        out[k] = y


class NotchBank:
    """Streaming predictive notch bank (chunk-size invariant).

    Parameters
    ----------
    spec : notch frequencies and widths.
    sample_rate_hz : Hz.
    """

    def __init__(self, spec: NotchBankSpec, sample_rate_hz: float) -> None:
        self.spec = spec
        self.sample_rate_hz = float(sample_rate_hz)
        fs = self.sample_rate_hz
        self._harm = np.asarray(spec.harmonics, dtype=float)
        self._fixed = np.asarray(spec.fixed_hz, dtype=float)
        self._prm = np.array(
            [
                fs,
                spec.wavelength_m,
                math.exp(-math.pi * spec.bandwidth_hz / fs),
                spec.min_hz,
                spec.max_hz,
                1.0 - math.exp(-2.0 * math.pi * spec.speed_cutoff_hz / fs),
            ]
        )
        self.reset()

    def reset(self) -> None:
        """Forget all state."""
        self._st = np.zeros((len(self._harm) + len(self._fixed), 2))
        self._sp = np.zeros(3)

    def process(self, x: ArrayLike, position_m: ArrayLike) -> FloatArray:
        """Notch one chunk of ``x``; ``position_m`` (m of travel) gives the feed speed."""
        xa = np.ascontiguousarray(x, dtype=np.float64)
        pa = np.ascontiguousarray(position_m, dtype=np.float64)
        if xa.shape != pa.shape:
            raise ValueError(f"signal {xa.shape} and position {pa.shape} differ in length")
        out = np.empty_like(xa)
        _notch_kernel(xa, pa, self._harm, self._fixed, self._prm, self._st, self._sp, out)
        return out


class NotchBlock(Block):
    """Streaming block: predictive notch bank on a force estimate.

    Parameters
    ----------
    axis : axis name; reads ``{axis}/{source}`` (N) and ``{axis}/motor_angle`` (rad); writes
        ``{axis}/{source}_notched``.
    source : the force channel's name within the axis (e.g. ``force_medob``).
    spec : notch bank.
    transmission_m_rad : R = ℓ/2π, m/rad (motor angle → travel).
    """

    def __init__(
        self, axis: str, source: str, spec: NotchBankSpec, transmission_m_rad: float
    ) -> None:
        self.axis = axis
        self.spec = spec
        self.transmission_m_rad = transmission_m_rad
        self.name = f"notch_{axis}_{source}"
        self.inputs = (f"{axis}/{source}", f"{axis}/motor_angle")
        self._out = f"{axis}/{source}_notched"
        self._bank: NotchBank | None = None

    def output_channels(self) -> list[ChannelInfo]:
        return [
            ChannelInfo(
                self._out,
                "N",
                f"{self.inputs[0]} with predictive notches at k·v/λ (λ = "
                f"{self.spec.wavelength_m * 1e6:.3f} µm, k = {list(self.spec.harmonics)}) and "
                f"{list(self.spec.fixed_hz)} Hz (Yamada Table 4-5)",
            )
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self._bank = NotchBank(self.spec, sample_rate_hz)

    def process(self, chunk: Chunk) -> BlockOutput:
        if self._bank is None:
            raise RuntimeError(f"block {self.name}: reset() was not called")
        x = np.asarray(chunk.data[self.inputs[0]], dtype=float)
        pos = self.transmission_m_rad * np.asarray(chunk.data[self.inputs[1]], dtype=float)
        return BlockOutput({self._out: self._bank.process(x, pos)})
