"""Predicted process states along a tool path: forces, torque, power, chip load, MRR.

For every path step with engagement (:mod:`millsense.plan.cwe`) the mechanistic model of
:mod:`millsense.process.forces` gives the forces over one period of the spindle; this module
reduces them to per-step statistics in the **machine frame**.

Grouping by engagement signature (efficiency)
---------------------------------------------
Many steps share the same engagement (a steady slot, a face pass). Steps are grouped by a
signature: the exact axial depth of a representative step (depths quantised to
``depth_quantum_m``), the per-layer intervals (already quantised to the CWE angle bins; keyed
to 1 µrad) and, only for a tool with runout, the feed per tooth in 0.5 % log bins. Each unique
signature is evaluated once. Without runout the chip thickness is linear in the feed per
tooth c (h = c g(φ), Altintas ch. 2) and the edge terms act where g > 0, so

    F(φ; c) = c F_shear(φ; c = 1) + F_edge(φ)

and one evaluation per signature serves every feed (reference c_ref = 1 m; with runout
c_ref is the bin's feed and the shear part is scaled by c/c_ref, exact to first order in the
bin width). Elemental forces come from :func:`millsense.process.forces.edge_forces` on the
discs of the depth; a compiled kernel sums those inside each signature's intervals (the
projection of :func:`~millsense.process.forces.milling_forces`; tests compare both).

Frames and statistics
---------------------
The process package works in the tool feed frame (x along the XY feed f, y = z × f). Forces
are rotated back with the feed angle θ = atan2(f_y, f_x) of the step:

    F_X = F_x cos θ − F_y sin θ,   F_Y = F_x sin θ + F_y cos θ,   F_Z = F_z.

Period: one tooth period 2π/N for a uniform-pitch tool without runout (the force repeats every
tooth), else one revolution (its mean is the mean of the tooth-period means; its peak the
largest tooth-period peak). Per step: mean F_X, F_Y, F_Z and torque; the peak (signed value at
the largest magnitude) of F_X, F_Y, F_Z; the peak XY resultant √(F_X² + F_Y²) (Aslan
Eq. 5.33) and the force vector there; the peak torque; the resultant of the mean XY force;
power P = T̄ Ω; chip load c = v_f/(N n); MRR = v_f × engaged area. Each force statistic
also has its shear (K_c-proportional) part, so a plan can be rescaled to a new K_tc
(:mod:`millsense.plan.calibration`): means exactly, peaks at the same spindle angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import ConfigError, InputDataError
from millsense.plan import _plan_kernels as _k
from millsense.plan.cwe import EngagementResult
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import edge_forces
from millsense.process.geometry import EndMill

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TWO_PI = 2.0 * math.pi
#: Feed-per-tooth bin width (relative) used for signatures of a tool with runout.
RUNOUT_FEED_BIN = 0.005

#: Names of the per-step statistics in the order of :data:`_k.N_STATS` columns, SI units.
STAT_NAMES: tuple[str, ...] = (
    "fx_avg",
    "fy_avg",
    "fz_avg",
    "torque_avg",
    "fx_avg_shear",
    "fy_avg_shear",
    "fz_avg_shear",
    "torque_avg_shear",
    "fx_peak",
    "fx_peak_shear",
    "fy_peak",
    "fy_peak_shear",
    "fz_peak",
    "fz_peak_shear",
    "fres_peak",
    "fres_peak_x",
    "fres_peak_y",
    "fres_peak_shear_x",
    "fres_peak_shear_y",
    "torque_peak",
    "torque_peak_shear",
)


@dataclass
class ForceBasis:
    """Force series of every unique engagement signature over one period.

    Attributes
    ----------
    shear, edge : (S, A, 4) float
        F_x, F_y, F_z [N] and torque [N·m] in the tool feed frame at A equally spaced spindle
        angles over ``period_rad``: the shear part at feed per tooth ``c_ref_m`` and the edge
        part.
    c_ref_m : (S,) float
        Feed per tooth of the shear series [m] (1 m without runout: the linear case).
    signature : (n,) int
        Signature of every step, −1 where nothing is predicted.
    period_rad : float
        Period of the series (2π/N or 2π).
    """

    shear: FloatArray
    edge: FloatArray
    c_ref_m: FloatArray
    signature: IntArray
    period_rad: float

    @property
    def n_signatures(self) -> int:
        """Number of unique signatures S."""
        return int(self.c_ref_m.size)


@dataclass
class ProcessPrediction:
    """Predicted process states per step (SI units; zero where out of cut).

    Attributes
    ----------
    stats : dict of str to (n,) float
        The statistics of :data:`STAT_NAMES` [N, N·m], machine frame.
    chip_load_m : (n,) float
        Feed per tooth c = v_f/(N n) [m] (0 where the spindle is stopped).
    power_w : (n,) float
        Mean cutting power T̄ Ω [W].
    mrr_m3_s : (n,) float
        Material removal rate v_f × engaged area [m³/s].
    fres_avg_n : (n,) float
        Resultant of the mean XY force √(F̄_X² + F̄_Y²) [N].
    active : (n,) bool
        Steps with a prediction (in cut, feed move, spindle turning).
    basis : ForceBasis
        Series per signature (for rescaling and feed scheduling).
    ktc_scale : float
        Factor applied to the shear coefficients relative to the ``coeffs`` given.
    """

    stats: dict[str, FloatArray]
    chip_load_m: FloatArray
    power_w: FloatArray
    mrr_m3_s: FloatArray
    fres_avg_n: FloatArray
    active: NDArray[np.bool_]
    basis: ForceBasis
    ktc_scale: float = 1.0


def _project(
    dft: FloatArray, dfr: FloatArray, dfa: FloatArray, phi: FloatArray, kappa: FloatArray
) -> FloatArray:
    """Elemental (F_x, F_y, F_z, torque/r) per edge point, as in ``milling_forces``."""
    s, c = np.sin(phi), np.cos(phi)
    sk = np.sin(kappa)[None, None, :]
    ck = np.cos(kappa)[None, None, :]
    radial_out = dfa * ck - dfr * sk
    fx = -dft * c + radial_out * s
    fy = dft * s + radial_out * c
    fz = dfr * ck + dfa * sk
    return np.stack((fx, fy, fz, dft), axis=-1)


def _signatures(
    eng: EngagementResult,
    active: NDArray[np.bool_],
    chip_load_m: FloatArray,
    depth_quantum_m: float,
    runout: bool,
) -> tuple[IntArray, IntArray, FloatArray]:
    """Unique signatures of the active steps: (signature per step, representative, c_ref)."""
    idx = np.flatnonzero(active)
    sig = np.full(len(eng), -1, dtype=np.int64)
    if idx.size == 0:
        return sig, np.zeros(0, dtype=np.int64), np.zeros(0)
    nv = eng.n_intervals[idx].astype(np.int32)
    iv = eng.intervals_rad[idx].astype(np.float64)
    m = iv.shape[2]
    valid = np.arange(m)[None, None, :] < nv[:, :, None]
    q = np.where(valid[..., None], np.round(iv * 1e6), 0.0).astype(np.int32)
    depth_q = np.round(eng.axial_depth_m[idx] / depth_quantum_m).astype(np.int32)
    if runout:
        c_bin = np.round(np.log(np.maximum(chip_load_m[idx], 1e-12)) / RUNOUT_FEED_BIN)
    else:
        c_bin = np.zeros(idx.size)
    key = np.concatenate(
        (depth_q[:, None], c_bin.astype(np.int32)[:, None], nv, q.reshape(idx.size, -1)),
        axis=1,
    )
    key = np.ascontiguousarray(key)
    void = key.view(np.dtype((np.void, key.dtype.itemsize * key.shape[1]))).ravel()
    _, first, inverse = np.unique(void, return_index=True, return_inverse=True)
    sig[idx] = inverse.ravel()
    rep = idx[first]
    c_ref = np.exp(c_bin[first] * RUNOUT_FEED_BIN) if runout else np.ones(first.size)
    return sig, rep, np.asarray(c_ref, dtype=np.float64)


def force_basis(
    eng: EngagementResult,
    tool: EndMill,
    coeffs: CuttingCoefficients,
    active: NDArray[np.bool_],
    chip_load_m: FloatArray,
    *,
    angles_per_rev: int = 720,
    n_discs: int | None = None,
    depth_quantum_m: float = 1e-6,
) -> ForceBasis:
    """Evaluate the force series of every unique engagement signature once.

    Parameters
    ----------
    eng : EngagementResult
        Engagement of every step.
    tool : EndMill
        The tool of ``eng``.
    coeffs : CuttingCoefficients
        Cutting coefficients [N/m², N/m].
    active : (n,) bool
        Steps to predict.
    chip_load_m : (n,) float
        Feed per tooth [m] (used for signatures only when the tool has runout).
    angles_per_rev : int
        Spindle angles per revolution (the series use angles_per_rev/N per tooth period).
    n_discs : int, optional
        Axial discs (default 2 per engagement layer).
    depth_quantum_m : float
        Axial depths closer than this [m] share a signature (evaluated at the representative
        step's exact depth).

    Returns
    -------
    ForceBasis
    """
    if angles_per_rev < 8:
        raise ConfigError(f"predict: angles_per_rev must be ≥ 8, got {angles_per_rev!r}")
    if not depth_quantum_m > 0:
        raise ConfigError(f"predict: depth_quantum_m must be > 0, got {depth_quantum_m!r}")
    runout = tool.runout_offset_m > 0.0
    uniform = tool.pitch_angles_rad is None or np.allclose(
        tool.pitches_rad, _TWO_PI / tool.n_flutes
    )
    period = _TWO_PI / tool.n_flutes if (uniform and not runout) else _TWO_PI
    n_ang = max(round(angles_per_rev * period / _TWO_PI), 4)
    angles: FloatArray = np.arange(n_ang, dtype=np.float64) * (period / n_ang)
    nd = int(n_discs) if n_discs is not None else 2 * eng.n_layers
    sig, rep, c_ref = _signatures(eng, active, chip_load_m, depth_quantum_m, runout)
    n_sig = rep.size
    shear = np.zeros((n_sig, n_ang, 4))
    edge = np.zeros((n_sig, n_ang, 4))
    if n_sig == 0:
        return ForceBasis(shear, edge, c_ref, sig, period)
    k_shear = CuttingCoefficients(coeffs.ktc, coeffs.krc, coeffs.kac)
    k_edge = CuttingCoefficients(0.0, 0.0, 0.0, coeffs.kte, coeffs.kre, coeffs.kae)
    full = Engagement.from_intervals([(0.0, _TWO_PI)])
    depth = eng.axial_depth_m[rep]
    groups: dict[tuple[float, float], list[int]] = {}
    for s in range(n_sig):
        groups.setdefault((float(depth[s]), float(c_ref[s])), []).append(s)
    n_layers = eng.n_layers
    for (a_m, c_m), members in groups.items():
        discs = tool.discs(a_m, nd)
        phi = tool.immersion_angles(angles, discs)  # (A, N, D)
        ws = edge_forces(tool, k_shear, full, c_m, angles, discs)
        we = edge_forces(tool, k_edge, full, c_m, angles, discs)
        radii = tool.flute_radii_m(discs)[None, :, :]
        w = np.concatenate(
            (
                _project(ws[0], ws[1], ws[2], phi, discs.kappa_rad),
                _project(we[0], we[1], we[2], phi, discs.kappa_rad),
            ),
            axis=-1,
        )
        w[..., 3] *= radii
        w[..., 7] *= radii
        layer = np.clip(np.floor(discs.axial_fraction * n_layers), 0, n_layers - 1)
        disc_layer = np.tile(layer.astype(np.int64), tool.n_flutes)  # k = j·D + d
        mem = np.asarray(members, dtype=np.int64)
        steps = rep[mem]
        out = np.zeros((mem.size, n_ang, 8))
        _k.masked_sums(
            np.ascontiguousarray(phi.reshape(n_ang, -1)),
            disc_layer,
            np.ascontiguousarray(eng.intervals_rad[steps].astype(np.float64)),
            np.ascontiguousarray(eng.n_intervals[steps].astype(np.int64)),
            np.ascontiguousarray(w.reshape(n_ang, -1, 8)),
            out,
        )
        shear[mem] = out[..., :4]
        edge[mem] = out[..., 4:]
    return ForceBasis(shear, edge, c_ref, sig, period)


def evaluate(
    basis: ForceBasis,
    chip_load_m: FloatArray,
    feed_angle_rad: FloatArray,
    ktc_scale: float = 1.0,
) -> dict[str, FloatArray]:
    """Per-step statistics (machine frame) from a basis at given feeds per tooth.

    Parameters
    ----------
    basis : ForceBasis
        From :func:`force_basis`.
    chip_load_m : (n,) float
        Feed per tooth of every step [m].
    feed_angle_rad : (n,) float
        XY feed direction θ [rad].
    ktc_scale : float
        Factor on the shear coefficients (K_tc, K_rc, K_ac) relative to the basis.

    Returns
    -------
    dict
        :data:`STAT_NAMES` → (n,) arrays [N, N·m].
    """
    sig = basis.signature
    n = sig.size
    c = np.asarray(chip_load_m, dtype=float)
    th = np.asarray(feed_angle_rad, dtype=float)
    if c.shape != (n,) or th.shape != (n,):
        raise InputDataError(f"predict: chip load and feed angle must have {n} values")
    factor = np.zeros(n)
    on = sig >= 0
    factor[on] = c[on] / basis.c_ref_m[sig[on]]
    out = np.zeros((n, _k.N_STATS))
    _k.step_stats(
        basis.shear,
        basis.edge,
        np.ascontiguousarray(sig),
        factor,
        float(ktc_scale),
        np.cos(th),
        np.sin(th),
        out,
    )
    return {name: np.ascontiguousarray(out[:, i]) for i, name in enumerate(STAT_NAMES)}


def chip_load(feed_m_s: FloatArray, spindle_speed_rad_s: FloatArray, n_flutes: int) -> FloatArray:
    """Feed per tooth c = v_f / (N Ω/2π) [m]; 0 where the spindle is stopped.

    Parameters
    ----------
    feed_m_s : (n,) float
        Feed along the path [m/s].
    spindle_speed_rad_s : (n,) float
        Spindle speed Ω [rad/s].
    n_flutes : int
        Number of flutes N.
    """
    f = np.asarray(feed_m_s, dtype=float)
    w = np.asarray(spindle_speed_rad_s, dtype=float)
    out = np.zeros(np.broadcast(f, w).shape)
    turning = w > 0
    out[turning] = (f * _TWO_PI / n_flutes)[turning] / w[turning]
    return out


def predict_states(
    eng: EngagementResult,
    coeffs: CuttingCoefficients,
    feed_m_s: FloatArray,
    spindle_speed_rad_s: FloatArray,
    *,
    active: NDArray[np.bool_] | None = None,
    angles_per_rev: int = 720,
    n_discs: int | None = None,
    depth_quantum_m: float = 1e-6,
) -> ProcessPrediction:
    """Predicted forces, torque, power, chip load and MRR at every step.

    Parameters
    ----------
    eng : EngagementResult
        Engagement of every step (its tool is used).
    coeffs : CuttingCoefficients
        Cutting coefficients [N/m², N/m].
    feed_m_s : (n,) float
        Feed along the path [m/s] at every step.
    spindle_speed_rad_s : (n,) float
        Spindle speed Ω [rad/s] at every step.
    active : (n,) bool, optional
        Steps to predict (default: in cut with feed and spindle speed > 0).
    angles_per_rev, n_discs, depth_quantum_m
        See :func:`force_basis`.

    Returns
    -------
    ProcessPrediction

    Notes
    -----
    Module docstring: signatures, linearity in c, frames and statistics. Chip load
    c = v_f 2π/(N Ω); MRR = v_f A_e with A_e the engaged area normal to the feed
    (:class:`~millsense.plan.cwe.EngagementResult`); P = T̄ Ω.
    """
    n = len(eng)
    f = np.asarray(feed_m_s, dtype=float)
    w = np.asarray(spindle_speed_rad_s, dtype=float)
    if f.shape != (n,) or w.shape != (n,):
        raise InputDataError(f"predict: feed and spindle speed must have {n} values each")
    tool = eng.tool
    c = chip_load(f, w, tool.n_flutes)
    if active is None:
        act = eng.in_cut & (f > 0) & (w > 0)
    else:
        act = np.asarray(active, dtype=bool) & eng.in_cut & (w > 0)
    basis = force_basis(
        eng,
        tool,
        coeffs,
        act,
        c,
        angles_per_rev=angles_per_rev,
        n_discs=n_discs,
        depth_quantum_m=depth_quantum_m,
    )
    stats = evaluate(basis, c, eng.feed_angle_rad)
    return ProcessPrediction(
        stats=stats,
        chip_load_m=np.where(act, c, 0.0),
        power_w=stats["torque_avg"] * np.where(act, w, 0.0),
        mrr_m3_s=np.where(act, f * eng.engaged_area_m2, 0.0),
        fres_avg_n=np.hypot(stats["fx_avg"], stats["fy_avg"]),
        active=act,
        basis=basis,
    )
