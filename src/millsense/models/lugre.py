"""LuGre friction of a feed drive, motor side (rad, rad/s, N·m) — Aslan Eq. 3.2–3.9.

``τ_f = σ0·z + σ1·dz/dt + σ2·v`` (Eq. 3.2) with the bristle state
``dz/dt = v − |v|·σ0·z/g(v)`` (Eq. 3.3) and the Stribeck curve
``g(v) = τ_coul + (τ_stat − τ_coul)·exp(−(v/v_s)²)`` (Eq. 3.4); every parameter is picked by the
sign of v (Aslan Table 3.2 gives a (+, −) pair for each).

Integration (decision docs/decisions/0037-lugre-integration-aslan-eq-3-9.md): Aslan's forward-Euler
update (Eq. 3.9) is unstable once ``|v|·σ0·t_s/g > 2`` — for the A axis (σ0 = 28 000 N·m/rad) that
is |v| > 2 rad/s at a 10 µs step. Over one step v is held, so Eq. 3.3 is linear in z and is
integrated exactly: ``z⁺ = z_ss + (z − z_ss)·exp(−a·h)`` with ``a = |v|σ0/g(v)`` and
``z_ss = sgn(v)·g(v)/σ0``; dz/dt is the step's mean ``(z⁺ − z)/h``. For ``a·h ≪ 1`` this is
Eq. 3.9; for any step it is stable and converges to the steady sliding torque
``sgn(v)·g(v) + σ2·v``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from millsense.core.config import FrictionConfig
from millsense.core.errors import ConfigError

# packed parameter layout for the numba kernels: (+, −) pairs
_S0, _S1, _S2, _TS, _TC, _VS = 0, 2, 4, 6, 8, 10
N_PARAMS = 12


@dataclass(frozen=True)
class LuGre:
    """Direction-dependent LuGre friction (Aslan Eq. 3.2–3.4, Table 3.2), motor side.

    Attributes
    ----------
    sigma0 : (+, −) bristle stiffness σ0, N·m/rad.
    sigma1 : (+, −) bristle damping σ1, N·m·s/rad.
    sigma2 : (+, −) viscous coefficient σ2, N·m·s/rad.
    static : (+, −) static torque τ_stat, N·m.
    coulomb : (+, −) Coulomb torque τ_coul, N·m.
    stribeck_velocity : (+, −) Stribeck velocity v_s, rad/s.
    """

    sigma0: tuple[float, float]
    sigma1: tuple[float, float]
    sigma2: tuple[float, float]
    static: tuple[float, float]
    coulomb: tuple[float, float]
    stribeck_velocity: tuple[float, float]

    @classmethod
    def from_config(cls, cfg: FrictionConfig, where: str = "friction") -> LuGre:
        """From a machine file's friction table; the bristle keys ``sigma0_nm_rad`` and
        ``sigma1_nm_s_rad`` must be present.

        Without ``static_nm`` and ``stribeck_velocity_rad_s`` (the constant-velocity moves did
        not resolve a Stribeck rise, :class:`~millsense.ident.friction.LuGreFit`) the Stribeck
        curve is flat: τ_stat = τ_coul, so g(v) = τ_coul for every v (Aslan Eq. 3.4) and v_s
        (set to 1 rad/s) multiplies nothing (decision 1695). The two keys come together or not
        at all.

        Raises
        ------
        ConfigError naming ``where`` and the first missing key.
        """
        for key in ("sigma0_nm_rad", "sigma1_nm_s_rad"):
            if getattr(cfg, key) is None:
                raise ConfigError(f"{where}: LuGre friction needs key '{key}'")
        if (cfg.static_nm is None) != (cfg.stribeck_velocity_rad_s is None):
            given, missing = (
                ("static_nm", "stribeck_velocity_rad_s")
                if cfg.stribeck_velocity_rad_s is None
                else ("stribeck_velocity_rad_s", "static_nm")
            )
            raise ConfigError(
                f"{where}: key '{given}' needs key '{missing}' (the Stribeck curve, Aslan Eq. "
                "3.4; give both or neither)"
            )
        assert cfg.sigma0_nm_rad is not None and cfg.sigma1_nm_s_rad is not None
        return cls(
            sigma0=cfg.sigma0_nm_rad,
            sigma1=cfg.sigma1_nm_s_rad,
            sigma2=cfg.viscous_nm_s_rad,
            static=cfg.static_nm if cfg.static_nm is not None else cfg.coulomb_nm,
            coulomb=cfg.coulomb_nm,
            stribeck_velocity=(
                cfg.stribeck_velocity_rad_s
                if cfg.stribeck_velocity_rad_s is not None
                else (1.0, 1.0)
            ),
        )

    @staticmethod
    def configured(cfg: FrictionConfig) -> bool:
        """True if ``cfg`` holds a LuGre friction: its bristle keys (a presliding fit), with or
        without a Stribeck curve (decision 1695)."""
        return cfg.sigma0_nm_rad is not None and cfg.sigma1_nm_s_rad is not None

    def as_array(self) -> np.ndarray:
        """Parameters packed for :func:`lugre_step`: (+, −) pairs of σ0, σ1, σ2, τ_s, τ_c, v_s."""
        return np.array(
            [
                *self.sigma0,
                *self.sigma1,
                *self.sigma2,
                *self.static,
                *self.coulomb,
                *self.stribeck_velocity,
            ],
            dtype=np.float64,
        )

    def stribeck(self, speed_rad_s: np.ndarray) -> np.ndarray:
        """g(v) of Aslan Eq. 3.4 (N·m, ≥ 0) for motor speeds in rad/s (vectorised)."""
        v = np.asarray(speed_rad_s, dtype=float)
        pos = v >= 0.0
        ts = np.where(pos, self.static[0], self.static[1])
        tc = np.where(pos, self.coulomb[0], self.coulomb[1])
        vs = np.where(pos, self.stribeck_velocity[0], self.stribeck_velocity[1])
        return tc + (ts - tc) * np.exp(-((v / vs) ** 2))

    def steady_torque(self, speed_rad_s: np.ndarray) -> np.ndarray:
        """Friction at steady sliding, ``sgn(v)·g(v) + σ2·v`` (N·m): Eq. 3.2 with dz/dt = 0."""
        v = np.asarray(speed_rad_s, dtype=float)
        s2 = np.where(v >= 0.0, self.sigma2[0], self.sigma2[1])
        return np.sign(v) * self.stribeck(v) + s2 * v

    def simulate(
        self, speed_rad_s: np.ndarray, step_s: float, z0_rad: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Friction torque along a prescribed speed history (the speed held over each step).

        Parameters
        ----------
        speed_rad_s : motor speed per step, rad/s.
        step_s : step length, s.
        z0_rad : initial bristle deflection, rad (Aslan Eq. 3.9 starts from 0).

        Returns
        -------
        (torque N·m, bristle state z rad at the end of each step).
        """
        v = np.ascontiguousarray(speed_rad_s, dtype=np.float64)
        tau = np.empty_like(v)
        z = np.empty_like(v)
        _simulate(v, step_s, z0_rad, self.as_array(), tau, z)
        return tau, z

    def critical_sigma1(self, inertia_kg_m2: float) -> tuple[float, float]:
        """σ1 of Aslan Eq. 3.8, ``2·√(J·σ0) − σ2`` (critically damped sticking), N·m·s/rad.

        Aslan's Table 3.2 σ1 were tuned by hand and differ (X: 15 printed vs about 5.2 from
        Eq. 3.8); the tabulated values are what the simulator uses.
        """
        return (
            2.0 * math.sqrt(inertia_kg_m2 * self.sigma0[0]) - self.sigma2[0],
            2.0 * math.sqrt(inertia_kg_m2 * self.sigma0[1]) - self.sigma2[1],
        )


#: width of :func:`lugre_speed_terms`' tuple
N_SPEED_TERMS = 6


@numba.njit(cache=True)
def lugre_speed_terms(
    speed: float, h: float, p: np.ndarray
) -> tuple[float, float, float, float, float, float]:
    """The part of :func:`lugre_step` that depends on the held speed alone (not on z):
    ``(kind, z_c, e, σ0, σ1, σ2·v)``, kind 0 ``z⁺ = z_c`` (``a·h > 40``), 1 ``z⁺ = z_c + (z −
    z_c)·e`` (``z_c = z_ss``, ``e = exp(−a·h)``), 2 ``z⁺ = z + z_c`` (``z_c = v·h``, ``a·h ≤
    1e-12``). An encoder's speed takes few distinct values, so a caller may keep these per
    speed (:func:`lugre_advance` gives the same numbers bit for bit)."""
    d = 0 if speed >= 0.0 else 1
    s0 = p[_S0 + d]
    ts = p[_TS + d]
    tc = p[_TC + d]
    vs = p[_VS + d]
    r2 = (speed / vs) ** 2
    # exp(−r²) < 1e-17 beyond r² = 40: skip it (the result is identical in double precision
    # relative to τ_coul)
    g = tc + (ts - tc) * math.exp(-r2) if r2 < 40.0 else tc
    a = abs(speed) * s0 / g
    ah = a * h
    s2v = p[_S2 + d] * speed
    if ah > 40.0:
        return 0.0, speed / a, 0.0, s0, p[_S1 + d], s2v
    if ah > 1e-12:
        return 1.0, speed / a, math.exp(-ah), s0, p[_S1 + d], s2v
    return 2.0, speed * h, 0.0, s0, p[_S1 + d], s2v


@numba.njit(cache=True)
def lugre_advance(
    z: float, terms: tuple[float, float, float, float, float, float], h: float
) -> tuple[float, float]:
    """:func:`lugre_step` from its speed's :func:`lugre_speed_terms`: (z⁺ rad, torque N·m)."""
    kind, zc, e, s0, s1, s2v = terms
    if kind == 0.0:
        z_new = zc
    elif kind == 1.0:
        z_new = zc + (z - zc) * e
    else:
        z_new = z + zc
    zdot = (z_new - z) / h
    tau = s0 * z_new + s1 * zdot + s2v
    return z_new, tau


@numba.njit(cache=True)
def lugre_step(z: float, speed: float, h: float, p: np.ndarray) -> tuple[float, float]:
    """One step of Eq. 3.2–3.3 with the speed held: returns (z⁺ rad, friction torque N·m).

    ``p`` from :meth:`LuGre.as_array`. The bristle ODE is integrated exactly for the held speed
    (module docstring), which is Aslan's Eq. 3.9 in the limit of small steps.
    """
    return lugre_advance(z, lugre_speed_terms(speed, h, p), h)


@numba.njit(cache=True)
def _simulate(
    v: np.ndarray, h: float, z0: float, p: np.ndarray, tau: np.ndarray, zout: np.ndarray
) -> None:
    z = z0
    for k in range(v.shape[0]):
        z, t = lugre_step(z, v[k], h, p)
        tau[k] = t
        zout[k] = z
