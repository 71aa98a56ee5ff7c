"""Spindle drive: residual structural dynamics and the disturbance FRF G_dτ (Aslan Ch. 5.2).

From a sine sweep (multisine) on the velocity reference of the closed velocity loop, with the
velocity-controller gains read from the CNC:

1. FRFs of the measured speed Ω_meas, the current command I_nom and the actual current I_act
   against the reference r (:func:`millsense.ident.drive.reference_frf`).
2. Open velocity loop ``G_oΩ = Ω_meas/e`` with ``e = r − Ω_meas`` (Aslan Eq. 5.9), current
   loop ``G_m = I_act/I_nom``.
3. Residual ``R = G_oΩ − G_Ω·G_m·K_t·G_r`` with the rigid body ``G_r = 1/(J s + B)`` (Eq. 5.1,
   5.10): the structural dynamics left after the rigid-body model (decision
   docs/decisions/0032-spindle-drive-reading-of-aslan-ch-5.md: R lives in the open velocity loop,
   the measured speed is ``Ω + R·e``). R is fitted by :func:`millsense.ident.modal_fit.fit_modes` in
   the α/β form of Appendix E.
4. ``G_dτ = I_nom/τ_d = G_Ω·G_r/(1 + G_oΩ)`` (Eq. 5.12) with the fitted R and the measured
   current loop (a first-order fit with dead time outside the sweep band).

``G_Ω`` is the CNC's PI ``K_p + K_i/s`` on the speed error (in rev/s per decision 2 of the
spindle reading, or rad/s), sampled every ``velocity_period_s`` and held. Inside the sweep
band the identification uses the measured ``I_nom/e`` (the PI as it acts on the recorded
signals, sample-and-hold and multirate effects included; decision
docs/decisions/0075-spindle-identification-issue-6-item-5.md), and the gains' model
``(K_p + K_i/s)·(1 − e^{−sT_v})/(sT_v)`` outside it; :meth:`SpindleFit.controller_mismatch_db`
compares the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize

from millsense.core.errors import InputDataError
from millsense.ident.drive import reference_frf, zoh_factor
from millsense.ident.frf import FrfEstimate
from millsense.ident.modal_fit import ModalFit, fit_modes


@dataclass(frozen=True)
class VelocityController:
    """Velocity PI of the spindle drive as read from the CNC.

    Attributes
    ----------
    kp : proportional gain, A per unit of speed error.
    ki : integral gain, A/s per unit of speed error.
    error_unit : ``rev/s`` or ``rad/s``: the unit of the speed error the gains act on.
    period_s : controller sample period T_v, s (0 for continuous).
    """

    kp: float
    ki: float
    error_unit: str = "rev/s"
    period_s: float = 2e-4

    def frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """G_Ω in A/(rad/s) at ``freq_hz``, including the sample-and-hold."""
        k = 1.0 / (2.0 * math.pi) if self.error_unit == "rev/s" else 1.0
        f = np.asarray(freq_hz, dtype=float)
        s = 2j * math.pi * f
        g = (self.kp + self.ki / s) * k
        if self.period_s > 0:
            g = g * zoh_factor(f, 1.0 / self.period_s)
        return np.asarray(g)


@dataclass(frozen=True)
class SpindleFit:
    """Identified spindle drive.

    Attributes
    ----------
    residual : modal fit of R (α/β form, Aslan App. E), per rad/s of speed error.
    current_loop_hz : first-order current-loop bandwidth fitted to I_act/I_nom, Hz.
    current_loop_delay_s : its dead time, s.
    freq_hz : sweep lines, Hz.
    open_loop : measured G_oΩ.
    residual_measured : measured R.
    current_loop_measured : measured G_m = I_act/I_nom at ``freq_hz``.
    controller_measured : measured G_Ω = I_nom/e at ``freq_hz`` (the CNC's PI as it acts on
        the recorded signals, sample-and-hold included).
    controller, inertia, viscous, torque_constant : the known quantities used (the inertia
        the sweep's own where ``fit_spindle(identify_inertia=True)``).
    admittance : the motor admittance's (a, b, c) fitted from the sweep (Eq. 5.7,
        :func:`motor_admittance`), or None (not asked for).
    """

    residual: ModalFit
    current_loop_hz: float
    current_loop_delay_s: float
    freq_hz: np.ndarray
    open_loop: np.ndarray
    residual_measured: np.ndarray
    current_loop_measured: np.ndarray
    controller_measured: np.ndarray
    controller: VelocityController
    inertia: float
    viscous: float
    torque_constant: float
    admittance: tuple[float, float, float] | None = None

    def _inside(self, f: np.ndarray, measured: np.ndarray, model: np.ndarray) -> np.ndarray:
        fm = self.freq_hz
        inside = (f >= fm[0]) & (f <= fm[-1])
        logmag = np.interp(f, fm, np.log(np.abs(measured)))
        phase = np.interp(f, fm, np.unwrap(np.angle(measured)))
        return np.asarray(np.where(inside, np.exp(logmag + 1j * phase), model))

    def current_loop_frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """Current loop G_m, A/A: the measured FRF interpolated inside the sweep band (log
        magnitude and unwrapped phase), the first-order fit with dead time outside it."""
        f = np.asarray(freq_hz, dtype=float)
        s = 2j * math.pi * f
        wc = 2.0 * math.pi * self.current_loop_hz
        model = wc / (s + wc) * np.exp(-s * self.current_loop_delay_s)
        return self._inside(f, self.current_loop_measured, model)

    def controller_frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """G_Ω, A/(rad/s): measured inside the sweep band, the CNC gains' model outside."""
        f = np.asarray(freq_hz, dtype=float)
        return self._inside(f, self.controller_measured, self.controller.frf(f))

    def controller_mismatch_db(self) -> float:
        """Largest |20·log10(G_Ω,measured/G_Ω,gains)| below a fifth of the velocity-loop rate,
        dB: a check on the gains read from the CNC and on the error unit (a wrong unit is
        16 dB). Nearer the loop's Nyquist frequency multirate effects dominate."""
        f_max = 0.2 / self.controller.period_s if self.controller.period_s > 0 else math.inf
        sel = self.freq_hz <= f_max
        ratio = self.controller_measured[sel] / self.controller.frf(self.freq_hz[sel])
        return float(np.max(np.abs(20.0 * np.log10(np.abs(ratio)))))

    def open_loop_frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """Model ``G_oΩ = G_Ω·G_m·K_t·G_r + R`` (Aslan Eq. 5.9–5.10, decision 1)."""
        f = np.asarray(freq_hz, dtype=float)
        s = 2j * math.pi * f
        g_r = 1.0 / (self.inertia * s + self.viscous)
        rigid = self.controller_frf(f) * self.current_loop_frf(f) * self.torque_constant * g_r
        return np.asarray(rigid + self.residual.frf(f))

    def disturbance_frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """``G_dτ = I_nom/τ_d = G_Ω·G_r/(1 + G_oΩ)``, A/(N·m) (Aslan Eq. 5.12)."""
        f = np.asarray(freq_hz, dtype=float)
        s = 2j * math.pi * f
        g_r = 1.0 / (self.inertia * s + self.viscous)
        return np.asarray(self.controller_frf(f) * g_r / (1.0 + self.open_loop_frf(f)))


def _fit_current_loop(f: np.ndarray, gm: np.ndarray) -> tuple[float, float]:
    """First order ω_c/(s + ω_c)·e^{−sT} fitted to the current-loop FRF (complex log)."""
    s = 2j * math.pi * f
    mag = np.abs(gm)
    below = np.flatnonzero(mag < mag[0] / math.sqrt(2.0))
    bw0 = float(f[below[0]]) if len(below) else float(f[-1])

    def resid(x: np.ndarray) -> np.ndarray:
        wc = 2.0 * math.pi * math.exp(x[0])
        e = np.log(wc / (s + wc) * np.exp(-s * x[1]) / gm)
        return np.concatenate([e.real, np.angle(np.exp(1j * e.imag))])

    sol = scipy.optimize.least_squares(resid, np.array([math.log(bw0), 0.0]), method="lm")
    return math.exp(float(sol.x[0])), float(sol.x[1])


def _band_lines(
    freq_hz: np.ndarray, band_hz: tuple[float, float], need: int, what: str
) -> np.ndarray:
    """The sweep's lines in ``band_hz`` (a mask), at least ``need`` of them for ``what``."""
    f = np.asarray(freq_hz, dtype=float)
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if sel.sum() < need:
        raise InputDataError(
            f"spindle sweep: {int(sel.sum())} lines in {band_hz[0]:g}-{band_hz[1]:g} Hz for "
            f"{what}; needs {need} or more"
        )
    return sel


#: Band of :func:`rigid_body_inertia`, Hz: J_eS·ω is ≥ 100× the viscous B_eS from 5 Hz on, and
#: to 50 Hz the spindle turns as one body (the truth's first torsional mode is at 2.6 kHz) and
#: the CNC's sampling of Ω and I_act shifts their phases by < 1°.
INERTIA_BAND_HZ = (5.0, 50.0)


def rigid_body_inertia(
    freq_hz: np.ndarray,
    speed_per_current: np.ndarray,
    torque_constant_nm_a: float,
    band_hz: tuple[float, float] = INERTIA_BAND_HZ,
) -> float:
    """J_eS, kg·m², from a velocity-loop sweep's ``Ω_meas/I_act`` (rad/s per A) by the rigid
    body (Aslan Eq. 5.1: ``J s Ω = K_t I_act − B Ω``): ``K_t·I_act/Ω_meas = J s + B``, whose
    imaginary part is fitted by least squares over ``band_hz`` (B is the friction test's).

    The measured current removes the current loop from the fit, so the sweep gives
    ``J/K_t``; with the machine file's K_t (the drive's parameter) this is the inertia the
    file's model needs for the spindle's acceleration per ampere: a K_t off by x % gives a
    J off by the same x %, and the observer's G_dτ keeps its shape (decision 1708)."""
    sel = _band_lines(freq_hz, band_hz, 3, "the inertia")
    w = 2.0 * math.pi * np.asarray(freq_hz, dtype=float)[sel]
    y = torque_constant_nm_a / np.asarray(speed_per_current, dtype=complex)[sel]
    j = float(np.sum(y.imag * w) / np.sum(w * w))
    if not j > 0:
        raise InputDataError(f"spindle sweep: the rigid-body inertia came out {j:.4g} kg·m²")
    return j


#: Band of :func:`motor_admittance`, Hz: around the current loop's bandwidth (a few hundred
#: Hz), where Eq. 5.7's second order holds for a drive whose current PI is sampled with a dead
#: time (the truth's: 20 kHz, one period; within 2.2 % there, 9.5 % at 1 kHz).
ADMITTANCE_BAND_HZ = (5.0, 500.0)


def motor_admittance(
    freq_hz: np.ndarray,
    current_cmd: np.ndarray,
    current: np.ndarray,
    speed: np.ndarray,
    current_pi: tuple[float, float],
    back_emf_v_s_rad: float,
    sample_rate_hz: float,
    band_hz: tuple[float, float] = ADMITTANCE_BAND_HZ,
) -> tuple[float, float, float]:
    """``(a, b, c)`` of the motor admittance ``I/V = 1/(a s² + b s + c)`` (Aslan Eq. 5.7) from a
    velocity-loop sweep: the FRFs of I_nom, I_act and Ω_meas (each against the same
    reference) and the drive's current PI ``G_I = k_p + k_i/s`` (Eq. 5.3) give
    ``1/Y = (G_I·(I_nom − I_act) − K_b·Ω)/I_act``, whose real part ``c − a ω²`` and imaginary
    part ``b ω`` are fitted by least squares relative to ``|1/Y|`` over ``band_hz``.
    What the fitted second order holds besides the winding (the sampled PI, its dead time) is
    what the observer's model of the current loop needs (decision 1708)."""
    sel = _band_lines(freq_hz, band_hz, 4, "the motor admittance")
    w = 2.0 * math.pi * np.asarray(freq_hz, dtype=float)[sel]
    i_nom, i_act, om = (np.asarray(h, dtype=complex)[sel] for h in (current_cmd, current, speed))
    g_i = current_pi[0] + current_pi[1] / (1j * w)
    # the drive's current PI acts on I_nom held between the CNC samples it is recorded at
    ts = 1.0 / sample_rate_hz
    held = np.exp(-0.5j * w * ts) * np.sinc(w * ts / (2.0 * math.pi))
    z = (g_i * (held * i_nom - i_act) - back_emf_v_s_rad * om) / i_act
    wt = 1.0 / np.abs(z)
    n = w.size
    lhs = np.zeros((2 * n, 3))
    lhs[:n, 0] = -(w**2) * wt
    lhs[:n, 2] = wt
    lhs[n:, 1] = w * wt
    rhs = np.concatenate([z.real * wt, z.imag * wt])
    a, b, c = (float(v) for v in np.linalg.lstsq(lhs, rhs, rcond=None)[0])
    if not (a > 0 and b > 0 and c >= 0):
        raise InputDataError(
            f"spindle sweep: the motor admittance came out a {a:.4g}, b {b:.4g}, c {c:.4g} "
            "(Eq. 5.7 needs a, b > 0, c ≥ 0)"
        )
    return a, b, c


def fit_spindle(
    reference: np.ndarray,
    speed: np.ndarray,
    current_cmd: np.ndarray,
    current: np.ndarray,
    sample_rate_hz: float,
    period_samples: int,
    *,
    controller: VelocityController,
    inertia_kg_m2: float,
    viscous_nm_s_rad: float,
    torque_constant_nm_a: float,
    band_hz: tuple[float, float] = (5.0, 2500.0),
    max_modes: int = 14,
    max_damping: float = 0.99,
    identify_inertia: bool = False,
    current_pi: tuple[float, float, float] | None = None,
) -> SpindleFit:
    """Fit the spindle's residual modes and current loop from a velocity-loop sweep.

    Parameters
    ----------
    reference : speed reference per sample (a periodic multisine around a constant speed),
        rad/s.
    speed : measured speed Ω_meas, rad/s.
    current_cmd : current command I_nom (velocity-controller output), A.
    current : actual current I_act, A.
    sample_rate_hz : Hz.
    period_samples : samples per period of the multisine.
    controller : the CNC's velocity PI.
    inertia_kg_m2 : J_eS, kg·m² (machine file or an acceleration test); replaced by the
        sweep's own (:func:`rigid_body_inertia`) with ``identify_inertia``.
    viscous_nm_s_rad : B_eS, N·m·s/rad (friction test).
    torque_constant_nm_a : K_tS of the speed range of the sweep, N·m/A.
    band_hz : band of the residual fit, Hz.
    max_modes : largest order of the stabilisation diagram.
    max_damping : largest damping ratio of a physical mode (Appendix E lists ζ up to 0.94).
    identify_inertia : identify J_eS from the sweep (:func:`rigid_body_inertia` with
        ``torque_constant_nm_a``) and take the rigid body and the residual with it.
    current_pi : the drive's current PI gains and back EMF ``(k_p V/A, k_i V/(A·s), K_b
        V·s/rad)``: also fit the motor admittance (:func:`motor_admittance`).

    Returns
    -------
    SpindleFit
    """
    h_w = reference_frf(
        reference, reference, speed, sample_rate_hz, period_samples,
        names=("speed_ref", "speed_ref", "speed"),
    )  # fmt: skip
    h_i = reference_frf(
        reference, reference, current_cmd, sample_rate_hz, period_samples,
        names=("speed_ref", "speed_ref", "current_cmd"),
    )  # fmt: skip
    h_a = reference_frf(
        reference, reference, current, sample_rate_hz, period_samples,
        names=("speed_ref", "speed_ref", "current"),
    )  # fmt: skip
    f = h_w.freq_hz
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if sel.sum() < 8:
        raise InputDataError(
            f"spindle sweep: {int(sel.sum())} lines in {band_hz[0]:g}-{band_hz[1]:g} Hz; "
            "needs 8 or more"
        )
    f = f[sel]
    hw, hi, ha = h_w.h1[sel], h_i.h1[sel], h_a.h1[sel]
    open_loop = hw / (1.0 - hw)  # Ω_meas/e with e = r − Ω_meas
    gm = ha / hi
    bw, delay = _fit_current_loop(f, gm)
    if identify_inertia:
        inertia_kg_m2 = rigid_body_inertia(f, hw / ha, torque_constant_nm_a)
    admittance = None
    if current_pi is not None:
        admittance = motor_admittance(f, hi, ha, hw, current_pi[:2], current_pi[2],
                                      sample_rate_hz)  # fmt: skip
    s = 2j * math.pi * f
    g_r = 1.0 / (inertia_kg_m2 * s + viscous_nm_s_rad)
    g_ctl = hi / (1.0 - hw)  # I_nom/e
    rigid = g_ctl * gm * torque_constant_nm_a * g_r
    resid = open_loop - rigid
    coh = np.minimum(h_w.coherence[sel], h_i.coherence[sel])
    est = FrfEstimate(f, resid, resid.copy(), coh, h_w.n_averages, "reference")
    try:
        fit = fit_modes(est, band_hz, max_modes=max_modes, max_damping=max_damping)
    except InputDataError as err:
        if "no stable mode" not in str(err):
            raise
        # no structural resonance in the band (e.g. the truth spindle of decision 1210, whose
        # torsional modes lie above the velocity loop's band): R = 0, the rigid-body G_dτ
        fit = ModalFit(
            (),
            0.0,
            band_hz,
            1.0,
            notes=("no stable mode in the band: residual R taken as zero (rigid-body G_dτ)",),
        )
    # an undamped out-of-band pole at the band edge (the velocity loop's Nyquist frequency,
    # where the sweep stops) is a fitting artefact, not structure: drop it
    fit = replace(
        fit, residual_modes=tuple(m for m in fit.residual_modes if m.damping_ratio > 1e-3)
    )
    return SpindleFit(
        residual=fit,
        current_loop_hz=bw,
        current_loop_delay_s=delay,
        freq_hz=f,
        open_loop=open_loop,
        residual_measured=resid,
        current_loop_measured=gm,
        controller_measured=g_ctl,
        controller=controller,
        inertia=inertia_kg_m2,
        viscous=viscous_nm_s_rad,
        torque_constant=torque_constant_nm_a,
        admittance=admittance,
    )


def residual_modes_table(fit: SpindleFit) -> dict[str, object]:
    """The residual's in-band modes with :class:`~millsense.core.config.DisturbanceModesConfig`
    keys (the out-of-band poles the fit keeps as residual terms are not identified modes)."""
    modes = fit.residual.modes
    return {
        "natural_frequency_hz": [m.natural_frequency_hz for m in modes],
        "damping_ratio": [m.damping_ratio for m in modes],
        "alpha": [m.alpha for m in modes],
        "beta": [m.beta for m in modes],
        "feedthrough": float(np.real(fit.residual.residual)),
    }
