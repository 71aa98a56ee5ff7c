"""Rigid-body and ball-screw drive parameters and dead times from drive tests (seed 001 C11).

Two tests:

- **Acceleration test** (:func:`rigid_body_from_acceleration`): motor current and speed during
  accelerating moves; the rigid-body balance ``J_e·dω/dt = K_t·i − τ_c·sgn ω − B·ω`` (Aslan
  Eq. 3.1, Yamada Eq. 2-7) integrated over windows is linear in ``K_t/J_e``, ``τ_c/J_e`` and
  ``B/J_e``. Only the ratio ``K_t/J_e`` is observable from current and motion: one of the two
  must be known (the motor's catalogue K_t, or a known inertia — decision
  docs/decisions/0074-drive-identification-issue-6-item-4.md).
- **Swept FRFs** (:func:`fit_dual_inertia`): current command → motor angle and → table position
  from a periodic current injection on top of a constant-velocity move (the velocity never
  reverses, so Coulomb friction is a constant). The FRFs are estimated against the injected
  reference (:func:`reference_frf`; unbiased under the closed position/velocity loops), turned
  into accelerations by ``(jω)²`` and fitted by frequency-domain nonlinear least squares with
  the dual-inertia model (Yamada Eq. 2-1/2-2), the known current loop ``ω_cc/(s + ω_cc)``, the
  zero-order hold of the sampled command and the dead times ``e^{−s(T_s+T_m)}`` (motor) and
  ``e^{−s(T_s+T_t)}`` (table). T_s follows from the current command → actual current FRF
  (:func:`fit_amplifier_delay`). :func:`compensation_delays` turns (T_s, T_m, T_t) into the
  observer's phase-lag compensation (T1, T2, T3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from millsense.core.errors import InputDataError
from millsense.ident.frf import FrfEstimate, check_records

# ---------------------------------------------------------------------------------------------
# Acceleration test: J_e and K_t
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RigidBodyFit:
    """Rigid-body drive parameters from an acceleration test (motor side).

    Attributes
    ----------
    inertia : J_e, kg·m².
    torque_constant : K_t, N·m/A.
    coulomb : (+, −) Coulomb torque, N·m.
    viscous : (+, −) viscous coefficient B, N·m·s/rad.
    gain_ratio : K_t/J_e, the quantity the test observes, A⁻¹·s⁻²·N·m/(kg·m²).
    rms_residual : RMS residual of the windowed speed change, rad/s.
    """

    inertia: float
    torque_constant: float
    coulomb: tuple[float, float]
    viscous: tuple[float, float]
    gain_ratio: float
    rms_residual: float


def rigid_body_from_acceleration(
    current_a: np.ndarray,
    speed_rad_s: np.ndarray,
    sample_rate_hz: float,
    *,
    torque_constant_nm_a: float | None = None,
    inertia_kg_m2: float | None = None,
    window_s: float = 0.01,
    min_speed_rad_s: float = 1.0,
) -> RigidBodyFit:
    """J_e (or K_t), Coulomb and viscous friction from accelerating and decelerating moves.

    Parameters
    ----------
    current_a : actual motor current per sample, A.
    speed_rad_s : motor speed per sample (encoder difference), rad/s.
    sample_rate_hz : sampling rate, Hz.
    torque_constant_nm_a : K_t if known (catalogue), N·m/A; then J_e is identified.
    inertia_kg_m2 : J_e if known, kg·m²; then K_t is identified. Give exactly one.
    window_s : integration window, s.
    min_speed_rad_s : windows in which |ω| drops below this are not used (presliding and
        reversals, where LuGre's bristle damping acts), rad/s.

    Notes
    -----
    Over a window ``[t_a, t_b]``: ``ω_b − ω_a = (K_t/J)∫i − (τ_c+/J)∫[ω>0] + (τ_c−/J)∫[ω<0]
    − (B±/J)∫ω`` (Aslan Eq. 3.1 integrated, friction per direction), solved by linear least
    squares over non-overlapping windows. Integrating avoids differentiating the quantised
    encoder speed.
    """
    if (torque_constant_nm_a is None) == (inertia_kg_m2 is None):
        raise InputDataError(
            "acceleration test: give exactly one known quantity, the torque constant or the "
            "inertia (current and motion only fix their ratio)"
        )
    # the current is checked for excitation and clipping; the speed (flat while cruising) only
    # for length and finite samples
    i, _ = check_records(current_a, current_a, sample_rate_hz, names=("current", "current"))
    w = np.asarray(speed_rad_s, dtype=float)
    if w.shape != i.shape or not np.all(np.isfinite(w)):
        raise InputDataError(
            f"acceleration test: channel 'speed' must be finite with {len(i)} samples like "
            "'current'"
        )
    dt = 1.0 / sample_rate_hz
    m = max(2, round(window_s * sample_rate_hz))
    n_win = (len(i) - 1) // m
    if n_win < 8:
        raise InputDataError(
            f"acceleration test: {len(i)} samples give {n_win} windows of {m}; needs 8 or more"
        )
    if float(np.ptp(w)) <= 0.0:
        raise InputDataError("acceleration test: channel 'speed' never changes (no motion)")
    # windowed integrals; speed sample k is the mean over (k−1, k], the current is held
    pos, neg = (w > 0).astype(float), (w < 0).astype(float)
    cols = np.column_stack([i, -pos, neg, -w * pos, -w * neg]) * dt
    csum = np.vstack([np.zeros(cols.shape[1]), np.cumsum(cols, axis=0)])
    idx = np.arange(n_win + 1) * m
    a = csum[idx[1:]] - csum[idx[:-1]]
    b = w[idx[1:]] - w[idx[:-1]]
    # windows that pass through presliding (|ω| below min_speed) are dropped: there the
    # bristle damping σ1·dz/dt of LuGre (Aslan Eq. 3.2) acts like a large viscous term
    slow = np.abs(w) < min_speed_rad_s
    cs = np.concatenate([[0], np.cumsum(slow)])
    keep = (cs[idx[1:] + 1] - cs[idx[:-1]]) == 0
    if keep.sum() < 8:
        raise InputDataError(
            f"acceleration test: {int(keep.sum())} windows above {min_speed_rad_s:g} rad/s; "
            "needs 8 or more"
        )
    a, b = a[keep], b[keep]
    # a direction never visited leaves its columns empty: drop them
    used = np.flatnonzero(np.any(a != 0.0, axis=0))
    sol, *_ = np.linalg.lstsq(a[:, used], b, rcond=None)
    coef = np.zeros(5)
    coef[used] = sol
    a = a[:, used]
    coef_used = sol
    res = a @ coef_used - b
    ratio = float(coef[0])
    if not ratio > 0:
        raise InputDataError("acceleration test: current and acceleration are not correlated")
    if torque_constant_nm_a is not None:
        kt = float(torque_constant_nm_a)
        j = kt / ratio
    else:
        assert inertia_kg_m2 is not None
        j = float(inertia_kg_m2)
        kt = j * ratio
    return RigidBodyFit(
        inertia=j,
        torque_constant=kt,
        coulomb=(float(coef[1]) * j, float(coef[2]) * j),
        viscous=(float(coef[3]) * j, float(coef[4]) * j),
        gain_ratio=ratio,
        rms_residual=float(np.sqrt(np.mean(res**2))),
    )


# ---------------------------------------------------------------------------------------------
# FRFs against the injected reference
# ---------------------------------------------------------------------------------------------


def reference_frf(
    reference: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    sample_rate_hz: float,
    period_samples: int,
    *,
    skip_periods: int = 1,
    detrend: bool = False,
    names: tuple[str, str, str] = ("reference", "input", "output"),
) -> FrfEstimate:
    """FRF y/u of a plant inside a feedback loop from a periodic reference r (joint I/O).

    Parameters
    ----------
    reference : the injected periodic signal r (e.g. a current injection), any unit.
    u : plant input (e.g. the total current command), unit U.
    y : plant output (e.g. motor angle), unit Y.
    sample_rate_hz : Hz.
    period_samples : samples per period of r.
    skip_periods : leading periods discarded (transient).
    detrend : remove a least-squares line from y first (a constant-velocity ramp).
    names : channel names for the messages.

    Returns
    -------
    FrfEstimate at the lines r excites; ``h1 = h2 = Ȳ/Ū`` (period-averaged spectra) and a
    coherence-like quality ``γ² = |Ȳ|²/mean|Y_p|²`` of the output (1 for noise-free data).

    Notes
    -----
    ``Y/R ÷ U/R`` (Pintelon & Schoukens, indirect method): noise that the loop feeds back into
    u is uncorrelated with r, so the ratio is unbiased where H1 from u would not be.
    """
    check_records(reference, u, sample_rate_hz, names=names[:2])
    r = np.asarray(reference, dtype=float)
    ua = np.asarray(u, dtype=float)
    ya = np.asarray(y, dtype=float)
    if len(ya) != len(r) or not np.all(np.isfinite(ya)):
        raise InputDataError(f"channel {names[2]!r} must be finite and as long as {names[0]!r}")
    if detrend:
        t = np.arange(len(ya), dtype=float)
        ya = ya - np.polyval(np.polyfit(t, ya, 1), t)
    n_per = len(r) // period_samples - skip_periods
    if n_per < 2:
        raise InputDataError(
            f"channel {names[0]!r} holds {len(r) // period_samples} periods of {period_samples} "
            f"samples; needs {skip_periods + 2} or more"
        )
    a, b = skip_periods * period_samples, (skip_periods + n_per) * period_samples

    def spec(x: np.ndarray) -> np.ndarray:
        return np.fft.rfft(x[a:b].reshape(n_per, period_samples), axis=1)

    R, U, Y = spec(r), spec(ua), spec(ya)
    f = np.fft.rfftfreq(period_samples, 1.0 / sample_rate_hz)
    rm = np.mean(np.abs(R) ** 2, axis=0)
    rm[0] = 0.0  # the mean (a constant speed) is not excitation
    sel = np.flatnonzero((rm > 1e-6 * rm.max()) & (f > 0))
    um, ym = np.mean(U[:, sel], axis=0), np.mean(Y[:, sel], axis=0)
    h = ym / um
    coh = np.abs(ym) ** 2 / np.maximum(np.mean(np.abs(Y[:, sel]) ** 2, axis=0), 1e-300)
    return FrfEstimate(
        np.asarray(f[sel], dtype=float), h, h.copy(), np.clip(coh, 0, 1), n_per, "reference"
    )


# ---------------------------------------------------------------------------------------------
# Dual-inertia model and fit
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DualInertiaParams:
    """Yamada Eq. 2-1/2-2 parameters (Table 3-3 symbols) and dead times.

    Attributes
    ----------
    screw_inertia : J_r, kg·m².
    table_mass : M_t, kg.
    axial_stiffness : K_r, N/m.
    axial_damping : C_k, N·s/m.
    table_damping : C_t, N·s/m.
    rotary_damping : D_r, N·m·s/rad.
    dead_time_amplifier : T_s, s.
    dead_time_motor : T_m, s.
    dead_time_table : T_t, s.
    """

    screw_inertia: float
    table_mass: float
    axial_stiffness: float
    axial_damping: float
    table_damping: float
    rotary_damping: float
    dead_time_amplifier: float = 0.0
    dead_time_motor: float = 0.0
    dead_time_table: float = 0.0

    def resonance_hz(self, lead_m: float) -> float:
        """ω_s/2π with ``ω_s = √((α+1)K_r/M_t)``, ``α = M_t R²/J_r`` (Yamada Eq. 2-5/2-6)."""
        r = lead_m / (2.0 * math.pi)
        alpha = self.table_mass * r * r / self.screw_inertia
        return math.sqrt((alpha + 1.0) * self.axial_stiffness / self.table_mass) / (2 * math.pi)


def dual_inertia_frf(
    p: DualInertiaParams, lead_m: float, freq_hz: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Motor angle / torque (rad/(N·m)) and table position / torque (m/(N·m)), no delays.

    Notes
    -----
    Yamada Eq. 2-1/2-2 without friction: with ``Z(s)`` the dynamic stiffness matrix of
    ``[θ_m, x_t]``, ``θ_m/τ = Z_22/det Z``, ``x_t/τ = R(C_k s + K_r)/det Z``.
    """
    r = lead_m / (2.0 * math.pi)
    s = 2j * math.pi * np.asarray(freq_hz, dtype=float)
    spring = p.axial_damping * s + p.axial_stiffness
    z11 = p.screw_inertia * s * s + p.rotary_damping * s + r * r * spring
    z22 = p.table_mass * s * s + p.table_damping * s + spring
    det = z11 * z22 - (r * spring) ** 2
    return z22 / det, r * spring / det


def zoh_factor(freq_hz: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """``(1 − e^{−jωT})/(jωT)``: a held command sampled at the same instants as the outputs."""
    wt = 2.0 * math.pi * np.asarray(freq_hz, dtype=float) / sample_rate_hz
    return np.asarray(np.exp(-0.5j * wt) * np.sinc(wt / (2.0 * math.pi)))


@dataclass(frozen=True)
class DriveFit:
    """Result of :func:`fit_dual_inertia`.

    Attributes
    ----------
    params : identified parameters (T_s as given; T_m, T_t from the phase).
    motor_delay : T_s + T_m, s.
    table_delay : T_s + T_t, s.
    rms_log_error : RMS of the complex log residual over both FRFs (≈ relative error).
    freq_hz, motor_accel, table_accel : the measured accelerance FRFs (rad/s²/A, m/s²/A).
    model_motor, model_table : the fitted model on ``freq_hz`` (same units, with delays).
    """

    params: DualInertiaParams
    motor_delay: float
    table_delay: float
    rms_log_error: float
    freq_hz: np.ndarray
    motor_accel: np.ndarray
    table_accel: np.ndarray
    model_motor: np.ndarray
    model_table: np.ndarray
    unmodelled_mode_hz: float | None = None


def _model(
    x: np.ndarray,
    f: np.ndarray,
    lead_m: float,
    kt: float,
    current_loop_hz: float,
    fs: float,
) -> tuple[np.ndarray, np.ndarray]:
    m = np.exp(x[:6])
    p = DualInertiaParams(
        float(m[0]), float(m[1]), float(m[2]), float(m[3]), float(m[4]), float(m[5])
    )
    hm, ht = dual_inertia_frf(p, lead_m, f)
    s = 2j * math.pi * f
    wc = 2.0 * math.pi * current_loop_hz
    common = kt * (wc / (s + wc)) * zoh_factor(f, fs) * s * s
    return common * hm * np.exp(-s * x[6]), common * ht * np.exp(-s * x[7])


def _first_ratio_peak(f: np.ndarray, ratio: np.ndarray, r: float) -> float:
    """Frequency of the lowest line where |x_t/θ_m| exceeds 2·R and is the largest within
    ±20 % of its frequency (the global maximum when there is none), Hz."""
    for k in np.nonzero(ratio > 2.0 * r)[0]:
        near = (f >= f[k] / 1.2) & (f <= f[k] * 1.2)
        if ratio[k] >= ratio[near].max():
            return float(f[k])
    return float(f[int(np.argmax(ratio))])


def first_unmodelled_mode_hz(
    motor: FrfEstimate,
    table: FrfEstimate,
    lead_m: float,
    f_max_hz: float,
    quantity: str = "displacement",
    f_min_hz: float = 10.0,
    min_coherence: float = 0.5,
) -> float | None:
    """The lowest resonance of the motor accelerance that the dual-inertia model cannot have,
    Hz, or None.

    The dual-inertia accelerance ``s²·θ_m/I`` has one anti-resonance (ω_t, the peak of
    |x_t/θ_m|) and one resonance just above it, then falls to K_t/J_r. A local maximum of
    |s²·θ_m/I| between 1.6·ω_t and ``f_max_hz`` that rises 6 dB above the accelerance at
    1.6·ω_t is another mode (Yamada §3.4: the screw torsional mode of machine B, seen as a
    sharp peak above the axial resonance); the dual-inertia fit's band must end below it and
    a notch may remove it. Refined by a parabola through the peak's neighbours in dB.
    ``quantity`` says what the FRFs' outputs are (``displacement`` or ``acceleration``); only
    lines from ``f_min_hz`` with both coherences ≥ ``min_coherence`` are used.
    """
    ok = (
        (motor.freq_hz >= f_min_hz)
        & (motor.coherence >= min_coherence)
        & (table.coherence >= min_coherence)
    )
    f = motor.freq_hz[ok]
    hm, ht = motor.h1[ok], table.h1[ok]
    if len(f) < 3:
        return None
    r = lead_m / (2.0 * math.pi)
    f_t = _first_ratio_peak(f, np.abs(ht / hm), r)
    acc = np.abs(hm) * ((2.0 * math.pi * f) ** 2 if quantity == "displacement" else 1.0)
    idx = np.nonzero((f >= 1.6 * f_t) & (f <= f_max_hz))[0]
    if len(idx) < 3:
        return None
    k = int(idx[int(np.argmax(acc[idx]))])
    if k in (idx[0], idx[-1]) or acc[k] < 2.0 * acc[idx[0]]:
        return None
    y0, y1, y2 = (20.0 * np.log10(acc[j]) for j in (k - 1, k, k + 1))
    shift = 0.5 * (y0 - y2) / (y0 - 2.0 * y1 + y2)
    return float(f[k] + shift * (f[k + 1] - f[k]))


def fit_dual_inertia(
    motor: FrfEstimate,
    table: FrfEstimate,
    *,
    lead_m: float,
    torque_constant_nm_a: float,
    current_loop_hz: float,
    sample_rate_hz: float,
    amplifier_delay_s: float = 0.0,
    band_hz: tuple[float, float] = (10.0, 1000.0),
    min_coherence: float = 0.5,
    quantity: str = "displacement",
    stop_below_unmodelled: bool = True,
) -> DriveFit:
    """Dual-inertia parameters and dead times from the two swept FRFs (Yamada C11, Table 3-3).

    Parameters
    ----------
    motor : FRF current command → motor angle (rad/A) or motor acceleration (rad/s²/A).
    table : FRF current command → table position (m/A) or acceleration (m/s²/A).
    lead_m : ball-screw lead ℓ, m (R = ℓ/2π).
    torque_constant_nm_a : K_t, N·m/A — the one known quantity (catalogue); every other
        parameter scales with it.
    current_loop_hz : current-loop bandwidth ω_cc/2π, Hz (first order, Yamada Table 3-2).
    sample_rate_hz : CNC sample rate, Hz (the command is held, :func:`zoh_factor`).
    amplifier_delay_s : T_s from :func:`fit_amplifier_delay` (0: T_m, T_t absorb it).
    band_hz : frequency band fitted, Hz.
    min_coherence : lines below this coherence are dropped.
    quantity : ``displacement`` or ``acceleration``: what the FRFs' outputs are.
    stop_below_unmodelled : end the band at 0.9 of the first mode above the axial one that the
        model cannot have (:func:`first_unmodelled_mode_hz`, e.g. the screw torsion of Yamada
        §3.4): left in the band it pulls J_r towards the motor's own inertia and K_r towards
        the coupling's (decision 1705).

    Returns
    -------
    DriveFit

    Notes
    -----
    Model ``K_t·ω_cc/(s+ω_cc)·ZOH(s)·s²·{θ_m, x_t}/τ(s)·e^{−sT}`` (:func:`dual_inertia_frf`);
    residual ``log(H_model/H_meas)`` (real: log-magnitude, imaginary: phase) on both FRFs,
    ``scipy.optimize.least_squares`` over the logarithms of the six mechanical parameters and
    the two delays. Start: K_t/J_a from the low-frequency accelerance, K_t/J_r from the
    high-frequency one, K_r from the anti-resonance, damping ratios 0.05, delays from a grid.
    """
    if quantity not in ("displacement", "acceleration"):
        raise InputDataError(f"quantity {quantity!r}: use 'displacement' or 'acceleration'")
    if len(motor.freq_hz) != len(table.freq_hz) or not np.allclose(motor.freq_hz, table.freq_hz):
        raise InputDataError("motor and table FRFs must share their frequency lines")
    f = motor.freq_hz
    f_extra = (
        first_unmodelled_mode_hz(
            motor, table, lead_m, band_hz[1], quantity, band_hz[0], min_coherence
        )
        if stop_below_unmodelled
        else None
    )
    if f_extra is not None:
        band_hz = (band_hz[0], min(band_hz[1], 0.9 * f_extra))
    sel = (
        (f >= band_hz[0])
        & (f <= band_hz[1])
        & (motor.coherence >= min_coherence)
        & (table.coherence >= min_coherence)
    )
    if sel.sum() < 12:
        raise InputDataError(
            f"dual-inertia fit: {int(sel.sum())} usable FRF lines in {band_hz[0]:g}-"
            f"{band_hz[1]:g} Hz (coherence ≥ {min_coherence}); needs 12 or more"
        )
    f = f[sel]
    s = 2j * math.pi * f
    conv = s * s if quantity == "displacement" else np.ones_like(s)
    hm = motor.h1[sel] * conv
    ht = table.h1[sel] * conv
    r = lead_m / (2.0 * math.pi)
    kt = torque_constant_nm_a
    # ---- start values from the accelerance's asymptotes and the anti-resonance
    mag = np.abs(hm)
    # the table/motor ratio R(C_k s + K_r)/(M_t s² + (C_t + C_k)s + K_r) peaks at ω_t; a real
    # drive has more modes (a screw torsional mode puts another anti-resonance into the motor
    # FRF, another peak of the ratio), so ω_t is the lowest peak above 2·R (6 dB over the
    # rigid-body value R) that dominates ±20 % around it: the axial mode the model describes
    f_t = _first_ratio_peak(f, np.abs(ht / hm), lead_m / (2.0 * math.pi))
    lo = (f > 0.1 * f_t) & (f < 0.4 * f_t)
    hi = f > 1.8 * f_t
    if lo.sum() < 2 or hi.sum() < 2:
        raise InputDataError(
            f"dual-inertia fit: the band {band_hz[0]:g}-{band_hz[1]:g} Hz must extend from "
            f"below {0.1 * f_t:.0f} Hz to above {1.8 * f_t:.0f} Hz around the anti-resonance"
        )
    j_a = kt / float(np.median(mag[lo]))
    j_r = min(kt / float(np.median(mag[hi])), 0.95 * j_a)
    m_t = (j_a - j_r) / (r * r)
    k_r = m_t * (2.0 * math.pi * f_t) ** 2
    w_t = 2.0 * math.pi * f_t
    c0 = 2.0 * 0.05 * w_t * m_t
    x_mech = np.log([j_r, m_t, k_r, c0, c0, c0 * r * r])
    # weights: inverse noise-to-signal ratio of each line (coherence), capped
    coh = np.minimum(motor.coherence[sel], table.coherence[sel])
    wt = np.sqrt(np.clip(coh / np.maximum(1.0 - coh, 1e-4), 0.0, 100.0))
    wt2 = np.concatenate([wt, wt])

    def resid(x: np.ndarray) -> np.ndarray:
        mm, mt = _model(x, f, lead_m, kt, current_loop_hz, sample_rate_hz)
        e = np.concatenate([np.log(mm / hm), np.log(mt / ht)])
        return np.concatenate([e.real * wt2, np.angle(np.exp(1j * e.imag)) * wt2])

    # delays: grid for each FRF with the start mechanics (the phase wraps otherwise)
    grid = np.linspace(0.0, 3e-3, 301)
    best = []
    for k in (0, 1):
        costs = []
        for d in grid:
            x = np.concatenate([x_mech, [d, d]])
            e = resid(x)
            half = len(f)
            ph = e[2 * half + k * half : 2 * half + (k + 1) * half]
            costs.append(float(ph @ ph))
        best.append(float(grid[int(np.argmin(costs))]))
    x0 = np.concatenate([x_mech, best])
    sol = scipy.optimize.least_squares(resid, x0, x_scale="jac", method="lm", max_nfev=4000)
    # a second start from the first solution with the delays re-gridded guards against a
    # wrapped phase
    sol2 = scipy.optimize.least_squares(resid, sol.x, method="lm", max_nfev=4000)
    if sol2.cost < sol.cost:
        sol = sol2
    x = sol.x
    mech = np.exp(x[:6])
    # a damping the FRFs cannot see runs off towards exp(−∞) in the log-parameter fit (1e-163
    # was written); below 1e-6 of its critical value it is reported as 0 (decision 1797)
    crit = 2.0 * math.sqrt(mech[2] * mech[1])
    for k, scale in ((3, crit), (4, crit), (5, crit * r * r)):
        if mech[k] < 1e-6 * scale:
            mech[k] = 0.0
    d_m, d_t = float(x[6]), float(x[7])
    ts = amplifier_delay_s
    params = DualInertiaParams(
        screw_inertia=float(mech[0]),
        table_mass=float(mech[1]),
        axial_stiffness=float(mech[2]),
        axial_damping=float(mech[3]),
        table_damping=float(mech[4]),
        rotary_damping=float(mech[5]),
        dead_time_amplifier=ts,
        dead_time_motor=d_m - ts,
        dead_time_table=d_t - ts,
    )
    mm, mt = _model(x, f, lead_m, kt, current_loop_hz, sample_rate_hz)
    return DriveFit(
        params=params,
        motor_delay=d_m,
        table_delay=d_t,
        rms_log_error=float(np.sqrt(np.mean((sol.fun / np.concatenate([wt2, wt2])) ** 2))),
        freq_hz=f,
        motor_accel=hm,
        table_accel=ht,
        model_motor=mm,
        model_table=mt,
        unmodelled_mode_hz=f_extra,
    )


def fit_amplifier_delay(
    current: FrfEstimate,
    *,
    sample_rate_hz: float,
    current_loop_hz: float | None = None,
    band_hz: tuple[float, float] = (1.0, 1000.0),
    current_sampled_at_end: bool = True,
) -> tuple[float, float]:
    """Amplifier dead time T_s and current-loop bandwidth from current command → actual current.

    Parameters
    ----------
    current : FRF I_cmd → I_act (A/A).
    sample_rate_hz : Hz.
    current_loop_hz : the bandwidth if known (then only T_s is fitted), Hz.
    band_hz : band used, Hz.
    current_sampled_at_end : the recorded actual current of sample k is the value at the end
        of the control period (as :class:`~millsense.simulator.feed_drive.FeedDriveSim` records
        it), one period after the command it responds to is issued.

    Returns
    -------
    (T_s s, current-loop bandwidth Hz).

    Notes
    -----
    Model ``ω_cc/(s + ω_cc)·ZOH(s)·e^{−sT_s}·e^{+sT}`` (the last factor when sampled at the
    period's end); least squares on the complex log.
    """
    f = current.freq_hz
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if sel.sum() < 4:
        raise InputDataError("amplifier delay fit: fewer than 4 FRF lines in the band")
    f = f[sel]
    h = current.h1[sel]
    s = 2j * math.pi * f
    shift = np.exp(s / sample_rate_hz) if current_sampled_at_end else np.ones_like(s)
    base = zoh_factor(f, sample_rate_hz) * shift

    def resid(x: np.ndarray) -> np.ndarray:
        wc = 2.0 * math.pi * (current_loop_hz if current_loop_hz is not None else math.exp(x[1]))
        e = np.log(wc / (s + wc) * base * np.exp(-s * x[0]) / h)
        return np.concatenate([e.real, np.angle(np.exp(1j * e.imag))])

    # start: bandwidth where |H| = −3 dB, delay 0
    mag = np.abs(h)
    below = np.flatnonzero(mag < mag[0] / math.sqrt(2.0))
    bw0 = float(f[below[0]]) if len(below) else float(f[-1])
    x0 = np.array([0.0] if current_loop_hz is not None else [0.0, math.log(bw0)])
    sol = scipy.optimize.least_squares(resid, x0, method="lm")
    bw = current_loop_hz if current_loop_hz is not None else math.exp(float(sol.x[1]))
    return float(sol.x[0]), float(bw)


def compensation_delays(
    amplifier_s: float, motor_s: float, table_s: float
) -> tuple[float, float, float]:
    """Phase-lag compensation delays (T1, T2, T3) of the observer (Yamada Fig. 2-5).

    Notes
    -----
    Delay the current command by T1, the motor angle by T2 and the table position by T3 so
    that every path has the same total delay: ``T1 = T_s + T_m + T2 = T_s + T_t + T3``, the
    minimal non-negative solution (seed 001 §2.4, [derived] rule consistent with Table 3-3):
    ``T1 = T_s + max(T_m, T_t)``.
    """
    for name, v in (("T_s", amplifier_s), ("T_m", motor_s), ("T_t", table_s)):
        if v < 0:
            raise InputDataError(f"dead time {name} = {v:g} s is negative")
    t1 = amplifier_s + max(motor_s, table_s)
    return t1, t1 - amplifier_s - motor_s, t1 - amplifier_s - table_s


def drive_config_table(fit: DriveFit, torque_constant_nm_a: float) -> dict[str, object]:
    """Keys of ``[axes.<name>]`` and ``[axes.<name>.ball_screw]`` (FeedAxisConfig field units)."""
    p = fit.params
    return {
        "inertia_kg_m2": p.screw_inertia,
        "torque_constant_nm_a": torque_constant_nm_a,
        "dead_time_amplifier_ms": p.dead_time_amplifier * 1e3,
        "dead_time_motor_encoder_ms": p.dead_time_motor * 1e3,
        "dead_time_scale_ms": p.dead_time_table * 1e3,
        "ball_screw": {
            "model": "dual",
            "table_mass_kg": p.table_mass,
            "table_damping_n_s_m": p.table_damping,
            "axial_damping_n_s_m": p.axial_damping,
            "rotary_damping_nm_s_rad": p.rotary_damping,
            "axial_stiffness_n_um": p.axial_stiffness * 1e-6,
        },
    }


__all__ = [
    "DriveFit",
    "DualInertiaParams",
    "RigidBodyFit",
    "compensation_delays",
    "drive_config_table",
    "dual_inertia_frf",
    "fit_amplifier_delay",
    "fit_dual_inertia",
    "reference_frf",
    "rigid_body_from_acceleration",
    "zoh_factor",
]
