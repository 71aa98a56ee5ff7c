"""Linear drive plants (Aslan Eq. 3.1 rigid body) and position-periodic disturbances
(Yamada §3.6): the mechanics that the simulator integrates and the observers are designed on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg

# plant output rows
OUT_THETA, OUT_OMEGA, OUT_ALPHA, OUT_X, OUT_V, OUT_A = 0, 1, 2, 3, 4, 5


# periodic term kinds
KIND_TORQUE, KIND_SCREW, KIND_MOTOR_ENCODER, KIND_SCALE = 0, 1, 2, 3


@dataclass(frozen=True)
class MechanicalPlant:
    """Continuous linear mechanics of a drive.

    Attributes
    ----------
    a : (n, n) state matrix.
    b : (n, 3) input matrix for ``[τ_m (N·m on the motor), F (load at the table, resisting),
        δ (kinematic screw error, m)]``.
    c : (6, n) and d : (6, 3) output map to ``[θ_m rad, ω_m rad/s, α_m rad/s², x_load, v_load,
        a_load]`` (load position in m, or rad for rotary axes).
    inertia : total inertia reflected to the motor, kg·m² (for gain design).
    name : description.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    inertia: float
    name: str

    def discretise(self, step_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact zero-order-hold (Ad, Bd) for one step."""
        n, m = self.b.shape
        aug = np.zeros((n + m, n + m))
        aug[:n, :n] = self.a * step_s
        aug[:n, n:] = self.b * step_s
        e = scipy.linalg.expm(aug)
        return np.ascontiguousarray(e[:n, :n]), np.ascontiguousarray(e[:n, n:])

    def frf(self, frequency_hz: np.ndarray, inp: int, out: int) -> np.ndarray:
        """Open-loop frequency response from input column ``inp`` to output row ``out``."""
        n = self.a.shape[0]
        res = np.empty(len(frequency_hz), dtype=complex)
        for j, f in enumerate(np.asarray(frequency_hz, dtype=float)):
            s = 2j * math.pi * f
            x = np.linalg.solve(s * np.eye(n) - self.a, self.b[:, inp])
            res[j] = self.c[out] @ x + self.d[out, inp]
        return res


def rigid_plant(
    inertia_kg_m2: float,
    transmission: float,
    efficiency: float = 1.0,
    viscous_nm_s_rad: float = 0.0,
    load: Literal["force", "torque"] = "force",
) -> MechanicalPlant:
    """Rigid body of Aslan Eq. 3.1, states ``[θ_m, ω_m]``.

    Parameters
    ----------
    inertia_kg_m2 : J_e, kg·m².
    transmission : r_g = h_p/2π, m/rad (rad/rad for rotary axes).
    efficiency : η; a table load F acts on the motor as ``(r_g/η)·F`` (Eq. 3.11).
    viscous_nm_s_rad : viscous damping inside the linear plant (friction models add their own).
    load : ``force`` — the load input is the table force F; ``torque`` — it is already the
        motor-side load torque (N·m).
    """
    j = inertia_kg_m2
    lg = transmission / efficiency if load == "force" else 1.0
    a = np.array([[0.0, 1.0], [0.0, -viscous_nm_s_rad / j]])
    b = np.array([[0.0, 0.0, 0.0], [1.0 / j, -lg / j, 0.0]])
    c = np.zeros((6, 2))
    d = np.zeros((6, 3))
    c[OUT_THETA, 0] = 1.0
    c[OUT_OMEGA, 1] = 1.0
    c[OUT_ALPHA] = a[1]
    d[OUT_ALPHA] = b[1]
    c[OUT_X, 0] = transmission
    d[OUT_X, 2] = 1.0  # a lead error shifts the table, the body stays rigid
    c[OUT_V, 1] = transmission
    c[OUT_A] = transmission * a[1]
    d[OUT_A] = transmission * b[1]
    return MechanicalPlant(a, b, c, d, j, "rigid")


@dataclass(frozen=True)
class PeriodicTerm:
    """``amplitude·sin(wavenumber·q + phase)`` with q the motor angle (rad) or, for the
    linear-scale kind, the table position (m).

    kind: 0 torque on the motor (N·m), 1 screw error (m), 2 motor-encoder error (rad),
    3 scale error (m).
    """

    kind: int
    wavenumber: float
    amplitude: float
    phase: float
