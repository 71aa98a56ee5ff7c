"""Feed-drive cutting-force estimator (Aslan C2–C7): current and encoder → force at the tool.

Per axis (:class:`FeedAxisEstimator`, a streaming :class:`~millsense.streaming.block.Block` that
reads only CNC channels ``{axis}/current_cmd`` and ``{axis}/motor_speed``):

1. C3 torque (Aslan Eq. 3.10): ``τ_c = K_t·I_nom − τ_f(ω) − J_e·Δω/Δt``, with the identified
   friction and inertia, then a 2nd-order Butterworth low-pass at ``lowpass_hz`` (the derivative
   filter: the backward difference of an encoder-derived speed is dominated by quantisation
   noise; see :mod:`millsense.estimation.feed.rigid_body` and
   docs/decisions/0083-c3-derivative-filter-inside-the-kalman-model-friction-sign.md). The low-pass
   is part of the estimator's model (below), so its lag is compensated, not ignored.
2. Disturbance Kalman filter (Eq. 3.21–3.29) over the *identified* disturbance path
   ``Φ_d = τ_c/τ_a`` (Eq. 3.13, modal fit of a simulated commissioning sweep) in series with
   the low-pass, discretised at the CNC rate, augmented with the random-walk τ_a; optionally
   (``teeth``) also with undamped pairs at the tooth harmonics ≤ 200 Hz of the commanded
   spindle speed ``spindle/speed_cmd`` (Aslan's full model, Eq. 3.16–3.20).
3. Fixed-lag smoother (Appendix B, 60 samples = 6 ms): output sample k is ``τ̂_a(k − L)``.
4. Axis load (Eq. 3.11/3.12): ``F = η·τ̂_a/r_g`` (N, linear axes; N·m at the table, rotary);
   a rotary axis with a moment arm ``d`` also gives ``F = η·τ̂_a/(r_g·d)`` (Eq. 3.12).

Five axes → forces at the tool (:class:`ToolForceBlock`, Eq. 3.51): ``F_tool = [Jᵀ·T]⁺·τ``
with :meth:`millsense.models.kinematics.TrunnionACKinematics.tool_force`, axis positions
from the encoder angles ``{axis}/motor_angle`` delayed by the smoother lag.

The model (:class:`FeedAxisModel`) comes from a machine file (:meth:`FeedAxisModel.from_config`)
or from simulated commissioning tests (:mod:`millsense.bench.feed_commissioning`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import signal

from millsense.core.config import FeedAxisConfig
from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.estimation.feed._tool_force_kernels import tool_force_kernel
from millsense.estimation.feed.rigid_body import DriveModel
from millsense.estimation.kalman.design import (
    KalmanDesign,
    StateSpaceModel,
    augment_disturbance,
    design_kalman,
    discretize_zoh,
)
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.estimation.kalman.smoother import ASLAN_LAG_SAMPLES, FixedLagSmoother, _smooth
from millsense.models.friction import coulomb_viscous_torque
from millsense.models.kinematics import Kinematics, TrunnionACKinematics, TrunnionACMachine
from millsense.models.lugre import (
    N_SPEED_TERMS,
    LuGre,
    lugre_advance,
    lugre_speed_terms,
    lugre_step,
)
from millsense.models.modal_ss import ModalStateSpace
from millsense.streaming.block import Block, BlockOutput, Chunk

#: Low-pass of the C3 torque, Hz (decision "C3 derivative filter inside the Kalman model").
DEFAULT_LOWPASS_HZ = 600.0
#: sgn(ω) of the estimator's friction is tanh(ω/ω_s); ω_s = 5 speed quanta of a 2²⁰-count
#: encoder at 10 kHz (decision "friction sign smoothing in the estimator").
DEFAULT_FRICTION_SMOOTHING_RAD_S = 0.3
#: Relative shift of the mode frequencies the tuning must tolerate (decision "Robust feed
#: estimator for position-dependent modes"): modes anywhere within ±2 % of the identified ones.
ROBUST_SHIFT = 0.0
#: Band the compensated FRF must be flat in (Aslan Fig. 3.8, C6), Hz: the robust tuning's
#: tie-break between designs of equal worst-case band.
TARGET_BAND_HZ = {"linear": 180.0, "rotary": 120.0}
#: Operating condition an estimator model is identified in (decision "Holding axis: Φ_d and R
#: identified at rest").
OperatingCondition = Literal["moving", "at_rest"]
#: Commanded motor speed below which an axis holds position, rad/s (decision as above).
REST_SPEED_RAD_S = 0.01
#: Channel of the CNC's commanded spindle speed, rad/s (the harmonic design reads it).
SPINDLE_SPEED_CMD = "spindle/speed_cmd"
#: Highest tooth harmonic k·f_t given its own disturbance state pair, Hz (decision
#: "Tooth-harmonic disturbance model in the feed estimator").
MAX_HARMONIC_HZ = 200.0
#: Spectral density of each harmonic pair's noise w_AC per unit of the random-walk q (same
#: decision): one rule for every axis, speed and harmonic.
HARMONIC_Q_RATIO = 0.1
#: Below this tooth frequency, Hz, only the random walk is used (a pair that slow is the random
#: walk's own band; the spindle is stopped or running up).
MIN_TOOTH_HZ = 5.0
#: Relative width of the tooth-frequency bins designs are cached by (0.1 %).
TOOTH_BIN_REL = 1e-3
#: The commanded spindle speed must stay in one bin this long before its harmonic design is used,
#: s (a speed ramp runs on the random-walk design).
HARMONIC_HOLD_S = 0.01


@dataclass(frozen=True)
class FeedAxisModel:
    """Everything the estimator of one axis believes (identified, never the simulator's).

    Attributes
    ----------
    axis : axis name (``x``, ``y``, ``z``, ``a``, ``c``).
    kind : ``linear`` or ``rotary``.
    drive : inertia J_e kg·m², K_t N·m/A, r_g m/rad (rad/rad rotary), η, friction (motor side).
    disturbance : identified Φ_d = τ_c/τ_a (rational fit of the sweep: Eq. 3.13 modes plus the
        real poles of the loop seen through the C3 torque), dimensionless.
    lowpass_hz : corner of the C3 low-pass, Hz.
    r : per-sample variance of the low-passed C3 torque in an air cut, N²·m².
    q : spectral density of τ̇_a, (N·m)²/s
        (docs/decisions/0044-units-of-q-and-r-of-the-disturbance-kalman-filter-aslan-eq.md).
    sample_rate_hz : CNC sample rate, Hz.
    moment_arm_m : d of Eq. 3.12 for a rotary axis (None: no force output, only the torque).
    lugre : identified LuGre friction (C2) used by the C3 stage instead of ``drive.friction``
        (static part from the line fit, σ0 and σ1 from a presliding test), or None.
    condition : operating condition Φ_d and R were identified in: ``moving`` (sweep during a
        constant-velocity move, R from an air cut) or ``at_rest`` (sweep and R with the servo on
        and the axis holding position; :func:`operating_condition` picks the model).
    design_damping : γ of :func:`millsense.estimation.feed.tuning.robust_fit`: the Kalman filter is
        designed on Φ_d with every mode's pole moved left by γ·|p| (robust to position-dependent
        mode frequencies); 0 = the identified Φ_d itself.
    """

    axis: str
    kind: Literal["linear", "rotary"]
    drive: DriveModel
    disturbance: RationalFit
    lowpass_hz: float
    r: float
    q: float
    sample_rate_hz: float = 10_000.0
    moment_arm_m: float | None = None
    lugre: LuGre | None = None
    condition: OperatingCondition = "moving"
    design_damping: float = 0.0

    @classmethod
    def from_config(
        cls,
        axis: str,
        cfg: FeedAxisConfig,
        *,
        sample_rate_hz: float = 10_000.0,
        use_lugre: bool = True,
        q_bounds: tuple[float, float] = (1.0, 1e7),
        where: str = "machine",
    ) -> FeedAxisModel:
        """The estimator model of one axis from a machine configuration (identified values).

        Parameters
        ----------
        axis : axis name (``x`` …), used in channel names and error messages.
        cfg : the axis table of the machine file (the values a user merged from
            ``millsense identify`` fragments: friction, disturbance_modes; nameplate J_e, K_t,
            lead, efficiency).
        sample_rate_hz : CNC rate of the stream, Hz.
        use_lugre : use the LuGre friction of the table when all its keys are present
            (Aslan C2); otherwise Coulomb + viscous (C1).
        q_bounds : search range of the automatic Q, (N·m)²/s.
        where : name of the configuration (file or preset) for error messages.

        Returns
        -------
        FeedAxisModel with Φ_d = ``estimator.disturbance_path`` when given (the identified
        rational path, Tustin at the stream rate), else the table's ``disturbance_modes``
        (Eq. 3.13, pole–residue form, ZOH),
        R and Q from ``[axes.<axis>.estimator]`` when given, else R from ``current_noise_a``
        and Q by :meth:`tuned`: the widest band (:func:`~millsense.estimation.feed.tuning.tune_q`,
        the default), the least noise for ``band_hz``, or the robust design (with its damping)
        for ``mode_shift_pct`` > 0.

        Raises
        ------
        ConfigError
            One line naming the missing key (``axes.<axis>.disturbance_modes``, or
            ``current_noise_a``/``estimator.r_nm2`` when R cannot be chosen).

        Notes
        -----
        Default R
        (docs/decisions/0100-estimators-built-from-the-machine-file-millsense-estimate.md): white
        current noise σ_I (``current_noise_a``, Aslan Eq. 3.30) seen through the C3 low-pass:
        ``R = (K_t·σ_I)²·Σ h_k²`` with h the impulse response of the 2nd-order Butterworth
        low-pass (the variance of the low-passed torque measurement the filter is designed on).
        """
        from millsense.models.modal_ss import ModalStateSpace as _Mss

        est = cfg.estimator
        path = est.disturbance_path if est is not None else None
        if cfg.disturbance_modes is None and path is None:
            raise ConfigError(
                f"{where}: missing key 'axes.{axis}.disturbance_modes' (the feed estimator needs "
                "the identified disturbance path: millsense identify path, or modes: millsense "
                "identify modal)"
            )
        if path is not None and not math.isclose(path.sample_rate_hz, sample_rate_hz):
            raise ConfigError(
                f"{where}: axes.{axis}.estimator.disturbance_path was identified at "
                f"{path.sample_rate_hz:g} Hz but the stream runs at {sample_rate_hz:g} Hz"
            )
        drive, lugre, lowpass = c3_front_end(axis, cfg, sample_rate_hz, where, use_lugre=use_lugre)
        if path is not None:
            fit = RationalFit.from_config(path)
        else:
            assert cfg.disturbance_modes is not None
            fit = RationalFit.from_modes(_Mss.from_config(cfg.disturbance_modes))
        r = est.r_nm2 if est is not None else None
        if r is None:
            if cfg.current_noise_a <= 0:
                raise ConfigError(
                    f"{where}: missing key 'axes.{axis}.estimator.r_nm2' (or a positive "
                    f"'axes.{axis}.current_noise_a'): the estimator's R cannot be chosen"
                )
            sos = signal.butter(2, lowpass, fs=sample_rate_hz, output="sos")
            imp = np.zeros(round(sample_rate_hz))  # 1 s: the 2nd-order low-pass has decayed
            imp[0] = 1.0
            h = signal.sosfilt(sos, imp)
            r = float((cfg.torque_constant_nm_a * cfg.current_noise_a) ** 2 * np.sum(h**2))
        kind: Literal["linear", "rotary"] = cfg.kind
        model = cls(axis, kind, drive, fit, lowpass, r, 1000.0, sample_rate_hz, None, lugre)
        q = est.q_nm2_s if est is not None else None
        shift = (est.mode_shift_pct if est is not None else 100.0 * ROBUST_SHIFT) / 100.0
        band = est.band_hz if est is not None else None
        try:
            return model.tuned(shift, q=q, q_bounds=q_bounds, band_hz=band)
        except InputDataError as exc:
            raise ConfigError(f"{where}: axes.{axis}.estimator.band_hz: {exc}") from None

    def tuned(
        self,
        shift: float,
        *,
        q: float | None = None,
        q_bounds: tuple[float, float] = (1.0, 1e7),
        band_hz: float | None = None,
    ) -> FeedAxisModel:
        """This model with Q (and the design damping) chosen.

        Parameters
        ----------
        shift : relative mode-frequency uncertainty δ; > 0 chooses Q and γ by
            :func:`millsense.estimation.feed.tuning.tune_robust` over modes × [1 − δ, 1 + δ], 0
            chooses
            Q by :func:`millsense.estimation.feed.tuning.tune_q` on the identified model.
        q : Q fixed by the user, (N·m)²/s (then only γ is chosen), or None.
        q_bounds : search range of Q, (N·m)²/s.
        band_hz : band to keep, Hz: Q by :func:`millsense.estimation.feed.tuning.least_noise_q`
            (the least-noise Q flat within ±1 dB to ``band_hz`` on the identified model) instead
            of the widest band; only with ``shift`` = 0 and no ``q``.

        Raises
        ------
        ConfigError
            ``band_hz`` with ``q`` or with ``shift`` > 0.
        InputDataError
            No Q keeps ``band_hz`` under the noise limit.
        """
        from millsense.estimation.feed import tuning

        if band_hz is not None:
            if q is not None or shift > 0:
                raise ConfigError(
                    f"estimator {self.axis}: band_hz is a nominal tuning rule (no fixed Q, no "
                    "mode-shift margin)"
                )
            q = tuning.least_noise_q(self.measurement_model(), self.r, band_hz, bounds=q_bounds).q
            return replace(self, q=float(q), design_damping=0.0)
        if shift > 0:
            rob = tuning.tune_robust(
                self.disturbance,
                lambda m: measurement_model(m, self.lowpass_hz, self.dt),
                self.r,
                shift=shift,
                q=q,
                bounds=q_bounds,
                lag=ASLAN_LAG_SAMPLES,
                f_target_hz=TARGET_BAND_HZ[self.kind],
            )
            return replace(self, q=rob.q, design_damping=rob.damping)
        if q is None:
            q = tuning.tune_q(self.measurement_model(), self.r, bounds=q_bounds).q
        return replace(self, q=float(q), design_damping=0.0)

    @property
    def dt(self) -> float:
        return 1.0 / self.sample_rate_hz

    def lowpass_sos(self) -> NDArray[np.float64]:
        """Second-order sections of the Butterworth low-pass at the sample rate."""
        return np.asarray(
            signal.butter(2, self.lowpass_hz, fs=self.sample_rate_hz, output="sos"), dtype=float
        )

    def measurement_model(self) -> StateSpaceModel:
        """Discrete design model τ_a → low-passed C3 torque: see :func:`measurement_model`.

        Φ_d is :attr:`disturbance` with :attr:`design_damping` added to its modes.
        """
        from millsense.estimation.feed.tuning import robust_fit

        fit = self.disturbance
        if self.design_damping > 0:
            fit = robust_fit(fit, self.design_damping)
        return measurement_model(fit, self.lowpass_hz, self.dt)

    def design(
        self,
        q: float | None = None,
        r: float | None = None,
        *,
        harmonics_hz: Sequence[float] = (),
        harmonic_q_ratio: float = HARMONIC_Q_RATIO,
    ) -> KalmanDesign:
        """Steady-state Kalman design on :meth:`measurement_model` (q, r default to the model's).

        ``harmonics_hz`` (Hz, e.g. :func:`tooth_harmonics`) adds one harmonic disturbance pair
        per frequency (Aslan Eq. 3.16–3.20), see :func:`design_feed_kalman`.
        """
        return design_feed_kalman(
            self.measurement_model(),
            self.q if q is None else q,
            self.r if r is None else r,
            harmonics_hz=harmonics_hz,
            harmonic_q_ratio=harmonic_q_ratio,
        )


def c3_front_end(
    axis: str,
    cfg: FeedAxisConfig,
    sample_rate_hz: float,
    where: str = "machine",
    *,
    use_lugre: bool = True,
) -> tuple[DriveModel, LuGre | None, float]:
    """The C3 stage (Aslan Eq. 3.10) of an axis from its machine-file table.

    Returns
    -------
    (drive, lugre, lowpass_hz): :meth:`DriveModel.from_config` (rigid-body limit, friction sign
    smoothed), the LuGre friction when the table has its bristle keys (a presliding fit; the
    Stribeck curve flat where the moves did not resolve one, decision 1695) and ``use_lugre``
    (else None: Coulomb + viscous), and the low-pass corner (``estimator.lowpass_hz``, default
    :data:`DEFAULT_LOWPASS_HZ`).

    Raises
    ------
    ConfigError
        A low-pass corner at or above the Nyquist frequency (one line naming the key).
    """
    est = cfg.estimator
    lowpass = (est.lowpass_hz if est is not None else None) or DEFAULT_LOWPASS_HZ
    if not 0 < lowpass < sample_rate_hz / 2:
        raise ConfigError(
            f"{where}: key 'axes.{axis}.estimator.lowpass_hz' = {lowpass:g} must be below "
            f"{sample_rate_hz / 2:g} Hz"
        )
    drive = DriveModel.from_config(cfg, DEFAULT_FRICTION_SMOOTHING_RAD_S, where=where, axis=axis)
    f = cfg.friction_table(where, axis)
    lugre = None
    if use_lugre and LuGre.configured(f):
        lugre = LuGre.from_config(f, f"{where} axes.{axis}.friction")
    return drive, lugre, lowpass


def measurement_model(
    modes: ModalStateSpace | RationalFit, lowpass_hz: float, dt: float
) -> StateSpaceModel:
    """Discrete path from the disturbance τ_a to the low-passed C3 torque.

    Parameters
    ----------
    modes : Φ_d = τ_c/τ_a (Aslan Eq. 3.13 modes, or the identified rational fit), continuous.
    lowpass_hz : Butterworth corner, Hz (the C3 low-pass; ``inf`` or 0 for none).
    dt : sample time, s.

    Returns
    -------
    Discrete :class:`StateSpaceModel`: Φ_d in series with the digital low-pass. Φ_d is
    discretised to match how it was obtained (decision "Discretisation of the identified
    disturbance model"): a :class:`RationalFit` of a *sampled* FRF on the bilinear-warped axis
    of this rate (:func:`sampled_fit_at`; what
    :func:`~millsense.bench.feed_commissioning.disturbance_sweep` returns) by Tustin,
    whose FRF then equals the fitted one at every frequency; a continuous model (Table 3.4
    modes, a machine file, an unwarped fit) by ZOH (τ_a piecewise constant over a sample,
    Aslan §3.3 "model actually used", as the simulator holds the load). ZOH of a fit of sampled
    data would add a second half-sample delay, 1.8° at 100 Hz, which the harmonic design turns
    straight into estimate error (V1 Y at 3000 rev/min: 5.1 % instead of 3.1 %).

    Notes
    -----
    Series connection ``x₁⁺ = A₁x₁ + B₁u, y₁ = C₁x₁ + D₁u; x₂⁺ = A₂x₂ + B₂y₁, y = C₂x₂ + D₂y₁``.
    """
    if isinstance(modes, RationalFit) and sampled_fit_at(modes, dt):
        phi = modes.discrete_model(dt)
    else:
        if isinstance(modes, RationalFit):
            cont = modes.continuous_model()
        else:
            a, b, c, d = modes.dense()
            cont = StateSpaceModel.from_arrays(a, b, c, d)
        phi = discretize_zoh(cont, dt)
    if not lowpass_hz or not math.isfinite(lowpass_hz):
        return phi
    bz, az = signal.butter(2, lowpass_hz, fs=1.0 / dt)
    al, bl, cl, dl = signal.tf2ss(bz, az)
    n1, n2 = phi.n_states, al.shape[0]
    aa = np.zeros((n1 + n2, n1 + n2))
    aa[:n1, :n1] = phi.a
    aa[n1:, :n1] = bl @ phi.c
    aa[n1:, n1:] = al
    bb = np.vstack([phi.b, bl @ phi.d])
    cc = np.hstack([dl @ phi.c, cl])
    dd = dl @ phi.d
    return StateSpaceModel(aa, bb, cc, dd, dt)


def sampled_fit_at(fit: RationalFit, dt: float) -> bool:
    """True when ``fit`` was fitted to a sampled FRF on the bilinear-warped axis of rate 1/dt."""
    return fit.warped_fs_hz is not None and math.isclose(fit.warped_fs_hz * dt, 1.0, rel_tol=1e-9)


def tooth_harmonics(tooth_hz: float, max_hz: float = MAX_HARMONIC_HZ) -> tuple[float, ...]:
    """The tooth frequency and its multiples ``k·f_t ≤ max_hz`` (Hz); empty when f_t > max_hz."""
    if not (math.isfinite(tooth_hz) and tooth_hz > 0):
        raise InputDataError(f"tooth frequency must be positive, got {tooth_hz}")
    kmax = math.floor(max_hz / tooth_hz * (1 + 1e-12))
    return tuple(k * tooth_hz for k in range(1, kmax + 1))


def design_feed_kalman(
    model: StateSpaceModel,
    q: float,
    r: float,
    *,
    harmonics_hz: Sequence[float] = (),
    harmonic_q_ratio: float = HARMONIC_Q_RATIO,
) -> KalmanDesign:
    """Disturbance Kalman filter (Eq. 3.21–3.29) on a discrete :func:`measurement_model`.

    Parameters
    ----------
    model : discrete τ_a → measured torque model.
    q : spectral density of τ̇_a, (N·m)²/s; the random walk of the discrete model gets the
        per-sample variance ``q·dt`` (the Van Loan value on the random-walk state).
    r : per-sample variance of the measured torque, N²·m².
    harmonics_hz : tooth harmonics (Hz) given a harmonic disturbance pair each (Aslan's full
        model, Eq. 3.16–3.20); empty: the random walk alone (Eq. 3.21–3.23, the thesis' filter).
    harmonic_q_ratio : κ, the spectral density of each pair's noise w_AC is ``κ·q``.

    Notes
    -----
    Each pair's noise enters its first state with the per-sample variance ``κ·q·dt``, the
    random-walk convention (the leading term of Van Loan for ``s/(s² + ω²)``, whose
    high-frequency asymptote is the random walk's ``1/s``), one κ for every axis, speed and
    harmonic (:data:`HARMONIC_Q_RATIO` = 0.1; decision "Tooth-harmonic disturbance model in the
    feed estimator": on the identified X/Y models, at the V1 speeds, the harmonic states
    converge to 1 % within 1–4 tooth periods of a cut entry while the smoothed noise gain stays
    within 1.1–2.9× the random walk's; κ = 1 about doubles it and converges no faster). The
    pairs are undamped, so the steady-state compensated transfer ``Φ_d·Φ_KF`` is exactly 1 at
    each included harmonic (internal model): what remains there is the model error
    ``Φ_true/Φ_model``.
    """
    assert model.dt is not None
    if not harmonic_q_ratio > 0:
        raise ConfigError(f"harmonic_q_ratio must be positive, got {harmonic_q_ratio}")
    aug = augment_disturbance(model, harmonics_hz=tuple(harmonics_hz))
    nh = len(aug.harmonics_hz)
    if nh == 0:
        return design_kalman(aug, q * model.dt, r)
    qd = np.diag([q * model.dt] + [harmonic_q_ratio * q * model.dt] * nh)
    return design_kalman(aug, qd, r)


@numba.njit(cache=True)
def c3_step(
    current: float,
    w: float,
    state: NDArray[np.float64],
    drive: NDArray[np.float64],
    fric_mode: int,
    fric: NDArray[np.float64],
    sos: NDArray[np.float64],
) -> float:  # pragma: no cover - compiled
    """One sample of the low-passed C3 torque (Aslan Eq. 3.10; ``state`` updated in place).

    ``state`` = [previous speed, bristle z, biquad w1, w2, started]; ``drive`` = [K_t, J_e, fs];
    ``fric_mode`` 1 LuGre (``lugre_step``), 0 Coulomb + viscous; ``sos`` one section
    [b0, b1, b2, 1, a1, a2] run in direct form II transposed.
    """
    if fric_mode == 1:
        z, tf = lugre_step(state[1], w, 1.0 / drive[2], fric)
        state[1] = z
    else:
        tf = coulomb_viscous_torque(w, fric)
    return c3_with_friction(current, w, tf, state, drive, sos)


@numba.njit(cache=True)
def c3_unfiltered(
    current: float, w: float, w_prev: float, tf: float, drive: tuple[float, float, float]
) -> float:
    """``τ_c = K_t·I_nom − τ_f − J_e·Δω/Δt`` (Aslan Eq. 3.10), ``drive`` = (K_t, J_e, fs)."""
    kt, j, fs = drive
    acc = (w - w_prev) * fs
    return kt * current - tf - j * acc


@numba.njit(cache=True)
def biquad_step(
    x: float, w1: float, w2: float, sos: tuple[float, float, float, float, float]
) -> tuple[float, float, float]:
    """One sample of a biquad in direct form II transposed, ``sos`` = (b0, b1, b2, a1, a2):
    (y, w1⁺, w2⁺)."""
    b0, b1, b2, a1, a2 = sos
    y = b0 * x + w1
    return y, b1 * x - a1 * y + w2, b2 * x - a2 * y


@numba.njit(cache=True)
def c3_with_friction(
    current: float,
    w: float,
    tf: float,
    state: NDArray[np.float64],
    drive: NDArray[np.float64],
    sos: NDArray[np.float64],
) -> float:  # pragma: no cover - compiled
    """:func:`c3_step` given the sample's friction torque ``tf``: ``τ_c = K_t·I_nom − τ_f −
    J_e·Δω/Δt`` and the low-pass (``state`` as there; its bristle z is not touched)."""
    b0, b1, b2, a1, a2 = sos[0], sos[1], sos[2], sos[4], sos[5]
    if state[4] == 0.0:
        state[0] = w
    tau = c3_unfiltered(current, w, state[0], tf, (drive[0], drive[1], drive[2]))
    state[0] = w
    if state[4] == 0.0:
        # start the low-pass in steady state on the first sample
        g = (b0 + b1 + b2) / (1.0 + a1 + a2)
        state[2] = tau * (g - b0)
        state[3] = tau * (b2 - a2 * g)
        state[4] = 1.0
    y, state[2], state[3] = biquad_step(tau, state[2], state[3], (b0, b1, b2, a1, a2))
    return y


#: distinct speeds whose friction terms :func:`_c3_kernel` keeps at once (an encoder's speed
#: takes 5–15 distinct values in a 0.1 s chunk of the V8 slot's axes)
FRICTION_MEMO_ROWS = 16


@numba.njit(cache=True)
def _friction_terms(
    w: float, fric_mode: int, fric: NDArray[np.float64], h: float
) -> tuple[float, float, float, float, float, float]:
    """What the friction of :func:`c3_step` computes from the speed alone: LuGre's
    :func:`~millsense.models.lugre.lugre_speed_terms`, or the Coulomb + viscous torque first."""
    if fric_mode == 1:
        return lugre_speed_terms(w, h, fric)
    return coulomb_viscous_torque(w, fric), 0.0, 0.0, 0.0, 0.0, 0.0


@numba.njit(cache=True)
def _memo_row(keys: NDArray[np.float64], count: int, w: float) -> int:
    """Row of ``keys[:count]`` holding ``w`` (sign of zero included; a NaN matches none), −1
    if none."""
    for i in range(count):
        if keys[i] == w and math.copysign(1.0, keys[i]) == math.copysign(1.0, w):
            return i
    return -1


@numba.njit(cache=True)
def _c3_kernel(
    current: NDArray[np.float64],
    speed: NDArray[np.float64],
    state: NDArray[np.float64],
    drive: NDArray[np.float64],
    fric_mode: int,
    fric: NDArray[np.float64],
    sos: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """Low-passed C3 torque of one chunk (state updated in place; :func:`c3_step` per
    sample).

    The friction's speed-dependent part (the Coulomb + viscous torque; LuGre's Stribeck curve,
    rate and steady deflection, two exponentials) is a function of the sample's speed alone: it
    is evaluated once per distinct speed of the chunk and kept in a small table (an encoder's
    speed repeats a few quantised values, and an axis at rest reads 0 for long stretches), the
    same values bit for bit, sign of zero included."""
    n = current.shape[0]
    if n == 0:
        return
    h = 1.0 / drive[2]
    keys = np.empty(FRICTION_MEMO_ROWS)
    memo = np.empty((FRICTION_MEMO_ROWS, N_SPEED_TERMS))
    count = 0
    row = -1
    terms = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # the state in locals for the loop (c3_with_friction's arithmetic, state[] written back
    # after it): kept in registers instead of stored and reloaded every sample
    coef = (sos[0], sos[1], sos[2], sos[4], sos[5])
    dr = (drive[0], drive[1], drive[2])
    z = state[1]
    w_prev, w1, w2 = state[0], state[2], state[3]
    for k in range(n):
        w = speed[k]
        same = row >= 0 and w == keys[row]
        if not (same and math.copysign(1.0, w) == math.copysign(1.0, keys[row])):
            row = _memo_row(keys, count, w)
            if row >= 0:
                terms = (memo[row, 0], memo[row, 1], memo[row, 2], memo[row, 3], memo[row, 4],
                         memo[row, 5])  # fmt: skip
            else:
                terms = _friction_terms(w, fric_mode, fric, h)
                row = k % FRICTION_MEMO_ROWS if count == FRICTION_MEMO_ROWS else count
                count = min(count + 1, FRICTION_MEMO_ROWS)
                keys[row] = w
                for i in range(N_SPEED_TERMS):
                    memo[row, i] = terms[i]
        if fric_mode == 1:
            z, tf = lugre_advance(z, terms, h)
        else:
            tf = terms[0]
        if state[4] == 0.0:  # the first sample of the stream starts the low-pass
            out[k] = c3_with_friction(current[k], w, tf, state, drive, sos)
            w_prev, w1, w2 = state[0], state[2], state[3]
            continue
        tau = c3_unfiltered(current[k], w, w_prev, tf, dr)
        w_prev = w
        out[k], w1, w2 = biquad_step(tau, w1, w2, coef)
    state[0], state[1], state[2], state[3] = w_prev, z, w1, w2


@numba.njit(cache=True)
def _estimate_kernel(
    current: NDArray[np.float64],
    speed: NDArray[np.float64],
    state: NDArray[np.float64],
    drive: NDArray[np.float64],
    fric_mode: int,
    fric: NDArray[np.float64],
    sos: NDArray[np.float64],
    modal: bool,
    diag: NDArray[np.float64],
    off: NDArray[np.float64],
    n_pairs: int,
    f: NDArray[np.float64],
    g: NDArray[np.float64],
    h: NDArray[np.float64],
    j: NDArray[np.float64],
    z: NDArray[np.float64],
    taps_t: NDArray[np.float64],
    hist_pred: NDArray[np.float64],
    hist_innov: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """C3 torque and the fixed-lag smoother in one compiled call (states updated in place)."""
    n = current.shape[0]
    tau = np.empty((n, 1))
    _c3_kernel(current, speed, state, drive, fric_mode, fric, sos, tau[:, 0])
    out = _smooth(modal, diag, off, n_pairs, f, g, h, j, tau, z, taps_t, hist_pred, hist_innov)
    return out[:, 0].copy()


class C3Torque:
    """Streaming C3 torque (Aslan Eq. 3.10) with the low-pass, state carried across chunks.

    Parameters
    ----------
    drive : the drive model (identified friction and inertia).
    lowpass_hz : Butterworth corner, Hz.
    sample_rate_hz : CNC rate, Hz.
    lugre : identified LuGre friction (bristle state carried), or None for ``drive.friction``.

    Notes
    -----
    One numba kernel per chunk: backward difference of the encoder speed, friction (LuGre
    integrated exactly for the held speed as in :mod:`millsense.models.lugre`, or Coulomb +
    viscous), ``τ_c = K_t·I_nom − τ_f − J_e·Δω/Δt`` and the 2nd-order Butterworth section.
    """

    def __init__(
        self,
        drive: DriveModel,
        lowpass_hz: float,
        sample_rate_hz: float,
        lugre: LuGre | None = None,
    ) -> None:
        if not 0 < lowpass_hz < sample_rate_hz / 2:
            raise ConfigError(
                f"estimator: lowpass_hz must be in (0, {sample_rate_hz / 2:g}) Hz, got {lowpass_hz}"
            )
        self.drive = drive
        self.lugre = lugre
        self.fs = sample_rate_hz
        self.sos = signal.butter(2, lowpass_hz, fs=sample_rate_hz, output="sos")
        self._sos = np.ascontiguousarray(self.sos[0], dtype=float)
        self._drive = np.array([drive.torque_constant, drive.inertia, sample_rate_hz])
        self._mode = 1 if lugre is not None else 0
        self._fric = lugre.as_array() if lugre is not None else drive.friction.as_array()
        self.reset()

    def reset(self) -> None:
        self._state = np.zeros(5)

    def process(self, current_a: ArrayLike1, speed_rad_s: ArrayLike1) -> NDArray[np.float64]:
        """Low-passed τ_c (N·m) of one chunk."""
        cur = np.ascontiguousarray(current_a, dtype=np.float64)
        spd = np.ascontiguousarray(speed_rad_s, dtype=np.float64)
        out = np.empty(len(cur))
        _c3_kernel(cur, spd, self._state, self._drive, self._mode, self._fric, self._sos, out)
        return out


ArrayLike1 = NDArray[np.float64] | Sequence[float]


@dataclass
class _HarmonicDesign:
    """A cached harmonic design: its smoother, tooth frequency (Hz) and harmonic orders."""

    smoother: FixedLagSmoother
    tooth_hz: float
    orders: tuple[int, ...]
    n_plant: int


class FeedAxisEstimator(Block):
    """Streaming estimator of one feed axis: C3 → Kalman → fixed-lag smoother → axis load.

    Parameters
    ----------
    model : identified axis model.
    lag : smoother lag, samples (Aslan Appendix B: 60 = 6 ms at 10 kHz); 0 = filter only.
    teeth : number of cutter teeth; given, the block also reads the CNC's commanded spindle
        speed (``spindle/speed_cmd``, rad/s) and adds the tooth harmonics ``k·f_t ≤
        max_harmonic_hz`` to the disturbance model (Aslan's full model, Eq. 3.16–3.20, see
        :func:`design_feed_kalman`); None (default): the random walk alone (Eq. 3.21–3.23).
    max_harmonic_hz : highest harmonic given a state pair, Hz.
    harmonic_q_ratio : κ of the harmonic pairs' noise (``κ·q``).

    Outputs (delayed by ``lag`` samples: sample k is the estimate of sample k − lag):
    ``{axis}/load_est`` — load resisting +motion, N (linear) or N·m at the table (rotary), the
    quantity the drive simulator takes as ``load`` and Eq. 3.51 takes as τ;
    ``{axis}/force_est`` — force on the table along +axis (= −load, linear axes; rotary only
    with a moment arm, Eq. 3.12).

    Notes
    -----
    Harmonic design and spindle speed (decision "Tooth-harmonic disturbance model in the feed
    estimator"): the tooth frequency ``f_t = teeth·|Ω_cmd|/2π`` is binned to 0.1 %
    (:data:`TOOTH_BIN_REL`); once the command has stayed in one bin for
    :data:`HARMONIC_HOLD_S`, the design for that bin (made at the first tooth frequency seen in
    it, cached) takes over; while the speed ramps, below :data:`MIN_TOOTH_HZ` or above
    ``max_harmonic_hz`` the random-walk design runs. At every switch the estimate is carried
    in physical coordinates (the modal kernel state z is mapped to x̂ by the eigenvectors and
    back): the plant states and τ_DC are kept; a harmonic of order k present in both designs
    keeps its amplitude and phase (``[τ_AC, ∫τ_AC]`` with the integral rescaled by
    ``ω_old/ω_new``); a harmonic the new design lacks is folded into τ_DC and a new one starts
    at 0, so τ̂_a is continuous. The smoother's delay line and innovation history are carried;
    for the ``lag`` samples after a switch its correction combines the old design's innovations
    with the new gains (a transient no longer than the lag).
    """

    def __init__(
        self,
        model: FeedAxisModel,
        lag: int = ASLAN_LAG_SAMPLES,
        *,
        teeth: int | None = None,
        max_harmonic_hz: float = MAX_HARMONIC_HZ,
        harmonic_q_ratio: float = HARMONIC_Q_RATIO,
    ) -> None:
        self.model = model
        ax = model.axis
        self.name = f"feed_force_{ax}"
        self.inputs: tuple[str, ...] = (f"{ax}/current_cmd", f"{ax}/motor_speed")
        self.lag = int(lag)
        self.design = model.design()
        self._c3 = C3Torque(model.drive, model.lowpass_hz, model.sample_rate_hz, model.lugre)
        self._smoother = FixedLagSmoother(self.design, self.lag)
        if teeth is not None and (int(teeth) != teeth or teeth < 1):
            raise ConfigError(f"block {self.name}: teeth must be a positive integer, got {teeth}")
        if not max_harmonic_hz > 0:
            raise ConfigError(
                f"block {self.name}: max_harmonic_hz must be positive, got {max_harmonic_hz}"
            )
        if not harmonic_q_ratio > 0:
            raise ConfigError(
                f"block {self.name}: harmonic_q_ratio must be positive, got {harmonic_q_ratio}"
            )
        self.teeth = None if teeth is None else int(teeth)
        self.max_harmonic_hz = float(max_harmonic_hz)
        self.harmonic_q_ratio = float(harmonic_q_ratio)
        if self.teeth is not None:
            self.inputs = (*self.inputs, SPINDLE_SPEED_CMD)
        self._hold = max(1, round(HARMONIC_HOLD_S * model.sample_rate_hz))
        self._base = _HarmonicDesign(self._smoother, 0.0, (), self.design.n_states - 1)
        self._cache: dict[int, _HarmonicDesign] = {}
        self._key = -1
        self._active = self._base
        self._last_bin = -1
        self._run = 0
        d = model.drive
        self._gain = d.efficiency / d.transmission
        self._force_gain: float | None = None
        if model.kind == "linear":
            self._force_gain = -self._gain
        elif model.moment_arm_m is not None:
            self._force_gain = -self._gain / model.moment_arm_m

    @property
    def delay_samples(self) -> int:
        return self.lag

    def output_channels(self) -> list[ChannelInfo]:
        ax = self.model.axis
        unit = "N" if self.model.kind == "linear" else "N*m"
        out = [
            ChannelInfo(
                f"{ax}/load_est",
                unit,
                f"{ax} axis load resisting +motion from the drive current, Kalman-compensated "
                f"(Aslan Eq. 3.10-3.29, 3.11/3.12), delayed {self.lag} samples",
            )
        ]
        if self._force_gain is not None:
            out.append(
                ChannelInfo(
                    f"{ax}/force_est",
                    "N",
                    f"{ax} force on the table along +axis, Kalman-compensated, delayed "
                    f"{self.lag} samples",
                )
            )
        return out

    def reset(self, sample_rate_hz: float) -> None:
        if not math.isclose(sample_rate_hz, self.model.sample_rate_hz, rel_tol=1e-9):
            raise ConfigError(
                f"block {self.name}: identified at {self.model.sample_rate_hz:g} Hz, stream is "
                f"{sample_rate_hz:g} Hz"
            )
        self._c3.reset()
        self._smoother.reset()
        for h in self._cache.values():
            h.smoother.reset()
        self._key = -1
        self._active = self._base
        self._last_bin = -1
        self._run = 0

    @property
    def harmonic_design(self) -> KalmanDesign:
        """The design running at the end of the last chunk (the random-walk one by default)."""
        return self._active.smoother.design

    @property
    def tooth_hz(self) -> float:
        """Tooth frequency of the running harmonic design, Hz (0 on the random-walk design)."""
        return self._active.tooth_hz

    def _bins(
        self, speed_cmd: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Effective design bin per sample (−1: random walk) and the tooth frequency, Hz."""
        assert self.teeth is not None
        ft = np.abs(np.asarray(speed_cmd, dtype=float)) * self.teeth / (2 * math.pi)
        ok = np.isfinite(ft) & (ft >= MIN_TOOTH_HZ) & (ft <= self.max_harmonic_hz)
        safe = np.where(ok, ft, 1.0)
        b = np.where(ok, np.rint(np.log(safe) / math.log1p(TOOTH_BIN_REL)), -1).astype(np.int64)
        # samples since the bin was entered (run length carried across chunks)
        n = len(b)
        change = np.empty(n, dtype=bool)
        change[0] = b[0] != self._last_bin
        change[1:] = b[1:] != b[:-1]
        idx = np.arange(n)
        start = np.maximum.accumulate(np.where(change, idx, 0))
        run = idx - start + 1
        if not change[0]:
            first = ~np.cumsum(change).astype(bool)
            run = np.where(first, run + self._run, run)
        self._last_bin = int(b[-1])
        self._run = int(run[-1])
        eff = np.where((run >= self._hold) & (b >= 0), b, -1)
        return eff, ft

    def _design_for(self, key: int, tooth_hz: float) -> _HarmonicDesign:
        if key < 0:
            return self._base
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        freqs = tooth_harmonics(tooth_hz, self.max_harmonic_hz)
        design = self.model.design(harmonics_hz=freqs, harmonic_q_ratio=self.harmonic_q_ratio)
        n_plant = design.n_states - 1 - 2 * len(freqs)
        entry = _HarmonicDesign(
            FixedLagSmoother(design, self.lag),
            tooth_hz,
            tuple(range(1, len(freqs) + 1)),
            n_plant,
        )
        if len(self._cache) >= 32:  # a long program with many speeds: drop the oldest
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = entry
        return entry

    def _switch(self, key: int, tooth_hz: float) -> None:
        """Make the design of ``key`` the running one, carrying the estimate across."""
        if key == self._key:
            return
        old, new = self._active, self._design_for(key, tooth_hz)
        x_old = old.smoother._kf.state
        n0 = old.n_plant + 1
        x_new = np.zeros(new.smoother.design.n_states)
        x_new[:n0] = x_old[:n0]
        w_old = {k: 2 * math.pi * k * old.tooth_hz for k in old.orders}
        for i, k in enumerate(old.orders):
            pair = x_old[n0 + 2 * i : n0 + 2 * i + 2]
            if k in new.orders:
                j = n0 + 2 * new.orders.index(k)
                x_new[j] = pair[0]
                x_new[j + 1] = pair[1] * w_old[k] / (2 * math.pi * k * new.tooth_hz)
            else:
                x_new[old.n_plant] += pair[0]
        sm_new, sm_old = new.smoother, old.smoother
        sm_new._kf.reset(x_new)
        sm_new._hist_pred = sm_old._hist_pred.copy()
        sm_new._hist_innov = sm_old._hist_innov.copy()
        self._active, self._key = new, key

    def _torque_harmonic(
        self, cur: NDArray[np.float64], spd: NDArray[np.float64], speed_cmd: ArrayLike1
    ) -> NDArray[np.float64]:
        tau = self._c3.process(cur, spd)
        keys, ft = self._bins(np.asarray(speed_cmd, dtype=float))
        bounds = np.flatnonzero(np.diff(keys)) + 1
        starts = np.concatenate([[0], bounds]).astype(int)
        ends = np.concatenate([bounds, [len(tau)]]).astype(int)
        out = np.empty(len(tau))
        for s0, s1 in zip(starts, ends, strict=True):
            self._switch(int(keys[s0]), float(ft[s0]))
            out[s0:s1] = self._active.smoother.process(tau[s0:s1])[:, 0]
        return out

    def torque(
        self,
        current_a: ArrayLike1,
        speed_rad_s: ArrayLike1,
        spindle_speed_cmd_rad_s: ArrayLike1 | None = None,
    ) -> NDArray[np.float64]:
        """τ̂_a (N·m, motor side) of one chunk, delayed by ``lag`` samples.

        ``spindle_speed_cmd_rad_s`` (rad/s, the CNC's commanded spindle speed) is required when
        the block was built with ``teeth``. On the random-walk design one compiled call runs
        the C3 stage and the smoother (the smoother's own kernel on its carried state), which
        keeps the per-chunk overhead at a few microseconds.
        """
        cur = np.ascontiguousarray(current_a, dtype=np.float64)
        if len(cur) == 0:
            return np.zeros(0)
        if self.teeth is not None:
            if spindle_speed_cmd_rad_s is None:
                raise InputDataError(
                    f"block {self.name}: the harmonic design needs channel '{SPINDLE_SPEED_CMD}'"
                )
            spd = np.ascontiguousarray(speed_rad_s, dtype=np.float64)
            return self._torque_harmonic(cur, spd, spindle_speed_cmd_rad_s)
        c3, sm = self._c3, self._smoother
        return np.asarray(
            _estimate_kernel(
                cur,
                np.ascontiguousarray(speed_rad_s, dtype=np.float64),
                c3._state,
                c3._drive,
                c3._mode,
                c3._fric,
                c3._sos,
                *sm._kf.kernel_args,
                sm._kf.z,
                sm._taps_t,
                sm._hist_pred,
                sm._hist_innov,
            )
        )

    def process(self, chunk: Chunk) -> BlockOutput:
        sp = chunk.data[SPINDLE_SPEED_CMD] if self.teeth is not None else None
        tau = self.torque(chunk.data[self.inputs[0]], chunk.data[self.inputs[1]], sp)
        ax = self.model.axis
        out = {f"{ax}/load_est": self._gain * tau}
        if self._force_gain is not None:
            out[f"{ax}/force_est"] = self._force_gain * tau
        return BlockOutput(out)


class ToolForceBlock(Block):
    """Forces on the tool from the five axis loads (Aslan Eq. 3.51, ``F = −[Jᵀ·T]⁺·τ``).

    Parameters
    ----------
    kinematics : the machine's kinematics (:class:`~millsense.models.kinematics.
        TrunnionACMachine` in the drives' frames, or Aslan's :class:`~millsense.models.
        kinematics.TrunnionACKinematics`).
    axes : the five axes in the order of ``q`` = [x, y, z, θ_A, θ_C].
    transmissions : r_g per axis (m/rad, rad/rad) to turn motor angles into axis positions.
    offsets : axis position at motor angle 0 (m, rad), per axis.
    lag : samples by which the loads lag the encoders (the smoother lag); positions are delayed
        by the same amount so that each load meets the pose it was produced at.
    pose_every : the (delayed) pose, hence ``[Jᵀ·T]⁺``, is evaluated at stream samples that are
        multiples of this and held in between (1 = every sample).
    load_channels : the five load inputs (default ``{axis}/load_est``).

    Reads the loads and ``{axis}/motor_angle``; writes ``tool/force_x_est`` …
    ``tool/force_z_est`` (N, the frame of ``kinematics``: drive frame for the machine).

    Notes
    -----
    Sign (decision "Forces at the tool in estimate"): the loads are the estimators' axis loads,
    positive when they resist positive motion, i.e. ``τ = −Jᵀ·T·F`` for a force F on the tool
    (what the drives feel is the reaction of the cut); Eq. 3.51 then gives
    ``F = −[Jᵀ·T]⁺·τ``.
    """

    def __init__(
        self,
        kinematics: Kinematics,
        axes: Sequence[str],
        transmissions: Sequence[float],
        offsets: Sequence[float] | None = None,
        lag: int = ASLAN_LAG_SAMPLES,
        pose_every: int = 10,
        load_channels: Sequence[str] | None = None,
    ) -> None:
        if len(axes) != 5 or len(transmissions) != 5:
            raise ConfigError("tool force block: needs five axes [x, y, z, a, c]")
        if not isinstance(kinematics, (TrunnionACKinematics, TrunnionACMachine)):
            raise ConfigError("tool force block: needs the 5-axis trunnion kinematics")
        self.load_channels = tuple(load_channels or (f"{a}/load_est" for a in axes))
        if len(self.load_channels) != 5:
            raise ConfigError("tool force block: needs five load channels")
        self.name = "tool_force"
        self.kin = kinematics
        self.axes = tuple(axes)
        self.rg = np.asarray(transmissions, dtype=float)
        self.offsets = np.zeros(5) if offsets is None else np.asarray(offsets, dtype=float)
        self.lag = int(lag)
        self.pose_every = max(1, int(pose_every))
        self._angle_channels = tuple(f"{a}/motor_angle" for a in self.axes)
        self.inputs = self.load_channels + self._angle_channels
        self.reset(0.0)

    def output_channels(self) -> list[ChannelInfo]:
        return [
            ChannelInfo(f"tool/force_{c}_est", "N", f"force at the tool along {c} (Eq. 3.51)")
            for c in "xyz"
        ]

    def reset(self, sample_rate_hz: float) -> None:
        self._hist = np.zeros((self.lag, 5))  # the last `lag` poses
        # [started, held]: started 0 until the first chunk fills _hist with its first pose;
        # held 1 once _held_pinv holds the pseudo-inverse of the chunk's last pose
        self._state = np.zeros(2)
        self._held_pinv = np.zeros((3, 5))

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        n = chunk.n
        if n == 0:
            return BlockOutput({f"tool/force_{c}_est": np.zeros(0) for c in "xyz"})
        loads = np.array([d[c] for c in self.load_channels], dtype=float)  # (5, n)
        angles = np.array([d[c] for c in self._angle_channels], dtype=float)
        # [Jᵀ·T]⁺·(−τ) by the normal equations (full column rank away from singular poses):
        # batched 3×3 solves instead of one SVD per sample; the (delayed) pose is evaluated at
        # stream samples that are multiples of `pose_every` and held in between (the machine
        # moves < 0.1 mm in 1 ms at cutting feeds); the delay line and the hold compiled
        # (decision 1655); delay line, kinematics, solves and hold in one compiled call
        every = self.pose_every
        first = -chunk.start % every  # the chunk's first pose sample
        rows = np.empty((3, n))
        kin = self.kin
        tool_force_kernel(angles, loads, self.rg, self.offsets, self._hist, self._state, first,
                          every, isinstance(kin, TrunnionACMachine), kin.a2_m, kin.d4_m,
                          self._held_pinv, rows)  # fmt: skip
        return BlockOutput({f"tool/force_{c}_est": rows[i] for i, c in enumerate("xyz")})


def operating_condition(
    commanded_speed_rad_s: NDArray[np.float64] | Sequence[float] | float,
    rest_speed_rad_s: float = REST_SPEED_RAD_S,
) -> OperatingCondition:
    """Which identified model an axis's estimator uses, from what the CNC commands.

    Parameters
    ----------
    commanded_speed_rad_s : the CNC's commanded motor speed of the axis over the segment to be
        estimated (velocity feed-forward of the interpolator), rad/s.
    rest_speed_rad_s : largest |commanded speed| of an axis that holds position, rad/s. The
        default 0.01 rad/s (19 µm/s on a 12 mm lead) needs 0.3 s to cross the bristle range
        τ_coul/σ0 ≈ 3·10⁻³ rad of the Quaser X/Y axes (Aslan Table 3.2), longer than the tooth
        periods the estimator resolves, so the bristles stay in presliding.

    Returns
    -------
    ``at_rest`` when every commanded speed is within ±rest_speed_rad_s, else ``moving``.

    Notes
    -----
    Decision docs/decisions/0106-holding-axis-phi-d-and-r-identified-at-rest-issue-7-v1.md: the
    condition is chosen by the command, never by the measured current or speed (a loaded axis at
    rest trembles by a few encoder counts; a command is exact).
    """
    v = np.abs(np.asarray(commanded_speed_rad_s, dtype=float))
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise InputDataError("operating condition: need finite commanded speeds")
    return "at_rest" if float(np.max(v)) <= rest_speed_rad_s else "moving"
