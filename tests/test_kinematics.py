"""Kinematics: Jacobian vs finite differences, inverse/forward round trip, force mapping."""

from __future__ import annotations

import numpy as np
import pytest

from millsense.core.errors import InputDataError
from millsense.models.kinematics import (
    ThreeAxisKinematics,
    TrunnionACKinematics,
    TrunnionACMachine,
    kinematics_for,
)

RNG = np.random.default_rng(5)


def _random_q(n: int) -> np.ndarray:
    q = np.empty((n, 5))
    q[:, :3] = RNG.uniform(-0.3, 0.3, (n, 3))
    q[:, 3] = RNG.uniform(-1.4, 1.4, n)  # θ_A inside (−π/2, π/2)
    q[:, 4] = RNG.uniform(-3.0, 3.0, n)
    return q


def test_jacobian_equals_central_differences() -> None:
    kin = TrunnionACKinematics()
    q = _random_q(50)
    j = kin.jacobian(q)
    h = 1e-6
    for k in range(5):
        dq = np.zeros(5)
        dq[k] = h
        fd = (kin.forward(q + dq) - kin.forward(q - dq)) / (2 * h)
        # central-difference truncation ~ h²·|P'''| ≈ 1e-12 and round-off ~ eps·|P|/h ≈ 1e-10:
        # 1e-8 bounds both with margin
        np.testing.assert_allclose(j[:, :, k], fd, atol=1e-8)


def test_jacobian_matches_printed_rows_3() -> None:
    # Aslan Eq. 3.39 row 3 printed: [0, sA, cA, y·cA − z·sA + a2·sA, 0]
    kin = TrunnionACKinematics(a2_m=0.2, d4_m=0.05)
    q = np.array([0.1, -0.05, 0.12, 0.4, 1.1])
    j = kin.jacobian(q)
    _, y, z, a, _ = q
    row3 = [0.0, np.sin(a), np.cos(a), y * np.cos(a) - z * np.sin(a) + 0.2 * np.sin(a), 0.0]
    np.testing.assert_allclose(j[2], row3, atol=1e-15)


def test_forward_of_inverse_is_identity() -> None:
    kin = TrunnionACKinematics()
    q = _random_q(200)
    pose = kin.forward_pose(q)
    q2 = kin.inverse(pose)
    # θ_A in (−π/2, π/2) and θ_C in (−π, π) are the principal branch: exact round trip up to
    # round-off (asin/atan2 ~1e-15 rad times lever arms < 1 m)
    np.testing.assert_allclose(q2, q, atol=1e-12)
    np.testing.assert_allclose(kin.forward_pose(q2), pose, atol=1e-12)


def test_orientation_is_eq_3_36_and_typo_fix() -> None:
    kin = TrunnionACKinematics()
    pose = kin.forward_pose(np.array([0.0, 0.0, 0.0, 0.3, -0.7]))
    # Eq. 3.36 O = [cA·sC, cA·cC, −sA]; θ_A = −asin(O_k) recovers 0.3 (not −sin(O_k))
    np.testing.assert_allclose(
        pose[3:], [np.cos(0.3) * np.sin(-0.7), np.cos(0.3) * np.cos(-0.7), -np.sin(0.3)], atol=1e-15
    )
    assert kin.inverse(pose)[3] == pytest.approx(0.3, abs=1e-15)


def test_drive_loads_match_eq_3_49_closed_form() -> None:
    # Aslan Eq. 3.49: F_Xa = F_tx, F_Ya = F_ty, F_Za = F_tz, τ_A = F_ty·(a2 − z) + F_tz·y,
    # τ_C = F_tx·(y·cA + (a2 − z)·sA) − F_ty·x·cA + F_tz·x·sA
    a2 = 0.15
    kin = TrunnionACKinematics(a2_m=a2, d4_m=0.08)
    q = _random_q(20)
    f = RNG.normal(0.0, 300.0, (20, 3))
    tau = kin.drive_loads(q, f)
    x, y, z, a = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    fx, fy, fz = f.T
    np.testing.assert_allclose(tau[:, :3], f, atol=1e-10)
    np.testing.assert_allclose(tau[:, 3], fy * (a2 - z) + fz * y, atol=1e-10)
    tc = fx * (y * np.cos(a) + (a2 - z) * np.sin(a)) - fy * x * np.cos(a) + fz * x * np.sin(a)
    # independent closed form from the thesis; round-off only
    np.testing.assert_allclose(tau[:, 4], tc, atol=1e-10)


def test_pseudo_inverse_returns_tool_force() -> None:
    kin = TrunnionACKinematics()
    q = _random_q(30)
    f = RNG.normal(0.0, 500.0, (30, 3))
    # Jᵀ·T has full column rank (its top block is I), so [Jᵀ·T]⁺ is an exact left inverse:
    # round-off only (1e-9 N on 500 N forces)
    np.testing.assert_allclose(kin.tool_force(q, kin.drive_loads(q, f)), f, atol=1e-9)


def test_three_axis_identity_and_dispatch() -> None:
    kin = kinematics_for("3-axis")
    assert isinstance(kin, ThreeAxisKinematics)
    q = np.array([[0.1, 0.2, 0.3]])
    np.testing.assert_array_equal(kin.forward(q), q)
    np.testing.assert_array_equal(kin.jacobian(q)[0], np.eye(3))
    np.testing.assert_array_equal(kin.tool_force(q, kin.drive_loads(q, q)), q)
    # machine files name the drives: the trunnion in drive / G-code frames
    assert isinstance(kinematics_for("5-axis-trunnion-ac"), TrunnionACMachine)
    with pytest.raises(InputDataError, match="shape"):
        TrunnionACKinematics().forward(np.zeros(3))


def test_compiled_kinematics_equal_the_numpy_form() -> None:
    # the compiled kernels (models/_kinematics_kernels.py) perform the numpy form's operations
    # P = R·(p − a2·e_z) − d4·e_z and J = [R·R0, ∂R/∂θ_A·rel, ∂R/∂θ_C·rel] (drive frames via
    # to_aslan); summed in another order they could differ by rounding only: 1e-15 m and 1e-15
    # on entries of order 1 bound one ulp of lever arms < 1 m
    machine = TrunnionACMachine(a2_m=0.151, d4_m=0.079)
    q = _random_q(500)
    qa = machine.to_aslan(q)
    r = TrunnionACKinematics.rotation(qa[:, 3], qa[:, 4])
    rel = qa[:, :3] - [0.0, 0.0, machine.a2_m]
    p = np.einsum("nij,nj->ni", r, rel) - [0.0, 0.0, machine.d4_m]
    np.testing.assert_allclose(machine.forward(q), p, rtol=0, atol=1e-15)
    h = 1e-7
    for k, d in ((3, np.array([0, 0, 0, h, 0])), (4, np.array([0, 0, 0, 0, h]))):
        # angular columns against central differences of the numpy rotation: truncation h² ≈
        # 1e-14, round-off eps/h ≈ 2e-9, bounded by 1e-8
        rp = TrunnionACKinematics.rotation(qa[:, 3] + d[3], qa[:, 4] + d[4])
        rm = TrunnionACKinematics.rotation(qa[:, 3] - d[3], qa[:, 4] - d[4])
        col = np.einsum("nij,nj->ni", (rp - rm) / (2 * h), rel)
        np.testing.assert_allclose(machine.jacobian(q)[:, :, k], col, rtol=0, atol=1e-8)
    r0 = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])
    np.testing.assert_allclose(machine.jacobian(q)[:, :, :3], r @ r0, rtol=0, atol=1e-15)
    j = machine.jacobian(q)
    lm = np.einsum("nji,njk->nik", j, j[:, :, :3])
    np.testing.assert_allclose(machine.load_matrix(q), lm, rtol=0, atol=1e-15)


def test_forward_rows_equal_forward() -> None:
    """An on-line block's row layout (axes × samples into 3 × samples) gives :meth:`forward`'s
    tool tips bit for bit on every kinematics (the same compiled kernel, or the identity)."""
    rng = np.random.default_rng(11)
    for kin in (ThreeAxisKinematics(), TrunnionACKinematics(), TrunnionACMachine()):
        q = rng.uniform(-0.3, 0.3, (kin.n_axes, 257))
        rows = np.empty((3, q.shape[1]))
        kin.forward_rows(q, rows)
        assert np.array_equal(rows, np.asarray(kin.forward(q.T)).T)
