"""Friction identification from constant-velocity moves (Aslan C1, Ch. 3.2.1).

At constant speed the torque balance (Aslan Eq. 3.1) has no inertia term, so the mean motor
torque ``K_t·ī`` of an air move equals the friction torque at that speed. Fitting
``τ = τ_coul + σ2·ω`` per direction by least squares over several speeds gives the Coulomb and
viscous parameters of the static friction model (the LuGre static parameters of issue 6 extend
this with the Stribeck term: :func:`fit_stribeck`, :func:`lugre_static_from_moves`), the
presliding stiffness and damping come from small motions below breakaway
(:func:`fit_presliding`), and the spindle's Coulomb + viscous from constant-speed runs
(:func:`spindle_friction_from_moves`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from millsense.core.errors import InputDataError
from millsense.models.friction import CoulombViscous
from millsense.models.lugre import lugre_step


@dataclass(frozen=True)
class LineFit:
    """``τ = intercept + slope·|ω|`` for one direction, with the RMS residual (N·m)."""

    intercept: float
    slope: float
    rms_residual: float


def fit_line(speed_rad_s: np.ndarray, torque_nm: np.ndarray) -> LineFit:
    """Least-squares Coulomb (intercept) and viscous (slope) torque for one direction.

    Parameters
    ----------
    speed_rad_s : mean motor speeds of the moves, rad/s, all of one sign (at least two).
    torque_nm : mean motor torques ``K_t·ī`` of the same moves, N·m.
    """
    w = np.abs(np.asarray(speed_rad_s, dtype=float))
    tau = np.abs(np.asarray(torque_nm, dtype=float))
    if len(w) < 2 or np.ptp(w) <= 0:
        raise InputDataError("friction fit needs constant-velocity moves at two speeds or more")
    a = np.column_stack([np.ones_like(w), w])
    coef, *_ = np.linalg.lstsq(a, tau, rcond=None)
    res = tau - a @ coef
    return LineFit(float(coef[0]), float(coef[1]), float(np.sqrt(np.mean(res**2))))


def coulomb_viscous_from_moves(
    speed_rad_s: np.ndarray, torque_nm: np.ndarray, smoothing_rad_s: float = 1e-3
) -> CoulombViscous:
    """Direction-dependent Coulomb + viscous friction from moves in both directions.

    Moves with positive mean speed give the positive-direction parameters, negative ones the
    negative-direction parameters. With moves in one direction only, both directions get the
    same values (stated in the returned model by equal fields).
    """
    w = np.asarray(speed_rad_s, dtype=float)
    tau = np.asarray(torque_nm, dtype=float)
    pos, neg = w > 0, w < 0
    fits = {}
    for name, sel in (("pos", pos), ("neg", neg)):
        if sel.sum() >= 2:
            fits[name] = fit_line(w[sel], tau[sel])
    if not fits:
        raise InputDataError("friction fit needs constant-velocity moves at two speeds or more")
    p = fits.get("pos", fits.get("neg"))
    n = fits.get("neg", p)
    assert p is not None and n is not None
    return CoulombViscous(p.intercept, n.intercept, p.slope, n.slope, smoothing_rad_s)


# ---------------------------------------------------------------------------------------------
# LuGre static parameters (Stribeck curve) per direction
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StribeckFit:
    """Steady-sliding friction of one direction, ``g(|ω|) + σ2·|ω|`` (Aslan Eq. 3.4).

    Attributes
    ----------
    coulomb : τ_coul, N·m.
    static : τ_stat, N·m (equal to ``coulomb`` when no Stribeck rise is resolved).
    stribeck_velocity : v_s, rad/s (NaN when no Stribeck rise is resolved).
    viscous : σ2, N·m·s/rad.
    rms_residual : RMS of the torque residual, N·m.
    resolved : True when the Stribeck rise ``τ_stat − τ_coul`` exceeds three standard errors.
    """

    coulomb: float
    static: float
    stribeck_velocity: float
    viscous: float
    rms_residual: float
    resolved: bool

    def torque(self, speed_rad_s: np.ndarray) -> np.ndarray:
        """Model friction magnitude at speeds ``|ω|`` (rad/s), N·m."""
        w = np.abs(np.asarray(speed_rad_s, dtype=float))
        if not self.resolved:
            return self.coulomb + self.viscous * w
        rise = (self.static - self.coulomb) * np.exp(-((w / self.stribeck_velocity) ** 2))
        return self.coulomb + rise + self.viscous * w


def _stribeck_columns(w: np.ndarray, samples: list[np.ndarray] | None, vs: float) -> np.ndarray:
    """Columns of (τ_coul, τ_stat − τ_coul, σ2) for the mean torque of each move.

    Without speed samples: ``[1, exp(−(w/v_s)²), w]``. With them: the mean over the samples
    of ``[sgn v, sgn v·exp(−(v/v_s)²), v]`` (in the move's direction), so speed fluctuations
    inside a move are modelled instead of smoothing the Stribeck curve.
    """
    if samples is None:
        return np.column_stack([np.ones_like(w), np.exp(-((w / vs) ** 2)), w])
    cols = np.empty((len(samples), 3))
    for j, v in enumerate(samples):
        sg = np.sign(np.mean(v))
        vv = v * sg
        sv = np.sign(vv)
        cols[j] = (np.mean(sv), np.mean(sv * np.exp(-((vv / vs) ** 2))), np.mean(vv))
    return cols


def _stribeck_linear(
    w: np.ndarray, tau: np.ndarray, wt: np.ndarray, vs: float, samples: list[np.ndarray] | None
) -> tuple[np.ndarray, float]:
    """For a fixed v_s the model is linear in (τ_coul, τ_stat − τ_coul, σ2): weighted LS."""
    a = _stribeck_columns(w, samples, vs) * wt[:, None]
    coef, *_ = np.linalg.lstsq(a, tau * wt, rcond=None)
    res = a @ coef - tau * wt
    return coef, float(res @ res)


def fit_stribeck(
    speed_rad_s: np.ndarray,
    torque_nm: np.ndarray,
    std_error_nm: np.ndarray | None = None,
    speed_samples: list[np.ndarray] | None = None,
) -> StribeckFit:
    """Coulomb, static, Stribeck velocity and viscous friction of one direction.

    Parameters
    ----------
    speed_rad_s : mean motor speeds of constant-velocity moves, rad/s, one sign (at least four
        speeds spanning the Stribeck region and the viscous range).
    torque_nm : mean motor torques ``K_t·ī`` of the same moves, N·m.
    std_error_nm : standard error of each mean, N·m (weights); None for equal weights.
    speed_samples : per move, its (smoothed) speed samples, rad/s (:func:`move_means`);
        when given, the model averages the friction over each move's speed fluctuation.

    Returns
    -------
    StribeckFit

    Notes
    -----
    Steady sliding of LuGre (Aslan Eq. 3.2 with dz/dt = 0, Eq. 3.4):
    ``|τ| = τ_coul + (τ_stat − τ_coul)·exp(−(ω/v_s)²) + σ2·|ω|``. Variable projection: for each
    v_s on a logarithmic grid the other three parameters follow by linear least squares; the
    best grid point starts a nonlinear least-squares refinement of all four
    (``scipy.optimize.least_squares``, v_s in log). If the rise ``τ_stat − τ_coul`` is below
    three standard errors the Stribeck term is not resolved and a Coulomb + viscous line is
    returned (decision docs/decisions/0073-friction-identification-issue-6-item-3.md). Under
    closed-loop speed control with torque noise the speed fluctuates inside each move; the mean
    torque is then the Stribeck curve averaged over the fluctuation, which looks like a larger v_s
    (+15 % on the Aslan Z axis at its noise level). With ``speed_samples`` that average is modelled.
    """
    import scipy.optimize

    w = np.abs(np.asarray(speed_rad_s, dtype=float))
    tau = np.abs(np.asarray(torque_nm, dtype=float))
    if len(w) < 4 or len(np.unique(np.round(w, 12))) < 4:
        raise InputDataError("Stribeck fit needs constant-velocity moves at four speeds or more")
    if std_error_nm is None:
        wt = np.ones_like(w)
    else:
        se = np.asarray(std_error_nm, dtype=float)
        wt = 1.0 / np.maximum(se, 1e-6 * max(float(np.max(tau)), 1e-12))
    grid = np.geomspace(0.3 * w.min(), 3.0 * w.max(), 80)
    if speed_samples is not None and len(speed_samples) != len(w):
        raise InputDataError("Stribeck fit: one speed-sample array per move is needed")
    costs = [_stribeck_linear(w, tau, wt, vs, speed_samples)[1] for vs in grid]
    vs0 = float(grid[int(np.argmin(costs))])
    c0, _ = _stribeck_linear(w, tau, wt, vs0, speed_samples)

    def resid(x: np.ndarray) -> np.ndarray:
        tc, rise, lvs, s2 = x
        model = _stribeck_columns(w, speed_samples, math.exp(lvs)) @ np.array([tc, rise, s2])
        return np.asarray((model - tau) * wt)

    x0 = np.array([c0[0], max(c0[1], 0.0), math.log(vs0), c0[2]])
    sol = scipy.optimize.least_squares(
        resid,
        x0,
        bounds=(
            [-np.inf, 0.0, math.log(grid[0]), -np.inf],
            [np.inf, np.inf, math.log(grid[-1]), np.inf],
        ),
        x_scale="jac",
    )
    tc, rise, lvs, s2 = (float(v) for v in sol.x)
    # standard error of the rise from the Jacobian (residuals scaled by the weights)
    dof = max(len(w) - 4, 1)
    s2_res = (
        float(sol.fun @ sol.fun) / dof
        if std_error_nm is None
        else max(float(sol.fun @ sol.fun) / dof, 1.0)
    )
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2_res
        se_rise = math.sqrt(max(float(cov[1, 1]), 0.0))
    except np.linalg.LinAlgError:
        se_rise = math.inf
    if rise > 3.0 * se_rise and rise > 0.0:
        res = resid(sol.x) / wt
        return StribeckFit(tc, tc + rise, math.exp(lvs), s2, float(np.sqrt(np.mean(res**2))), True)
    line = fit_line(w, tau)
    return StribeckFit(
        line.intercept, line.intercept, math.nan, line.slope, line.rms_residual, False
    )


@dataclass(frozen=True)
class LuGreFit:
    """Identified LuGre friction, (+, −) direction pairs as in :class:`FrictionConfig`.

    ``sigma0``/``sigma1`` are None until a presliding test has been fitted.
    """

    positive: StribeckFit
    negative: StribeckFit
    sigma0: tuple[float, float] | None = None
    sigma1: tuple[float, float] | None = None

    def config_table(self) -> dict[str, object]:
        """Keys of ``[axes.<name>.friction]`` (FrictionConfig field names, field units)."""
        p, n = self.positive, self.negative
        out: dict[str, object] = {
            "coulomb_nm": [p.coulomb, n.coulomb],
            "viscous_nm_s_rad": [max(p.viscous, 0.0), max(n.viscous, 0.0)],
        }
        if p.resolved and n.resolved:
            out["static_nm"] = [p.static, n.static]
            out["stribeck_velocity_rad_s"] = [p.stribeck_velocity, n.stribeck_velocity]
        if self.sigma0 is not None and self.sigma1 is not None:
            out["sigma0_nm_rad"] = list(self.sigma0)
            out["sigma1_nm_s_rad"] = list(self.sigma1)
        return out


def lugre_static_from_moves(
    speed_rad_s: np.ndarray,
    torque_nm: np.ndarray,
    std_error_nm: np.ndarray | None = None,
    speed_samples: list[np.ndarray] | None = None,
) -> LuGreFit:
    """Per-direction Stribeck fits (:func:`fit_stribeck`) from moves in both directions.

    Parameters
    ----------
    speed_rad_s : mean motor speed per move, rad/s (signed).
    torque_nm : mean motor torque per move, N·m (signed).
    std_error_nm : standard error of each mean torque, N·m, or None.
    speed_samples : per move, its smoothed speed samples (rad/s), or None.
    """
    w = np.asarray(speed_rad_s, dtype=float)
    tau = np.asarray(torque_nm, dtype=float)
    se = None if std_error_nm is None else np.asarray(std_error_nm, dtype=float)
    fits = []
    for sel, name in ((w > 0, "positive"), (w < 0, "negative")):
        if sel.sum() < 4:
            raise InputDataError(
                f"Stribeck fit: {int(sel.sum())} moves in the {name} direction, needs four or more"
            )
        smp = None if speed_samples is None else [speed_samples[i] for i in np.flatnonzero(sel)]
        fits.append(fit_stribeck(w[sel], tau[sel], None if se is None else se[sel], smp))
    return LuGreFit(fits[0], fits[1])


def steady_segments(
    velocity_ref: np.ndarray, *, min_samples: int, settle_fraction: float = 0.5
) -> list[slice]:
    """Index ranges where the velocity reference is constant and non-zero.

    Parameters
    ----------
    velocity_ref : commanded velocity per sample (any unit).
    min_samples : shortest plateau that counts, samples.
    settle_fraction : leading fraction of each plateau discarded (transients), 0…1.

    Returns
    -------
    list of slices (the steady part of each plateau, in time order).
    """
    v = np.asarray(velocity_ref, dtype=float)
    if len(v) == 0:
        return []
    scale = max(float(np.max(np.abs(v))), 1e-300)
    change = np.flatnonzero(np.abs(np.diff(v)) > 1e-9 * scale) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(v)]])
    out = []
    for a, b in zip(starts, ends, strict=True):
        if b - a >= min_samples and abs(v[a]) > 1e-9 * scale:
            out.append(slice(int(a + settle_fraction * (b - a)), int(b)))
    return out


def move_means(
    speed: np.ndarray, torque: np.ndarray, segments: list[slice], n_sub: int = 10
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean speed, mean torque and the torque's standard error per segment.

    The standard error is the spread of ``n_sub`` sub-window means over √n_sub.
    """
    ws, ts, ses = [], [], []
    for seg in segments:
        tq = np.asarray(torque[seg], dtype=float)
        ws.append(float(np.mean(speed[seg])))
        ts.append(float(np.mean(tq)))
        parts = np.array([np.mean(c) for c in np.array_split(tq, n_sub)])
        ses.append(float(np.std(parts, ddof=1) / math.sqrt(n_sub)))
    return np.array(ws), np.array(ts), np.array(ses)


def move_speed_samples(
    speed: np.ndarray, segments: list[slice], smooth_samples: int = 10
) -> list[np.ndarray]:
    """Per segment, the speed smoothed by a moving average of ``smooth_samples`` (rad/s).

    The moving average removes the encoder's quantisation steps (one count per sample is a
    large speed at low speed) and keeps the physical fluctuation, which lies inside the
    velocity-loop bandwidth.
    """
    kernel = np.ones(smooth_samples) / smooth_samples
    out = []
    for seg in segments:
        v = np.asarray(speed[seg], dtype=float)
        out.append(np.convolve(v, kernel, mode="valid") if len(v) > smooth_samples else v)
    return out


# ---------------------------------------------------------------------------------------------
# Presliding: bristle stiffness σ0 and damping σ1
# ---------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _rigid_lugre(
    torque: np.ndarray, inertia: float, p: np.ndarray, dt: float, substeps: int, out: np.ndarray
) -> None:
    """Motor angle of ``J·dω/dt = τ − τ_f`` with LuGre friction, from rest (semi-implicit)."""
    h = dt / substeps
    z = 0.0
    om = 0.0
    th = 0.0
    for k in range(torque.shape[0]):
        out[k] = th
        for _ in range(substeps):
            z, tf = lugre_step(z, om, h, p)
            om += h * (torque[k] - tf) / inertia
            th += h * om


@dataclass(frozen=True)
class PreslidingFit:
    """Bristle stiffness and damping from a presliding test.

    Attributes
    ----------
    sigma0 : σ0, N·m/rad.
    sigma1 : σ1, N·m·s/rad.
    rms_residual_rad : RMS angle residual, rad.
    peak_angle_rad : largest motion in the record, rad (for judging the test).
    """

    sigma0: float
    sigma1: float
    rms_residual_rad: float
    peak_angle_rad: float


class PreslidingNotIdentified(InputDataError):
    """The presliding record does not identify σ0 (decision 1603): the friction is identified
    without it (static parameters only) and the user is told."""


def fit_presliding(
    current_a: np.ndarray,
    angle_rad: np.ndarray,
    sample_rate_hz: float,
    *,
    inertia_kg_m2: float,
    torque_constant_nm_a: float,
    static: LuGreFit,
    substeps: int = 10,
) -> PreslidingFit:
    """σ0 and σ1 from small motions below breakaway (current steps, drive controller off).

    Parameters
    ----------
    current_a : actual motor current per sample, A (the test: steps of either sign below the
        breakaway current ``τ_stat/K_t``, the drive's position and velocity loops open).
    angle_rad : motor encoder angle per sample, rad (its first sample is taken as rest).
    sample_rate_hz : sampling rate, Hz.
    inertia_kg_m2 : J_e, kg·m² (from :mod:`millsense.ident.drive` or the machine file).
    torque_constant_nm_a : K_t, N·m/A.
    static : the static parameters from constant-velocity moves (:func:`lugre_static_from_moves`).
    substeps : integration steps per sample of the model.

    Returns
    -------
    PreslidingFit (one σ0, σ1 pair for both directions).

    Notes
    -----
    Model: ``J·θ̈ = K_t·i − τ_f`` with LuGre τ_f (Aslan Eq. 3.2–3.4) integrated from rest with
    :func:`millsense.models.lugre.lugre_step`; nonlinear least squares on the angle
    (``scipy.optimize.least_squares``, σ0 and σ1 in log). Below breakaway the motion is the
    bristle spring: deflection ``τ/σ0`` at rest and a resonance ``√(σ0/J)`` damped by σ1 + σ2
    (Aslan Eq. 3.8). The presliding regime does not tell the two directions apart (the bristle
    crosses zero), so one pair is returned for both.
    """
    import scipy.optimize

    i = np.asarray(current_a, dtype=float)
    th = np.asarray(angle_rad, dtype=float) - float(angle_rad[0])
    if len(i) != len(th) or len(i) < 200:
        raise InputDataError(
            f"presliding fit needs equal current and angle records of 200 samples or more "
            f"(got {len(i)} and {len(th)})"
        )
    tau = torque_constant_nm_a * i
    breakaway = min(static.positive.static, static.negative.static)
    if float(np.max(np.abs(tau))) >= breakaway:
        raise InputDataError(
            f"presliding test: torque {float(np.max(np.abs(tau))):.3g} N·m reaches breakaway "
            f"{breakaway:.3g} N·m; use current steps below it"
        )
    if float(np.std(tau)) <= 0.0:
        raise InputDataError("presliding test: the current carries no excitation")
    peak = float(np.max(np.abs(th)))
    if peak <= 0.0:
        raise InputDataError("presliding test: the angle never moves (encoder too coarse?)")
    dt = 1.0 / sample_rate_hz
    p, n = static.positive, static.negative

    def pack(s0: float, s1: float) -> np.ndarray:
        vsp = p.stribeck_velocity if p.resolved else 1.0
        vsn = n.stribeck_velocity if n.resolved else 1.0
        return np.array(
            [
                s0,
                s0,
                s1,
                s1,
                max(p.viscous, 0.0),
                max(n.viscous, 0.0),
                p.static,
                n.static,
                p.coulomb,
                n.coulomb,
                vsp,
                vsn,
            ]
        )

    out = np.empty(len(th))

    def resid(x: np.ndarray) -> np.ndarray:
        _rigid_lugre(tau, inertia_kg_m2, pack(math.exp(x[0]), math.exp(x[1])), dt, substeps, out)
        return np.asarray((out - th) / peak)

    # start: stiffness from the largest quasi-static deflection, damping from Eq. 3.8
    k = int(np.argmax(np.abs(th)))
    s0_start = max(abs(tau[k] / th[k]), 1e-6)
    s1_start = max(2.0 * math.sqrt(inertia_kg_m2 * s0_start), 1e-6)
    best = None
    for f1 in (0.1, 1.0):
        sol = scipy.optimize.least_squares(
            resid, np.log([s0_start, s1_start * f1]), x_scale=1.0, diff_step=1e-4
        )
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    r = resid(best.x) * peak
    sigma0 = float(math.exp(best.x[0]))
    # the fit must be the bristle spring the record shows (decision 1603): the quasi-static
    # deflection of the largest step within a decade of the measured peak, and the angle
    # explained to half its peak; else the record does not identify σ0 (a truth whose motion
    # below breakaway is not LuGre's, an encoder too coarse for it)
    deflection = float(np.max(np.abs(tau))) / sigma0
    rms = float(np.sqrt(np.mean(r**2)))
    if not (0.1 * peak <= deflection <= 10.0 * peak) or rms > 0.5 * peak:
        raise PreslidingNotIdentified(
            f"presliding test: the fit (σ0 {sigma0:.3g} N·m/rad: deflection {deflection:.3g} rad "
            f"against the measured {peak:.3g} rad, residual {rms / peak:.0%} of it) does not "
            "describe the record; identify friction without it"
        )
    return PreslidingFit(sigma0, float(math.exp(best.x[1])), rms, peak)


# ---------------------------------------------------------------------------------------------
# Spindle
# ---------------------------------------------------------------------------------------------


def spindle_friction_from_moves(
    speed_rad_s: np.ndarray, torque_nm: np.ndarray
) -> tuple[float, float]:
    """Spindle Coulomb τ_coul,S (N·m) and viscous B_eS (N·m·s/rad) from constant-speed runs.

    Parameters
    ----------
    speed_rad_s : mean spindle speed per run, rad/s (one direction or both).
    torque_nm : mean motor torque ``K_tS·ī`` per run, N·m (with the K_tS of the speed range
        the run was in).

    Notes
    -----
    Aslan Eq. 5.1–5.2 at constant speed: ``K_tS·I = B_eS·Ω + τ_coul·sgn Ω``; one line through
    |Ω| and |τ| (the spindle model has no direction dependence).
    """
    fit = fit_line(np.asarray(speed_rad_s, dtype=float), np.asarray(torque_nm, dtype=float))
    return fit.intercept, fit.slope
