"""Comb filter removing the spindle harmonics (seed 000, Aslan Eq. 5.26–5.29), streaming.

``G_cb(z) = β·(1 − z^−d)/(1 − α·z^−d)`` (Eq. 5.26), i.e. the difference equation
``Δτ(k) = α·Δτ(k−d) + β·[τ(k) − τ(k−d)]`` (Eq. 5.27), with ``d`` the samples per spindle
revolution. Coefficients (Eq. 5.28–5.29): ``γ = (√(1 − |G|²)/|G|)·tan(d·ω_bw/4)``,
``α = 2/(1 + γ) − 1``, ``β = 1/(1 + γ)`` and ``ω_bw = 2π·(Ω_rs/f_s)/Q``. Since
``d·ω_bw = 2π/Q`` the coefficients do not depend on the speed (digest §2.7, derived): with
Q = 10 and |G| = 0.708, γ = 0.1580, α = 0.7271, β = 0.8636.

The thesis leaves open how ``d`` is rounded when a revolution is not a whole number of
samples (digest §5). Here (decision 1502) the delay is fractional: ``τ(k−d)`` and ``Δτ(k−d)``
are read from ring buffers by 8-point Lagrange interpolation, so the notches sit on the true
harmonics up to the 2.5 kHz band (a rounded ``d`` misplaces the l-th notch by
``l·f_rev·δd/d``, which leaves the high tooth harmonics unfiltered), and ``d`` follows the
spindle-speed channel sample by sample (smoothed by a 10 ms one-pole), so speed changes and
overrides are followed. Below ``min_speed_rev_s`` (spindle stopped, run-up) the output is 0.
The per-sample recursion is a compiled (numba) loop.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Seed 000 settings (Aslan §5.4, digest P10): quality factor and gain at the notch edges.
Q_COMB = 10.0
G_COMB = 0.708


def comb_coefficients(q: float = Q_COMB, gain: float = G_COMB) -> tuple[float, float]:
    """(α, β) of Eq. 5.28–5.29; independent of the speed because ``d·ω_bw = 2π/Q``."""
    if not (q > 0 and 0 < gain < 1):
        raise ValueError(f"comb filter: need Q > 0 and 0 < |G| < 1, got Q={q}, |G|={gain}")
    gamma = math.sqrt(1.0 - gain**2) / gain * math.tan(2.0 * math.pi / q / 4.0)
    return 2.0 / (1.0 + gamma) - 1.0, 1.0 / (1.0 + gamma)


#: Points of the Lagrange fractional-delay interpolation (nodes at delays k−3 … k+4).
_NODES = 8
_HALF = _NODES // 2
#: 1/Π_{m≠j}(j − m) for the nodes j = −3 … 4 (relative to k).
_DEN = np.array(
    [
        1.0 / math.prod(float(j - m) for m in range(1 - _HALF, _HALF + 1) if m != j)
        for j in range(1 - _HALF, _HALF + 1)
    ]
)


@numba.njit(cache=True, nogil=True)
def _weights(mu: float, den: FloatArray, out: FloatArray) -> None:  # pragma: no cover
    """Lagrange weights of the nodes −3 … 4 at ``mu`` ∈ [0, 1) (no allocation)."""
    n = len(den)
    for j in range(n):
        acc = den[j]
        for m in range(n):
            if m != j:
                acc *= mu - (m + 1 - n // 2)
        out[j] = acc


@numba.njit(cache=True, nogil=True, inline="always")
def _delayed(
    ring: FloatArray, p: int, k: int, w: FloatArray, mask: int
) -> float:  # pragma: no cover
    """``ring`` at delay ``k + mu`` behind position ``p`` with the weights ``w`` of ``mu``:
    Σ_j w[j]·ring[p − k − (j − 3)] for the nodes j = 0 … 7, summed in that order (written out:
    the compiled loop over a run-time length cost a fifth of the comb filter; decision 1536).
    Where the eight nodes do not wrap around the ring's end their indices need no mask: the
    same loads and additions with a tenth less work (decision 1538). Inlined into
    :func:`ingest` by Numba (``inline="always"``): as a call it passed both arrays and the
    weights through the stack twice a sample, half of the filter's time; the same operations
    in the same order."""
    b = p - k + _HALF - 1
    acc = 0.0
    c = b & mask
    if c >= _NODES - 1:
        acc += w[0] * ring[c]
        acc += w[1] * ring[c - 1]
        acc += w[2] * ring[c - 2]
        acc += w[3] * ring[c - 3]
        acc += w[4] * ring[c - 4]
        acc += w[5] * ring[c - 5]
        acc += w[6] * ring[c - 6]
        acc += w[7] * ring[c - 7]
        return acc
    acc += w[0] * ring[b & mask]
    acc += w[1] * ring[(b - 1) & mask]
    acc += w[2] * ring[(b - 2) & mask]
    acc += w[3] * ring[(b - 3) & mask]
    acc += w[4] * ring[(b - 4) & mask]
    acc += w[5] * ring[(b - 5) & mask]
    acc += w[6] * ring[(b - 6) & mask]
    acc += w[7] * ring[(b - 7) & mask]
    return acc


assert _NODES == 8  # :func:`_delayed` writes the eight nodes out


@numba.njit(cache=True, nogil=True)
def ingest(
    x: FloatArray,
    speed_rev_s: FloatArray,
    fs: float,
    alpha: float,
    beta: float,
    ring_x: FloatArray,
    ring_y: FloatArray,
    pos: int,
    state: FloatArray,
    min_speed_rev_s: float,
    smooth: float,
    speed_factor: float = 1.0,
) -> None:  # pragma: no cover - compiled
    """Write ``x`` and its comb-filtered version into the rings from position ``pos`` on.

    ``state[0]`` is the smoothed |speed| (rev/s), ``state[1]`` the sum of the smoothed speed
    since the last reset of ``state[1]``/``state[2]`` (sample count), for the window's mean;
    ``state[3]``, ``state[4]`` the smallest and largest smoothed speed since their reset.
    ``speed_factor`` converts the speed channel to rev/s (sample by sample, as multiplying
    the channel first would).
    """
    mask = len(ring_x) - 1
    d_max = len(ring_x) - 2.0 * _NODES
    den = _DEN
    w = np.empty(_NODES)
    last_q = -1
    # the state in locals (the compiler cannot keep array elements in registers across the
    # ring writes); written back at the end
    s = state[0]
    s_sum = state[1]
    s_cnt = state[2]
    s_min = state[3]
    s_max = state[4]
    for i in range(len(x)):
        p = (pos + i) & mask
        xi = x[i]
        ring_x[p] = xi
        s = s + smooth * (abs(speed_rev_s[i] * speed_factor) - s)
        s_sum += s
        s_cnt += 1.0
        if s < s_min:
            s_min = s
        if s > s_max:
            s_max = s
        y = 0.0
        if s >= min_speed_rev_s:
            d = fs / s
            if _HALF + 1.0 <= d <= d_max:
                # the delay on a 1/4096-sample grid (a phase error below 4e-4 rad at 2.5 kHz):
                # the weights are recomputed only when it moves
                q = int(d * 4096.0 + 0.5)
                k = q >> 12
                if q != last_q:
                    _weights((q & 4095) / 4096.0, den, w)
                    last_q = q
                xd = _delayed(ring_x, p, k, w, mask)
                yd = _delayed(ring_y, p, k, w, mask)
                y = alpha * yd + beta * (xi - xd)
        ring_y[p] = y
    state[0] = s
    state[1] = s_sum
    state[2] = s_cnt
    state[3] = s_min
    state[4] = s_max
