"""Ilme angular-harmonic force model (Eq. 2.38) against the sliced model and the seed numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.process.harmonic import harmonic_forces, measurement_matrix

# Seed 003 Tables 3.1/3.2: K = 700/300 N/mm², 25/35 N/mm, t_x = 0.1667 mm, D = 12 mm, N = 3,
# helix 45°, a_p = 2 mm, down milling 90°→180° (digest §7).
K = CuttingCoefficients(ktc=700e6, krc=300e6, kte=25e3, kre=35e3)
GEO = dict(
    n_flutes=3,
    diameter_m=12e-3,
    helix_rad=math.radians(45.0),
    axial_depth_m=2e-3,
    entry_rad=math.pi / 2,
    exit_rad=math.pi,
)
TX = 0.1667e-3


def test_ilme_peak_and_rms() -> None:
    # Ilme Table 3.4: generated y-force peak 307.07 N and RMS 200.05 N (± 0.1 %).
    phi = np.linspace(0, 2 * math.pi, 12000, endpoint=False)
    _, fy = harmonic_forces(phi, K, TX, n_harmonics=100, **GEO)  # type: ignore[arg-type]
    assert fy.max() == pytest.approx(307.07, rel=1e-3)
    assert np.sqrt(np.mean(fy**2)) == pytest.approx(200.05, rel=1e-3)


def test_harmonic_equals_sliced_model() -> None:
    # benchmarks.md §4: the sliced model agrees with Eq. 2.38 within 0.3 N; with q = 400
    # harmonics and 1000 discs the residual (Gibbs ripple at the window corners plus disc
    # steps) is below that.
    phi = np.linspace(0, 2 * math.pi / 3, 300, endpoint=False)
    tool = EndMill(12e-3, 3, helix_rad=math.radians(45.0))
    eng = Engagement.from_intervals([(math.pi / 2, math.pi)])
    sliced = milling_forces(tool, K, eng, TX, 2e-3, phi, n_discs=1000)
    fx, fy = harmonic_forces(phi, K, TX, n_harmonics=400, **GEO)  # type: ignore[arg-type]
    assert np.max(np.abs(fy - sliced.fy_n)) < 0.3
    assert np.max(np.abs(fx - sliced.fx_n)) < 0.3


def test_measurement_matrix_recovers_coefficients() -> None:
    # Erratum 1 of the seed 003 digest: H derived from K_4 must give back q from forces by
    # least squares (the printed Eq. 3.9 row y has the wrong sign and would flip q).
    phi = np.linspace(0, 2 * math.pi, 900, endpoint=False)
    tool = EndMill(12e-3, 3, helix_rad=math.radians(45.0))
    eng = Engagement.from_intervals([(math.pi / 2, math.pi)])
    sliced = milling_forces(tool, K, eng, TX, 2e-3, phi, n_discs=400)
    h = measurement_matrix(phi, TX, n_harmonics=200, **GEO)
    a = h.reshape(-1, 4)
    b = np.column_stack([sliced.fx_n, sliced.fy_n]).reshape(-1)
    q, *_ = np.linalg.lstsq(a, b, rcond=None)
    assert np.allclose(q, [K.ktc, K.krc, K.kte, K.kre], rtol=5e-3)
    printed = h.copy()
    printed[:, 1, :] *= -1.0
    a2 = printed[:, 1, :]
    q2, *_ = np.linalg.lstsq(a2, sliced.fy_n, rcond=None)
    assert q2[0] < 0  # printed row: K_tc comes out negative


def test_frf_shifts_harmonics() -> None:
    # Eq. 3.5: with G(f_k) = 1 for all k the response is the force without its DC part.
    phi = np.linspace(0, 2 * math.pi, 600, endpoint=False)
    fx, fy = harmonic_forces(phi, K, TX, n_harmonics=50, **GEO)  # type: ignore[arg-type]
    h = measurement_matrix(phi, TX, n_harmonics=50, frf=np.ones(50, complex), **GEO)
    q = np.array([K.ktc, K.krc, K.kte, K.kre])
    a = h @ q
    assert np.allclose(a[:, 1], fy - fy.mean(), atol=1e-9)
    assert np.allclose(a[:, 0], fx - fx.mean(), atol=1e-9)
