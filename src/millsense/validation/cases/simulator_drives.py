"""Validation cases of the feed drives (:mod:`millsense.simulator.feed_drive` and friends).

Every FRF here is measured the way a machine is: a sine sweep through the time-domain simulator,
then the ratio of the Fourier transforms of the recorded output and input — an independent
check of the state-space realisation, the discretisation and the kernel's wiring.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable

import numpy as np
from scipy.signal import find_peaks

from millsense.models.lugre import LuGre
from millsense.models.modal_ss import ModalStateSpace
from millsense.simulator.feed_drive import FeedDriveParams, FeedDriveSim, constant_velocity_sweep
from millsense.simulator.machine_file import simulator_machine
from millsense.validation import Measured, case


def log_chirp(
    f0_hz: float, f1_hz: float, sweep_s: float, tail_s: float, fs_hz: float
) -> np.ndarray:
    """Unit exponential sine sweep f0 → f1 over ``sweep_s``, then ``tail_s`` of zeros (lets
    the response decay so the FFT ratio of the whole record is the FRF)."""
    n = round(sweep_s * fs_hz)
    t = np.arange(n) / fs_hz
    k = math.log(f1_hz / f0_hz)
    sweep = np.sin(2 * math.pi * f0_hz * sweep_s / k * (np.exp(t / sweep_s * k) - 1.0))
    return np.concatenate([sweep, np.zeros(round(tail_s * fs_hz))])


def frf_from_signals(u: np.ndarray, y: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies Hz, Y/U) from whole-record FFTs."""
    f = np.fft.rfftfreq(len(u), 1.0 / fs_hz)
    return f, np.fft.rfft(y) / np.fft.rfft(u)


def peak_frequencies(f: np.ndarray, h: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Local maxima of |h| within [lo, hi] Hz (prominence 1 % of the band maximum)."""
    band = (f >= lo) & (f <= hi)
    mag = np.abs(h[band])
    idx, _ = find_peaks(mag, prominence=0.01 * mag.max())
    return f[band][idx]


def quaser_disturbance_frf(axis: str, *, lugre: bool = True) -> dict[str, np.ndarray]:
    """Sweep the load of a Quaser axis (full drive: cascade, LuGre, noise) and return the
    simulated τ_a → τ_c FRF and the model's (Eq. 3.13) on the same grid."""
    ax = simulator_machine("quaser-ux600").axis(axis)
    params = FeedDriveParams.from_config(ax, friction="lugre" if lugre else "none")
    assert params.modes is not None
    fs = 10000.0
    load = 50.0 * log_chirp(5.0, 400.0, 20.0, 4.0, fs)  # N (N·m rotary) at the table
    n = len(load)
    sim = FeedDriveSim(params, fs, seed=1)
    res = sim.advance(np.zeros(n), np.zeros(n), load)
    tau_a = params.transmission / params.efficiency * load
    f, h = frf_from_signals(tau_a, res["load_torque_motor"], fs)
    return {"f": f, "h_sim": h, "h_model": params.modes.frf_modal(f)}


def _dominant_mode_hz(modes: ModalStateSpace) -> float:
    """Table 3.4 frequency of the mode with the largest single-mode peak |α + jωβ|/(2ζω²)."""
    w = 2 * math.pi * modes.frequency_hz
    gain = np.abs(modes.alpha + 1j * w * modes.beta) / (2 * modes.damping_ratio * w**2)
    return float(modes.frequency_hz[int(np.argmax(gain))])


@functools.cache
def _disturbance_case(axis: str) -> Measured:
    r = quaser_disturbance_frf(axis)
    f, hs, hm = r["f"], r["h_sim"], r["h_model"]
    band = (f >= 10.0) & (f <= 300.0)
    f_dom = float(f[band][np.argmax(np.abs(hs[band]))])
    ps = peak_frequencies(f, hs, 10.0, 300.0)
    pm = peak_frequencies(f, hm, 10.0, 300.0)
    ax = simulator_machine("quaser-ux600").axis(axis)
    assert ax.disturbance_modes is not None
    modes = ModalStateSpace.from_config(ax.disturbance_modes)
    rows = [
        "| Table 3.4 mode (Hz) | nearest simulated peak (Hz) | deviation | within ±2 % |",
        "|---|---|---|---|",
    ]
    for fk in modes.frequency_hz:
        j = int(np.argmin(np.abs(ps - fk)))
        dev = (ps[j] - fk) / fk
        rows.append(
            f"| {fk:g} | {ps[j]:.2f} | {100 * dev:+.1f} % | {'yes' if abs(dev) <= 0.02 else 'no'} |"
        )
    model_vs_sim = max(float(np.min(np.abs(ps - p)) / p) for p in pm)
    details = "\n".join(
        [
            f"Axis {axis.upper()}: dominant simulated peak {f_dom:.2f} Hz; "
            f"static gain of the printed modes Φ_d(0) = {modes.static_gain():.3f} (not 1). "
            "Largest offset of a simulated peak from the Eq. 3.13 peaks: "
            f"{100 * model_vs_sim:.2f} %.",
            "",
            *rows,
        ]
    )
    return Measured(f_dom, details)


def _dominant_reference(axis: str) -> float:
    ax = simulator_machine("quaser-ux600").axis(axis)
    assert ax.disturbance_modes is not None
    return _dominant_mode_hz(ModalStateSpace.from_config(ax.disturbance_modes))


def _disturbance_case_for(axis: str) -> Callable[[], Measured]:
    return lambda: _disturbance_case(axis)


for _ax in ("x", "y", "z", "c"):
    case(
        f"simulator.quaser_disturbance_frf_peak_{_ax}",
        source="Aslan Table 3.4, Eq. 3.13",
        reference=_dominant_reference(_ax),
        unit="Hz",
        rel_tol=0.02,
        quick=False,
        description=f"{_ax.upper()} axis: frequency of the largest peak of the simulated τ_a → τ_c "
        "sine-sweep FRF (full drive, LuGre, noise) vs the Table 3.4 mode with the largest peak",
    )(_disturbance_case_for(_ax))

# A axis: with ζ as fractions (0.12–0.69, see
# docs/decisions/0038-aslan-table-3-4-damping-and-static-gain.md) the printed modes merge; the
# dominant 50 Hz mode of Table 3.4 peaks at about 54 Hz in Eq. 3.13 itself, an 8 % gap no simulation
# can close. Two cases: the stated mode (documented gap), and the simulation against the peak of Eq.
# 3.13 computed here from the printed coefficients (an independent evaluation).
case(
    "simulator.quaser_disturbance_frf_peak_a",
    source="Aslan Table 3.4 (A axis, dominant mode 50 Hz)",
    reference=50.0,
    unit="Hz",
    rel_tol=0.02,
    quick=False,
    gap="with the printed A-axis coefficients (ζ read as fractions, 0.12-0.69) the modes merge "
    "and Eq. 3.13 itself peaks near 54 Hz; "
    "docs/decisions/0038-aslan-table-3-4-damping-and-static-gain.md",
    issue=12,
    description="A axis: largest peak of the simulated τ_a → τ_c FRF against Table 3.4's "
    "dominant mode",
)(lambda: _disturbance_case("a"))


def _eq313_peak_hz(axis: str) -> float:
    """Frequency of the maximum of |Eq. 3.13| with the preset's printed modes (0.01 Hz grid)."""
    from millsense.models.modal_ss import ModalStateSpace

    cfg = simulator_machine("quaser-ux600").axis(axis).disturbance_modes
    assert cfg is not None
    f = np.arange(1.0, 400.0, 0.01)
    mag = np.abs(ModalStateSpace.from_config(cfg).frf_modal(f))
    return float(f[int(np.argmax(mag))])


case(
    "simulator.quaser_disturbance_frf_peak_a_vs_eq313",
    source="Aslan Eq. 3.13 evaluated with the Table 3.4 A-axis coefficients",
    reference=_eq313_peak_hz("a"),
    unit="Hz",
    rel_tol=0.02,
    quick=False,
    description="A axis: the simulated sine-sweep FRF peaks where Eq. 3.13 of the printed "
    "coefficients does (simulation against the analytic model)",
)(lambda: _disturbance_case("a"))


def yamada_table_accel_frf(machine: str) -> tuple[np.ndarray, np.ndarray]:
    """Current-command sweep on a Yamada stage in closed loop (P-P cascade, dead times,
    current loop, encoders; friction and periodic disturbances off as in Yamada §4.1):
    (f, FRF I_cmd → table acceleration). The stage is the one the simulator runs: the truth's
    coupled drive for yamada-a and yamada-b (decisions 1711, 1705)."""
    from dataclasses import replace

    from millsense.simulator.commissioning import plant_params

    m = simulator_machine(machine)
    plant, sub = plant_params(m, "x", friction="none", periodic=False)
    params = replace(plant, friction=None, periodic=())
    fs = m.sample_rate_hz
    inj = 0.3 * log_chirp(50.0, 1000.0, 8.0, 0.5, fs)
    n = len(inj)
    res = FeedDriveSim(params, fs, substeps=sub).advance(np.zeros(n), np.zeros(n), np.zeros(n), inj)
    return frf_from_signals(res["current_cmd"], res["true_acceleration"], fs)


def _yamada_case(machine: str) -> Measured:
    f, h = yamada_table_accel_frf(machine)
    band = (f >= 200.0) & (f <= 600.0)
    # mild smoothing of the FFT ratio (11 bins = 1.4 Hz) before picking the maximum
    mag = np.convolve(np.abs(h), np.ones(11) / 11, mode="same")
    f_peak = float(f[band][np.argmax(mag[band])])
    return Measured(f_peak, f"Peak of |a_t/I_cmd| at {f_peak:.1f} Hz ({machine}).")


case(
    "simulator.yamada_a_resonance",
    source="Yamada Table 3-3 (Machine A)",
    reference=335.0,
    unit="Hz",
    rel_tol=0.02,
    quick=True,
    description="Peak of the simulated I_cmd → table-acceleration FRF, stage A (the yamada-a "
    "truth's coupled drive, decision 1711)",
)(lambda: _yamada_case("yamada-a"))
case(
    "simulator.yamada_b_resonance",
    source="Yamada Table 3-3 (Machine B)",
    reference=408.0,
    unit="Hz",
    rel_tol=0.02,
    quick=True,
    description="Peak of the simulated I_cmd → table-acceleration FRF, stage B (the yamada-b "
    "truth's coupled drive, decision 1705)",
)(lambda: _yamada_case("yamada-b"))

STRIBECK_SPEEDS = np.array([-4.0, -1.0, -0.5, -0.25, 0.25, 0.5, 1.0, 2.0, 4.0])


@case(
    "simulator.lugre_stribeck_sweep",
    source="Aslan Eq. 3.2–3.4, Table 3.2 (Z axis)",
    reference=0.0,
    unit="σ",
    abs_tol=4.0,
    quick=False,
    description="Constant-velocity sweep of the Z drive (LuGre, noise): largest deviation of the "
    "mean torque from g(v) + σ2·v, in standard errors of the mean",
)
def _stribeck() -> Measured:
    ax = simulator_machine("quaser-ux600").axis("z")
    params = FeedDriveParams.from_config(ax, friction="lugre")
    assert isinstance(params.friction, LuGre)
    means, sems = constant_velocity_sweep(params, STRIBECK_SPEEDS, 10000.0, duration_s=4.0)
    model = params.friction.steady_torque(STRIBECK_SPEEDS)
    z = (means - model) / sems
    rows = [
        "| v (rad/s) | mean K_t·i (N·m) | g(v)+σ2·v (N·m) | σ_mean (N·m) |",
        "|---|---|---|---|",
    ]
    rows += [
        f"| {v:g} | {a:.4f} | {b:.4f} | {s:.4f} |"
        for v, a, b, s in zip(STRIBECK_SPEEDS, means, model, sems, strict=True)
    ]
    return Measured(float(np.max(np.abs(z))), "\n".join(rows))


@case(
    "simulator.feed_drive_chunk_invariance",
    source="issue 5 (resumable simulator); bit-identity",
    reference=0.0,
    unit="A",
    abs_tol=0.0,
    quick=True,
    description="Largest difference of the current command between one run and a run in uneven "
    "chunks (Quaser X: modes, LuGre, noise; 0.5 s at 10 kHz)",
)
def _chunks() -> float:
    ax = simulator_machine("quaser-ux600").axis("x")
    params = FeedDriveParams.from_config(ax)
    fs = 10000.0
    n = 5000
    t = np.arange(n) / fs
    pos = 30.0 * np.sin(2 * math.pi * t)
    vel = 30.0 * 2 * math.pi * np.cos(2 * math.pi * t)
    load = 200.0 * np.sin(2 * math.pi * 80.0 * t)
    whole = FeedDriveSim(params, fs, seed=2).advance(pos, vel, load)["current_cmd"]
    sim = FeedDriveSim(params, fs, seed=2)
    cuts = [0, 1, 13, 400, 2501, 4999, n]
    parts = [
        sim.advance(pos[a:b], vel[a:b], load[a:b])["current_cmd"]
        for a, b in itertools.pairwise(cuts)
    ]
    return float(np.max(np.abs(np.concatenate(parts) - whole)))
