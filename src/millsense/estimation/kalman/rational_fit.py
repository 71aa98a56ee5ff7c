"""Rational model of a measured disturbance path for an estimator: real and complex poles.

:func:`millsense.ident.modal_fit.fit_modes` reports the physical *modes* of an FRF (complex
pole pairs; real poles are dropped). An estimator needs instead a model that reproduces the
measured path everywhere in its band, including the real poles a closed loop has (the velocity
PI of the spindle, the current loop of a feed drive seen through the C3 torque). This module
runs the same relaxed vector fitting (:func:`millsense.ident.modal_fit.vector_fit`) keeping the
real poles, chooses the order by the fit error, and realises the result as a
:class:`~millsense.estimation.kalman.design.StateSpaceModel` (2×2 blocks for pairs, 1×1 for real
poles). Decision docs/decisions/0082-feed-drive-estimator-model-identified-through-the-c3-path.md.

For a sampled loop (the spindle's I_nom is produced at the velocity-loop rate) the FRF is fitted
on the bilinear-warped axis ``f_w = (f_s/π)·tan(π f/f_s)`` and the continuous fit mapped back by
the Tustin transform, which is exact: ``H(e^{jωT}) = H_c(j·(2/T)·tan(ωT/2))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from millsense.core.errors import InputDataError
from millsense.estimation.kalman.design import StateSpaceModel
from millsense.ident.modal_fit import vector_fit
from millsense.models.modal_ss import ModalStateSpace

if TYPE_CHECKING:
    from millsense.core.config import DisturbancePathConfig

ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class RationalFit:
    """``H(s) = d + Σ r_k/(s − a_k) + Σ [ρ/(s − p) + ρ̄/(s − p̄)]`` (s in rad/s).

    Attributes
    ----------
    complex_poles : (m,) upper-half-plane poles p, rad/s.
    complex_residues : (m,) residues ρ.
    real_poles : (k,) real poles a, rad/s.
    real_residues : (k,) residues r.
    d : constant term.
    rms_error : weighted relative RMS error over the fitted lines.
    warped_fs_hz : sample rate of the bilinear warping, or None (continuous FRF).
    """

    complex_poles: ComplexArray
    complex_residues: ComplexArray
    real_poles: NDArray[np.float64]
    real_residues: NDArray[np.float64]
    d: float
    rms_error: float
    warped_fs_hz: float | None = None

    @property
    def n_states(self) -> int:
        return 2 * len(self.complex_poles) + len(self.real_poles)

    @classmethod
    def from_modes(cls, modes: ModalStateSpace) -> RationalFit:
        """The pole–residue form of Eq. 3.13 modes (e.g. Table 3.4 as nominal data).

        ``(α + βs)/(s² + 2ζωs + ω²) = ρ/(s − p) + ρ̄/(s − p̄)`` with ``ρ = (α + βp)/(p − p̄)``.
        Modes with ζ ≥ 1 are not supported (their poles are real).
        """
        w = 2 * np.pi * modes.frequency_hz
        z = modes.damping_ratio
        if np.any(z >= 1):
            raise InputDataError("rational fit: overdamped modes (ζ ≥ 1) have real poles")
        p = -z * w + 1j * w * np.sqrt(1 - z**2)
        rho = (modes.alpha + modes.beta * p) / (p - np.conj(p))
        return cls(
            np.asarray(p, dtype=np.complex128),
            np.asarray(rho, dtype=np.complex128),
            np.zeros(0),
            np.zeros(0),
            float(modes.d),
            0.0,
        )

    def continuous_frf(self, f_hz: ArrayLike) -> ComplexArray:
        """H at s = j2πf (on the warped axis when the fit is warped)."""
        s = 2j * np.pi * np.atleast_1d(np.asarray(f_hz, dtype=float))
        out = np.full(s.shape, self.d, dtype=complex)
        for p, r in zip(self.complex_poles, self.complex_residues, strict=True):
            out += r / (s - p) + np.conj(r) / (s - np.conj(p))
        for a, r in zip(self.real_poles, self.real_residues, strict=True):
            out += r / (s - a)
        return out

    def frf(self, f_hz: ArrayLike) -> ComplexArray:
        """The fitted FRF at the physical frequencies ``f_hz``, Hz."""
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        if self.warped_fs_hz is not None:
            f = self.warped_fs_hz / np.pi * np.tan(np.pi * f / self.warped_fs_hz)
        return self.continuous_frf(f)

    def continuous_model(self) -> StateSpaceModel:
        """Real block-diagonal realisation: ``[[σ, ω], [−ω, σ]]`` per pair, 1×1 per real pole."""
        m, k = len(self.complex_poles), len(self.real_poles)
        n = 2 * m + k
        a = np.zeros((n, n))
        b = np.zeros((n, 1))
        c = np.zeros((1, n))
        for i, (p, r) in enumerate(zip(self.complex_poles, self.complex_residues, strict=True)):
            j = 2 * i
            # x' = [[σ, ω], [−ω, σ]] x + [2, 0]ᵀ u, y = [Re ρ, Im ρ] x  ⇔  ρ/(s−p) + ρ̄/(s−p̄)
            a[j : j + 2, j : j + 2] = [[p.real, p.imag], [-p.imag, p.real]]
            b[j, 0] = 2.0
            c[0, j] = r.real
            c[0, j + 1] = r.imag
        for i, (ar, r) in enumerate(zip(self.real_poles, self.real_residues, strict=True)):
            j = 2 * m + i
            a[j, j] = ar
            b[j, 0] = 1.0
            c[0, j] = r
        return StateSpaceModel(a, b, c, np.array([[self.d]]))

    def discrete_model(self, dt: float) -> StateSpaceModel:
        """Tustin image of :meth:`continuous_model` (exact for a warped fit at ``1/dt``)."""
        cm = self.continuous_model()
        ad, bd, cd, dd, _ = signal.cont2discrete((cm.a, cm.b, cm.c, cm.d), dt, method="bilinear")
        return StateSpaceModel(np.asarray(ad), np.asarray(bd), np.asarray(cd), np.asarray(dd), dt)

    @classmethod
    def from_config(cls, cfg: DisturbancePathConfig) -> RationalFit:
        """The fit a ``[axes.<a>.estimator.disturbance_path]`` table describes (its inverse is
        :meth:`config_table`)."""
        w = 2 * math.pi * np.asarray(cfg.natural_frequency_hz, dtype=float)
        z = np.asarray(cfg.damping_ratio, dtype=float)
        poles = w * (-z + 1j * np.sqrt(1.0 - z**2))
        res = np.asarray(cfg.residue_real_1_s, dtype=float) + 1j * np.asarray(
            cfg.residue_imag_1_s, dtype=float
        )
        return cls(
            np.asarray(poles, dtype=np.complex128),
            np.asarray(res, dtype=np.complex128),
            -2 * math.pi * np.asarray(cfg.real_pole_hz, dtype=float),
            np.asarray(cfg.real_residue_1_s, dtype=float),
            float(cfg.constant),
            float(cfg.rms_error),
            float(cfg.sample_rate_hz),
        )

    def config_table(self, source: str = "") -> dict[str, object]:
        """The keys of a ``disturbance_path`` table (field units: Hz, 1/s) for this fit.

        Raises
        ------
        InputDataError
            The fit is not on a warped axis (a continuous fit has no sampled-path meaning), or
            a pole is unstable or a complex pole overdamped (|ζ| ≥ 1 cannot be a pair).
        """
        if self.warped_fs_hz is None:
            raise InputDataError("disturbance path: the fit must be of a sampled FRF (warped)")
        w = np.abs(self.complex_poles)
        z = -self.complex_poles.real / np.maximum(w, 1e-300)
        if np.any(z <= 0) or np.any(z >= 1) or np.any(self.real_poles >= 0):
            raise InputDataError("disturbance path: the fit has an unstable or overdamped pole")
        return {
            "natural_frequency_hz": [float(v) for v in w / (2 * math.pi)],
            "damping_ratio": [float(v) for v in z],
            "residue_real_1_s": [float(v) for v in self.complex_residues.real],
            "residue_imag_1_s": [float(v) for v in self.complex_residues.imag],
            "real_pole_hz": [float(v) for v in -self.real_poles / (2 * math.pi)],
            "real_residue_1_s": [float(v) for v in self.real_residues],
            "constant": float(self.d),
            "sample_rate_hz": float(self.warped_fs_hz),
            "rms_error": float(self.rms_error),
            "source": source,
        }

    def with_modes_scaled(self, frequency_scale: float) -> RationalFit:
        """Every complex (structural-mode) pole and residue × ``frequency_scale``.

        ``ρ/(s − p) + c.c.`` keeps its static gain (as the simulator's position-dependent modes
        keep α/ω²); real poles (the loop seen through the C3 torque, not structural) and the
        constant stay.
        """
        return replace(
            self,
            complex_poles=self.complex_poles * frequency_scale,
            complex_residues=self.complex_residues * frequency_scale,
        )


#: Poles faster than this multiple of the top fitted frequency are dropped before the residues
#: are solved (decision "Rational fit: poles far above the band").
FAR_POLE_RATIO = 10.0


def _basis(s: ComplexArray, cp: ComplexArray, rp: NDArray[np.float64]) -> ComplexArray:
    g1 = 1.0 / (s[:, None] - cp[None, :])
    g2 = 1.0 / (s[:, None] - np.conj(cp)[None, :])
    return np.concatenate(
        [1.0 / (s[:, None] - rp[None, :]), g1 + g2, 1j * (g1 - g2), np.ones((len(s), 1))], axis=1
    )


def _fit_order(
    s: ComplexArray, h: ComplexArray, w: NDArray[np.float64], n_pairs: int, w_lo: float
) -> tuple[ComplexArray, NDArray[np.float64], NDArray[np.float64], float]:
    beta = np.geomspace(w_lo, 1.0, n_pairs)
    cp, rp = vector_fit(s, h, w, np.asarray(-beta / 100 + 1j * beta), 30)
    # poles far above the band are constants there: fold them into the feedthrough
    cp, rp = cp[np.abs(cp) <= FAR_POLE_RATIO], rp[np.abs(rp) <= FAR_POLE_RATIO]
    basis = _basis(s, cp, rp) * w[:, None]
    lhs = np.vstack([basis.real, basis.imag])
    rhs = np.concatenate([(w * h).real, (w * h).imag])
    x = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    err = float(np.linalg.norm(lhs @ x - rhs) / np.linalg.norm(rhs))
    return cp, rp, x, err


def fit_rational(
    freq_hz: ArrayLike,
    h: ArrayLike,
    *,
    n_pairs: int | None = None,
    max_pairs: int = 16,
    coherence: ArrayLike | None = None,
    warped_fs_hz: float | None = None,
    error_tolerance: float = 0.2,
) -> RationalFit:
    """Fit a stable rational model with real and complex poles to an FRF.

    Parameters
    ----------
    freq_hz : frequencies of the FRF lines, Hz (> 0, increasing).
    h : FRF values.
    n_pairs : number of starting complex pairs; None chooses the lowest order 1..max_pairs whose
        error is within (1 + error_tolerance) of the best (as in ``fit_modes``).
    max_pairs : largest order tried.
    coherence : γ² per line; weights 1/|H| are multiplied by √(γ²/(1 − γ²)) (the inverse H1
        random error, Bendat & Piersol Eq. 9.90, up to a constant) when given.
    warped_fs_hz : fit a sampled FRF on the bilinear-warped axis (see module notes).
    error_tolerance : order selection tolerance.

    Returns
    -------
    RationalFit (unstable poles reflected into the left half plane by vector fitting).
    """
    f = np.asarray(freq_hz, dtype=float)
    hh = np.asarray(h, dtype=complex)
    if len(f) < 8 or f.shape != hh.shape or not np.all(np.isfinite(hh)) or np.any(f <= 0):
        raise InputDataError("rational fit: need at least 8 finite FRF lines at f > 0")
    fw = f if warped_fs_hz is None else warped_fs_hz / np.pi * np.tan(np.pi * f / warped_fs_hz)
    w = 1.0 / np.maximum(np.abs(hh), 1e-300)
    if coherence is not None:
        g = np.clip(np.asarray(coherence, dtype=float), 1e-6, 1 - 1e-9)
        w = w * np.sqrt(g / (1 - g))
    w0 = 2 * math.pi * float(fw[-1])
    s = np.asarray(2j * np.pi * fw / w0, dtype=np.complex128)
    w_lo = 2 * math.pi * float(fw[0]) / w0
    if n_pairs is not None:
        cp, rp, x, err = _fit_order(s, hh, w, n_pairs, w_lo)
    else:
        fits = [_fit_order(s, hh, w, m, w_lo) for m in range(1, max_pairs + 1)]
        best = min(ft[3] for ft in fits)
        cp, rp, x, err = next(ft for ft in fits if ft[3] <= (1 + error_tolerance) * best + 1e-9)
    k, m = len(rp), len(cp)
    return RationalFit(
        np.asarray(cp * w0, dtype=np.complex128),
        np.asarray((x[k : k + m] + 1j * x[k + m : k + 2 * m]) * w0),
        np.asarray(rp * w0, dtype=float),
        np.asarray(x[:k] * w0, dtype=float),
        float(x[-1]),
        err,
        warped_fs_hz,
    )
