"""Modal structures: multi-mode frequency response functions in x and y, oriented FRFs.

A mode is kept in the residue form of Aslan Eq. 3.13::

    Phi(s) = (alpha + beta s) / (s^2 + 2 zeta omega s + omega^2),

which covers the usual stiffness form (``alpha = omega^2 / k = 1/m``, ``beta = 0``) and fitted
residues with a velocity term. A :class:`ModalModel` holds the modes of the tool tip in x and
in y (uncoupled directions; an empty direction is rigid) and gives their FRFs, their modal
mass/damping/stiffness matrices and a state-space realisation for the delay-equation builders
(ZOA, SDM, and the time-domain simulator).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class Mode:
    """One structural mode in residue form (Aslan Eq. 3.13).

    Attributes
    ----------
    omega : natural angular frequency ω [rad/s].
    zeta : damping ratio ζ [-].
    alpha : residue α [m/(N s²)] (= 1/m for a mass-normalised mode).
    beta : velocity residue β [m/(N s)] (0 for a mode given by stiffness).
    """

    omega: float
    zeta: float
    alpha: float
    beta: float = 0.0

    def __post_init__(self) -> None:
        if not (self.omega > 0 and math.isfinite(self.omega)):
            raise ValueError(f"mode natural frequency must be positive, got {self.omega} rad/s")
        if not (0.0 <= self.zeta < 1.0):
            raise ValueError(f"mode damping ratio must be in [0, 1), got {self.zeta}")

    @classmethod
    def from_stiffness(
        cls, natural_frequency_hz: float, damping_ratio: float, stiffness_n_m: float
    ) -> Mode:
        """Mode from natural frequency [Hz], damping ratio [-] and modal stiffness [N/m]."""
        if not stiffness_n_m > 0:
            raise ValueError(f"modal stiffness must be positive, got {stiffness_n_m} N/m")
        w = 2.0 * math.pi * natural_frequency_hz
        return cls(w, damping_ratio, w * w / stiffness_n_m, 0.0)

    @classmethod
    def from_residues(
        cls, natural_frequency_hz: float, damping_ratio: float, alpha: float, beta: float = 0.0
    ) -> Mode:
        """Mode from natural frequency [Hz], damping ratio [-] and residues α, β (Eq. 3.13)."""
        return cls(2.0 * math.pi * natural_frequency_hz, damping_ratio, alpha, beta)

    @property
    def natural_frequency_hz(self) -> float:
        return self.omega / (2.0 * math.pi)

    @property
    def stiffness(self) -> float:
        """Static stiffness ω²/α [N/m] (the modal stiffness when β = 0)."""
        return self.omega**2 / self.alpha

    @property
    def mass(self) -> float:
        """Modal mass 1/α [kg] (meaningful when β = 0)."""
        return 1.0 / self.alpha

    def frf(self, freq_hz: ArrayLike) -> ComplexArray:
        """Receptance Φ(iω) [m/N] at frequencies ``freq_hz`` [Hz]."""
        s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
        return (self.alpha + self.beta * s) / (
            s * s + 2 * self.zeta * self.omega * s + self.omega**2
        )


def frf_sum(modes: Sequence[Mode], freq_hz: ArrayLike) -> ComplexArray:
    """Sum of the receptances of ``modes`` at ``freq_hz`` [Hz]; zero for a rigid direction."""
    f = np.asarray(freq_hz, dtype=float)
    out = np.zeros(f.shape, dtype=complex)
    for md in modes:
        out = out + md.frf(f)
    return out


@dataclass(frozen=True)
class ModalModel:
    """Tool-tip structure: uncoupled modes in x (feed) and y (normal to feed).

    Attributes
    ----------
    x, y : modes of each direction; an empty tuple is a rigid direction.
    """

    x: tuple[Mode, ...] = field(default_factory=tuple)
    y: tuple[Mode, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not self.x and not self.y:
            raise ValueError("a modal model needs at least one mode")

    @property
    def modes(self) -> tuple[Mode, ...]:
        """All modes, x first."""
        return (*self.x, *self.y)

    @property
    def directions(self) -> tuple[int, ...]:
        """Indices of the flexible directions (0 = x, 1 = y)."""
        return tuple(d for d, ms in enumerate((self.x, self.y)) if ms)

    def frf(self, freq_hz: ArrayLike) -> ComplexArray:
        """FRF matrix (..., 2, 2) [m/N]: diagonal Φ_xx, Φ_yy (no cross terms)."""
        f = np.asarray(freq_hz, dtype=float)
        out = np.zeros((*f.shape, 2, 2), dtype=complex)
        out[..., 0, 0] = frf_sum(self.x, f)
        out[..., 1, 1] = frf_sum(self.y, f)
        return out

    def mass_damping_stiffness(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Diagonal modal mass [kg], damping [N s/m] and stiffness [N/m] matrices.

        Only for modes given by stiffness (β = 0); modes with a velocity residue have no
        mass/stiffness form, use :meth:`state_space` instead.
        """
        if any(md.beta != 0.0 for md in self.modes):
            raise ValueError("modes with a velocity residue beta have no M, C, K form")
        mass = np.array([md.mass for md in self.modes])
        k = np.array([md.stiffness for md in self.modes])
        c = np.array([2 * md.zeta * md.omega * md.mass for md in self.modes])
        return np.diag(mass), np.diag(c), np.diag(k)

    def mode_direction_matrix(self) -> FloatArray:
        """S (2, n_modes): row d has ones at the modes of direction d (x = 0, y = 1)."""
        S = np.zeros((2, len(self.modes)))
        S[0, : len(self.x)] = 1.0
        S[1, len(self.x) :] = 1.0
        return S

    def state_space(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """First-order realisation ``z' = A z + B F``, ``r = C z`` with r = (x, y) [m], F [N].

        Modal coordinates ``q_k'' + 2 ζ_k ω_k q_k' + ω_k² q_k = F_d(k)`` with output
        ``r_d = Σ_k (α_k q_k + β_k q_k')`` over the modes of direction ``d`` realise Eq. 3.13
        exactly. The state is balanced, ``z = (ω_1 q_1..ω_M q_M, q'_1..q'_M)``, so that
        ``A = [[0, Ω], [−Ω, −2ZΩ]]`` has entries of order ω rather than ω² (the matrix
        exponentials of the semi-discretisation then need few squarings).
        Returns A (2M, 2M) [1/s], B (2M, 2) [s/(kg·s)], C (2, 2M).
        """
        M = len(self.modes)
        w = np.array([md.omega for md in self.modes])
        z = np.array([md.zeta for md in self.modes])
        al = np.array([md.alpha for md in self.modes])
        be = np.array([md.beta for md in self.modes])
        S = self.mode_direction_matrix()
        A = np.zeros((2 * M, 2 * M))
        A[:M, M:] = np.diag(w)
        A[M:, :M] = -np.diag(w)
        A[M:, M:] = -np.diag(2 * z * w)
        B = np.zeros((2 * M, 2))
        B[M:, :] = S.T
        C = np.zeros((2, 2 * M))
        C[:, :M] = S * (al / w)
        C[:, M:] = S * be
        return A, B, C


@dataclass(frozen=True)
class OrientedMode:
    """A mode of a turning/orthogonal-cutting structure, inclined to the cut.

    Attributes
    ----------
    mode : the structural mode.
    angle : θ [rad], angle between the mode direction and the normal of the cut surface
        (the direction of the chip-thickness change).
    """

    mode: Mode
    angle: float


def oriented_frf(
    modes: Sequence[OrientedMode], freq_hz: ArrayLike, force_angle: float = 0.0
) -> ComplexArray:
    """Oriented FRF of orthogonal cutting / turning [m/N].

    Parameters
    ----------
    modes : modes with their inclination θ_i [rad] to the chip-thickness direction.
    freq_hz : frequencies [Hz].
    force_angle : β [rad], angle between the resultant cutting force and the chip-thickness
        direction (0: force along the normal).

    Notes
    -----
    ``Φ = Σ_i cos(θ_i) cos(θ_i − β) Φ_i(iω)``: the force projected on mode i is
    ``F cos(θ_i − β)``, its displacement projected back on the chip-thickness direction is
    multiplied by ``cos θ_i`` (Tlusty's directional factor). With β = 0 this is
    ``Σ cos² θ_i Φ_i`` as in benchmarks.md §3.
    """
    f = np.asarray(freq_hz, dtype=float)
    out = np.zeros(f.shape, dtype=complex)
    for om in modes:
        u = math.cos(om.angle) * math.cos(om.angle - force_angle)
        out = out + u * om.mode.frf(f)
    return out
