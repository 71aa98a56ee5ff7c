"""Modal FRFs, residue form (Aslan Eq. 3.13) and oriented FRFs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from millsense.stability.modal import ModalModel, Mode, OrientedMode, oriented_frf


def test_stiffness_mode_static_and_resonant_receptance() -> None:
    # Φ(0) = 1/k, |Φ(iω_n)| = 1/(2 k ζ) for a single mode
    md = Mode.from_stiffness(922.0, 0.011, 1.34e6)
    assert md.frf(0.0).real == pytest.approx(1 / 1.34e6, rel=1e-12)
    assert abs(md.frf(922.0)) == pytest.approx(1 / (2 * 1.34e6 * 0.011), rel=1e-12)


def test_residue_form_matches_transfer_function() -> None:
    # Eq. 3.13: (α + β s)/(s² + 2ζωs + ω²) evaluated independently by scipy.signal.freqs
    md = Mode.from_residues(300.0, 0.05, 2.0e3, 0.7)
    f = np.linspace(10, 900, 50)
    w = 2 * np.pi * f
    _, ref = scipy.signal.freqs([0.7, 2.0e3], [1.0, 2 * 0.05 * md.omega, md.omega**2], worN=w)
    np.testing.assert_allclose(md.frf(f), ref, rtol=1e-12)


def test_state_space_realises_the_frf() -> None:
    # C (iωI − A)^-1 B equals the modal FRF matrix (including a β ≠ 0 mode)
    st = ModalModel(
        x=(Mode.from_stiffness(900, 0.02, 1e6), Mode.from_residues(2000, 0.03, 50.0, 0.01)),
        y=(Mode.from_stiffness(700, 0.01, 2e6),),
    )
    A, B, C = st.state_space()
    for f in (100.0, 905.0, 1999.0):
        s = 2j * math.pi * f
        G = C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B)
        np.testing.assert_allclose(G, st.frf(f), rtol=1e-10, atol=1e-18)


def test_mass_damping_stiffness() -> None:
    # m = k/ω², c = 2ζ m ω
    st = ModalModel(x=(Mode.from_stiffness(922.0, 0.011, 1.34005e6),))
    M, Cd, K = st.mass_damping_stiffness()
    w = 2 * math.pi * 922.0
    assert M[0, 0] == pytest.approx(1.34005e6 / w**2, rel=1e-12)
    assert K[0, 0] == pytest.approx(1.34005e6, rel=1e-12)
    assert Cd[0, 0] == pytest.approx(2 * 0.011 * M[0, 0] * w, rel=1e-12)


def test_oriented_frf_cos_squared() -> None:
    # β = 0: Φ = Σ cos²θ Φ_i (benchmarks.md §3); β = θ for one mode gives cos θ
    md = Mode.from_stiffness(250.0, 0.012, 2.26e8)
    th = math.radians(30.0)
    f = np.array([100.0, 253.0])
    np.testing.assert_allclose(
        oriented_frf([OrientedMode(md, th)], f), math.cos(th) ** 2 * md.frf(f)
    )
    np.testing.assert_allclose(
        oriented_frf([OrientedMode(md, th)], f, force_angle=th), math.cos(th) * md.frf(f)
    )


def test_invalid_modes() -> None:
    with pytest.raises(ValueError):
        Mode.from_stiffness(900.0, -0.01, 1e6)
    with pytest.raises(ValueError):
        ModalModel()
