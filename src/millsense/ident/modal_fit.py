"""Automated modal fitting of FRFs: vector fitting, stabilisation diagram, modal realisation.

:func:`fit_modes` fits a measured FRF ``H(iω)`` in a selectable band by a sum of modes in the
residue form of Aslan Eq. 3.13 plus a constant residual::

    H(s) ≈ Σ_k (α_k + β_k s) / (s² + 2 ζ_k ω_k s + ω_k²) + D,

chooses the number of modes from a stabilisation diagram, and returns a :class:`ModalFit`
convertible to :class:`millsense.stability.modal.Mode` and to a real state space made of 2×2
modal blocks. :func:`fit_batch` fits many FRFs (the speed × load map of Aslan Ch. 4).

Method (docs/decisions/0051-modal-fitting-by-relaxed-vector-fitting-issue-6-item-2.md): vector
fitting with relaxed Sanathanan–Koerner iterations (Gustavsen & Semlyen 1999; Gustavsen 2006), the
method of MATLAB's ``modalfit`` used in Aslan Ch. 4. Each iteration solves the linear least-squares
problem ``w·(σ(s) H(s) − p(s)) ≈ 0`` with ``σ(s) = Σ c̃_i φ_i(s) + d̃`` on the current poles
(real basis φ for conjugate pairs) and a relaxation row fixing the mean of σ; the zeros of σ
(eigenvalues of ``Λ − b c̃ᵀ / d̃``) become the next poles, unstable ones reflected. Frequencies
are scaled by the upper band edge so the problem is well conditioned.

Order selection: models with 1..``max_modes`` modes are fitted. A pole at order m is *stable*
if order m−1 has a pole within ±1 % in frequency and ±5 % in damping ratio (the stabilisation
criteria of issue 6). The selected order is the lowest whose weighted error is within
``error_tolerance`` of the best; its poles that are stable against the order below or above,
lie in the band, have ζ < ``max_damping`` and a half-power bandwidth of at least half a line
are the physical modes. Poles of that order outside the band are kept as residual terms (the
upper/lower residuals of modes outside the band); in-band poles that fail the tests are
dropped. Residues and D are then re-estimated by linear least squares.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from millsense.core.errors import InputDataError
from millsense.ident.frf import FrfEstimate
from millsense.models.modal_ss import ModalStateSpace
from millsense.stability.modal import Mode

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

__all__ = [
    "FittedMode",
    "ModalFit",
    "StabilisationDiagram",
    "fit_batch",
    "fit_modes",
    "vector_fit",
]


# ---------------------------------------------------------------------------------------------
# Data classes
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FittedMode:
    """One fitted mode: pole ``p`` [rad/s] and residue ``r`` of ``r/(s−p) + r̄/(s−p̄)``.

    ``α = −2 Re(r p̄)``, ``β = 2 Re r`` (Aslan Eq. 3.13); ``ω = |p|``, ``ζ = −Re p / |p|``.
    """

    pole: complex
    residue: complex

    @property
    def omega(self) -> float:
        """Natural angular frequency ω [rad/s]."""
        return abs(self.pole)

    @property
    def natural_frequency_hz(self) -> float:
        """Natural frequency [Hz]."""
        return self.omega / (2 * math.pi)

    @property
    def damping_ratio(self) -> float:
        """Damping ratio ζ [-]."""
        return -self.pole.real / abs(self.pole)

    @property
    def alpha(self) -> float:
        """Residue α [output/(input·s²)] of Eq. 3.13."""
        return float(-2.0 * (self.residue * self.pole.conjugate()).real)

    @property
    def beta(self) -> float:
        """Velocity residue β [output/(input·s)] of Eq. 3.13."""
        return float(2.0 * self.residue.real)

    def to_mode(self) -> Mode:
        """The mode as :class:`millsense.stability.modal.Mode`."""
        return Mode(self.omega, self.damping_ratio, self.alpha, self.beta)

    @classmethod
    def from_mode(cls, mode: Mode) -> FittedMode:
        """Pole/residue form of a :class:`Mode` (inverse of :meth:`to_mode`)."""
        wd = mode.omega * math.sqrt(1.0 - mode.zeta**2)
        p = complex(-mode.zeta * mode.omega, wd)
        # β = 2 Re r, α = −2 Re(r p̄) = −2 (Re r Re p + Im r Im p)
        re = mode.beta / 2.0
        im = (-mode.alpha / 2.0 - re * p.real) / p.imag
        return cls(p, complex(re, im))

    def frf(self, freq_hz: ArrayLike) -> ComplexArray:
        """Receptance of the mode at ``freq_hz`` [Hz]."""
        s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
        r, p = self.residue, self.pole
        return np.asarray(r / (s - p) + np.conj(r) / (s - np.conj(p)))


@dataclass(frozen=True)
class StabilisationDiagram:
    """Poles per model order with their stability labels and the fit error per order.

    Attributes
    ----------
    orders : number of complex pole pairs of each model.
    poles : complex poles [rad/s] (upper half plane) of each order.
    labels : per pole: "s" stable in frequency and damping, "f" in frequency only, "o" new.
    errors : weighted relative RMS error of each order's fit [-].
    selected : the selected order.
    """

    orders: tuple[int, ...]
    poles: tuple[ComplexArray, ...]
    labels: tuple[tuple[str, ...], ...]
    errors: tuple[float, ...]
    selected: int


@dataclass(frozen=True)
class ModalFit:
    """Result of :func:`fit_modes`.

    Attributes
    ----------
    modes : physical modes in the band, ascending frequency.
    residual : constant residual D [output/input] (out-of-band modes).
    residual_modes : stable poles outside the band kept as residual terms (not reported as
        identified modes; included in :meth:`frf` and :meth:`state_space` by default).
    band_hz : fitting band (low, high) [Hz].
    rms_error : relative RMS error of the fitted FRF over the band [-].
    diagram : stabilisation diagram (None when the order was given).
    """

    modes: tuple[FittedMode, ...]
    residual: float
    band_hz: tuple[float, float]
    rms_error: float
    diagram: StabilisationDiagram | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    residual_modes: tuple[FittedMode, ...] = field(default_factory=tuple)

    def all_modes(self, include_residual: bool = True) -> tuple[FittedMode, ...]:
        """Band modes, then the stable out-of-band poles kept as residual terms."""
        return self.modes + self.residual_modes if include_residual else self.modes

    def to_modes(self, include_residual: bool = False) -> list[Mode]:
        """The modes as :class:`millsense.stability.modal.Mode` (α/β form of Eq. 3.13).

        ``include_residual`` adds the out-of-band poles (they represent the modes outside the
        band only approximately; their parameters are not identified values).
        """
        return [m.to_mode() for m in self.all_modes(include_residual)]

    def frf(self, freq_hz: ArrayLike, include_residual: bool = True) -> ComplexArray:
        """Fitted FRF (modes + out-of-band poles + constant residual) at ``freq_hz`` [Hz]."""
        f = np.asarray(freq_hz, dtype=float)
        out = np.full(f.shape, self.residual, dtype=complex)
        for m in self.all_modes(include_residual):
            out = out + m.frf(f)
        return out

    def state_space(self, include_residual: bool = True) -> ModalStateSpace:
        """Minimal real realisation in balanced 2×2 modal blocks.

        The project's one modal realisation, :class:`millsense.models.modal_ss.
        ModalStateSpace` (Aslan Eq. 3.13 in normal, balanced blocks; far better conditioned
        than the companion form of Appendix A). Blocks follow :meth:`all_modes`; D is the
        constant residual.
        """
        modes = self.all_modes(include_residual)
        return ModalStateSpace.from_modes(
            [m.natural_frequency_hz for m in modes],
            [m.damping_ratio for m in modes],
            [m.alpha for m in modes],
            [m.beta for m in modes],
            float(np.real(self.residual)),
        )


# ---------------------------------------------------------------------------------------------
# Vector fitting core
# ---------------------------------------------------------------------------------------------


def _basis(s: ComplexArray, cpoles: ComplexArray, rpoles: FloatArray) -> ComplexArray:
    """Real-coefficient basis: 1/(s−a) for real a; φ1, φ2 for each pair (a, ā), Im a > 0."""
    cols = []
    if len(rpoles):
        cols.append(1.0 / (s[:, None] - rpoles[None, :]))
    if len(cpoles):
        g1 = 1.0 / (s[:, None] - cpoles[None, :])
        g2 = 1.0 / (s[:, None] - np.conj(cpoles)[None, :])
        phi = np.empty((len(s), 2 * len(cpoles)), dtype=complex)
        phi[:, 0::2] = g1 + g2
        phi[:, 1::2] = 1j * g1 - 1j * g2
        cols.append(phi)
    return np.concatenate(cols, axis=1) if cols else np.zeros((len(s), 0), dtype=complex)


def _lstsq(a: FloatArray, b: FloatArray) -> FloatArray:
    """Least squares with column scaling, by the R factor of the augmented matrix [A b].

    ``qr([A b], mode="r")`` gives R and ``Qᵀb`` in one pass without forming Q (several times
    faster than an SVD-based solver on these tall matrices).
    """
    norm = np.linalg.norm(a, axis=0)
    norm[norm == 0] = 1.0
    n = a.shape[1]
    r = cast(FloatArray, np.linalg.qr(np.concatenate([a / norm, b[:, None]], axis=1), mode="r"))
    diag = np.abs(np.diag(r[:n, :n]))
    if diag.min() <= 1e-13 * diag.max():
        x = np.linalg.lstsq(a / norm, b, rcond=None)[0]
    else:
        x = scipy.linalg.solve_triangular(r[:n, :n], r[:n, n])
    return np.asarray(x / norm)


def _split_poles(z: ComplexArray) -> tuple[ComplexArray, FloatArray]:
    """Upper-half-plane complex poles and real poles; unstable poles reflected."""
    z = np.where(z.real > 0, -np.conj(z), z)
    tol = 1e-9 * np.maximum(np.abs(z), 1e-300)
    cpx = z[z.imag > tol]
    real = z[np.abs(z.imag) <= tol].real
    return np.sort_complex(cpx), np.sort(real)


def _stack(m: ComplexArray) -> FloatArray:
    return np.concatenate([m.real, m.imag], axis=0)


def vector_fit(
    s: ComplexArray,
    h: ComplexArray,
    weights: FloatArray,
    cpoles: ComplexArray,
    n_iter: int = 12,
    tol: float = 1e-7,
) -> tuple[ComplexArray, FloatArray]:
    """Relaxed vector fitting (Sanathanan–Koerner iterations) of the pole set.

    Parameters
    ----------
    s : complex frequencies iω (scaled; any consistent unit).
    h : FRF values at ``s``.
    weights : least-squares weights (inverse standard deviation, up to a factor).
    cpoles : starting poles, upper half plane (conjugates implied).
    n_iter : maximum number of pole relocations.
    tol : stop when the largest relative pole change is below this.

    Returns
    -------
    Complex poles (upper half plane) and real poles after relocation.

    Notes
    -----
    Gustavsen & Semlyen (1999) with the relaxed normalisation of Gustavsen (2006): unknowns
    c, d of p(s) and c̃, d̃ of σ(s); the row ``scale · Re Σ_k σ(s_k) = scale · K`` fixes the
    level of σ. New poles are eig(Λ − b c̃ᵀ/d̃) with Λ = blkdiag([[a_r, a_i], [−a_i, a_r]]),
    b = [2, 0] per pair and 1 per real pole.
    """
    K = len(s)
    rpoles = np.zeros(0)
    w = weights[:, None]
    scale = float(np.linalg.norm(weights * h)) / K
    for _ in range(n_iter):
        phi = _basis(s, cpoles, rpoles)
        N = phi.shape[1]
        lhs = np.concatenate(
            [w * phi, w * np.ones((K, 1)), -w * h[:, None] * phi, -w * h[:, None]], axis=1
        )
        a = _stack(lhs)
        relax = np.zeros((1, 2 * N + 2))
        relax[0, N + 1 : 2 * N + 1] = scale * np.sum(phi.real, axis=0)
        relax[0, -1] = scale * K
        a = np.concatenate([a, relax], axis=0)
        b = np.zeros(a.shape[0])
        b[-1] = scale * K
        x = _lstsq(a, b)
        ct, dt = x[N + 1 : 2 * N + 1], x[-1]
        if abs(dt) < 1e-8:
            dt = math.copysign(1e-8, dt) if dt != 0 else 1e-8
        lam = np.zeros((N, N))
        bv = np.zeros(N)
        nr = len(rpoles)
        lam[np.arange(nr), np.arange(nr)] = rpoles
        bv[:nr] = 1.0
        for k, p in enumerate(cpoles):
            i = nr + 2 * k
            lam[i : i + 2, i : i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
            bv[i] = 2.0
        zeros = np.linalg.eigvals(lam - np.outer(bv, ct) / dt)
        new_c, new_r = _split_poles(zeros)
        done = len(new_c) == len(cpoles) and len(new_r) == len(rpoles)
        if done and len(new_c):
            change = np.max(np.abs(new_c - cpoles) / np.abs(new_c))
            done = bool(change < tol)
        else:
            done = False
        cpoles, rpoles = new_c, new_r
        if done:
            break
    return cpoles, rpoles


def _residues(
    s: ComplexArray, h: ComplexArray, weights: FloatArray, cpoles: ComplexArray
) -> tuple[ComplexArray, float]:
    """Residues of the pairs and the constant D by weighted linear least squares."""
    phi = _basis(s, cpoles, np.zeros(0))
    w = weights[:, None]
    a = _stack(np.concatenate([w * phi, w * np.ones((len(s), 1))], axis=1))
    x = _lstsq(a, _stack((weights * h)[:, None])[:, 0])
    c = x[:-1]
    return c[0::2] + 1j * c[1::2], float(x[-1])


# ---------------------------------------------------------------------------------------------
# Automated fit
# ---------------------------------------------------------------------------------------------


def _initial_poles(n: int, w_lo: float, w_hi: float) -> ComplexArray:
    beta = np.linspace(w_lo, w_hi, n + 2)[1:-1] if n > 0 else np.zeros(0)
    return np.asarray(-beta / 100.0 + 1j * beta, dtype=np.complex128)


def _match(p: complex, others: ComplexArray, f_tol: float, z_tol: float) -> str:
    """Stability label of pole ``p`` against the poles of a neighbouring order."""
    if len(others) == 0:
        return "o"
    w, z = abs(p), -p.real / abs(p)
    wo = np.abs(others)
    zo = -others.real / wo
    fok = np.abs(wo / w - 1.0) <= f_tol
    if not fok.any():
        return "o"
    zok = fok & (np.abs(zo / z - 1.0) <= z_tol)
    return "s" if zok.any() else "f"


def _weights(h: ComplexArray, coherence: FloatArray | None, kind: str, n_avg: int) -> FloatArray:
    if kind == "uniform":
        return np.ones(len(h))
    if kind != "relative":
        raise InputDataError(f"unknown weighting {kind!r} (use 'relative' or 'uniform')")
    mag = np.abs(h)
    floor = 1e-3 * float(np.max(mag)) if len(mag) else 1.0
    w = 1.0 / np.maximum(mag, floor)
    if coherence is not None:
        # inverse of the normalised random error of H1 (Bendat & Piersol Eq. 9.90), capped
        g2 = np.clip(coherence, 1e-6, 1.0 - 1e-9)
        inv_err = np.sqrt(2.0 * n_avg * g2 / (1.0 - g2))
        w = w * np.minimum(inv_err, 1e4)
    return np.asarray(w / np.max(w))


def fit_modes(
    data: FrfEstimate | tuple[ArrayLike, ArrayLike],
    band_hz: tuple[float, float],
    *,
    n_modes: int | None = None,
    max_modes: int = 16,
    weighting: str = "relative",
    use_coherence: bool = True,
    error_tolerance: float = 0.2,
    freq_tol: float = 0.01,
    damping_tol: float = 0.05,
    max_damping: float = 0.3,
    min_contribution: float = 1e-3,
    n_iter: int = 12,
) -> ModalFit:
    """Fit modes to an FRF in a band, choosing the model order from a stabilisation diagram.

    Parameters
    ----------
    data : an :class:`~millsense.ident.frf.FrfEstimate` (H1 and its coherence are used, and an
        exponential-window pole shift is removed) or a pair ``(freq_hz, h)``.
    band_hz : fitting band (low, high) [Hz].
    n_modes : fixed number of complex pole pairs; None selects it automatically.
    max_modes : largest order of the stabilisation diagram.
    weighting : "relative" (1/|H|, times the inverse H1 random error when the coherence is
        known) or "uniform".
    use_coherence : include the coherence in the weights.
    error_tolerance : the selected order is the lowest whose weighted RMS error is at most
        (1 + error_tolerance) × the lowest over all orders.
    freq_tol, damping_tol : stabilisation tolerances (relative, ±1 % and ±5 % by default).
    max_damping : poles with a larger damping ratio are not physical modes. Poles whose
        half-power bandwidth 2ζf_n is below half the line spacing are noise spikes and are
        dropped as well (such a mode is not resolved by the FRF).
    min_contribution : modes whose peak magnitude |r|/|Re p| is below this fraction of the
        largest |H| in the band are dropped (pole-zero cancellations, numerical modes).
    n_iter : maximum Sanathanan–Koerner iterations per order.

    Returns
    -------
    ModalFit

    Raises
    ------
    InputDataError
        Band outside the data, too few lines, non-finite data, no stable mode.
    """
    shift = 0.0
    coh: FloatArray | None = None
    n_avg = 1
    if isinstance(data, FrfEstimate):
        f_all, h_all = data.freq_hz, data.h1
        if use_coherence and data.method != "stepped_sine":
            coh = data.coherence
        n_avg = data.n_averages
        shift = data.pole_shift_rad_s
    else:
        f_all = np.asarray(data[0], dtype=float)
        h_all = np.asarray(data[1], dtype=complex)
    lo, hi = band_hz
    if not (0 <= lo < hi):
        raise InputDataError(f"fitting band must satisfy 0 <= low < high, got {lo}-{hi} Hz")
    sel = (f_all >= lo) & (f_all <= hi)
    f, h = f_all[sel], h_all[sel]
    if len(f) < 8:
        raise InputDataError(
            f"only {len(f)} FRF lines in the band {lo:g}-{hi:g} Hz; need at least 8"
        )
    if not np.all(np.isfinite(h)):
        raise InputDataError("FRF has non-finite values in the fitting band")
    cw = coh[sel] if coh is not None else None
    w = _weights(h, cw, weighting, n_avg)
    w0 = 2 * np.pi * hi
    s = np.asarray(2j * np.pi * f / w0, dtype=np.complex128)
    w_lo = max(2 * np.pi * lo, 2 * np.pi * (hi - lo) * 0.01) / w0

    def err_of(cp: ComplexArray) -> tuple[float, ComplexArray, float]:
        r, d = _residues(s, h, w, cp)
        fit = np.full(len(s), d, dtype=complex)
        if len(cp):
            fit = fit + np.sum(
                r / (s[:, None] - cp) + np.conj(r) / (s[:, None] - np.conj(cp)), axis=1
            )
        e = float(np.sqrt(np.mean(np.abs(w * (fit - h)) ** 2) / np.mean(np.abs(w * h) ** 2)))
        return e, r, d

    df = float(np.median(np.diff(f)))

    def physical(cp: ComplexArray) -> NDArray[np.bool_]:
        # a half-power bandwidth 2ζf_n narrower than half a line spacing is a noise spike
        z = -cp.real / np.abs(cp)
        fn = np.abs(cp) * w0 / (2 * np.pi)
        return np.asarray((z < max_damping) & (2 * z * fn >= 0.5 * df))

    def in_band(cp: ComplexArray) -> NDArray[np.bool_]:
        wn = np.abs(cp) * w0
        return np.asarray((wn >= 2 * np.pi * lo) & (wn <= 2 * np.pi * hi))

    diagram: StabilisationDiagram | None = None
    if n_modes is not None:
        cp, _ = vector_fit(s, h, w, _initial_poles(n_modes, w_lo, 1.0), n_iter)
        chosen = cp[(physical(cp) & in_band(cp)) | ~in_band(cp)]
    else:
        max_modes = min(max_modes, max(1, (len(f) - 2) // 4))
        orders = list(range(1, max_modes + 1))
        poles: list[ComplexArray] = []
        errs: list[float] = []
        for m in orders:
            cp, _ = vector_fit(s, h, w, _initial_poles(m, w_lo, 1.0), n_iter)
            poles.append(cp)
            errs.append(err_of(cp)[0])
        labels: list[tuple[str, ...]] = []
        for i, cp in enumerate(poles):
            prev = poles[i - 1] if i > 0 else np.zeros(0, dtype=complex)
            labels.append(tuple(_match(p, prev, freq_tol, damping_tol) for p in cp))

        def kept(i: int) -> ComplexArray:
            # in-band: stable physical poles only; out-of-band poles all kept as residual terms
            cp = poles[i]
            nxt = poles[i + 1] if i + 1 < len(poles) else np.zeros(0, dtype=complex)
            stable = np.array(
                [
                    labels[i][j] == "s" or _match(p, nxt, freq_tol, damping_tol) == "s"
                    for j, p in enumerate(cp)
                ],
                dtype=bool,
            )
            return np.asarray(cp[(physical(cp) & stable & in_band(cp)) | ~in_band(cp)])

        # the order is chosen on the error of the poles it keeps (decision "Modal fit: order
        # chosen on the kept poles"): a noise-fitting order can split a mode into two unstable
        # poles, and its low error then says nothing of what is returned
        kept_sets = [kept(i) for i in range(len(poles))]
        kept_errs = [err_of(k)[0] if len(k) else math.inf for k in kept_sets]
        best = min(kept_errs)
        limit = (1 + error_tolerance) * best + 1e-6  # 1e-6: round-off floor of exact data
        sel_i = next(i for i, e in enumerate(kept_errs) if e <= limit)
        chosen = kept_sets[sel_i]
        diagram = StabilisationDiagram(
            tuple(orders),
            tuple(p * w0 for p in poles),
            tuple(labels),
            tuple(errs),
            orders[sel_i],
        )
    if len(chosen) == 0:
        raise InputDataError(
            f"no stable mode found in the band {lo:g}-{hi:g} Hz (check coherence and band)"
        )
    _, r, d = err_of(chosen)
    # drop poles whose peak contribution |r|/|Re p| is negligible against the FRF
    peak = np.abs(r) / np.maximum(-chosen.real, 1e-300)
    keep = (peak >= min_contribution * float(np.max(np.abs(h)))) | ~in_band(chosen)
    if not keep.all() and keep.any():
        chosen = chosen[keep]
        _, r, d = err_of(chosen)
    fitted = [
        FittedMode(complex(p * w0), complex(ri * w0)) for p, ri in zip(chosen, r, strict=True)
    ]
    raw = ModalFit(tuple(fitted), d, (lo, hi), 0.0)
    rel = np.abs(raw.frf(f) - h) / np.maximum(np.abs(h), 1e-300)
    rms = float(np.sqrt(np.mean(rel**2)))
    # remove the exponential-window decay (impact tests): p_true = p_fit + 1/τ
    shifted = sorted((FittedMode(m.pole + shift, m.residue) for m in fitted), key=lambda m: m.omega)
    ok = in_band(np.array([m.pole / w0 for m in shifted], dtype=np.complex128))
    band = [m for m, k in zip(shifted, ok, strict=True) if k]
    outside = [m for m in shifted if m not in band]
    notes = (f"pole shift {shift:g} 1/s of the exponential window removed",) if shift else ()
    if not band:
        raise InputDataError(f"no stable mode found in the band {lo:g}-{hi:g} Hz")
    return ModalFit(tuple(band), d, (lo, hi), rms, diagram, notes, tuple(outside))


def _fit_one(args: tuple[int, object, tuple[float, float], dict[str, object]]) -> ModalFit:
    i, d, band, kwargs = args
    try:
        return fit_modes(d, band, **kwargs)  # type: ignore[arg-type]
    except InputDataError as err:
        raise InputDataError(f"FRF {i} of the batch: {err}") from err


def fit_batch(
    frfs: Sequence[FrfEstimate | tuple[ArrayLike, ArrayLike]],
    band_hz: tuple[float, float],
    *,
    workers: int = 1,
    **kwargs: object,
) -> list[ModalFit]:
    """Fit each FRF of a batch (e.g. the speed × load map of Aslan Ch. 4) with :func:`fit_modes`.

    Parameters
    ----------
    frfs : FRF estimates or ``(freq_hz, h)`` pairs.
    band_hz : fitting band [Hz], common to the batch.
    workers : processes; above 1 the FRFs are fitted in a spawned process pool whose workers
        run single-threaded BLAS (OPENBLAS/OMP/MKL_NUM_THREADS=1 while the pool lives): the
        least-squares problems are small, and multi-threaded BLAS on small matrices is slower
        than one thread per process, markedly so on a loaded machine.
    kwargs : passed to :func:`fit_modes`.

    Raises
    ------
    InputDataError
        An FRF that cannot be fitted, naming its index in the batch.
    """
    jobs = [(i, d, band_hz, dict(kwargs)) for i, d in enumerate(frfs)]
    if workers <= 1 or len(jobs) < 2:
        return [_fit_one(j) for j in jobs]
    import concurrent.futures
    import multiprocessing
    import os

    keys = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {k: os.environ.get(k) for k in keys}
    try:
        os.environ.update({k: "1" for k in keys})
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            chunk = max(1, len(jobs) // (4 * workers))
            return list(pool.map(_fit_one, jobs, chunksize=chunk))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
