"""Problem builders: milling and turning as linear periodic delay-differential equations.

Milling (Insperger et al. 2003, benchmarks.md §1; Altintas & Budak 1995 for the force
convention)::

    z' = A_s z + B F,   r = C z,   F(t) = -w Σ_j H_j(t) [r(t) - r(t - τ_j)],

with ``w`` the axial depth of cut [m], ``r = (x, y)`` the tool-tip displacement [m], tooth
``j`` at angle ``φ_j(t) = Ω t - Σ_{k<j} p_k`` (measured clockwise from +y, tool rotating
clockwise, feed along +x), ``p_k`` the pitch angle from tooth k to tooth k+1, and::

    H_j(t) = g_j(t) [[ (K_t cos φ_j + K_r sin φ_j) sin φ_j,  (K_t cos φ_j + K_r sin φ_j) cos φ_j ],
                     [ (-K_t sin φ_j + K_r cos φ_j) sin φ_j, (-K_t sin φ_j + K_r cos φ_j) cos φ_j ]]

``g_j = 1`` while ``φ_st < φ_j mod 2π < φ_ex``. Tooth j removes the surface left by the tooth
ahead of it, so its delay is ``τ_j = p_{j-1}/Ω``. Down milling: ``φ_st = arccos(2a/D - 1)``,
``φ_ex = π``; up milling: ``φ_st = 0``, ``φ_ex = arccos(1 - 2a/D)`` (a = radial immersion).
The (x, x) entry is Insperger's ``h(t)`` and ``-H/ (K_t/2)`` is Altintas' ``A(t)``.

H_j is averaged EXACTLY over each step (closed-form integrals of sin², sin·cos, cos² over the
part of the step inside the engagement window): sampling it at a step's start or midpoint
shifts low-immersion results by up to ±7 % (benchmarks.md §1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.stability.modal import ModalModel, OrientedMode
from millsense.stability.sdm import StepMeans

FloatArray = NDArray[np.float64]
TWO_PI = 2.0 * math.pi


def immersion_angles(radial_immersion: float, diameter: float, mode: str) -> tuple[float, float]:
    """Entry and exit angles φ_st, φ_ex [rad] of a straight cut.

    Parameters
    ----------
    radial_immersion : radial depth of cut a [m], 0 < a <= D.
    diameter : tool diameter D [m].
    mode : ``"down"`` (climb) or ``"up"`` (conventional).

    Notes
    -----
    benchmarks.md §1: down φ_st = arccos(2a/D − 1), φ_ex = π; up φ_st = 0, φ_ex = arccos(1 − 2a/D).
    """
    if not 0.0 < radial_immersion <= diameter:
        raise ValueError(f"radial immersion {radial_immersion} m outside (0, D = {diameter} m]")
    ratio = radial_immersion / diameter
    if mode == "down":
        return math.acos(2.0 * ratio - 1.0), math.pi
    if mode == "up":
        return 0.0, math.acos(1.0 - 2.0 * ratio)
    raise ValueError(f"milling mode must be 'down' or 'up', got {mode!r}")


def _trig_integrals(a: FloatArray, b: FloatArray) -> FloatArray:
    """∫ (sin², sin cos, cos²) dφ from a to b, shape (..., 3)."""

    def prim(p: FloatArray) -> FloatArray:
        s2 = np.sin(2.0 * p)
        out = np.empty((*np.shape(p), 3))
        out[..., 0] = p / 2 - s2 / 4
        out[..., 1] = np.sin(p) ** 2 / 2
        out[..., 2] = p / 2 + s2 / 4
        return out

    return prim(b) - prim(a)


def windowed_trig_means(
    phi_a: FloatArray, phi_b: FloatArray, phi_st: float, phi_ex: float
) -> FloatArray:
    """Means over [φ_a, φ_b] of g(φ)·(sin², sin cos, cos²), g the engagement window.

    Parameters
    ----------
    phi_a, phi_b : step start and end angles [rad], ``0 < φ_b − φ_a < 2π``.
    phi_st, phi_ex : engagement window [rad] in [0, 2π], repeated every 2π.

    Returns
    -------
    (..., 3) means [-].
    """
    total = np.zeros((*np.shape(phi_a), 3))
    k0 = np.floor(np.min(phi_a) / TWO_PI) - 1
    k1 = np.floor(np.max(phi_b) / TWO_PI) + 1
    for k in np.arange(k0, k1 + 1):
        lo = np.maximum(phi_a, phi_st + TWO_PI * k)
        hi = np.minimum(phi_b, phi_ex + TWO_PI * k)
        hi = np.maximum(hi, lo)
        if np.any(hi > lo):  # a window no step reaches adds exact zeros
            total += _trig_integrals(lo, hi)
    return total / (phi_b - phi_a)[..., None]


def directional_from_trig(trig: FloatArray, kt: float, kr: float) -> FloatArray:
    """H (..., 2, 2) [N/m²] from the trig means (sin², sin cos, cos²) (module equation)."""
    ss, sc, cc = trig[..., 0], trig[..., 1], trig[..., 2]
    H = np.empty((*trig.shape[:-1], 2, 2))
    H[..., 0, 0] = kt * sc + kr * ss
    H[..., 0, 1] = kt * cc + kr * sc
    H[..., 1, 0] = -kt * ss + kr * sc
    H[..., 1, 1] = -kt * sc + kr * cc
    return H


@dataclass(frozen=True)
class DepthFamily:
    """A DDE whose coefficients are affine in a depth ``w``: one spindle speed of a process.

    ``A(w) = A0 - w Bd Hsum C`` and ``E_j(w) = w Bd H_j``, per step. Built by
    :func:`milling_dde` and :func:`turning_dde`; :meth:`step_means` gives the SDM input.

    Attributes
    ----------
    A0 : (n, n) structure [1/s].
    Bd : (n, d) force input of the flexible directions.
    C : (d, n) displacement output of the flexible directions.
    H : (m, J, d, d) per-step means of the directional matrices [N/m²] per delay.
    delays : (J,) [s].
    h : step [s].
    period : principal period T [s] (``m h``).
    """

    A0: FloatArray
    Bd: FloatArray
    C: FloatArray
    H: FloatArray
    delays: FloatArray
    h: float
    period: float

    def step_means(self, depth: float) -> StepMeans:
        """Step means at depth ``depth`` [m] (axial depth for milling, width for turning)."""
        Hsum = self.H.sum(axis=1)  # (m, d, d)
        A = self.A0[None] - depth * np.einsum("nd,mde,ek->mnk", self.Bd, Hsum, self.C)
        E = depth * np.einsum("nd,mjde->mjne", self.Bd, self.H)
        return StepMeans(A, E, self.C, self.delays, self.h)


def tooth_delays(pitch: Sequence[float] | FloatArray, omega: float) -> FloatArray:
    """Delay of each tooth [s]: tooth j follows tooth j−1 by pitch p_{j−1} [rad]."""
    p = np.asarray(pitch, dtype=float)
    return np.roll(p, 1) / omega


def milling_dde(
    structure: ModalModel,
    flutes: int,
    kt: float,
    kr: float,
    phi_st: float,
    phi_ex: float,
    spindle_rpm: float,
    steps_per_period: int,
    pitch: Sequence[float] | None = None,
) -> DepthFamily:
    """Regenerative milling at one spindle speed as a depth family of periodic DDEs.

    Parameters
    ----------
    structure : tool-tip modes in x and y.
    flutes : number of teeth N.
    kt, kr : tangential and radial (normal) cutting-force coefficients [N/m²].
    phi_st, phi_ex : engagement window [rad] (:func:`immersion_angles`).
    spindle_rpm : spindle speed [rev/min].
    steps_per_period : SDM steps per tooth-passing period (mean tooth period for variable
        pitch, where the DDE period is one revolution and ``N·steps_per_period`` steps are used).
    pitch : pitch angles p_j [rad] from tooth j to tooth j+1 (sum 2π); None for uniform pitch.

    Returns
    -------
    DepthFamily with one delay (uniform pitch) or one per tooth (variable pitch).
    """
    omega = spindle_rpm * TWO_PI / 60.0
    if pitch is None:
        pitch = [TWO_PI / flutes] * flutes
    p = np.asarray(pitch, dtype=float)
    if p.size != flutes or abs(p.sum() - TWO_PI) > 1e-9 or np.any(p <= 0):
        raise ValueError("pitch angles must be N positive angles summing to 2π")
    uniform = bool(np.allclose(p, TWO_PI / flutes, rtol=0, atol=1e-12))
    if uniform:
        period = TWO_PI / (flutes * omega)
        m = steps_per_period
    else:
        period = TWO_PI / omega
        m = steps_per_period * flutes
    h = period / m
    offsets = -np.concatenate([[0.0], np.cumsum(p)[:-1]])  # φ_j(0)
    t = np.arange(m) * h
    phi_a = omega * t[:, None] + offsets[None, :]  # (m, N)
    phi_b = phi_a + omega * h
    trig = windowed_trig_means(phi_a, phi_b, phi_st, phi_ex)
    Hj = directional_from_trig(trig, kt, kr)  # (m, N, 2, 2)
    dirs = list(structure.directions)
    Hj = Hj[:, :, dirs][:, :, :, dirs]
    A0, B, Cfull = structure.state_space()
    if uniform:
        H = Hj.sum(axis=1, keepdims=True)
        delays = np.array([period])
    else:
        H = Hj
        delays = tooth_delays(p, omega)
    return DepthFamily(
        A0=A0,
        Bd=np.ascontiguousarray(B[:, dirs]),
        C=np.ascontiguousarray(Cfull[dirs]),
        H=np.ascontiguousarray(H),
        delays=delays,
        h=h,
        period=period,
    )


def turning_dde(
    modes: Sequence[OrientedMode],
    kf: float,
    spindle_rpm: float,
    steps_per_period: int,
    force_angle: float = 0.0,
) -> DepthFamily:
    """Orthogonal cutting / turning with an oriented multi-mode structure.

    ``F(t) = -K_f b [u(t) - u(t - τ)]`` along the force direction, ``u`` the displacement
    normal to the cut surface, ``τ = 60/n`` one revolution; mode i receives ``F cos(θ_i − β)``
    and contributes ``cos θ_i`` of its displacement to ``u`` (see
    :func:`millsense.stability.modal.oriented_frf`). Constant coefficients: the SDM result
    converges to Tlusty's closed form.

    Parameters
    ----------
    modes : oriented modes.
    kf : cutting-force coefficient K_f [N/m²].
    spindle_rpm : [rev/min].
    steps_per_period : steps per revolution.
    force_angle : β [rad].
    """
    from millsense.stability.modal import ModalModel, Mode

    ms: list[Mode] = [om.mode for om in modes]
    A0, B, C = ModalModel(x=tuple(ms)).state_space()
    Bu = B[:, :1] * np.array([math.cos(om.angle - force_angle) for om in modes] * 2)[:, None]
    Cu = C[:1] * np.array([math.cos(om.angle) for om in modes] * 2)[None, :]
    period = 60.0 / spindle_rpm
    h = period / steps_per_period
    H = np.full((steps_per_period, 1, 1, 1), kf)
    return DepthFamily(A0, Bu, Cu, H, np.array([period]), h, period)
