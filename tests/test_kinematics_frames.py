"""Trunnion in the drive / G-code frames (decision "Trunnion frames: G-code and drives")."""

from __future__ import annotations

import numpy as np

from millsense.models.kinematics import TrunnionACKinematics, TrunnionACMachine

RNG = np.random.default_rng(11)
KIN = TrunnionACMachine()


def _random_q(n: int) -> np.ndarray:
    q = np.empty((n, 5))
    q[:, :3] = RNG.uniform(-0.3, 0.3, (n, 3))
    q[:, 3] = RNG.uniform(-1.9, 1.9, n)  # A ±110°, the UX600 tilt range, both signs
    q[:, 4] = RNG.uniform(-6.0, 6.0, n)  # C unwrapped
    return q


def test_level_table_is_three_axis_machine() -> None:
    # A = C = 0: tool along workpiece +Z and P = [X, Y, Z] (CAM convention), exactly
    q = np.column_stack([RNG.uniform(-0.3, 0.3, (10, 3)), np.zeros((10, 2))])
    np.testing.assert_allclose(KIN.forward(q), q[:, :3], atol=1e-15)
    np.testing.assert_allclose(KIN.orientation(0.0, 0.0), [0.0, 0.0, 1.0], atol=0)
    np.testing.assert_allclose(KIN.jacobian(q)[0][:, :3], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(KIN.rotation(0.0, 0.0), np.eye(3), atol=1e-15)
    # a force along the tool loads Z only among the linear drives (round-off)
    loads = KIN.drive_loads(q[0], np.array([0.0, 0.0, 100.0]))
    np.testing.assert_allclose(loads[:3], [0.0, 0.0, 100.0], atol=1e-12)


def test_orientation_is_aslan_with_a_offset() -> None:
    # O = [sA·sC, sA·cC, cA] equals Aslan Eq. 3.36 at θ_A = A − π/2, θ_C = C
    q = _random_q(50)
    o_aslan = TrunnionACKinematics.orientation(q[:, 3] - np.pi / 2, q[:, 4])
    np.testing.assert_allclose(KIN.orientation(q[:, 3], q[:, 4]), o_aslan, atol=1e-15)
    # T·e_z is the tool axis: the spindle is the drive frame's Z axis
    t = KIN.rotation(q[:, 3], q[:, 4])
    np.testing.assert_allclose(t[:, :, 2], o_aslan, atol=1e-15)
    # T is a proper rotation
    np.testing.assert_allclose(np.linalg.det(t), 1.0, atol=1e-12)


def test_jacobian_equals_central_differences() -> None:
    q = _random_q(50)
    j = KIN.jacobian(q)
    h = 1e-6
    for k in range(5):
        dq = np.zeros(5)
        dq[k] = h
        fd = (KIN.forward(q + dq) - KIN.forward(q - dq)) / (2 * h)
        # truncation ~1e-12, round-off ~1e-10 (see test_kinematics)
        np.testing.assert_allclose(j[:, :, k], fd, atol=1e-8)


def test_inverse_at_keeps_any_branch_and_round_trips() -> None:
    q = _random_q(100)
    p = KIN.forward(q)
    q2 = KIN.inverse_at(p, q[:, 3], q[:, 4])
    # exact inverse for the given angles: round-off of the lever arms (< 1 m)
    np.testing.assert_allclose(q2, q, atol=1e-12)
    # the pose inverse returns the principal branch with the same pose
    pose = KIN.forward_pose(q)
    np.testing.assert_allclose(KIN.forward_pose(KIN.inverse(pose)), pose, atol=1e-12)


def test_loads_and_pseudo_inverse() -> None:
    q = _random_q(30)
    f = RNG.normal(0.0, 500.0, (30, 3))
    tau = KIN.drive_loads(q, f)
    # virtual work: τ·δq = F_w·δP with F_w = T·F and δP = J·δq
    dq = RNG.normal(0.0, 1e-3, (30, 5))
    f_w = np.einsum("nij,nj->ni", KIN.rotation(q[:, 3], q[:, 4]), f)
    dp = np.einsum("nij,nj->ni", KIN.jacobian(q), dq)
    np.testing.assert_allclose(np.sum(tau * dq, axis=1), np.sum(f_w * dp, axis=1), atol=1e-9)
    # full column rank: exact left inverse up to round-off
    np.testing.assert_allclose(KIN.tool_force(q, tau), f, atol=1e-9)
    # and the same loads as Aslan's equations with the frames mapped: diag(R0, 1, 1)·τ_Aslan
    qa = KIN.to_aslan(q)
    r0 = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])
    f_a = f @ r0.T  # drive-frame force in Aslan's machine frame
    tau_a = TrunnionACKinematics().drive_loads(qa, f_a)
    np.testing.assert_allclose(tau[:, :3], tau_a[:, :3] @ r0, atol=1e-9)
    np.testing.assert_allclose(tau[:, 3:], tau_a[:, 3:], atol=1e-9)
    np.testing.assert_allclose(KIN.from_aslan(qa), q, atol=1e-15)
