"""Modal transfer functions as well-conditioned real state spaces in 2×2 blocks.

A sum of modes in the residue form of Aslan Eq. 3.13,
``Φ(s) = D + Σ_k (α_k + β_k·s)/(s² + 2ζ_k·ω_k·s + ω_k²)``, is realised mode by mode, each mode
a real 2×2 block; nothing is multiplied out into the polynomial of Eq. 3.14 or the companion
form of Appendix A, whose coefficients span ten orders of magnitude for 12–24 states (the
thesis needed power-of-two scalings to make it usable).

Per mode with ζ < 1 (poles σ ± jω_d, σ = −ζω, ω_d = ω√(1−ζ²)) the block is the real Jordan form
``A_k = [[σ, ω_d], [−ω_d, σ]]``, ``B_k = [b, 0]``, ``C_k = [β/b, −(α + σβ)/(ω_d·b)]`` — this gives
``C_k(sI − A_k)⁻¹B_k = ((s − σ)β + α + σβ)/((s − σ)² + ω_d²)`` = the mode. The free scale b is
chosen so that ‖B_k‖ = ‖C_k‖ (an input–output balanced block). A_k is normal, so each block's
eigenvector matrix is unitary and the realisation's condition number is 1 block by block.
Overdamped modes (ζ > 1) become two real first-order states, ζ = 1 a scaled Jordan block.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from millsense.core.config import DisturbanceModesConfig


@dataclass(frozen=True)
class ModalStateSpace:
    """Block-diagonal real state space of a sum of modes.

    Attributes
    ----------
    a : (m, 2, 2) block dynamics matrices, 1/s.
    b : (m, 2) input vectors.
    c : (m, 2) output vectors.
    d : direct feed-through (output units per input unit).
    frequency_hz, damping_ratio, alpha, beta : the modes as given (ζ a fraction; α in 1/s², β
        in 1/s for a dimensionless Φ).
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: float
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray

    @classmethod
    def from_modes(
        cls,
        frequency_hz: Sequence[float] | np.ndarray,
        damping_ratio: Sequence[float] | np.ndarray,
        alpha: Sequence[float] | np.ndarray,
        beta: Sequence[float] | np.ndarray,
        d: float = 0.0,
    ) -> ModalStateSpace:
        """Realise ``D + Σ (α + β s)/(s² + 2ζω s + ω²)`` (Aslan Eq. 3.13; ω = 2π·f).

        Parameters
        ----------
        frequency_hz : natural frequencies f_k, Hz (> 0).
        damping_ratio : ζ_k as fractions (≥ 0), not percent.
        alpha, beta : residue coefficients α_k, β_k.
        d : feed-through.
        """
        f = np.asarray(frequency_hz, dtype=float)
        z = np.asarray(damping_ratio, dtype=float)
        al = np.asarray(alpha, dtype=float)
        be = np.asarray(beta, dtype=float)
        if not (f.shape == z.shape == al.shape == be.shape) or f.ndim != 1:
            raise ValueError("modes: frequency, damping, alpha and beta must be equal-length 1-D")
        if np.any(f <= 0) or np.any(z < 0):
            raise ValueError("modes: frequencies must be > 0 and damping ratios >= 0")
        m = f.size
        a = np.zeros((m, 2, 2))
        b = np.zeros((m, 2))
        c = np.zeros((m, 2))
        for k in range(m):
            a[k], b[k], c[k] = _block(2.0 * math.pi * f[k], z[k], al[k], be[k])
        return cls(a, b, c, float(d), f, z, al, be)

    @classmethod
    def from_config(cls, cfg: DisturbanceModesConfig) -> ModalStateSpace:
        return cls.from_modes(
            cfg.natural_frequency_hz, cfg.damping_ratio, cfg.alpha, cfg.beta, cfg.feedthrough
        )

    def frequency_scaled(self, scale: float) -> ModalStateSpace:
        """The same modes on a scaled frequency axis, ``Φ(s/λ)`` with λ = ``scale`` (> 0).

        Frequencies × λ, α × λ², β × λ; damping ratios, static gains α/ω² and the
        feed-through unchanged (position-dependent modes, decision "Position-dependent
        disturbance modes").
        """
        lam = float(scale)
        if not lam > 0:
            raise ValueError(f"modes: frequency scale must be > 0, got {lam:g}")
        return ModalStateSpace.from_modes(
            self.frequency_hz * lam,
            self.damping_ratio,
            self.alpha * lam**2,
            self.beta * lam,
            self.d,
        )

    @property
    def n_states(self) -> int:
        return 2 * self.a.shape[0]

    def frf(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Complex frequency response from the state space, block by block (vectorised)."""
        s = 2j * math.pi * np.asarray(frequency_hz, dtype=float)
        h = np.full(s.shape, self.d, dtype=complex)
        for k in range(self.a.shape[0]):
            a = self.a[k]
            # (sI − A)⁻¹ of a 2×2 block in closed form
            p, q, r, t = s - a[0, 0], -a[0, 1], -a[1, 0], s - a[1, 1]
            det = p * t - q * r
            x0 = (t * self.b[k, 0] - q * self.b[k, 1]) / det
            x1 = (-r * self.b[k, 0] + p * self.b[k, 1]) / det
            h += self.c[k, 0] * x0 + self.c[k, 1] * x1
        return h

    def frf_modal(self, frequency_hz: np.ndarray) -> np.ndarray:
        """The same response evaluated directly from Eq. 3.13 (reference for the realisation)."""
        s = 2j * math.pi * np.asarray(frequency_hz, dtype=float)
        w = 2.0 * math.pi * self.frequency_hz
        h = np.full(s.shape, self.d, dtype=complex)
        for wk, zk, ak, bk in zip(w, self.damping_ratio, self.alpha, self.beta, strict=True):
            h += (ak + bk * s) / (s * s + 2.0 * zk * wk * s + wk * wk)
        return h

    def static_gain(self) -> float:
        """Φ(0) = D + Σ α_k/ω_k² (Aslan's printed modes give 0.49–1.02, not 1; see digest P5)."""
        w = 2.0 * math.pi * self.frequency_hz
        return float(self.d + np.sum(self.alpha / w**2))

    def dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(A, B, C, D) as full matrices (n×n, n, n, scalar), block-diagonal A."""
        n = self.n_states
        big = np.zeros((n, n))
        for k in range(self.a.shape[0]):
            big[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = self.a[k]
        return big, self.b.reshape(-1), self.c.reshape(-1), self.d

    def discretise(self, step_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact zero-order-hold blocks for a step: (Ad (m,2,2), Bd (m,2))."""
        m = self.a.shape[0]
        ad = np.zeros((m, 2, 2))
        bd = np.zeros((m, 2))
        for k in range(m):
            aug = np.zeros((3, 3))
            aug[:2, :2] = self.a[k] * step_s
            aug[:2, 2] = self.b[k] * step_s
            e = scipy.linalg.expm(aug)
            ad[k] = e[:2, :2]
            bd[k] = e[:2, 2]
        return ad, bd


def _block(w: float, zeta: float, alpha: float, beta: float) -> tuple[np.ndarray, ...]:
    """One mode (α + βs)/(s² + 2ζωs + ω²) as a balanced real 2×2 block (A, B, C)."""
    if zeta < 1.0:
        sig = -zeta * w
        wd = w * math.sqrt(1.0 - zeta * zeta)
        c1 = beta
        c2 = -(alpha + sig * beta) / wd
        g = math.hypot(c1, c2)
        bscale = math.sqrt(g) if g > 0.0 else 1.0
        a = np.array([[sig, wd], [-wd, sig]])
        return a, np.array([bscale, 0.0]), np.array([c1 / bscale, c2 / bscale])
    if zeta > 1.0:
        root = w * math.sqrt(zeta * zeta - 1.0)
        p1, p2 = -zeta * w + root, -zeta * w - root
        r1 = (alpha + beta * p1) / (p1 - p2)
        r2 = (alpha + beta * p2) / (p2 - p1)
        s1 = math.sqrt(abs(r1)) or 1.0
        s2 = math.sqrt(abs(r2)) or 1.0
        return np.diag([p1, p2]), np.array([s1, s2]), np.array([r1 / s1, r2 / s2])
    # critically damped: (α + βs)/(s + ω)² = β/(s + ω) + (α − βω)/(s + ω)²; Jordan block with
    # its coupling scaled to ω so that both states carry comparable magnitudes
    p = -w
    a = np.array([[p, w], [0.0, p]])
    # x1 = w/(s−p)² u·b, x2 = 1/(s−p) u·b
    bscale = 1.0
    return a, np.array([0.0, bscale]), np.array([(alpha + beta * p) / w, beta])
