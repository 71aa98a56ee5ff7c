"""Depths of cut, runout and K_t from the harmonics of one revolution of cutting torque.

Seed 004 ch. 2 (Lee; digest §2.1–2.6 with errata V1–V3), re-derived in the convention of
:mod:`millsense.process.geometry` (immersion φ_j(z) = φ − θ_j − ψ(z), ψ = z tanβ/r, chip
h_j = c sin φ_j + r_j − r_{j−1}, r_j = r + ρ cos(θ_j + ψ − λ)) and with the Fourier-series
coefficients of numpy's sign, T_k = (1/2π)∫τ(φ) e^{−ikφ} dφ (decision 1524):

* G_m = (1/2π)∫_{θst}^{θex} e^{−imu} du (Lee's G, Eq. 2.12, as a series coefficient);
* L_m = ∫_0^{d_a} e^{−imψ(z)} dz = (1 − e^{−imΨ})/(im tanβ/r), Ψ = d_a tanβ/r, L_0 = d_a
  (Lee's Λ with the height r/tanβ and the factor N of V1 restored);
* static torque (Eq. 2.11, T_s): T_k = r K_t N S_k L_k for k ≡ 0 (mod N), with
  S_k = (c/2i)(G_{k−1} − G_{k+1}) (the series coefficient of g·c sin);
* runout torque (T_ec, Eqs. 2.17, 2.20–2.22 re-derived as V2/V3): with w = ρ e^{−iλ},
  T_1 = r K_t G_1 N d_a (1 − e^{−i2π/N}) w / 2 for N ≥ 3, and
  T_1 = r K_t G_1 N (w d_a + w̄ L_2) for N = 2 (the 2 × 2 real system of V3); N = 1: none.
* runout edge torque (decision 1540; the thesis' model is single-mechanism): the edge force
  acts only where a flute's chip is > 0, and near a boundary where the feed term c sin φ
  vanishes (down-milling exit π, up-milling entry 0) runout decides where that is: flute j
  at height z cuts only where sin φ_j > s_j = max_m (r_{j−m} − r_j)/(m c) (the chip left by
  the deepest earlier flute). This gives T_1 an edge part of the size of the shear part at
  0.025 mm/tooth; for N ≥ 3 with a fitted K_e > 0 the runout solves shear + edge T_1 = the
  measured T_1, with the engagement boundaries whose flute means are the fitted θ_st, θ_ex
  (the tooth-passing harmonics see the mean). N = 2 keeps the shear-only system.
* mean torque (decision 1806): the same model at k = 0 (Eq. 2.13 includes k = 0, Λ(0) = d_a,
  G(0) = θ_ex − θ_st; no runout term), T_0 = α A_0 + β B_0 with B_0 = d_a (θ_ex − θ_st)/2π,
  K_e times the engaged edge length, plus the air torque (Lee Fig. 3.6 subtracts it). Where
  the harmonics observe K_e less well than T_0 − T_air would (the regression's Schur
  complement against |B_0|², white noise), the fit adds T_0 − T_air as one more row; with no
  air torque known the harmonics' K_e is kept and flagged (``edge_source`` = 3).

Identification per revolution (Fig. 2.9 order ADOC → RDOC → K_t and runout → σ): the thesis
locates the notch of |L| between tooth-passing harmonics (not said how) and inverts
Ψ = (T_2N/L_2N)(L_N/T_N) through lookup tables (resolution not given). Here (digest §2.9 [S],
decision 1524) (d_a, θ_st, θ_ex) are fitted jointly to the complex ratios T_kN/T_N, k = 2…K,
by least squares from the best point of a coarse grid — the same information (K_t and c cancel
as in Ψ), with sub-harmonic resolution of the notch. Then K_t from |T_N| (Eq. 2.19 physically
normalised, V1), the runout from T_1 (with the edge part, decision 1540), and the reliability
index (Eq. 2.23) with m = ⌊ω_notch/ω_N⌋ (the prose; the printed ⌊ω_notch/ω_n⌋ agrees only
for N = 1; decision 1525).
d_r = r (cos θ_st − cos θ_ex) (digest §2.4 [S]; = r(1 + cos θ_st) in down milling).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.monitoring import _spectrum_kernels as _sk

FloatArray = NDArray[np.float64]
FloatLike = NDArray[np.float64] | float
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class ToolGeometry:
    """What the method knows of the tool: flutes, nominal radius (m), helix angle (rad)."""

    n_flutes: int
    radius_m: float
    helix_rad: float

    @property
    def tan_beta(self) -> float:
        return math.tan(self.helix_rad)

    @property
    def axial_pitch_m(self) -> float:
        """d_a,p = 2π r/(N tanβ): the largest axial depth the notch can tell (Lee Sec. 2.3.1)."""
        return 2 * math.pi * self.radius_m / (self.n_flutes * self.tan_beta)


def g_coeff(m: FloatLike, th_st: FloatLike, th_ex: FloatLike) -> ComplexArray:
    """G_m = (1/2π)∫_{θst}^{θex} e^{−imu} du (broadcasting)."""
    m = np.asarray(m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        val = (np.exp(-1j * m * th_st) - np.exp(-1j * m * th_ex)) / (1j * m)
    out = np.where(m == 0, np.asarray(th_ex) - th_st + 0j, val) / (2 * math.pi)
    return np.asarray(out, dtype=np.complex128)


def l_coeff(m: FloatLike, depth_m: FloatLike, geom: ToolGeometry) -> ComplexArray:
    """L_m = ∫_0^{d_a} e^{−imψ(z)} dz (broadcasting)."""
    m = np.asarray(m, dtype=np.float64)
    k = geom.tan_beta / geom.radius_m
    with np.errstate(divide="ignore", invalid="ignore"):
        val = (1 - np.exp(-1j * m * k * depth_m)) / (1j * m * k)
    return np.where(m == 0, depth_m + 0j, val)


def static_harmonics(
    k: FloatLike,
    depth_m: FloatLike,
    th_st: FloatLike,
    th_ex: FloatLike,
    geom: ToolGeometry,
    kt_n_m2: float = 1.0,
    feed_per_tooth_m: float = 1.0,
    edge_ratio: FloatLike | float = 0.0,
) -> ComplexArray:
    """T_k of the runout-free torque for harmonics k ≡ 0 (mod N) (module notes), with an edge
    force K_e = e·K_t·c per unit length of engaged edge (``edge_ratio`` e; decision 1525)."""
    s = (g_coeff(k - 1, th_st, th_ex) - g_coeff(k + 1, th_st, th_ex)) / 2j
    s = s + np.asarray(edge_ratio) * g_coeff(k, th_st, th_ex)
    return (
        geom.radius_m * kt_n_m2 * feed_per_tooth_m * geom.n_flutes * s * l_coeff(k, depth_m, geom)
    )


def runout_harmonic(
    w: complex, depth_m: float, th_st: float, th_ex: float, geom: ToolGeometry, kt_n_m2: float
) -> complex:
    """T_1 of the runout torque for w = ρ e^{−iλ} (module notes)."""
    n = geom.n_flutes
    base = geom.radius_m * kt_n_m2 * complex(g_coeff(np.array(1.0), th_st, th_ex)) * n
    if n == 1:
        return 0j
    if n == 2:
        l2 = complex(l_coeff(np.array(2.0), depth_m, geom))
        return base * (w * depth_m + np.conj(w) * l2)
    return base * depth_m * (1 - np.exp(-2j * math.pi / n)) * w / 2


#: Relative singular-value cut-off of the N = 2 runout system (decision 1525).
RUNOUT_RCOND = 0.05


def solve_runout(
    t1: complex, depth_m: float, th_st: float, th_ex: float, geom: ToolGeometry, kt_n_m2: float
) -> complex:
    """w = ρ e^{−iλ} from the first harmonic T_1 (inverse of :func:`runout_harmonic`: the
    shear part only; the monitor adds the edge part for N ≥ 3, decision 1540)."""
    g1 = complex(g_coeff(np.array(1.0), th_st, th_ex))
    l2 = complex(l_coeff(np.array(2.0), depth_m, geom))
    return _runout_from(t1, depth_m, geom, kt_n_m2, g1, l2)


def _runout_from(
    t1: complex, depth_m: float, geom: ToolGeometry, kt_n_m2: float, g1: complex, l2: complex
) -> complex:
    n = geom.n_flutes
    if n == 1:
        return complex(math.nan, math.nan)
    base = geom.radius_m * kt_n_m2 * g1 * n
    if abs(base) == 0 or not math.isfinite(abs(base)):
        return complex(math.nan, math.nan)
    if n >= 3:
        return complex(t1 / (base * depth_m * (1 - np.exp(-2j * math.pi / n)) / 2))
    q = t1 / base
    p, s = l2.real, l2.imag
    mat = np.array([[depth_m + p, s], [s, depth_m - p]])
    # d_a² − |L_2|² → 0 for a small helix lag: then only one component of w is observable;
    # the minimum-norm solution keeps it and drops the other (decision 1525)
    sol, *_ = np.linalg.lstsq(mat, np.array([q.real, q.imag]), rcond=RUNOUT_RCOND)
    return complex(sol[0], sol[1])


@dataclass(frozen=True)
class EngagementEstimate:
    """One revolution's estimate (SI): depths m, angles rad, K_t N/m², runout m."""

    axial_depth_m: float
    radial_depth_m: float
    entry_rad: float
    exit_rad: float
    kt_n_m2: float
    runout_m: float
    runout_angle_rad: float
    reliability: float
    #: standard deviation of d_a from the harmonics' scatter about the fit, m (decision 1558)
    axial_depth_sd_m: float
    notch_index: float  #: ω_notch/ω_N = d_a,p/d_a
    cost: float
    edge_n_m: float = 0.0  #: edge-force coefficient K_e = e K_t c, N/m
    #: where K_e came from (decision 1806): 0 not fitted, 1 the tooth-passing harmonics, 2 the
    #: mean torque (air torque subtracted), 3 the harmonics although they do not observe it
    #: (no air torque known: K_e and the runout's edge part are less reliable)
    edge_source: float = 0.0


def _basis(
    k: FloatLike, depth_m: FloatLike, th_st: FloatLike, th_ex: FloatLike, geom: ToolGeometry
) -> tuple[ComplexArray, ComplexArray]:
    """Shear and edge basis of the static harmonics: T_k = α A_k + β B_k with
    α = r N K_t c, β = r N K_e (module notes; broadcasting)."""
    a = (g_coeff(k - 1, th_st, th_ex) - g_coeff(k + 1, th_st, th_ex)) / 2j
    lk = l_coeff(k, depth_m, geom)
    return a * lk, g_coeff(k, th_st, th_ex) * lk


def _project(
    x: ComplexArray, a: ComplexArray, b: ComplexArray | None
) -> tuple[FloatArray, FloatArray, ComplexArray]:
    """Real least-squares amplitudes (α, β) of x ≈ α a + β b along the last axis, and the
    residual (variable projection)."""
    aa = np.sum(np.abs(a) ** 2, axis=-1)
    ax = np.sum((np.conj(a) * x).real, axis=-1)
    if b is None:
        with np.errstate(divide="ignore", invalid="ignore"):
            alpha = ax / aa
        beta = np.zeros_like(alpha)
        return alpha, beta, x - alpha[..., None] * a
    bb = np.sum(np.abs(b) ** 2, axis=-1)
    ab = np.sum((np.conj(a) * b).real, axis=-1)
    bx = np.sum((np.conj(b) * x).real, axis=-1)
    det = aa * bb - ab**2
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = (bb * ax - ab * bx) / det
        beta = (aa * bx - ab * ax) / det
    return alpha, beta, x - alpha[..., None] * a - beta[..., None] * b


@dataclass(frozen=True)
class _GridBases:
    """The coarse grid of (d_a, θ_st, θ_ex) with what its projected misfits need that does not
    depend on the measurement. The grid is every angle pair at every depth (row = depth index
    × pairs + pair index), and its bases factor as A_k = a_k(θ_st, θ_ex) L_k(d_a), B_k =
    g_k(θ_st, θ_ex) L_k(d_a) (:func:`_basis`). Per row the QR factors of [A B] in the real
    inner product Re(u^H v) (Gram–Schmidt applied twice: q₁ = A/r₁₁, B = r₁₂ q₁ + r₂₂ q₂), so
    that a measurement x's projections are q₁·x = Re(A^H x)/r₁₁ and q₂·x = (Re(B^H x) −
    r₁₂ q₁·x)/r₂₂, with Re(A^H x) = Re(a^H y), y = conj(L) x per depth: two products with the
    pairs' small matrices (in cache) per depth instead of with every row's bases (22 MB read
    per revolution searched, about 3 MB here; the misfits differ from the rows' own
    orthonormal bases' by round-off)."""

    params: tuple[FloatArray, FloatArray, FloatArray]
    #: the same points as rows (d_a, θ_st, θ_ex)
    points: FloatArray
    #: a and g of every angle pair, rows [Re | Im] (2K × pairs); L of every depth, real and
    #: imaginary parts (depths × K)
    a_pairs: FloatArray
    g_pairs: FloatArray
    l_re: FloatArray
    l_im: FloatArray
    #: per row 1/r₁₁ = 1/|A| (0 where A = 0), r₁₂ = q₁·B, 1/r₂₂ = 1/|B − r₁₂ q₁| (NaN where
    #: singular)
    inv_r11: FloatArray
    r12: FloatArray
    inv_r22: FloatArray
    #: rows whose A is zero, or whose B is zero or parallel to A (no unique α, β)
    singular: NDArray[np.bool_]

    def costs(self, x: ComplexArray, edge: bool) -> FloatArray:
        """Projected misfit min over α, β of Σ|x − αA − βB|² of every row (β = 0 without the
        edge term; what :func:`_project` leaves): |x|² − (q₁·x)² − (q₂·x)², one compiled loop.
        A singular row gives +inf."""
        out = np.empty(self.r12.shape[0])
        x = np.ascontiguousarray(x, dtype=np.complex128)
        _sk.grid_costs(self.a_pairs, self.g_pairs, self.l_re, self.l_im, x.real.copy(),
                       x.imag.copy(), self.inv_r11, self.r12, self.inv_r22, edge, out)  # fmt: skip
        return out


@functools.lru_cache(maxsize=16)
def _grid(geom: ToolGeometry, n_harmonics: int, max_depth_m: float) -> _GridBases:
    """Coarse grid of (d_a, θ_st, θ_ex) and the factors of its bases (cached per tool)."""
    d = np.linspace(0.03, 0.97, 48) * max_depth_m
    ang = np.linspace(0.0, math.pi, 61)
    st, ex = np.meshgrid(ang, ang, indexing="ij")
    keep = ex > st + 1e-9
    st, ex = st[keep], ex[keep]
    grid = (np.repeat(d, st.size), np.tile(st, d.size), np.tile(ex, d.size))
    k = geom.n_flutes * np.arange(1, n_harmonics + 1, dtype=np.float64)
    a, b = _basis(k[None, :], grid[0][:, None], grid[1][:, None], grid[2][:, None], geom)
    wa = np.hstack([a.real, a.imag])
    wb = np.hstack([b.real, b.imag])
    r11 = np.sqrt(np.sum(wa * wa, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        q1 = np.where(r11[:, None] > 0, wa / r11[:, None], 0.0)
    perp = wb.copy()
    r12 = np.zeros(r11.size)
    for _ in range(2):  # twice is enough: orthogonal to round-off however close B is to A
        s = np.sum(q1 * perp, axis=1)
        perp -= s[:, None] * q1
        r12 += s
    r22 = np.sqrt(np.sum(perp * perp, axis=1))
    nb = np.sqrt(np.sum(wb * wb, axis=1))
    singular = ~(r11 > 0) | ~(r22 > 1e-12 * nb)
    # the factors: a_k, g_k per angle pair (the first depth's rows), L_k per depth
    pa = (g_coeff(k[None, :] - 1, st[:, None], ex[:, None])
          - g_coeff(k[None, :] + 1, st[:, None], ex[:, None])) / 2j  # fmt: skip
    pg = g_coeff(k[None, :], st[:, None], ex[:, None])
    lk = l_coeff(k[None, :], d[:, None], geom)
    points = np.ascontiguousarray(np.stack(grid, axis=1))
    c = np.ascontiguousarray
    with np.errstate(divide="ignore"):
        inv_r11 = np.where(r11 > 0, 1.0 / r11, 0.0)
        inv_r22 = np.where(singular, math.nan, 1.0 / r22)
    return _GridBases(grid, points, c(np.hstack([pa.real, pa.imag]).T),
                      c(np.hstack([pg.real, pg.imag]).T), c(lk.real), c(lk.imag), inv_r11, r12,
                      inv_r22, singular)  # fmt: skip


#: Decision 1557 (the test is compiled: :func:`._spectrum_kernels.local_fit_holds`, which
#: the streaming block's scan applies too).
MISFIT_REVS = _sk.MISFIT_REVS
MISFIT_JUMP = _sk.MISFIT_JUMP
REGRID_REVS = _sk.REGRID_REVS

#: Harmonics of the spindle frequency covered by the coarse grid and the first least-squares
#: stage (16 ω_n: 4 tooth harmonics of a 4-flute tool, 16 of a 1-flute one).
GRID_ORDER = 16


class SpectrumIdentifier:
    """Identify (d_a, θ_st, θ_ex), K_t, K_e, runout and σ from tooth-passing harmonics.

    Parameters
    ----------
    geom : flutes, radius, helix.
    n_harmonics : K, tooth-passing harmonics used (k N, k = 1…K).
    edge : also fit an edge-force coefficient K_e (decision 1525); False is the thesis'
        single-mechanism model.
    max_depth_fraction : largest axial depth searched, as a fraction of the axial pitch d_a,p.
        d_a and d_a,p − d_a give nearly the same harmonics (their |L| are mirror images at the
        tooth-passing harmonics; the angles absorb the phases), so by default the search stays
        below d_a,p/2, which holds every row of Tables 2.3–2.5 (decision 1524).

    The complex harmonics are fitted as α A_k(d_a, θ_st, θ_ex) + β B_k(d_a, θ_st, θ_ex) with
    the real amplitudes α, β eliminated by linear least squares (variable projection), so the
    nonlinear search is over (d_a, θ_st, θ_ex) only; with β = 0 this is the information of
    the thesis' ratio Ψ and notch. Each revolution starts from the previous one's solution; if
    that leaves a relative misfit above ``accept``, least squares also starts from the best
    ``n_starts`` points of a coarse grid (48 depths × 1830 angle pairs, 3°, up to 16 ω_n),
    unless that misfit is within :data:`MISFIT_JUMP` of the last revolutions' (the noise of a
    sensorless torque, not a new engagement) and a grid search ran within
    :data:`REGRID_REVS` revolutions (decision 1557).
    The Levenberg–Marquardt fit is bounded by an active set (decision 1535): a parameter on
    its bound whose descent direction leaves the box (θ_ex = π in down milling, θ_st = 0 in up
    milling) is held, and the fit converges to the bounded least-squares optimum.
    """

    def __init__(
        self,
        geom: ToolGeometry,
        n_harmonics: int = 12,
        edge: bool = True,
        max_depth_fraction: float = 0.5,
    ) -> None:
        self.geom = geom
        self.edge = edge
        self.max_depth_m = max_depth_fraction * geom.axial_pitch_m
        self.k = geom.n_flutes * np.arange(1, n_harmonics + 1, dtype=np.float64)
        self.k_grid = self.k[: max(min(GRID_ORDER // geom.n_flutes, self.k.size), 2)]
        self._grid = _grid(geom, self.k_grid.size, self.max_depth_m)
        self.reset()
        #: relative misfit below which the previous revolution's start is kept (no grid)
        self.accept = 1e-3
        #: least-squares starts taken from the best grid points
        self.n_starts = 6
        dap = geom.axial_pitch_m
        self._lo = np.array([1e-3 * dap, 0.0, 0.0])
        self._hi = np.array([self.max_depth_m, math.pi, math.pi])
        self._scl = np.array([dap, 1.0, 1.0])
        self._kb = geom.tan_beta / geom.radius_m

    def reset(self) -> None:
        """Forget the previous revolution (a new stream)."""
        self._prev: FloatArray | None = None
        #: the misfits of the last revolutions and the revolutions since the last grid search
        #: (layout ``_spectrum_kernels.MST_*``; the streaming block's scan shares it)
        self._mstate = np.zeros(_sk.MST_SIZE)
        #: no running mean's fit here (the streaming block keeps one, decision 1704)
        self._no_anchor = np.zeros(_sk.AST_SIZE)

    def _residual(self, p: FloatArray, x: ComplexArray) -> FloatArray:
        a, b = _basis(self.k[: x.size], p[0], p[1], p[2], self.geom)
        _, _, r = _project(x, a, b if self.edge else None)
        return np.concatenate([r.real, r.imag])

    def identify(
        self,
        x: ComplexArray,
        t1: complex,
        feed_per_tooth_m: float,
        mean_cut_torque_nm: float = math.nan,
        mean_var: float = 1.0,
    ) -> EngagementEstimate:
        """Estimate from the measured T_kN (k = 1…K, ``x``) and T_1 (``t1``); with the mean
        cutting torque T_0 − T_air (``mean_cut_torque_nm``, NaN: no air torque known) where the
        harmonics do not observe K_e (decision 1806; ``mean_var``: its error variance in units
        of the white-noise variance of T_0, 1 for an exactly known air torque)."""
        out = self.identify_array(x, t1, feed_per_tooth_m, mean_cut_torque_nm, mean_var)
        return EngagementEstimate(
            axial_depth_m=float(out[_sk.EST_AXIAL]),
            radial_depth_m=float(out[_sk.EST_RADIAL]),
            entry_rad=float(out[_sk.EST_ENTRY]),
            exit_rad=float(out[_sk.EST_EXIT]),
            kt_n_m2=float(out[_sk.EST_KT]),
            runout_m=float(out[_sk.EST_RUNOUT]),
            runout_angle_rad=float(out[_sk.EST_RUNOUT_ANGLE]),
            reliability=float(out[_sk.EST_RELIABILITY]),
            axial_depth_sd_m=float(out[_sk.EST_AXIAL_SD]),
            notch_index=float(out[_sk.EST_NOTCH]),
            cost=float(out[_sk.EST_COST]),
            edge_n_m=float(out[_sk.EST_EDGE]),
            edge_source=float(out[_sk.EST_EDGE_SOURCE]),
        )

    def identify_array(
        self,
        x: ComplexArray,
        t1: complex,
        feed_per_tooth_m: float,
        mean_cut_torque_nm: float = math.nan,
        mean_var: float = 1.0,
        warm: tuple[FloatArray, float] | None = None,
    ) -> FloatArray:
        """:meth:`identify` as an array of the fields ``_spectrum_kernels.EST_*`` (the
        streaming block's form: one compiled call per revolution on the common path).
        ``warm``: the fit from the previous revolution's solution (point, cost) where the
        caller already made it and it missed the accept misfit (the block's compiled scan)."""
        geom = self.geom
        x = np.ascontiguousarray(x, dtype=np.complex128)
        t1 = complex(t1)
        c = float(feed_per_tooth_m)
        out = np.empty(_sk.EST_SIZE)
        args = (self._kb, self.edge, self._lo, self._hi, self._scl)
        tail = (geom.radius_m, geom.n_flutes, geom.axial_pitch_m, RUNOUT_RCOND)
        mean = (float(mean_cut_torque_nm), float(mean_var))
        prev = self._prev
        accepted = (
            warm is None
            and prev is not None
            and _sk.identify_from(
                prev, x, t1, c, self.k, *args, self.accept, *tail, *mean, out, self._no_anchor
            )
        )
        if not accepted:
            xn, norm = _sk.normalised(x)
            if warm is not None:
                best: tuple[FloatArray, float] | None = (np.array(warm[0]), float(warm[1]))
            else:
                best = None if prev is None else (out[:3].copy(), float(out[_sk.EST_COST]))
            if best is not None and _sk.local_fit_holds(self._mstate, 2.0 * best[1] / norm):
                # the misfit is the noise's of the last revolutions: no new global search
                # (decision 1557)
                self._mstate[_sk.MST_SINCE] += 1.0
            else:
                # the previous revolution's solution does not explain this one: grid starts too
                best = self._grid_search(xn, norm, args, best)
                self._mstate[_sk.MST_SINCE] = 0.0
            _sk.estimate(best[0], best[1], x, t1, c, self.k, self._kb, self.edge, *tail, *mean,
                         self._lo, self._hi, self._scl, out)  # fmt: skip
        self.note_misfit(float(out[_sk.EST_COST]))
        self._prev = out[[_sk.EST_AXIAL, _sk.EST_ENTRY, _sk.EST_EXIT]]
        return out

    def note_misfit(self, misfit: float) -> None:
        """Record a revolution's relative misfit (:meth:`identify_array` does; the streaming
        block's compiled scan for the revolutions it identified)."""
        _sk.note_misfit(self._mstate, misfit)

    def _grid_search(
        self,
        xn: ComplexArray,
        norm: float,
        args: tuple[float, bool, FloatArray, FloatArray, FloatArray],
        best: tuple[FloatArray, float] | None,
    ) -> tuple[FloatArray, float]:
        """The best of ``best`` and Levenberg–Marquardt fits from the :attr:`n_starts` best
        points of the coarse grid (normalised harmonics ``xn``, Σ|xn|² = ``norm``)."""
        ng = self.k_grid.size
        grid = self._grid
        x_low = np.ascontiguousarray(xn[:ng])
        for j in _sk.smallest(grid.costs(x_low, self.edge), self.n_starts):
            # coarse to fine: the low harmonics pin the angles before the high ones, whose
            # phases turn k N times faster with θ, are added
            p0 = grid.points[j].copy()
            low = _sk.lm_fit(p0, x_low, self.k[:ng], *args, 60)
            sol = _sk.lm_fit(low[0], xn, self.k[: xn.size], *args, 60)
            if best is None or sol[1] < best[1]:
                best = sol
            if 2 * best[1] / norm < 1e-8:
                break
        assert best is not None
        return best


#: Profile-likelihood level of the depth interval: Δχ² = 4, two standard deviations of one
#: parameter (decision 1698).
PROFILE_CHI2 = 4.0

#: Fewest revolutions averaged (decision 1698): their scatter gives the harmonics' variances.
AVERAGED_MIN_REVS = 8


@dataclass(frozen=True)
class AveragedEstimate:
    """The engagement of several revolutions of one cut from their averaged harmonics
    (decision 1698): the estimate at the global least-squares optimum, the n revolutions
    averaged, and the profile-likelihood set of d_a (Δχ² ≤ :data:`PROFILE_CHI2`): its lowest
    and highest depth (m; NaN/inf where it reaches the search range's ends) and whether it is
    one interval (``connected``: no second basin of the fit within the noise)."""

    n: int
    estimate: EngagementEstimate
    depth_low_m: float
    depth_high_m: float
    connected: bool


def _estimate_of(out: FloatArray) -> EngagementEstimate:
    """:class:`EngagementEstimate` of an array of the fields ``_spectrum_kernels.EST_*``."""
    return EngagementEstimate(*(float(v) for v in out[: _sk.EST_SIZE]))


def identify_averaged(
    ident: SpectrumIdentifier,
    coeffs: ComplexArray,
    feed_per_tooth_m: FloatArray,
    mean_cut_torque_nm: FloatArray,
    mean_var: FloatArray,
    rel_error: float = 0.0,
) -> AveragedEstimate:
    """The engagement of n ≥ :data:`AVERAGED_MIN_REVS` revolutions of one steady cut (decision
    1698).

    ``coeffs`` (n × (K+1)): each revolution's T_1 and T_kN (k = 1…K), in the spindle angle's
    phase reference, so a steady cut's revolutions add coherently. Their mean has the noise of
    one revolution / √n, which is what separates the fit's basins on a sensorless torque (a
    single revolution's cost is within its noise over most depths). Each harmonic's variance
    (real or imaginary part) is the revolutions' scatter about their mean / n plus
    (``rel_error`` |T̄_kN|)²/2, the relative error of the channel's response model the
    harmonics were equalised by (decision 1554; 0: a dynamometer); the fit is weighted by it
    (χ²), and where χ² at the optimum exceeds its degrees of freedom 2K − 3 − amplitudes (a
    model error or a changing engagement the variances do not hold) the variances are scaled
    up by that ratio.

    The mean is fitted from the coarse grid (no previous revolution) and every depth of the
    grid is refitted over the angles at that depth from its best two angle pairs: the profile
    of χ² over d_a, whose best points start the final fit. The estimate there is one
    revolution's (:func:`._spectrum_kernels.estimate`: K_t, runout, σ), and the depths whose
    profile is within Δχ² ≤ :data:`PROFILE_CHI2` of it form the depth's set: its ends by
    bisection, and whether any grid depth outside them is in it too (a second basin). Seed 004
    Eqs. 2.11-2.13 (the model, :func:`static_harmonics`), 2.19 (K_t), 2.23 (σ)."""
    x_all = np.asarray(coeffs, dtype=np.complex128)
    n = x_all.shape[0]
    if n < AVERAGED_MIN_REVS:
        raise ValueError(f"identify_averaged: needs at least {AVERAGED_MIN_REVS} revolutions")
    mean = x_all.mean(axis=0)
    t1, x = complex(mean[0]), np.ascontiguousarray(mean[1 : ident.k.size + 1])
    nk = x.size
    c = float(np.mean(feed_per_tooth_m))
    t0 = np.asarray(mean_cut_torque_nm, dtype=np.float64)
    t0_mean = float(np.mean(t0)) if np.all(np.isfinite(t0)) else math.nan
    var_factor = float(np.mean(mean_var))
    h = x_all[:, 1 : nk + 1]
    var = 0.5 * (h.real.var(axis=0, ddof=1) + h.imag.var(axis=0, ddof=1)) / n
    var = var + 0.5 * (rel_error * np.abs(x)) ** 2
    xn, norm = _sk.normalised(x)
    ax0 = abs(x[0])
    with np.errstate(divide="ignore"):
        wt = np.where(var > 0, ax0 / np.sqrt(var), 0.0)  # 1/s.d. in the normalised units
    if not np.all(wt > 0):  # a noiseless average: equal weights, χ² from the residual
        wt = np.ones(nk)
    xw = xn * wt
    geom = ident.geom
    kk = ident.k[:nk]
    kb, edge = ident._kb, ident.edge
    lo_b, hi_b, scl = ident._lo, ident._hi, ident._scl

    def fit(
        p0: FloatArray, lo: FloatArray, hi: FloatArray, iters: int = 60
    ) -> tuple[FloatArray, float]:
        return _sk.lm_fit_weighted(p0, xw, kk, kb, edge, lo, hi, scl, iters, wt)

    def at_depth(d: float, starts: list[FloatArray]) -> tuple[FloatArray, float]:
        lo, hi = lo_b.copy(), hi_b.copy()
        lo[0] = hi[0] = d
        best: tuple[FloatArray, float] | None = None
        for p0 in starts:
            sol = fit(p0, lo, hi)
            if best is None or sol[1] < best[1]:
                best = sol
        assert best is not None
        return best

    # the profile over the grid's depths: each depth's best angle pairs (the identifier's
    # coarse grid, its low harmonics' unweighted misfits: the starts) refitted at that depth
    grid = ident._grid
    depths = np.unique(grid.params[0])
    pairs = grid.r12.size // depths.size
    low = np.ascontiguousarray(xn[: ident.k_grid.size])
    rows = grid.costs(low, edge).reshape(depths.size, pairs)
    prof = np.empty(depths.size)
    pts = []
    for i, d in enumerate(depths):
        starts = [grid.points[i * pairs + j] for j in _sk.smallest(rows[i], 2)]
        p, cost = at_depth(float(d), starts)
        prof[i] = cost
        pts.append(p)
    # the global optimum: free fits from the profile's best depths and from the usual search
    first = ident._grid_search(xn, norm, (kb, edge, lo_b, hi_b, scl), None)[0]
    best = fit(first, lo_b, hi_b)
    for i in np.argsort(prof)[:3]:
        sol = fit(pts[i], lo_b, hi_b)
        if sol[1] < best[1]:
            best = sol
    p_hat, c_hat = best
    dof = 2 * nk - 3 - (2 if edge else 1)
    scale = max(1.0, 2.0 * c_hat / max(dof, 1))  # χ²/dof beyond 1: variances scaled up

    def chi2(d: float, start: FloatArray) -> tuple[float, FloatArray]:
        p, cost = at_depth(d, [start, p_hat])
        return 2.0 * (cost - c_hat) / scale, p

    d_hat = float(p_hat[0])
    inside = 2.0 * (prof - c_hat) / scale <= PROFILE_CHI2
    ends = []
    for side in (-1, 1):
        outside = [i for i in range(depths.size) if side * (depths[i] - d_hat) > 0
                   and not inside[i]]  # fmt: skip
        if not outside:  # the set reaches the search range's end on this side
            ends.append(math.nan if side < 0 else math.inf)
            continue
        j = min(outside, key=lambda i: abs(depths[i] - d_hat))
        a, b, start = d_hat, float(depths[j]), p_hat
        for _ in range(40):  # bisection of Δχ²(d) = PROFILE_CHI2 between the fit and depth j
            mid = 0.5 * (a + b)
            val, p = chi2(mid, start)
            if val <= PROFILE_CHI2:
                a, start = mid, p
            else:
                b = mid
            if abs(b - a) < 1e-4 * d_hat:
                break
        ends.append(0.5 * (a + b))
    lo_d, hi_d = ends
    lo_c = lo_d if math.isfinite(lo_d) else 0.0
    connected = not bool(np.any(inside & ((depths < lo_c) | (depths > hi_d))))
    out = np.empty(_sk.EST_SIZE)
    tail = (geom.radius_m, geom.n_flutes, geom.axial_pitch_m, RUNOUT_RCOND)
    cost = _sk.lm_fit(p_hat, xn, kk, kb, edge, lo_b, hi_b, scl, 0)[1]  # unweighted, at p_hat
    _sk.estimate(p_hat, cost, x, t1, c, ident.k, kb, edge, *tail, t0_mean, var_factor, lo_b,
                 hi_b, scl, out)  # fmt: skip
    return AveragedEstimate(n, _estimate_of(out), lo_d, hi_d, connected)
