"""The coupled lumped-mass truth drives (issue 12): statics, modes, position dependence, fit,
passivity and chunking, each against an independent computation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from millsense.models.modal_ss import ModalStateSpace
from millsense.simulator.feed_drive import FeedDriveSim
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.truth_drive import (
    Q_SCREW,
    CoupledDrive,
    ScrewGeometry,
    ServoLoop,
    disturbance_frf,
)
from millsense.simulator.truth_fit import FIT_BAND_HZ, servo_for
from millsense.simulator.truth_machine import load_truth, truth_feed_params

RG = 0.012 / (2 * math.pi)


def _screw(support: str = "fixed-fixed") -> ScrewGeometry:
    return ScrewGeometry(
        ea_n=210e9 * math.pi * 0.034**2 / 4,
        span_m=0.9,
        offset_m=0.45,
        support=support,  # type: ignore[arg-type]
        nut_stiffness_n_m=4e8,
        bearing_stiffness_n_m=1e9,
    )


def _drive(eta: float = 0.92, zeta: float = 0.03, **kw: object) -> CoupledDrive:
    base = dict(
        kind="linear",
        transmission=RG,
        efficiency=eta,
        motor_inertia=0.0077,
        screw_inertia=0.0025,
        coupling_stiffness=5e4,
        table_mass=700.0,
        base_mass=3000.0,
        base_stiffness=5e9,
        attached_mass=(40.0, 80.0),
        attached_stiffness=(4e6, 3e7),
        damping_ratio=(zeta,) * 6,
        screw=_screw(),
    )
    base.update(kw)
    return CoupledDrive(**base)  # type: ignore[arg-type]


def test_static_load_reaches_the_motor_as_rg_over_eta() -> None:
    """Motor held, a static table load F: the torque on the motor is (r_g/η)·F (Aslan
    Eq. 3.11) by the statics of the chain, at any nut position; Φ_d(0) = 1 with or without
    the servo (the printed Table 3.4 gives 0.49–1.02)."""
    for eta in (0.92, 0.62):
        d = _drive(eta=eta)
        for x in (-0.25, 0.0, 0.2):
            k = d.stiffness_matrix(x)[1:, 1:]
            f = d.input_matrix(x)[1:, 1] * 1000.0  # F = 1000 N resisting
            q = np.linalg.solve(k, f)
            tau_motor = -d.coupling_stiffness * q[Q_SCREW - 1]  # k_c·(θ_m − θ_s), θ_m = 0
            assert tau_motor == pytest.approx(RG / eta * 1000.0, rel=1e-9)
        servo = ServoLoop(d.inertia * 250.0, d.inertia * 250.0**2 / 4, 62.0, 1000.0)
        for sv in (None, servo):
            phi0 = disturbance_frf(d, np.array([1e-4]), sv)[0]
            assert phi0.real == pytest.approx(1.0, abs=1e-4)


def test_modes_are_the_eigenvalues_of_the_assembled_m_k() -> None:
    """Undamped, η = 1: the plant's poles are ±jω with ω² the generalised eigenvalues of
    (K, M) (scipy.linalg.eig, independent of the plant's M⁻¹ assembly) plus the rigid body;
    damped: the poles solve det(s²M + sC + K) = 0 (linearised pencil, scipy.linalg.eig)."""
    d = _drive(eta=1.0, zeta=0.0)
    w2, _ = scipy.linalg.eig(d.stiffness_matrix(0.1), d.mass_matrix())
    w_ref = np.sort(np.sqrt(np.clip(w2.real, 0, None)))
    poles = np.linalg.eigvals(d.plant(0.1).a)
    assert np.all(np.abs(poles.real) < 1e-6 * np.abs(poles).max())
    # the rigid body is a defective double pole at 0, found only to √eps and with either sign
    # of a tiny imaginary part depending on the LAPACK build: the modes are the poles away
    # from 0, one per conjugate pair
    rigid = np.abs(poles) < 1e-3
    assert np.count_nonzero(rigid) == 2
    w_plant = np.sort(poles.imag[~rigid & (poles.imag > 0)])
    np.testing.assert_allclose(w_plant, w_ref[1:], rtol=1e-8)
    assert w_ref[0] < 1e-3  # the rigid body
    dd = _drive(eta=0.92, zeta=0.04)
    m, k, c = dd.mass_matrix(), dd.stiffness_matrix(0.1), dd.damping_matrix()
    n = m.shape[0]
    big_a = np.block([[np.zeros((n, n)), np.eye(n)], [-k, -c]])
    big_b = np.block([[np.eye(n), np.zeros((n, n))], [np.zeros((n, n)), m]])
    ref = scipy.linalg.eig(big_a, big_b, right=False)
    got = np.linalg.eigvals(dd.plant(0.1).a)
    # the rigid body is a defective double pole at 0 (found only to √eps): compare the rest
    got, ref = got[np.abs(got) > 1.0], ref[np.abs(ref) > 1.0]
    assert len(got) == len(ref) == 2 * n - 2
    key = lambda z: (round(abs(z), 3), round(z.imag, 3))  # noqa: E731
    np.testing.assert_allclose(sorted(got, key=key), sorted(ref, key=key), rtol=1e-7)


@pytest.mark.parametrize("support", ["fixed-fixed", "fixed-free"])
def test_axial_mode_follows_the_screw_stiffness(support: str) -> None:
    """Stiff coupling and column, no substructures, motor held: the table's axial mode is
    √(k(x)/M_t) with k(x) the closed form 1/(1/k_s(ℓ) + 1/k_nut + 1/k_b),
    k_s = EA·L/(ℓ(L − ℓ)) (fixed–fixed) or EA/ℓ (fixed–free)."""
    scr = _screw(support)
    d = _drive(
        screw=scr,
        coupling_stiffness=1e12,
        base_stiffness=1e15,
        base_mass=1.0,
        attached_mass=(),
        attached_stiffness=(),
        screw_inertia=10.0,
    )
    ea, span = scr.ea_n, scr.span_m
    for x in (-0.3, -0.1, 0.0, 0.15, 0.3):
        ell = 0.45 + x
        ks = ea * span / (ell * (span - ell)) if support == "fixed-fixed" else ea / ell
        k = 1 / (1 / ks + 1 / 4e8 + 1 / 1e9)
        f_closed = math.sqrt(k / 700.0) / (2 * math.pi)
        f = d.locked_frequencies_hz(x)
        assert np.min(np.abs(f / f_closed - 1)) < 2e-3, (x, f, f_closed)
    f_mid, f_end = (math.sqrt(float(scr.stiffness(v)) / 700.0) / (2 * math.pi) for v in (0.0, 0.3))
    # the mode moves by several per cent over the stroke (not a constant)
    assert abs(f_end / f_mid - 1) > 0.03


MACHINE = simulator_machine("quaser-ux600")
TRUTH = load_truth("quaser-ux600")
#: Documented tolerances of the fit (decision 0973): locked-mode frequencies within 3 % of
#: Table 3.4; the closed-loop Φ_d magnitude within 20 dB of Table 3.4 in 20–250 Hz and its RMS
#: error between 2 and 8 dB — resembling, not equal (below 2 dB it would be the estimators'
#: own model again).
FREQ_TOL = 0.03
RMS_DB = (2.0, 8.0)
MAX_DB = 20.0


@pytest.mark.parametrize("axis", ["x", "y", "z", "a", "c"])
def test_fitted_frf_resembles_table_3_4(axis: str) -> None:
    ax = MACHINE.axes[axis]
    d = TRUTH[axis].drive
    assert ax.disturbance_modes is not None
    table = ModalStateSpace.from_config(ax.disturbance_modes)
    f_tab = np.sort(table.frequency_hz)
    f_sim = d.locked_frequencies_hz()[: len(f_tab)]
    err = f_sim / f_tab - 1
    assert np.all(np.abs(err) <= FREQ_TOL), err
    grid = np.geomspace(*FIT_BAND_HZ, 200)
    sim = disturbance_frf(d, grid, servo_for(ax, d.inertia))
    db = 20 * np.log10(np.abs(sim) / np.abs(table.frf(grid)))
    rms = float(np.sqrt(np.mean(db**2)))
    assert RMS_DB[0] <= rms <= RMS_DB[1], rms
    assert np.max(np.abs(db)) <= MAX_DB
    # static gain 1 by physics, unlike the printed table
    assert abs(disturbance_frf(d, np.array([1e-4]), None)[0]) == pytest.approx(1.0, abs=1e-4)
    assert abs(table.static_gain() - 1.0) > 0.2


def test_passive_without_efficiency_loss() -> None:
    """η = 1: K and C symmetric positive semi-definite, and along a forced run the work of the
    inputs equals the stored energy plus the dissipation ∫q̇ᵀCq̇ (independent quadrature of the
    exact ZOH trajectory)."""
    d = _drive(eta=1.0)
    m, k, c = d.mass_matrix(), d.stiffness_matrix(0.05), d.damping_matrix()
    for mat in (k, c):
        np.testing.assert_allclose(mat, mat.T, atol=1e-9 * np.abs(mat).max())
        assert np.linalg.eigvalsh(0.5 * (mat + mat.T)).min() > -1e-9 * np.abs(mat).max()
    plant = d.plant(0.05)
    h = 1e-6
    ad, bd = plant.discretise(h)
    n = d.n_dof
    t = np.arange(40000) * h
    tau = 2.0 * np.sin(2 * math.pi * 80 * t)
    force = 300.0 * np.sin(2 * math.pi * 130 * t + 0.4)
    x = np.zeros(2 * n)
    work = diss = 0.0
    for j in range(len(t)):
        u = np.array([tau[j], force[j], 0.0])
        xn = ad @ x + bd @ u
        v = 0.5 * (x[n:] + xn[n:])
        work += h * (tau[j] * v[0] - force[j] * v[2])
        diss += h * float(v @ c @ v)
        x = xn
    q, qd = x[:n], x[n:]
    energy = 0.5 * qd @ m @ qd + 0.5 * q @ k @ q
    assert work > 0
    assert energy + diss == pytest.approx(work, rel=2e-3)


def test_truth_drive_chunking_is_bit_identical() -> None:
    """X truth (position-scheduled plant, LuGre, PI current loop, dead times, ripple) over a
    100 mm move: chunks of 1, 7, 100 and the rest give the same arrays bit for bit."""
    p = truth_feed_params(MACHINE.axes["x"], TRUTH["x"])
    assert p.plant_schedule is not None
    fs = 10000.0
    n = 3000
    t = np.arange(n) / fs
    v = 0.1 / 0.3  # m/s
    pos = np.minimum(v * t, 0.1) / p.transmission
    vel = np.where(v * t < 0.1, v, 0.0) / p.transmission
    load = 200.0 * np.sin(2 * math.pi * 90 * t)
    one = FeedDriveSim(p, fs, seed=3).advance(pos, vel, load)
    sim = FeedDriveSim(p, fs, seed=3)
    parts: dict[str, list[np.ndarray]] = {}
    start = 0
    for size in (1, 7, 100, n - 108):
        r = sim.advance(
            pos[start : start + size], vel[start : start + size], load[start : start + size]
        )
        for key, arr in r.items():
            parts.setdefault(key, []).append(arr)
        start += size
    for key, arr in one.items():
        assert np.array_equal(np.concatenate(parts[key]), arr), key
    assert one["true_position"][-1] == pytest.approx(0.1, abs=2e-4)


def test_few_term_rows_equal_the_dense_dot_product() -> None:
    """The kernel evaluates the motor angle, motor speed and lost-motion stretch at every
    substep from their nonzeros (speed work, issue 12): the products the dense sequential dot
    product sums, in its order, less exact zeros — equal bit for bit, so the drives' results
    are unchanged. On every truth drive's own rows (single states; the stretch three nonzeros)
    at random states, and on random rows of 0–3 nonzeros; a denser row takes the dense sum."""
    from millsense.models.drive_plant import OUT_OMEGA, OUT_THETA
    from millsense.simulator.feed_drive import _dot, _few, _few_dot

    rng = np.random.default_rng(11)

    def states(n: int) -> np.ndarray:
        return rng.normal(size=n) * 10.0 ** rng.uniform(-9, 3, size=n)

    rows = []
    for ax in TRUTH:
        p = truth_feed_params(MACHINE.axes[ax], TRUTH[ax])
        assert p.lost_motion is not None
        sim = FeedDriveSim(p, 10000.0)
        rows += [sim._cy[OUT_OMEGA], sim._cy[OUT_THETA], p.lost_motion.stretch]
    for _ in range(200):
        row = np.zeros(16)
        k = rng.integers(0, 4)
        row[rng.choice(16, size=k, replace=False)] = rng.normal(size=k) * 10.0 ** rng.uniform(-3, 3)
        rows.append(row)
    for row in rows:
        t = _few(row)
        assert t[0]
        for _ in range(20):
            x = states(row.shape[0])
            assert _few_dot(t, row, x) == _dot(row, x)
    dense = rng.normal(size=16)
    assert not _few(dense)[0]
    x = states(16)
    assert _few_dot(_few(dense), dense, x) == _dot(dense, x)


def test_zoh_step_is_the_matrix_product() -> None:
    """The ZOH product of the coupled plants (four rows per pass, reassociated sums; speed
    work, issue 12) against NumPy's ``Ad·x + Bd·u`` on every truth drive's own map and on
    random ones of 8–33 states (the four-row blocks and the remainder rows). Tolerance 1e-14
    of ``|Ad|·|x| + |Bd|·|u|`` per row: a sum of ≤ 36 products in another order differs by a
    few units of 2.2e-16 of that bound."""
    from millsense.simulator.feed_drive import _zoh_step

    rng = np.random.default_rng(12)
    maps = []
    for ax in TRUTH:
        sim = FeedDriveSim(truth_feed_params(MACHINE.axes[ax], TRUTH[ax]), 10000.0, substeps=4)
        maps.append((sim._ad, sim._bd))
    for n in range(8, 34):
        maps.append((rng.normal(size=(n, n)), rng.normal(size=(n, 3))))
    for ad, bd in maps:
        n = ad.shape[0]
        for _ in range(5):
            x = rng.normal(size=n) * 10.0 ** rng.uniform(-6, 2, size=n)
            u = rng.normal(size=3) * 100.0
            out = np.empty(n)
            _zoh_step(ad, bd, x, u[0], u[1], u[2], out)
            bound = np.abs(ad) @ np.abs(x) + np.abs(bd) @ np.abs(u)
            assert np.all(np.abs(out - (ad @ x + bd @ u)) <= 1e-14 * bound)


def test_schedule_interpolates_the_discretised_plant() -> None:
    """The kernel's plant at a grid position is that position's exact ZOH map; half-way it is
    the mean of the two neighbours; beyond the grid the end plant (decision 0974)."""
    from millsense.simulator.feed_drive import _interpolate_plant

    p = truth_feed_params(MACHINE.axes["x"], TRUTH["x"])
    sch = p.plant_schedule
    assert sch is not None
    h = 1e-4 / 4
    disc = [pl.discretise(h) for pl in sch.plants]
    pad = np.stack([d[0] for d in disc])
    pbd = np.stack([d[1] for d in disc])
    pcy = np.stack([pl.c for pl in sch.plants])
    pdy = np.stack([pl.d for pl in sch.plants])
    x = np.asarray(sch.positions)
    grid = np.array([x[0], x[1] - x[0]])
    n = pad.shape[1]
    ad, bd, cy, dy = np.zeros((n, n)), np.zeros((n, 3)), np.zeros((6, n)), np.zeros((6, 3))
    _interpolate_plant(float(x[5]), grid, pad, pbd, pcy, pdy, ad, bd, cy, dy)
    exact = TRUTH["x"].drive.plant(float(x[5])).discretise(h)
    np.testing.assert_allclose(ad, exact[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(bd, exact[1], rtol=1e-9, atol=1e-15)
    _interpolate_plant(float(0.5 * (x[5] + x[6])), grid, pad, pbd, pcy, pdy, ad, bd, cy, dy)
    np.testing.assert_allclose(ad, 0.5 * (pad[5] + pad[6]), rtol=0, atol=1e-12)
    _interpolate_plant(10.0, grid, pad, pbd, pcy, pdy, ad, bd, cy, dy)
    np.testing.assert_allclose(ad, pad[-1], rtol=0, atol=1e-15)


def test_truth_is_not_the_preset() -> None:
    """The truth parameters differ from what the preset (the estimators' file) says: K_t
    within 0.5–3 % of Table 3.1, no printed modes, a coupled plant of ≥ 14 states, a Stribeck
    hump (τ_stat > τ_coul by ≥ 15 %), a PI current loop and dead times (decision 0975)."""
    for name, ax in MACHINE.axes.items():
        p = truth_feed_params(ax, TRUTH[name])
        dev = abs(p.torque_constant / ax.torque_constant_nm_a - 1)
        assert 0.005 <= dev <= 0.03, (name, dev)
        assert p.modes is None and p.plant.a.shape[0] >= 14
        assert p.current_loop is not None and p.dead_time_amplifier_s == pytest.approx(1e-4)
        fr = TRUTH[name].friction
        assert min(fr.static[0] / fr.coulomb[0], fr.static[1] / fr.coulomb[1]) >= 1.15
        # the total reflected inertia is Table 3.1's J_e (the fit keeps it)
        assert p.plant.inertia == pytest.approx(ax.inertia_kg_m2, rel=1e-5)  # 6 digits stored


def test_four_substeps_match_twenty() -> None:
    """X truth on a 1 Hz ±50 mm move with a 150 Hz load: the motor current with 4 substeps is
    within 1 % RMS of 20 substeps (decision 0977; measured 0.6 %)."""
    p = truth_feed_params(MACHINE.axes["x"], TRUTH["x"])
    fs = 10000.0
    t = np.arange(10000) / fs
    amp = 0.05 / p.transmission
    pos = amp * np.sin(2 * math.pi * t)
    vel = amp * 2 * math.pi * np.cos(2 * math.pi * t)
    load = 300.0 * (1 + np.sin(2 * math.pi * 150 * t))
    ref = FeedDriveSim(p, fs, substeps=20, seed=1).advance(pos, vel, load)["current"]
    got = FeedDriveSim(p, fs, substeps=TRUTH["x"].substeps, seed=1).advance(pos, vel, load)
    rel = np.sqrt(np.mean((got["current"] - ref) ** 2) / np.mean(ref**2))
    assert 1e-4 < rel < 0.01


def _held_table_position(p: object, load: float, seconds: float = 0.6) -> float:
    """Table position with the servo holding the motor at 0 under a constant table load
    (mean of the last 0.1 s; no torque noise)."""
    import dataclasses

    q = dataclasses.replace(p, torque_noise_nm=0.0, periodic=())  # type: ignore[type-var]
    fs = 10000.0
    n = round(seconds * fs)
    ramp = np.minimum(np.arange(n) / (0.2 * fs), 1.0) * load
    r = FeedDriveSim(q, fs, substeps=4).advance(np.zeros(n), np.zeros(n), ramp)  # type: ignore[arg-type]
    return float(np.mean(r["true_position"][-1000:]))


def test_backlash_and_preload_lift_off() -> None:
    """A: the table angle between +T and −T held loads exceeds the elastic difference of the
    same drive without backlash by the backlash (12″) within 2 %. X: beyond the lift-off force
    2.83·F_p the table's compliance grows by exactly 1/(ratio·k) − 1/k (decision 0978)."""
    import dataclasses

    pa = truth_feed_params(MACHINE.axes["a"], TRUTH["a"])
    assert pa.lost_motion is not None
    gap = 12.0 * math.pi / 648000.0
    no_gap = dataclasses.replace(pa, lost_motion=None)
    t = 40.0  # N·m at the table
    with_gap = _held_table_position(pa, -t) - _held_table_position(pa, t)
    elastic = _held_table_position(no_gap, -t) - _held_table_position(no_gap, t)
    assert with_gap - elastic == pytest.approx(gap, rel=0.02)
    px = truth_feed_params(MACHINE.axes["x"], TRUTH["x"])
    lm = px.lost_motion
    assert lm is not None and lm.half_gap == 0.0 and 0.5 < lm.ratio < 1.0
    k = TRUTH["x"].drive.transmission_stiffness(0.0)
    lift_n = 2.83 * 2500.0
    assert lm.lift * k == pytest.approx(lift_n, rel=1e-12)
    below = _held_table_position(px, 2000.0) - _held_table_position(px, 4000.0)
    above = _held_table_position(px, 9000.0) - _held_table_position(px, 11000.0)
    assert above - below == pytest.approx(2000.0 * (1 / (lm.ratio * k) - 1 / k), rel=0.02)
