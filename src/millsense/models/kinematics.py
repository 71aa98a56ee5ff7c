"""Machine kinematics: 3-axis (identity) and the A/C trunnion table of Aslan Ch. 3.4.

The trunnion comes in Aslan's frames (:class:`TrunnionACKinematics`, his equations as
decided) and in the frames of the drives and of G-code (:class:`TrunnionACMachine`, tool along
+Z at A = C = 0), which the simulator and the machine files use.

Both classes map axis positions ``q`` (m for x, y, z; rad for θ_A, θ_C) to the tool tip ``P``
in the workpiece frame, give the position Jacobian ``J = ∂P/∂q`` and map a force at the tool
(machine/tool frame) to drive loads with the principle of virtual work, ``τ = Jᵀ·T·F_tool``
(Aslan Eq. 3.40–3.49), and back with the pseudo-inverse (Aslan Eq. 3.51). Every function
accepts a single pose (shape ``(n,)``) or a batch (shape ``(N, n)``), vectorised.

Loads are generalised forces on the axes: N for x, y, z and N·m about the A and C axes (on the
table side, before the worm-gear ratio; the drive models apply their transmissions).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from millsense.core.errors import InputDataError
from millsense.models._kinematics_kernels import (
    trunnion_forward,
    trunnion_jacobian,
    trunnion_load_matrix,
)

#: Trunnion offsets chosen for a UX600-sized table (docs/decisions/0031-trunnion-offsets-a2-d4.md).
DEFAULT_A2_M = 0.150
DEFAULT_D4_M = 0.080


def _as_batch(q: np.ndarray, n: int, what: str) -> tuple[np.ndarray, bool]:
    arr = np.asarray(q, dtype=np.float64)
    single = arr.ndim == 1
    arr2 = arr[None, :] if single else arr
    if arr2.ndim != 2 or arr2.shape[1] != n:
        raise InputDataError(
            f"kinematics: {what} must have shape ({n},) or (N, {n}), got {arr.shape}"
        )
    return arr2, single


def _matrix3(like: np.ndarray, *rows: tuple[np.ndarray | float, ...]) -> np.ndarray:
    """3×3 matrices (..., 3, 3) from their entries (arrays of the shape of ``like`` or scalars),
    filled in place: on the few poses of a 10 ms chunk nested ``np.stack`` calls cost more than
    the trigonometry."""
    out = np.empty((*np.shape(like), 3, 3), dtype=np.result_type(like))
    for i, row in enumerate(rows):
        for j, v in enumerate(row):
            out[..., i, j] = v
    return out


@dataclass(frozen=True)
class ThreeAxisKinematics:
    """Cartesian 3-axis machine: the tool tip is the axis position (``P = q``, ``J = I``)."""

    n_axes: int = 3

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Tool tip (m) from axis positions (m); identity."""
        _as_batch(q, 3, "q")
        return np.array(q, dtype=np.float64, copy=True)

    def forward_rows(self, q_rows: np.ndarray, out: np.ndarray) -> None:
        """:meth:`forward` of a chunk laid out by rows: ``q_rows`` (3, n) → ``out`` (3, n)."""
        out[:] = q_rows

    def inverse(self, p: np.ndarray) -> np.ndarray:
        """Axis positions (m) from the tool tip (m); identity."""
        _as_batch(p, 3, "p")
        return np.array(p, dtype=np.float64, copy=True)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """∂P/∂q, shape (3, 3) or (N, 3, 3): the identity."""
        arr, single = _as_batch(q, 3, "q")
        j = np.broadcast_to(np.eye(3), (arr.shape[0], 3, 3)).copy()
        return j[0] if single else j

    def drive_loads(self, q: np.ndarray, force_tool_n: np.ndarray) -> np.ndarray:
        """Axis loads (N) of a force at the tool (N): equal to the force."""
        _as_batch(q, 3, "q")
        return np.array(force_tool_n, dtype=np.float64, copy=True)

    def tool_force(self, q: np.ndarray, loads: np.ndarray) -> np.ndarray:
        """Force at the tool (N) from axis loads (N): equal to the loads."""
        _as_batch(q, 3, "q")
        return np.array(loads, dtype=np.float64, copy=True)


@dataclass(frozen=True)
class TrunnionACKinematics:
    """Five-axis machine with an A-tilt / C-rotary trunnion table (Quaser UX600, Aslan 3.4).

    Axis vector ``q = [x, y, z, θ_A, θ_C]`` (m, m, m, rad, rad), Aslan Eq. 3.34.

    Attributes
    ----------
    a2_m : distance of the A-axis line from the machine origin along machine z, m.
    d4_m : distance of the workpiece origin from the A axis along the C axis, m.

    Notes
    -----
    Forward kinematics, Aslan Eq. 3.38 as printed: ``P = R·(p − a2·e_z) − d4·e_z`` with
    ``p = [x, y, z]`` and the rotation ``R`` (rows)::

        [−cC, −cA·sC,  sA·sC]
        [ sC, −cA·cC,  sA·cC]
        [  0,     sA,     cA]

    ``R`` is a proper rotation (orthonormal, det +1). The printed inverse (Eq. 3.37) is not the
    inverse of Eq. 3.38: its (1,1) entry has the wrong sign and its z offset reads
    ``d4·cA − a2`` instead of ``d4·cA + a2``. Decision
    (docs/decisions/0030-trunnion-kinematics-aslan-eq-3-35-3-51.md): Eq. 3.38 is kept and the
    inverse is its exact inverse ``p = Rᵀ·(P + d4·e_z) + a2·e_z``; the Jacobian rows printed in
    Eq. 3.39/3.47 are the derivatives of Eq. 3.38, which confirms that choice.

    Tool orientation in the workpiece frame, Aslan Eq. 3.36: ``O = [cA·sC, cA·cC, −sA]``
    (= −R·e_y, the spindle axis of Aslan's machine frame), so the inverse is
    ``θ_A = −asin(O_k)`` (the text's "−sin(O_k)" is a typo, see the digest) and
    ``θ_C = atan2(O_i, O_j)`` (Eq. 3.35). The tool frame has the machine frame's axes, so the
    tool-to-workpiece rotation of Eq. 3.45/3.48 is ``T = R``.
    """

    a2_m: float = DEFAULT_A2_M
    d4_m: float = DEFAULT_D4_M
    n_axes: int = 5

    @staticmethod
    def rotation(theta_a: np.ndarray, theta_c: np.ndarray) -> np.ndarray:
        """R(θ_A, θ_C) of Aslan Eq. 3.38, shape (..., 3, 3)."""
        ca, sa = np.cos(theta_a), np.sin(theta_a)
        cc, sc = np.cos(theta_c), np.sin(theta_c)
        return _matrix3(
            ca,
            (-cc, -ca * sc, sa * sc),
            (sc, -ca * cc, sa * cc),
            (0.0, sa, ca),
        )

    @staticmethod
    def orientation(theta_a: np.ndarray, theta_c: np.ndarray) -> np.ndarray:
        """Tool axis O in the workpiece frame (Aslan Eq. 3.36), shape (..., 3)."""
        ca, sa = np.cos(theta_a), np.sin(theta_a)
        return np.stack([ca * np.sin(theta_c), ca * np.cos(theta_c), -sa], axis=-1)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Tool tip P (m, workpiece frame) from axes q = [x, y, z, θ_A, θ_C] (Eq. 3.38)."""
        arr, single = _as_batch(q, 5, "q")
        p = np.empty((arr.shape[0], 3))
        trunnion_forward(arr, False, self.a2_m, self.d4_m, p)  # compiled (module notes)
        return p[0] if single else p

    def forward_rows(self, q_rows: np.ndarray, out: np.ndarray) -> None:
        """:meth:`forward` of a chunk laid out by rows, ``q_rows`` (5, n) → ``out`` (3, n): one
        compiled call, without the batch checks and copies (an on-line block's 100 poses)."""
        trunnion_forward(q_rows.T, False, self.a2_m, self.d4_m, out.T)

    def forward_pose(self, q: np.ndarray) -> np.ndarray:
        """Tool tip and axis [P_x, P_y, P_z, O_i, O_j, O_k] (m, unit vector) from q."""
        arr, single = _as_batch(q, 5, "q")
        pose = np.concatenate([self.forward(arr), self.orientation(arr[:, 3], arr[:, 4])], axis=1)
        return pose[0] if single else pose

    def inverse(self, pose: np.ndarray) -> np.ndarray:
        """Axes q from the tool tip and axis ``[P (m), O (unit)]`` in the workpiece frame.

        Notes
        -----
        ``θ_A = −asin(O_k)``, ``θ_C = atan2(O_i, O_j)`` (Aslan Eq. 3.35 with the digest's typo
        fix); positions by the exact inverse of Eq. 3.38 (see the class Notes). O is
        normalised first. θ_A lies in [−π/2, π/2]; at O_k = ±1 (θ_A = ∓π/2) θ_C is undefined
        and atan2(0, 0) = 0 is returned.
        """
        arr, single = _as_batch(pose, 6, "pose")
        o = arr[:, 3:6] / np.linalg.norm(arr[:, 3:6], axis=1, keepdims=True)
        theta_a = -np.arcsin(np.clip(o[:, 2], -1.0, 1.0))
        theta_c = np.arctan2(o[:, 0], o[:, 1])
        r = self.rotation(theta_a, theta_c)
        shifted = arr[:, :3].copy()
        shifted[:, 2] += self.d4_m
        p = np.einsum("nji,nj->ni", r, shifted)
        p[:, 2] += self.a2_m
        q = np.concatenate([p, theta_a[:, None], theta_c[:, None]], axis=1)
        return q[0] if single else q

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Position Jacobian ∂P/∂q, shape (3, 5) or (N, 3, 5) (Aslan Eq. 3.39/3.47).

        Notes
        -----
        Columns 1–3 are R; column 4 is ``(∂R/∂θ_A)·(p − a2·e_z)``, column 5
        ``(∂R/∂θ_C)·(p − a2·e_z)``. The orientation rows of the 6×5 Jacobian are omitted, as
        in the thesis (torques at the tool tip are neglected).
        """
        arr, single = _as_batch(q, 5, "q")
        j = np.empty((arr.shape[0], 3, 5))
        trunnion_jacobian(arr, False, self.a2_m, self.d4_m, j)  # compiled (module notes)
        return j[0] if single else j

    def load_matrix(self, q: np.ndarray) -> np.ndarray:
        """``Jᵀ·T`` (5×3 or N×5×3): drive loads per unit tool force (Aslan Eq. 3.49)."""
        arr, single = _as_batch(q, 5, "q")
        m = np.empty((arr.shape[0], 5, 3))
        # T = R: the Jacobian's first three columns; compiled (module notes)
        trunnion_load_matrix(arr, False, self.a2_m, self.d4_m, m)
        return m[0] if single else m

    def drive_loads(self, q: np.ndarray, force_tool_n: np.ndarray) -> np.ndarray:
        """Axis loads ``τ = Jᵀ·T·F_tool``: [F_x, F_y, F_z (N), τ_A, τ_C (N·m)].

        Parameters
        ----------
        q : axis positions, (5,) or (N, 5), m and rad.
        force_tool_n : force at the tool tip in the tool (machine) frame, (3,) or (N, 3), N.

        Notes
        -----
        Aslan Eq. 3.40–3.49 (virtual work). The expanded τ_C of Eq. 3.50 drops an ``x``;
        this follows the matrix of Eq. 3.49 (tested against its closed form).
        """
        arr, single = _as_batch(q, 5, "q")
        f, _ = _as_batch(force_tool_n, 3, "force_tool_n")
        loads = np.einsum(
            "nij,nj->ni", self.load_matrix(arr), np.broadcast_to(f, (arr.shape[0], 3))
        )
        return loads[0] if single else loads

    def tool_force(self, q: np.ndarray, loads: np.ndarray) -> np.ndarray:
        """Force at the tool (N, tool frame) from axis loads: ``[Jᵀ·T]⁺·τ`` (Aslan Eq. 3.51)."""
        arr, single = _as_batch(q, 5, "q")
        tau, _ = _as_batch(loads, 5, "loads")
        pinv = np.linalg.pinv(self.load_matrix(arr))
        f = np.einsum("nij,nj->ni", pinv, np.broadcast_to(tau, (arr.shape[0], 5)))
        return f[0] if single else f


#: Aslan's machine axes from the machine's drive axes at θ_A = −π/2, θ_C = 0 (involution).
_R0 = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class TrunnionACMachine:
    """The A/C trunnion table in the frames of the machine's drives and of G-code / CAM.

    Axis vector ``q = [X, Y, Z, A, C]`` (m, m, m, rad, rad) as the CNC and the presets name
    the drives: Z along the spindle, A = C = 0 with the table level, the tool along workpiece
    +Z (the CAM convention), and a 3-axis program (A = C = 0) moves X, Y, Z by the programmed
    amounts. The workpiece frame is the G-code frame and equals Aslan's workpiece frame.

    Notes
    -----
    Aslan's Eq. 3.36 puts the tool along workpiece +Y at θ_A = θ_C = 0, with the C axis
    along workpiece z: his A zero tilts the table by 90° and his machine axis y is the
    spindle axis. The mapping to :class:`TrunnionACKinematics` (decision
    docs/decisions/0078-trunnion-frames-g-code-and-drives.md) is

    - ``θ_A = A − π/2``, ``θ_C = C``: the tool axis becomes
      ``O = [sA·sC, sA·cC, cA]`` (the usual A/C trunnion form, C about the table normal);
    - ``p_Aslan = R0·[X, Y, Z] + [0, −d4, a2]`` with the fixed rotation
      ``R0 = R(−π/2, 0) = [[−1, 0, 0], [0, 0, −1], [0, −1, 0]]`` (det +1, R0 = R0ᵀ = R0⁻¹):
      Aslan's x, y, z are the drives' −X, −Z, −Y, and the offset puts the drive zero at the
      workpiece origin for A = C = 0, so that ``P = [X, Y, Z]`` there.

    Hence ``P = R(θ_A, θ_C)·R0·[X, Y, Z] + R(θ_A, θ_C)·[0, −d4, 0] − d4·e_z``, the tool
    (drive) frame to workpiece rotation ``T = R(θ_A, θ_C)·R0`` (the identity at A = C = 0),
    ``J = J_Aslan·diag(R0, 1, 1)`` and the loads ``τ = Jᵀ·T·F = diag(R0, 1, 1)·τ_Aslan``
    with ``F`` in the drive frame (Aslan Eq. 3.49 in these frames).
    """

    a2_m: float = DEFAULT_A2_M
    d4_m: float = DEFAULT_D4_M
    n_axes: int = 5

    @functools.cached_property
    def aslan(self) -> TrunnionACKinematics:
        """The same table in Aslan's frames."""
        return TrunnionACKinematics(a2_m=self.a2_m, d4_m=self.d4_m)

    def to_aslan(self, q: np.ndarray) -> np.ndarray:
        """Aslan's axis vector ``[x, y, z, θ_A, θ_C]`` of drive positions ``q``."""
        arr, single = _as_batch(q, 5, "q")
        out = np.empty_like(arr)
        out[:, :3] = arr[:, :3] @ _R0.T
        out[:, 1] -= self.d4_m
        out[:, 2] += self.a2_m
        out[:, 3] = arr[:, 3] - 0.5 * np.pi
        out[:, 4] = arr[:, 4]
        return out[0] if single else out

    def from_aslan(self, q_aslan: np.ndarray) -> np.ndarray:
        """Drive positions from Aslan's axis vector (inverse of :meth:`to_aslan`)."""
        arr, single = _as_batch(q_aslan, 5, "q_aslan")
        rel = arr[:, :3].copy()
        rel[:, 1] += self.d4_m
        rel[:, 2] -= self.a2_m
        out = np.empty_like(arr)
        out[:, :3] = rel @ _R0  # R0⁻¹ = R0ᵀ
        out[:, 3] = arr[:, 3] + 0.5 * np.pi
        out[:, 4] = arr[:, 4]
        return out[0] if single else out

    @staticmethod
    def rotation(a: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Tool (drive) frame to workpiece frame, ``T = R(A − π/2, C)·R0``, (..., 3, 3)."""
        r = TrunnionACKinematics.rotation(np.asarray(a) - 0.5 * np.pi, np.asarray(c))
        return np.asarray(r @ _R0)

    @staticmethod
    def orientation(a: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Tool axis in the workpiece frame, ``[sA·sC, sA·cC, cA]``, shape (..., 3)."""
        sa = np.sin(a)
        return np.stack([sa * np.sin(c), sa * np.cos(c), np.cos(a)], axis=-1)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Tool tip (m, workpiece/G-code frame) from drive positions q."""
        arr, single = _as_batch(q, 5, "q")
        p = np.empty((arr.shape[0], 3))
        trunnion_forward(arr, True, self.a2_m, self.d4_m, p)  # Aslan's, after to_aslan
        return p[0] if single else p

    def forward_rows(self, q_rows: np.ndarray, out: np.ndarray) -> None:
        """:meth:`forward` of a chunk laid out by rows, ``q_rows`` (5, n) → ``out`` (3, n): one
        compiled call, without the batch checks and copies (an on-line block's 100 poses)."""
        trunnion_forward(q_rows.T, True, self.a2_m, self.d4_m, out.T)

    def forward_pose(self, q: np.ndarray) -> np.ndarray:
        """``[P (m), O (unit)]`` in the workpiece frame from drive positions q."""
        arr, single = _as_batch(q, 5, "q")
        pose = np.concatenate([self.forward(arr), self.orientation(arr[:, 3], arr[:, 4])], axis=1)
        return pose[0] if single else pose

    def inverse_at(self, p: np.ndarray, a: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Drive positions that put the tool tip at ``p`` (m) with the rotary axes at A, C.

        The exact inverse of :meth:`forward` for given rotary angles (any branch: a program's
        A and C words are kept as written, so ``forward(inverse_at(p, a, c)) = p``).
        """
        pts, single = _as_batch(p, 3, "p")
        a_arr = np.broadcast_to(np.asarray(a, dtype=np.float64), (pts.shape[0],))
        c_arr = np.broadcast_to(np.asarray(c, dtype=np.float64), (pts.shape[0],))
        r = TrunnionACKinematics.rotation(a_arr - 0.5 * np.pi, c_arr)
        shifted = pts.copy()
        shifted[:, 2] += self.d4_m
        qa = np.empty((pts.shape[0], 5))
        qa[:, :3] = np.einsum("nji,nj->ni", r, shifted)
        qa[:, 2] += self.a2_m
        qa[:, 3] = a_arr - 0.5 * np.pi
        qa[:, 4] = c_arr
        q = self.from_aslan(qa)
        return q[0] if single else q

    def inverse(self, pose: np.ndarray) -> np.ndarray:
        """Drive positions from ``[P (m), O (unit)]``: ``A = acos(O_k) ∈ [0, π]``,
        ``C = atan2(O_i, O_j)`` (Aslan Eq. 3.35 with θ_A = A − π/2)."""
        arr, single = _as_batch(pose, 6, "pose")
        q = self.from_aslan(self.aslan.inverse(arr))
        return q[0] if single else q

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """∂P/∂q in drive coordinates, ``J_Aslan·diag(R0, 1, 1)``, (3, 5) or (N, 3, 5)."""
        arr, single = _as_batch(q, 5, "q")
        j = np.empty((arr.shape[0], 3, 5))
        trunnion_jacobian(arr, True, self.a2_m, self.d4_m, j)  # Aslan's, after to_aslan
        return j[0] if single else j

    def load_matrix(self, q: np.ndarray) -> np.ndarray:
        """``Jᵀ·T`` (5×3 or N×5×3): drive loads per unit tool force (drive frame)."""
        arr, single = _as_batch(q, 5, "q")
        m = np.empty((arr.shape[0], 5, 3))
        # T = R(A − π/2, C)·R0: the Jacobian's first three columns; compiled (module notes)
        trunnion_load_matrix(arr, True, self.a2_m, self.d4_m, m)
        return m[0] if single else m

    def drive_loads(self, q: np.ndarray, force_tool_n: np.ndarray) -> np.ndarray:
        """Drive loads ``[F_X, F_Y, F_Z (N), τ_A, τ_C (N·m)]`` of a tool force (drive frame)."""
        arr, single = _as_batch(q, 5, "q")
        f, _ = _as_batch(force_tool_n, 3, "force_tool_n")
        loads = np.einsum(
            "nij,nj->ni", self.load_matrix(arr), np.broadcast_to(f, (arr.shape[0], 3))
        )
        return loads[0] if single else loads

    def tool_force(self, q: np.ndarray, loads: np.ndarray) -> np.ndarray:
        """Tool force (N, drive frame) from drive loads, ``[Jᵀ·T]⁺·τ`` (Aslan Eq. 3.51)."""
        arr, single = _as_batch(q, 5, "q")
        tau, _ = _as_batch(loads, 5, "loads")
        pinv = np.linalg.pinv(self.load_matrix(arr))
        f = np.einsum("nij,nj->ni", pinv, np.broadcast_to(tau, (arr.shape[0], 5)))
        return f[0] if single else f


Kinematics = ThreeAxisKinematics | TrunnionACKinematics | TrunnionACMachine


def kinematics_for(kind: str, a2_m: float = DEFAULT_A2_M, d4_m: float = DEFAULT_D4_M) -> Kinematics:
    """The kinematics named by ``MachineConfig.kinematics`` ("3-axis", "5-axis-trunnion-ac").

    Machine files name the drives as the CNC does, so the trunnion is returned in the drive /
    G-code frames (:class:`TrunnionACMachine`); Aslan's frames are
    :class:`TrunnionACKinematics`.
    """
    if kind == "3-axis":
        return ThreeAxisKinematics()
    if kind == "5-axis-trunnion-ac":
        return TrunnionACMachine(a2_m=a2_m, d4_m=d4_m)
    raise InputDataError(f"kinematics: unknown kind '{kind}' (3-axis, 5-axis-trunnion-ac)")
