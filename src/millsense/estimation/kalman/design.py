"""Design of the steady-state disturbance Kalman filter shared by every millsense estimator.

Pipeline (Aslan §3.3, §5.3):

1. :class:`StateSpaceModel` — the disturbance path of a drive, continuous (``dt=None``) or
   discrete: ``ẋ = A x + B τ_a``, ``y = C x + D τ_a`` (Aslan Eq. 3.15, 5.14).
2. :func:`augment_disturbance` — adds the disturbance as a random-walk state (Eq. 3.21–3.23:
   ``x_exp = [x; τ_a]``, ``A_exp = [[A, B], [0, 0]]``, ``L = [0 … 0 1]ᵀ``), optionally with a
   harmonic state pair per given frequency, e.g. the tooth frequency and its multiples
   (Eq. 3.16–3.20: ``A_F = [[0, −ω_t²], [1, 0]]``).
3. :func:`design_kalman` — exact ZOH discretisation of the augmented model with the process
   noise covariance by Van Loan, then the steady-state gains from
   ``scipy.linalg.solve_discrete_are``.
4. :meth:`KalmanDesign.filter` — the frozen-gain filter as a :class:`~millsense.estimation.
   lti_filter.LinearFilter` run by :class:`~millsense.estimation.kalman.lti_filter.StreamingFilter`.

Noise conventions (decision
docs/decisions/0044-units-of-q-and-r-of-the-disturbance-kalman-filter-aslan-eq.md): for a continuous
model, ``q`` is the spectral density of the white noise driving the disturbance (Eq. 3.28 is a
continuous Riccati equation), converted to the per-sample covariance by Van Loan; ``r`` is always
the per-sample variance of the measurement (Aslan: "RMS of the air-cut torque fluctuation", which
docs/decisions/0003-current-noise-from-aslan-eq-3-30.md reads as a variance). For a discrete model,
``q`` is already the per-sample covariance.

Forms (Notes of :func:`design_kalman`): the predictor form ``x̂(k+1|k) = (A_d − K_p C) x̂(k|k−1)
+ K_p y(k)`` has the structure of Aslan Eq. 3.26 and of the Luenberger form Eq. 5.17; Eq. 3.26
itself is the ZOH discretisation of the *continuous* Kalman–Bucy filter, available as
:func:`continuous_kalman_filter` for comparison.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg

from millsense.estimation.kalman.lti_filter import LinearFilter

Output = Literal["filtered", "predicted"]


def _as2d(x: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.atleast_2d(np.asarray(x, dtype=float))
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a matrix, got shape {np.shape(x)}")
    return arr


@dataclass(frozen=True)
class StateSpaceModel:
    """LTI model ``ẋ = A x + B u`` (or ``x⁺ = A x + B u`` if ``dt`` is set), ``y = C x + D u``.

    Attributes
    ----------
    a, b, c, d : system matrices (n×n, n×m, p×n, p×m); units those of the signals (SI).
    dt : sample time, s, for a discrete model; None for a continuous one.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    c: NDArray[np.float64]
    d: NDArray[np.float64]
    dt: float | None = None

    @classmethod
    def from_arrays(
        cls, a: ArrayLike, b: ArrayLike, c: ArrayLike, d: ArrayLike = 0.0, dt: float | None = None
    ) -> StateSpaceModel:
        """Build from array-likes; a 1-D ``b`` is a column, a 1-D ``c`` a row, scalar ``d``."""
        am = _as2d(a, "A")
        n = am.shape[0]
        bm = np.asarray(b, dtype=float)
        bm = bm.reshape(n, -1) if bm.ndim < 2 else bm
        cm = np.asarray(c, dtype=float)
        cm = cm.reshape(-1, n) if cm.ndim < 2 else cm
        dm = np.asarray(d, dtype=float)
        dm = np.broadcast_to(dm, (cm.shape[0], bm.shape[1])).copy() if dm.ndim < 2 else dm
        return cls(am, bm, cm, dm, dt)

    def __post_init__(self) -> None:
        n = self.a.shape[0]
        if self.a.shape != (n, n) or self.b.shape[0] != n or self.c.shape[1] != n:
            raise ValueError(
                f"inconsistent shapes A {self.a.shape}, B {self.b.shape}, C {self.c.shape}"
            )
        if self.d.shape != (self.c.shape[0], self.b.shape[1]):
            raise ValueError(
                f"D has shape {self.d.shape}, expected {(self.c.shape[0], self.b.shape[1])}"
            )
        if self.dt is not None and not self.dt > 0:
            raise ValueError(f"dt must be positive or None, got {self.dt}")

    @property
    def n_states(self) -> int:
        return int(self.a.shape[0])

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    def frf(self, f_hz: ArrayLike) -> NDArray[np.complex128]:
        """Frequency response ``C (sI − A)⁻¹ B + D`` (s = j2πf, or z = e^{j2πf·dt}).

        Parameters
        ----------
        f_hz : frequencies, Hz.

        Returns
        -------
        (nf, p, m) complex array.
        """
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        if self.dt is None:
            s = 2j * np.pi * f
        else:
            s = np.exp(2j * np.pi * f * self.dt)
        # one batched LU solve over the frequencies: LAPACK's gesv per frequency as a loop of
        # single solves would call it, the same operations in the same order (bit-identical)
        lhs = s[:, None, None] * np.eye(self.n_states) - self.a
        x = np.linalg.solve(lhs, np.broadcast_to(self.b, (len(f), *self.b.shape)))
        return np.asarray(self.c @ x + self.d, dtype=complex)


def discretize_zoh(model: StateSpaceModel, dt: float) -> StateSpaceModel:
    """Exact zero-order-hold discretisation.

    Parameters
    ----------
    model : continuous model.
    dt : sample time, s.

    Notes
    -----
    ``expm([[A, B], [0, 0]]·dt) = [[A_d, B_d], [0, I]]``; C and D are unchanged.
    """
    if model.is_discrete:
        raise ValueError("model is already discrete")
    n, m = model.b.shape
    blk = np.zeros((n + m, n + m))
    blk[:n, :n] = model.a
    blk[:n, n:] = model.b
    e = linalg.expm(blk * dt)
    return StateSpaceModel(e[:n, :n], e[:n, n:], model.c.copy(), model.d.copy(), dt)


def van_loan(
    a: ArrayLike, g: ArrayLike, q: ArrayLike, dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Discrete transition and process-noise covariance of ``ẋ = A x + G w``.

    Parameters
    ----------
    a : (n, n) continuous state matrix, 1/s.
    g : (n, r) noise coupling (Aslan's L, Eq. 3.20/3.23; Γ_s in Eq. 5.20).
    q : (r, r) spectral density of the white noise w (units of w² · s), or a scalar.
    dt : sample time, s.

    Returns
    -------
    (A_d, Q_d) with ``A_d = e^{A dt}`` and ``Q_d = ∫₀^dt e^{Aτ} G Q Gᵀ e^{Aᵀτ} dτ``.

    Notes
    -----
    Van Loan (1978): ``expm([[−A, GQGᵀ], [0, Aᵀ]]·dt) = [[·, M₁₂], [0, M₂₂]]`` gives
    ``A_d = M₂₂ᵀ`` and ``Q_d = A_d·M₁₂``. The result is symmetrised.
    """
    am = _as2d(a, "A")
    n = am.shape[0]
    gm = np.asarray(g, dtype=float).reshape(n, -1)
    qm = np.atleast_2d(np.asarray(q, dtype=float))
    if qm.shape == (1, 1) and gm.shape[1] != 1:
        qm = qm[0, 0] * np.eye(gm.shape[1])
    blk = np.zeros((2 * n, 2 * n))
    blk[:n, :n] = -am
    blk[:n, n:] = gm @ qm @ gm.T
    blk[n:, n:] = am.T
    e = linalg.expm(blk * dt)
    ad = e[n:, n:].T
    qd = ad @ e[:n, n:]
    return ad, 0.5 * (qd + qd.T)


@dataclass(frozen=True)
class AugmentedModel:
    """Plant augmented with its disturbance states (Aslan Eq. 3.20, 3.23, 5.16).

    Attributes
    ----------
    a : (n, n) augmented state matrix A_exp (continuous, or discrete if ``dt`` is set).
    c : (p, n) measurement matrix C_exp.
    g : (n, r) noise coupling L (Eq. 3.23) / Γ_s (Eq. 5.20).
    disturbance : (d, n) rows giving the disturbance estimate (C0 of Eq. 3.24).
    dt : None for a continuous model, else the sample time, s.
    n_plant : number of plant states before augmentation.
    harmonics_hz : frequencies of the harmonic disturbance pairs, Hz (empty: random walk only).
    """

    a: NDArray[np.float64]
    c: NDArray[np.float64]
    g: NDArray[np.float64]
    disturbance: NDArray[np.float64]
    dt: float | None
    n_plant: int
    harmonics_hz: tuple[float, ...] = ()

    @property
    def n_states(self) -> int:
        return int(self.a.shape[0])

    @property
    def harmonic_hz(self) -> float | None:
        """The first harmonic frequency, Hz, or None (single-pair API of Eq. 3.16–3.20)."""
        return self.harmonics_hz[0] if self.harmonics_hz else None

    def harmonic_states(self, i: int) -> slice:
        """Indices of the i-th harmonic pair ``[τ_AC,i, ∫τ_AC,i]`` in the augmented state."""
        if not 0 <= i < len(self.harmonics_hz):
            raise IndexError(f"harmonic pair {i} of {len(self.harmonics_hz)}")
        start = self.n_plant + 1 + 2 * i
        return slice(start, start + 2)


def augment_disturbance(
    model: StateSpaceModel,
    *,
    harmonic_hz: float | None = None,
    harmonics_hz: Sequence[float] | None = None,
    feedthrough: bool = True,
    noise_on_all_states: bool = False,
) -> AugmentedModel:
    """Augment the disturbance path with random-walk (and harmonic) disturbance states.

    Parameters
    ----------
    model : disturbance-to-measurement model Φ_d (single disturbance input), continuous or
        discrete.
    harmonic_hz : one harmonic disturbance at this frequency (Hz), e.g. the tooth frequency
        ω_t/2π (Aslan Eq. 3.16–3.20; Ch. 4 uses the spindle frequency, Eq. 4.3). Shorthand for
        ``harmonics_hz=[harmonic_hz]``; give one or the other.
    harmonics_hz : several harmonic disturbances (Hz), e.g. the tooth frequency and its
        multiples k·f_t; one state pair each, in the given order. Each must be positive and
        below the Nyquist frequency of a discrete model, and no two may coincide.
    feedthrough : measurement ``C_exp = [C D …]`` (True) or ``[C 0 …]`` (Aslan's printed
        Eq. 3.23). The digest notes ``[C D]`` is the correct one when D ≠ 0; it is the default.
    noise_on_all_states : noise coupling Γ = I (one white noise per augmented state), as in the
        spindle observer (Aslan Eq. 5.20 with Q_s = q·I₂₁, Table 5.2); default False: noise on
        the disturbance states only (Eq. 3.23, L = [0 … 0 1]ᵀ).

    Returns
    -------
    AugmentedModel with states ``[x; τ_DC; x_F,1; …; x_F,h]``; noise inputs
    ``[w_DC, w_AC,1, …, w_AC,h]``; disturbance row ``τ̂_a = τ_DC + Σᵢ C_F x_F,i``.

    Notes
    -----
    Continuous: ``A_exp = [[A, B, B C_F, …], [0, 0, 0, …], [0, 0, A_F,1, …], …]``,
    ``A_F,i = [[0, −ω_i²], [1, 0]]``, ``C_F = [1, 0]``, noise ``w_AC,i`` entering the first state
    of pair i so that ``τ_AC,i / w_AC,i = s / (s² + ω_i²)`` (Eq. 3.18–3.19; the thesis writes one
    pair at ω_t, several pairs are the same generator repeated at the tooth harmonics).
    Discrete: the random walk is ``τ(k+1) = τ(k) + w`` and each harmonic pair is
    ``e^{A_F,i dt}``, whose eigenvalues ``e^{±jω_i dt}`` lie on the unit circle (an undamped
    internal model of the sinusoid, exact for the sampled sinusoid).
    """
    if model.b.shape[1] != 1:
        raise ValueError(f"the disturbance model must have one input, has {model.b.shape[1]}")
    if harmonic_hz is not None and harmonics_hz is not None:
        raise ValueError("give harmonic_hz or harmonics_hz, not both")
    freqs: tuple[float, ...] = (
        (float(harmonic_hz),)
        if harmonic_hz is not None
        else tuple(float(f) for f in (harmonics_hz or ()))
    )
    for f in freqs:
        if not f > 0:
            raise ValueError(f"harmonic frequencies must be positive, got {f}")
        if model.dt is not None and not f < 0.5 / model.dt:
            raise ValueError(f"harmonic {f} Hz is not below the Nyquist frequency")
    if len(set(freqs)) != len(freqs):
        raise ValueError(f"harmonic frequencies must be distinct, got {freqs}")
    n = model.n_states
    p = model.c.shape[0]
    nh = len(freqs)
    na = n + 1 + 2 * nh
    a = np.zeros((na, na))
    a[:n, :n] = model.a
    a[:n, n] = model.b[:, 0]
    c = np.zeros((p, na))
    c[:, :n] = model.c
    if feedthrough:
        c[:, n] = model.d[:, 0]
    g = np.zeros((na, 1 + nh))
    dist = np.zeros((1, na))
    dist[0, n] = 1.0
    if model.is_discrete:
        a[n, n] = 1.0
    g[n, 0] = 1.0
    for i, f in enumerate(freqs):
        k = n + 1 + 2 * i
        w = 2 * np.pi * f
        af = np.array([[0.0, -(w**2)], [1.0, 0.0]])
        if model.dt is not None:
            af = linalg.expm(af * model.dt)
        a[k : k + 2, k : k + 2] = af
        a[:n, k] = model.b[:, 0]  # B·C_F with C_F = [1, 0]
        if feedthrough:
            c[:, k] = model.d[:, 0]
        g[k, 1 + i] = 1.0
        dist[0, k] = 1.0
    if noise_on_all_states:
        g = np.eye(na)
    return AugmentedModel(a, c, g, dist, model.dt, n, freqs)


@dataclass(frozen=True)
class KalmanDesign:
    """Steady-state discrete Kalman filter of an augmented model.

    Attributes
    ----------
    a : (n, n) discrete transition A_d.
    c : (p, n) measurement matrix.
    qd : (n, n) per-sample process noise covariance.
    r : (p, p) per-sample measurement noise covariance.
    disturbance : (d, n) rows of the disturbance estimate.
    dt : sample time, s.
    p_prior : (n, n) steady prior covariance ``P(k|k−1)`` (DARE solution).
    k_filter : (n, p) filter gain ``K_f = P Cᵀ (C P Cᵀ + R)⁻¹`` (measurement update).
    k_predictor : (n, p) predictor gain ``K_p = A_d K_f``.
    """

    a: NDArray[np.float64]
    c: NDArray[np.float64]
    qd: NDArray[np.float64]
    r: NDArray[np.float64]
    disturbance: NDArray[np.float64]
    dt: float
    p_prior: NDArray[np.float64]
    k_filter: NDArray[np.float64]
    k_predictor: NDArray[np.float64]

    @property
    def n_states(self) -> int:
        return int(self.a.shape[0])

    @property
    def innovation_covariance(self) -> NDArray[np.float64]:
        """``C P Cᵀ + R``, the covariance of the innovation ``y − C x̂(k|k−1)``."""
        return self.c @ self.p_prior @ self.c.T + self.r

    @property
    def p_filtered(self) -> NDArray[np.float64]:
        """Steady posterior covariance ``P(k|k) = (I − K_f C) P(k|k−1)``."""
        p = (np.eye(self.n_states) - self.k_filter @ self.c) @ self.p_prior
        return 0.5 * (p + p.T)

    @property
    def closed_loop(self) -> NDArray[np.float64]:
        """``A_d − K_p C``, the transition of the predictor (error dynamics, Eq. 5.18)."""
        return self.a - self.k_predictor @ self.c

    def filter(
        self,
        output: Output = "filtered",
        rows: ArrayLike | None = None,
        *,
        innovation: bool = False,
    ) -> LinearFilter:
        """The frozen-gain filter as an LTI system with state ``x̂(k|k−1)`` and input ``y(k)``.

        Parameters
        ----------
        output : ``"filtered"`` emits ``S x̂(k|k)`` (uses y(k), no delay); ``"predicted"``
            emits ``S x̂(k|k−1)`` (Eq. 3.26/5.17 form, one sample behind).
        rows : (d, n) selection S; default the disturbance rows (``τ̂_a``); pass
            ``np.eye(n)`` for the whole state.
        innovation : also emit the innovation ``e(k) = y(k) − C x̂(k|k−1)`` as the last p
            outputs (used by the fixed-lag smoother and whiteness checks).

        Notes
        -----
        ``x̂(k+1|k) = (A_d − K_p C) x̂(k|k−1) + K_p y(k)``;
        ``x̂(k|k) = (I − K_f C) x̂(k|k−1) + K_f y(k)``.
        """
        s = self.disturbance if rows is None else _as2d(rows, "rows")
        n = self.n_states
        p = self.c.shape[0]
        if output == "filtered":
            h = s @ (np.eye(n) - self.k_filter @ self.c)
            j = s @ self.k_filter
        elif output == "predicted":
            h = s.copy()
            j = np.zeros((s.shape[0], p))
        else:
            raise ValueError(f"output must be 'filtered' or 'predicted', got {output!r}")
        if innovation:
            h = np.vstack([h, -self.c])
            j = np.vstack([j, np.eye(p)])
        return LinearFilter(self.closed_loop, self.k_predictor.copy(), h, j, self.dt)


def design_kalman(
    aug: AugmentedModel,
    q: ArrayLike,
    r: ArrayLike,
    dt: float | None = None,
) -> KalmanDesign:
    """Steady-state discrete Kalman gains for an augmented model.

    Parameters
    ----------
    aug : augmented model (continuous or discrete).
    q : process noise: spectral density of w (continuous model; e.g. (N·m)²/s for the
        disturbance random walk) or per-sample covariance (discrete model); scalar or (r, r).
    r : per-sample measurement noise covariance (e.g. N²·m² for a torque), scalar or (p, p).
    dt : sample time, s; required for a continuous model (0.1 ms in Aslan Eq. 3.26).

    Returns
    -------
    KalmanDesign with the DARE prior covariance and the filter and predictor gains.

    Notes
    -----
    Continuous model: ``(A_d, Q_d)`` by Van Loan (:func:`van_loan`), exact for the augmented
    model of Eq. 3.23. The DARE ``P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ + Q_d`` is the
    discrete counterpart of Aslan Eq. 3.28, solved by ``scipy.linalg.solve_discrete_are``;
    its solution is the prior covariance P(k|k−1). The filter gain ``K_f = P Cᵀ (C P Cᵀ+R)⁻¹``
    is the discrete analogue of Eq. 3.29 and the predictor gain ``K_p = A_d K_f`` is the gain of
    the one-step predictor, whose structure is that of Eq. 3.26 and of the Luenberger observer
    Eq. 5.17/5.21 (``L_ds``).
    """
    qm = np.atleast_2d(np.asarray(q, dtype=float))
    nw = aug.g.shape[1]
    if qm.shape == (1, 1) and nw != 1:
        qm = qm[0, 0] * np.eye(nw)
    if qm.shape != (nw, nw):
        raise ValueError(f"q must be scalar or {nw}×{nw}, got shape {qm.shape}")
    p_meas = aug.c.shape[0]
    rm = np.atleast_2d(np.asarray(r, dtype=float))
    if rm.shape == (1, 1) and p_meas != 1:
        rm = rm[0, 0] * np.eye(p_meas)
    if rm.shape != (p_meas, p_meas):
        raise ValueError(f"r must be scalar or {p_meas}×{p_meas}, got shape {rm.shape}")
    if aug.dt is None:
        if dt is None or not dt > 0:
            raise ValueError("dt (s) is required to design a filter for a continuous model")
        ad, qd = van_loan(aug.a, aug.g, qm, dt)
        step = dt
    else:
        if dt is not None and not np.isclose(dt, aug.dt):
            raise ValueError(f"dt {dt} differs from the discrete model's {aug.dt}")
        ad = aug.a.copy()
        qd = aug.g @ qm @ aug.g.T
        step = aug.dt
    p = linalg.solve_discrete_are(ad.T, aug.c.T, qd, rm)
    p = 0.5 * (p + p.T)
    s = aug.c @ p @ aug.c.T + rm
    kf = np.linalg.solve(s.T, (p @ aug.c.T).T).T
    kp = ad @ kf
    return KalmanDesign(ad, aug.c.copy(), qd, rm, aug.disturbance.copy(), step, p, kf, kp)


def continuous_kalman_filter(
    aug: AugmentedModel, q: ArrayLike, r_c: ArrayLike, dt: float
) -> tuple[NDArray[np.float64], LinearFilter]:
    """Aslan Eq. 3.24–3.29 literally: continuous gain, then the ZOH-discretised filter Eq. 3.26.

    Parameters
    ----------
    aug : continuous augmented model.
    q : spectral density of w, as in Eq. 3.28.
    r_c : measurement noise *spectral density* of the continuous filter (Eq. 3.28's R).
    dt : sample time of the discretised filter, s.

    Returns
    -------
    (K, filt): the continuous gain ``K = P Cᵀ R⁻¹`` (Eq. 3.29, P from the algebraic form of
    Eq. 3.28) and the filter ``x̂(k+1) = e^{(A−KC)dt} x̂(k) + ∫₀^dt e^{(A−KC)τ}dτ K y(k)``,
    ``τ̂_a(k) = C0 x̂(k)`` (Eq. 3.26).

    Notes
    -----
    Kept for comparison with the thesis; millsense estimators use :func:`design_kalman`.
    """
    if aug.dt is not None:
        raise ValueError("continuous_kalman_filter needs a continuous augmented model")
    qm = np.atleast_2d(np.asarray(q, dtype=float))
    if qm.shape == (1, 1) and aug.g.shape[1] != 1:
        qm = qm[0, 0] * np.eye(aug.g.shape[1])
    rm = np.atleast_2d(np.asarray(r_c, dtype=float))
    p = linalg.solve_continuous_are(aug.a.T, aug.c.T, aug.g @ qm @ aug.g.T, rm)
    k = np.linalg.solve(rm.T, (p @ aug.c.T).T).T
    acl = aug.a - k @ aug.c
    disc = discretize_zoh(StateSpaceModel(acl, k, aug.disturbance, np.zeros((1, k.shape[1]))), dt)
    return k, LinearFilter(disc.a, disc.b, disc.c, disc.d, dt)


def compensated_frf(
    model: StateSpaceModel,
    gains: KalmanDesign | LinearFilter,
    f_hz: ArrayLike,
    *,
    output: int = 0,
    measurement: int = 0,
    plant_frf: NDArray[np.complex128] | None = None,
) -> NDArray[np.complex128]:
    """Compensated FRF ``τ̂_a / τ_a`` through the plant and the estimator.

    Parameters
    ----------
    model : disturbance path Φ_d = τ_c/τ_a (continuous: evaluated at jω, since a sinusoidal
        disturbance gives a sampled sinusoidal measurement; discrete: at e^{jωdt}).
    gains : a design (its ``filter("filtered")`` is used) or any LTI estimator whose input is
        the measurement.
    f_hz : frequencies, Hz.
    output : index of the estimator output (disturbance row).
    measurement : index of the measurement (row of Φ_d, input of the estimator).
    plant_frf : ``model.frf(f_hz)`` when the caller already has it (a tuning evaluates many
        designs on one model: the model's response is the same for each).

    Returns
    -------
    (nf,) complex FRF; 1 means perfect compensation (Aslan Eq. 5.23: G_cτ = G_dτ·G_Lτ; Fig. 3.8:
    Φ_d·Φ_KL).
    """
    filt = gains.filter("filtered") if isinstance(gains, KalmanDesign) else gains
    plant = (model.frf(f_hz) if plant_frf is None else plant_frf)[:, measurement, 0]
    est = filt.frf(f_hz)[:, output, measurement]
    return plant * est


def bandwidth_3db(f: ArrayLike, h: ArrayLike, tol_db: float = 3.0) -> float:
    """Highest frequency up to which ``|H|`` stays within ``±tol_db`` of 0 dB.

    Parameters
    ----------
    f : increasing frequencies, Hz (start at or near 0).
    h : complex or magnitude FRF at ``f`` (the compensated FRF, ideal 1).
    tol_db : band half-width, dB.

    Returns
    -------
    The frequency, Hz, where ``|20 log₁₀|H||`` first reaches ``tol_db`` (linear interpolation
    in dB between grid points); ``f[-1]`` if it never does; ``f[0]`` if the first point is
    already outside.
    """
    fa = np.asarray(f, dtype=float)
    db = 20 * np.log10(np.maximum(np.abs(np.asarray(h)), 1e-300))
    dev = np.abs(db)
    out = np.nonzero(dev >= tol_db)[0]
    if len(out) == 0:
        return float(fa[-1])
    i = int(out[0])
    if i == 0:
        return float(fa[0])
    d0, d1 = dev[i - 1], dev[i]
    frac = (tol_db - d0) / (d1 - d0) if d1 != d0 else 0.0
    return float(fa[i - 1] + frac * (fa[i] - fa[i - 1]))
