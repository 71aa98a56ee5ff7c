"""Validation of the five-axis trunnion kinematics (Aslan Ch. 3.4)."""

from __future__ import annotations

import numpy as np

from millsense.validation import Measured, case


def _poses(n: int = 200) -> np.ndarray:
    rng = np.random.default_rng(11)
    q = np.empty((n, 5))
    q[:, :3] = rng.uniform(-0.3, 0.3, (n, 3))
    q[:, 3] = rng.uniform(-1.4, 1.4, n)
    q[:, 4] = rng.uniform(-3.0, 3.0, n)
    return q


@case(
    "models.kinematics_jacobian_fd",
    source="central differences of Aslan Eq. 3.38 (digest §6 test list)",
    reference=0.0,
    unit="m/rad",
    abs_tol=1e-8,
    quick=True,
    description="max |J − finite-difference ∂P/∂q| over 200 random trunnion poses, h = 1e-6",
)
def _jacobian_fd() -> Measured:
    from millsense.models.kinematics import TrunnionACKinematics

    kin = TrunnionACKinematics()
    q = _poses()
    j = kin.jacobian(q)
    h = 1e-6
    err = 0.0
    for k in range(5):
        dq = np.zeros(5)
        dq[k] = h
        fd = (kin.forward(q + dq) - kin.forward(q - dq)) / (2 * h)
        err = max(err, float(np.abs(j[:, :, k] - fd).max()))
    return Measured(err, "Tolerance: truncation h²·|P'''| plus round-off eps·|P|/h, both < 1e-9.")


@case(
    "models.kinematics_force_roundtrip",
    source="Aslan Eq. 3.49/3.51: [Jᵀ·T]⁺·(Jᵀ·T·F) = F",
    reference=0.0,
    unit="N",
    abs_tol=1e-8,
    quick=True,
    description="max |F − pinv(Jᵀ·T)·Jᵀ·T·F| for 200 poses and random 500 N forces",
)
def _force_roundtrip() -> float:
    from millsense.models.kinematics import TrunnionACKinematics

    kin = TrunnionACKinematics()
    q = _poses()
    f = np.random.default_rng(12).normal(0.0, 500.0, (len(q), 3))
    return float(np.abs(kin.tool_force(q, kin.drive_loads(q, f)) - f).max())
