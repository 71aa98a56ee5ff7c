"""A discrete linear time-invariant filter run on chunks at 10 kHz, with its state carried.

Every steady-state estimator of millsense (Kalman filter, Luenberger observer, the innovation
path of the fixed-lag smoother) is, once its gains are frozen, the LTI system

    s(k+1) = F·s(k) + G·u(k),    y(k) = H·s(k) + J·u(k)

with a few inputs (measurements) and a few outputs (disturbance estimates, innovation).
``scipy.signal.lfilter`` runs only single-input single-output filters, and a transfer function
of order 25 is numerically poor, so the state update runs in a numba kernel.

Realisation (decision docs/decisions/0047-real-modal-form-of-the-steady-state-filter.md): F
is brought to real block-diagonal (modal) form, 1×1 blocks for real eigenvalues and 2×2 blocks
``[[a, b], [−b, a]]`` for complex pairs ``a ± jb``, so a sample costs about ``n·(3 + m) +
p·(n + m)`` multiply-adds instead of ``n² + n·m + p·(n + m)``. The transformation is used only
when its eigenvector matrix is well conditioned (cond < 1e8) and it reproduces F to 1e-9
relative; otherwise the dense kernel runs. Both kernels do the same floating-point operations
whatever the chunking, so outputs are bitwise chunk-size invariant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

Realisation = Literal["auto", "modal", "dense"]

_MAX_MODAL_COND = 1e8
_MODAL_REL_TOL = 1e-9


@dataclass(frozen=True)
class LinearFilter:
    """Discrete LTI system ``s⁺ = F s + G u``, ``y = H s + J u`` at sample time ``dt`` (s).

    Attributes
    ----------
    f : (n, n) state transition.
    g : (n, m) input matrix.
    h : (p, n) output matrix.
    j : (p, m) feedthrough.
    dt : sample time, s.
    """

    f: NDArray[np.float64]
    g: NDArray[np.float64]
    h: NDArray[np.float64]
    j: NDArray[np.float64]
    dt: float

    def __post_init__(self) -> None:
        n = self.f.shape[0]
        if self.f.shape != (n, n) or self.g.shape[0] != n or self.h.shape[1] != n:
            raise ValueError(
                f"inconsistent shapes F {self.f.shape}, G {self.g.shape}, H {self.h.shape}"
            )
        if self.j.shape != (self.h.shape[0], self.g.shape[1]):
            raise ValueError(
                f"J has shape {self.j.shape}, expected {(self.h.shape[0], self.g.shape[1])}"
            )
        if not self.dt > 0:
            raise ValueError(f"dt must be positive, got {self.dt}")

    @property
    def n_states(self) -> int:
        return int(self.f.shape[0])

    @property
    def n_inputs(self) -> int:
        return int(self.g.shape[1])

    @property
    def n_outputs(self) -> int:
        return int(self.h.shape[0])

    def frf(self, f_hz: ArrayLike) -> NDArray[np.complex128]:
        """Frequency response ``H (zI − F)⁻¹ G + J`` at ``z = exp(j2πf·dt)``.

        Parameters
        ----------
        f_hz : frequencies, Hz.

        Returns
        -------
        (nf, p, m) complex array.

        Notes
        -----
        In the eigenbasis of F, ``F = V Λ V⁻¹``: ``H V diag(1/(z − λ)) V⁻¹ G + J``, O(n) per
        frequency after one eigendecomposition (the spindle observer's tuning evaluates it
        hundreds of times). Where V is ill-conditioned, or the result at three frequencies
        disagrees with the direct solve by more than 1e-9 of its size, every frequency is
        solved directly (one batched LU solve).
        """
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        z = np.exp(2j * np.pi * f * self.dt)
        if len(f) > 8:
            modal = self._frf_modal(z)
            if modal is not None:
                return modal
        return self._frf_direct(z)

    def _frf_direct(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        a = np.empty((len(z), self.n_states, self.n_states), dtype=np.complex128)
        a[:] = -self.f
        diag = np.arange(self.n_states)
        a[:, diag, diag] += z[:, None]
        x = np.linalg.solve(a, np.broadcast_to(self.g, (len(z), *self.g.shape)))
        return np.asarray(self.h @ x + self.j, dtype=np.complex128)

    def _frf_modal(self, z: NDArray[np.complex128]) -> NDArray[np.complex128] | None:
        lam, v = np.linalg.eig(self.f)
        if np.linalg.cond(v) > _MAX_MODAL_COND:
            return None
        hv = self.h @ v  # (p, n)
        vg = np.linalg.solve(v, self.g)  # (n, m)
        inv = 1.0 / (z[:, None] - lam[None, :])  # (nf, n)
        out = np.einsum("pk,fk,km->fpm", hv, inv, vg) + self.j
        check = np.array([0, len(z) // 2, len(z) - 1])
        direct = self._frf_direct(z[check])
        scale = max(float(np.max(np.abs(direct))), 1e-300)
        if float(np.max(np.abs(out[check] - direct))) > 1e-9 * scale:
            return None
        return np.asarray(out, dtype=np.complex128)

    def output_covariance(self, input_cov: ArrayLike) -> NDArray[np.float64]:
        """Steady-state output covariance for white inputs of covariance ``input_cov``.

        ``H W Hᵀ + J Σ Jᵀ`` with ``W = F W Fᵀ + G Σ Gᵀ`` (discrete Lyapunov equation), solved
        exactly in the eigenbasis of F: ``W̃_ij = Q̃_ij / (1 − λ_i λ̄_j)``. scipy's default
        (bilinear) solver maps F through ``(F + I)⁻¹`` and breaks down when F has an
        eigenvalue near −1, as the Kalman filters of fast-sampled modes do (rcond 1e-25 seen on
        the spindle observer); the direct Kronecker solver is the fallback when the
        eigenvectors are ill-conditioned. This is the noise gain every tuning criterion uses.
        """
        sigma = np.atleast_2d(np.asarray(input_cov, dtype=float))
        q = self.g @ sigma @ self.g.T
        lam, v = np.linalg.eig(self.f)
        if np.linalg.cond(v) < 1e8:
            vi = np.linalg.inv(v)
            qt = vi @ q @ vi.conj().T
            wt = qt / (1.0 - np.outer(lam, lam.conj()))
            w = np.real(v @ wt @ v.conj().T)
        else:
            from scipy import linalg

            w = linalg.solve_discrete_lyapunov(self.f, q, method="direct")
        return np.asarray(self.h @ w @ self.h.T + self.j @ sigma @ self.j.T)

    def is_stable(self) -> bool:
        """All eigenvalues of F strictly inside the unit circle."""
        return bool(np.max(np.abs(np.linalg.eigvals(self.f))) < 1.0)


def real_modal_form(
    f: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Real block-diagonal form ``F = T·M·T⁻¹``.

    Returns
    -------
    t : (n, n) real transformation (columns: real eigenvectors, or real and imaginary parts of
        one eigenvector of each complex pair).
    diag : (n,) diagonal of M.
    off : (n,) the off-diagonal entry of each row's 2×2 block (0 for real eigenvalues).
    partner : (n,) index of the other state in the row's block (itself for 1×1 blocks).

    Raises
    ------
    ValueError if F is (numerically) defective, i.e. T is ill conditioned.
    """
    n = f.shape[0]
    lam, v = np.linalg.eig(f)
    t = np.zeros((n, n))
    diag = np.zeros(n)
    off = np.zeros(n)
    partner = np.arange(n, dtype=np.int64)
    used = np.zeros(n, dtype=bool)
    col = 0
    scale = max(1.0, float(np.max(np.abs(lam))))
    # complex pairs first (states 0, 1 / 2, 3 / ...), then real eigenvalues
    for i in np.argsort(-np.abs(lam.imag), kind="stable"):
        if used[i]:
            continue
        li = lam[i]
        if abs(li.imag) <= 1e-12 * scale:
            t[:, col] = v[:, i].real
            diag[col] = li.real
            used[i] = True
            col += 1
            continue
        # find the conjugate partner
        cand = np.where(~used)[0]
        cand = cand[cand != i]
        k = cand[np.argmin(np.abs(lam[cand] - np.conj(li)))]
        if li.imag < 0:
            li = np.conj(li)
            vec = np.conj(v[:, i])
        else:
            vec = v[:, i]
        t[:, col] = vec.real
        t[:, col + 1] = vec.imag
        a, b = li.real, li.imag
        diag[col] = a
        diag[col + 1] = a
        off[col] = b
        off[col + 1] = -b
        partner[col] = col + 1
        partner[col + 1] = col
        used[i] = used[k] = True
        col += 2
    if col != n:
        raise ValueError("eigenvalues of F could not be paired into a real modal form")
    # numpy's eigenvectors have unit norm, so the columns are already scaled alike (a pair's
    # two columns must share one scale factor, or the 2×2 block changes)
    cond = np.linalg.cond(t)
    if not np.isfinite(cond) or cond > _MAX_MODAL_COND:
        raise ValueError(f"modal transformation ill conditioned (cond {cond:.3g})")
    # the block form must reproduce F
    m = np.diag(diag)
    for r in range(n):
        if partner[r] != r:
            m[r, partner[r]] = off[r]
    recon = t @ m @ np.linalg.inv(t)
    if np.max(np.abs(recon - f)) > _MODAL_REL_TOL * max(1.0, float(np.max(np.abs(f)))) * cond:
        raise ValueError("modal form does not reproduce F")
    return t, diag, off, partner


@numba.njit(cache=True)
def run_lti(
    modal: bool,
    diag: NDArray[np.float64],
    off: NDArray[np.float64],
    n_pairs: int,
    f: NDArray[np.float64],
    g: NDArray[np.float64],
    h: NDArray[np.float64],
    j: NDArray[np.float64],
    u: NDArray[np.float64],
    z: NDArray[np.float64],
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Run ``z⁺ = F z + G u``, ``y = H z + J u`` over ``u`` (N, m); updates ``z`` in place.

    ``modal``: F is block diagonal, given by ``diag``/``off`` with states 0 .. 2·n_pairs−1 in
    2×2 blocks (2i, 2i+1) and the rest 1×1 (``f`` unused); otherwise F is the dense ``f``.
    """
    n_samples, m = u.shape
    p = h.shape[0]
    n = z.shape[0]
    y = np.empty((n_samples, p))
    gu = np.empty(n)
    zn = np.empty(n)
    for k in range(n_samples):
        for r in range(p):
            acc = 0.0
            for i in range(n):
                acc += h[r, i] * z[i]
            for c in range(m):
                acc += j[r, c] * u[k, c]
            y[k, r] = acc
        for i in range(n):
            acc = 0.0
            for c in range(m):
                acc += g[i, c] * u[k, c]
            gu[i] = acc
        if modal:
            for b in range(n_pairs):
                i = 2 * b
                z0 = z[i]
                z1 = z[i + 1]
                z[i] = diag[i] * z0 + off[i] * z1 + gu[i]
                z[i + 1] = off[i + 1] * z0 + diag[i + 1] * z1 + gu[i + 1]
            for i in range(2 * n_pairs, n):
                z[i] = diag[i] * z[i] + gu[i]
        else:
            for i in range(n):
                acc = gu[i]
                for q in range(n):
                    acc += f[i, q] * z[q]
                zn[i] = acc
            for i in range(n):
                z[i] = zn[i]
    return y


KernelArgs = tuple[
    bool,
    NDArray[np.float64],
    NDArray[np.float64],
    int,
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]


class StreamingFilter:
    """Runs a :class:`LinearFilter` on consecutive chunks, carrying its state.

    Parameters
    ----------
    filt : the LTI filter.
    realisation : ``"modal"`` (real block-diagonal form, fast), ``"dense"`` (F as given) or
        ``"auto"`` (modal when well conditioned, otherwise dense).
    """

    def __init__(self, filt: LinearFilter, realisation: Realisation = "auto") -> None:
        if realisation not in ("auto", "modal", "dense"):
            raise ValueError(f"realisation must be auto, modal or dense, got {realisation!r}")
        self.filter = filt
        self._t: NDArray[np.float64] | None = None
        empty = np.zeros(0)
        args: KernelArgs = (
            False,
            empty,
            empty,
            0,
            np.ascontiguousarray(filt.f),
            np.ascontiguousarray(filt.g),
            np.ascontiguousarray(filt.h),
            np.ascontiguousarray(filt.j),
        )
        if realisation in ("auto", "modal"):
            try:
                t, diag, off, partner = real_modal_form(filt.f)
            except ValueError:
                if realisation == "modal":
                    raise
            else:
                self._t = t
                n_pairs = int(np.count_nonzero(partner != np.arange(len(partner))) // 2)
                args = (
                    True,
                    diag,
                    off,
                    n_pairs,
                    np.zeros((0, 0)),
                    np.ascontiguousarray(np.linalg.solve(t, filt.g)),
                    np.ascontiguousarray(filt.h @ t),
                    np.ascontiguousarray(filt.j),
                )
        self.kernel_args = args
        self.z = np.zeros(filt.n_states)

    @property
    def realisation(self) -> str:
        """``"modal"`` or ``"dense"``, the kernel actually used."""
        return "modal" if self._t is not None else "dense"

    def reset(self, state: ArrayLike | None = None) -> None:
        """Set the filter state ``s`` (in the original coordinates; zero if omitted)."""
        if state is None:
            self.z = np.zeros(self.filter.n_states)
            return
        s = np.asarray(state, dtype=float).reshape(self.filter.n_states)
        self.z = np.linalg.solve(self._t, s) if self._t is not None else s.copy()

    @property
    def state(self) -> NDArray[np.float64]:
        """Current state ``s`` in the original coordinates."""
        return self._t @ self.z if self._t is not None else self.z.copy()

    def as_input(self, u: ArrayLike) -> NDArray[np.float64]:
        """``u`` as a C-contiguous (N, m) float array; raises ValueError on a shape mismatch."""
        arr = np.asarray(u, dtype=float)
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != self.filter.n_inputs:
            raise ValueError(f"input has shape {np.shape(u)}, expected (N, {self.filter.n_inputs})")
        return np.ascontiguousarray(arr)

    def process(self, u: ArrayLike) -> NDArray[np.float64]:
        """Filter one chunk.

        Parameters
        ----------
        u : (N,) for a single input or (N, m) samples of the inputs.

        Returns
        -------
        (N, p) outputs, one row per input sample.
        """
        return run_lti(*self.kernel_args, self.as_input(u), self.z)
