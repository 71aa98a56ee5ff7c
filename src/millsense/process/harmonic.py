"""Angular-harmonic milling force model of Ilme (Eq. 2.38) and its measurement matrix.

The force of a flat helical end mill with uniform pitch, no runout and one immersion interval
[θ_st, θ_ex] is written as a Fourier series in the spindle angle that holds only the
tooth-passing orders k N and is linear in q = [K_tc, K_rc, K_te, K_re] (Zheng, Liang &
Melkote; edge terms added by Ilme). Forces returned here are on the tool in the frame of
:mod:`millsense.process.geometry` (Ilme's printed f_x is −F_x of that frame, f_y = F_y; the
thesis's sign for x follows its own projection Eq. 2.5).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import ConfigError
from millsense.process.coefficients import CuttingCoefficients

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def window_fourier(
    entry_rad: float, exit_rad: float, orders: NDArray[np.int64]
) -> tuple[FloatArray, FloatArray]:
    """Fourier coefficients a_m, b_m of the engagement window (Ilme Eq. 2.15).

    a_0 = (θ_2 − θ_1)/π, a_m = (sin mθ_2 − sin mθ_1)/(mπ), b_m = (cos mθ_1 − cos mθ_2)/(mπ),
    extended to negative orders by a_{−m} = a_m, b_{−m} = −b_m, b_0 = 0.
    """
    m = np.asarray(orders, dtype=float)
    am = np.abs(m)
    safe = np.where(am == 0, 1.0, am)
    a = np.where(
        am == 0,
        (exit_rad - entry_rad) / math.pi,
        (np.sin(am * exit_rad) - np.sin(am * entry_rad)) / (safe * math.pi),
    )
    b = np.where(am == 0, 0.0, (np.cos(am * entry_rad) - np.cos(am * exit_rad)) / (safe * math.pi))
    return a, np.sign(m) * b


def harmonic_basis(
    spindle_angle_rad: ArrayLike,
    *,
    n_flutes: int,
    diameter_m: float,
    helix_rad: float,
    axial_depth_m: float,
    entry_rad: float,
    exit_rad: float,
    n_harmonics: int = 100,
    frf: ArrayLike | None = None,
) -> FloatArray:
    """The four basis functions b_h P_i(φ) of Ilme Eq. 2.38 (t_x taken out of P_1, P_2).

    Parameters
    ----------
    spindle_angle_rad : (n,) float
        Spindle angle φ [rad].
    n_flutes : int
        Number of flutes N (uniform pitch).
    diameter_m : float
        Tool diameter D = 2R [m].
    helix_rad : float
        Helix angle α [rad] (0 allowed: the straight-flute limit is taken).
    axial_depth_m : float
        Axial depth a_p [m].
    entry_rad, exit_rad : float
        Immersion interval θ_st, θ_ex [rad].
    n_harmonics : int
        Number q of tooth-passing harmonics kept.
    frf : (q,) complex, optional
        Transfer function G(f_k) at the harmonics k = 1 … q (Ilme Eq. 3.5): each harmonic is
        scaled by |G| and shifted by ∠G, and the DC term is dropped. ``None`` gives the force.

    Returns
    -------
    (n, 4) float
        Columns b_h·P_1 … b_h·P_4 [m] so that, in Ilme's frame,
        f_x = K_t t_x P_1 + K_r t_x P_2 + K_te P_3 + K_re P_4 (times b_h).

    Notes
    -----
    b_h = R/tan α, β_0 = a_p tan α / R, so b_h N β_0 = N a_p and
    b_h sin(kNβ_0/2) = a_p (kN/2) sinc(kNβ_0/2) (finite as α → 0).
    D = [b_2/4, (a_0 − a_2)/4, a_1/2, b_1/2],
    S_k = [(a_{kN−2} − a_{kN+2})/(2k), (2b_{kN} − b_{kN−2} − b_{kN+2})/(2k),
           (b_{kN−1} + b_{kN+1})/k, (a_{kN−1} − a_{kN+1})/k],
    C_k = [(b_{kN+2} − b_{kN−2})/(2k), (2a_{kN} − a_{kN−2} − a_{kN+2})/(2k),
           (a_{kN+1} + a_{kN−1})/k, (b_{kN+1} − b_{kN−1})/k].
    """
    if n_flutes < 1 or n_harmonics < 0:
        raise ConfigError("harmonic model: n_flutes ≥ 1 and n_harmonics ≥ 0 are required")
    phi = np.atleast_1d(np.asarray(spindle_angle_rad, dtype=float))
    n = n_flutes
    r = 0.5 * diameter_m
    beta0 = axial_depth_m * math.tan(helix_rad) / r
    k = np.arange(1, n_harmonics + 1)
    kn = k * n
    ak, bk = {}, {}
    for off in (-2, -1, 0, 1, 2):
        ak[off], bk[off] = window_fourier(entry_rad, exit_rad, kn + off)
    a0, _ = window_fourier(entry_rad, exit_rad, np.array([0]))
    a1, b1 = window_fourier(entry_rad, exit_rad, np.array([1]))
    a2, b2 = window_fourier(entry_rad, exit_rad, np.array([2]))
    dc = np.array([b2[0] / 4, (a0[0] - a2[0]) / 4, a1[0] / 2, b1[0] / 2]) * n * axial_depth_m
    s = np.stack(
        [
            (ak[-2] - ak[2]) / (2 * k),
            (2 * bk[0] - bk[-2] - bk[2]) / (2 * k),
            (bk[-1] + bk[1]) / k,
            (ak[-1] - ak[1]) / k,
        ]
    )  # (4, q)
    c = np.stack(
        [
            (bk[2] - bk[-2]) / (2 * k),
            (2 * ak[0] - ak[-2] - ak[2]) / (2 * k),
            (ak[1] + ak[-1]) / k,
            (bk[1] - bk[-1]) / k,
        ]
    )
    x = kn * beta0 / 2
    amp = axial_depth_m * (kn / 2.0) * np.sinc(x / math.pi)  # = b_h sin(kNβ0/2)
    arg = kn[None, :] * (phi[:, None] - beta0 / 2)  # (n, q)
    if frf is None:
        out = np.tile(dc, (phi.size, 1))
        gain = np.ones(n_harmonics)
        phase = np.zeros(n_harmonics)
    else:
        g = np.asarray(frf, dtype=complex)
        if g.shape != (n_harmonics,):
            raise ConfigError(f"harmonic model: frf needs {n_harmonics} values, got {g.shape}")
        out = np.zeros((phi.size, 4))
        gain = np.abs(g)
        phase = np.angle(g)
    arg = arg + phase[None, :]
    w = (amp * gain)[None, :]
    out = out + (np.sin(arg) * w) @ s.T + (np.cos(arg) * w) @ c.T
    return out


def measurement_matrix(
    spindle_angle_rad: ArrayLike,
    feed_per_tooth_m: float,
    **kwargs: object,
) -> FloatArray:
    """Rows H(φ) with [F_x, F_y] = H q, q = [K_tc, K_rc, K_te, K_re] (Ilme Eq. 3.9, corrected).

    Parameters
    ----------
    spindle_angle_rad : (n,) float
        Spindle angle [rad].
    feed_per_tooth_m : float
        Feed per tooth t_x [m].
    **kwargs
        The geometry and ``frf`` arguments of :func:`harmonic_basis`.

    Returns
    -------
    (n, 2, 4) float
        Row 0 gives F_x, row 1 gives F_y on the tool (or the response through ``frf``).

    Notes
    -----
    Derived from the coefficient matrix K_4 of Eq. 2.38 (seed 003 digest §6, erratum 1): in
    Ilme's frame row x = [t P_1, t P_2, P_3, P_4] and row y = [t P_2, −t P_1, P_4, −P_3]
    (the printed Eq. 3.9 row y has the opposite sign). Our F_x = −f_x(Ilme), F_y = f_y(Ilme).
    """
    p = harmonic_basis(spindle_angle_rad, **kwargs)  # type: ignore[arg-type]
    t = float(feed_per_tooth_m)
    h = np.empty((p.shape[0], 2, 4))
    h[:, 0, :] = -np.column_stack([t * p[:, 0], t * p[:, 1], p[:, 2], p[:, 3]])
    h[:, 1, :] = np.column_stack([t * p[:, 1], -t * p[:, 0], p[:, 3], -p[:, 2]])
    return h


def harmonic_forces(
    spindle_angle_rad: ArrayLike,
    coeffs: CuttingCoefficients,
    feed_per_tooth_m: float,
    *,
    n_flutes: int,
    diameter_m: float,
    helix_rad: float,
    axial_depth_m: float,
    entry_rad: float,
    exit_rad: float,
    n_harmonics: int = 100,
) -> tuple[FloatArray, FloatArray]:
    """F_x, F_y on the tool [N] from Ilme Eq. 2.38 (K_ac, K_ae are not part of the model).

    See :func:`harmonic_basis` for the parameters and :func:`measurement_matrix` for the
    frame.
    """
    h = measurement_matrix(
        spindle_angle_rad,
        feed_per_tooth_m,
        n_flutes=n_flutes,
        diameter_m=diameter_m,
        helix_rad=helix_rad,
        axial_depth_m=axial_depth_m,
        entry_rad=entry_rad,
        exit_rad=exit_rad,
        n_harmonics=n_harmonics,
    )
    q = np.array([coeffs.ktc, coeffs.krc, coeffs.kte, coeffs.kre])
    f = h @ q
    return f[:, 0], f[:, 1]
