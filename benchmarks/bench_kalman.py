"""Kalman toolkit: five feed-axis estimators plus the spindle observer at 10 kHz on one core.

Feed axes (issue 7): the disturbance Kalman filters of X, Y, Z, A, C built from Aslan
Table 3.4 (13, 25, 17, 13, 11 augmented states) with R, Q of Eq. 3.30, each followed by the
60-sample fixed-lag smoother (Appendix B), as the feed-drive pipeline runs them. Spindle: a
21-state observer (20 plant states + the random-walk torque, Q_s = 2·10⁴·I₂₁, R = 0.378 as in
Table 5.2), whose plant is a stand-in of the same size built from the ten G_sp modes of
Appendix E range 1 (the spindle helper builds the real G_dτ of Eq. 5.12). 10 s of data per
channel, streamed in chunks of 100 samples (10 ms) as the online engine does; numba kernels are
compiled before the timing. Single-threaded: every kernel is sequential numba or scipy.
"""

from __future__ import annotations

import time

import numpy as np

from _harness import Metric, benchmark
from millsense.estimation.kalman.design import KalmanDesign, augment_disturbance, design_kalman
from millsense.estimation.kalman.lti_filter import StreamingFilter
from millsense.estimation.kalman.smoother import FixedLagSmoother
from millsense.models.modal_ss import ModalStateSpace
from millsense.models.spindle_modes import MODES_RANGE1
from millsense.validation.cases._thesis_models import (
    aslan_disturbance_model,
    aslan_r_q,
    state_space_from_modal,
)

FS_HZ = 10_000.0
DT = 1.0 / FS_HZ
SECONDS = 10.0
CHUNK = 100
LAG = 60


#: Aslan Appendix E, G_sp range 1: (f_n Hz, ζ %, α, β)
def _feed_designs() -> dict[str, KalmanDesign]:
    out = {}
    for axis in ("x", "y", "z", "a", "c"):
        r, q = aslan_r_q(axis)
        out[axis] = design_kalman(augment_disturbance(aslan_disturbance_model(axis)), q, r, dt=DT)
    return out


def _spindle_design() -> KalmanDesign:
    # Appendix E range-1 modes (machine.spindle_modes, ζ as fractions) + the torque state
    model = state_space_from_modal(ModalStateSpace.from_modes(*MODES_RANGE1.T))
    return design_kalman(augment_disturbance(model, noise_on_all_states=True), 2e4, 0.378, dt=DT)


def _rts_estimate(design: KalmanDesign, y: np.ndarray, t: int, lag: int) -> float:
    """x̂(t | t+lag) by Aslan Eq. B.1-B.2 (RTS) over one window, for the delay measurement."""
    xp = np.zeros(design.n_states)
    post = []
    for k in range(t + lag + 1):
        xf = xp + design.k_filter[:, 0] * (y[k] - design.c[0] @ xp)
        post.append(xf)
        xp = design.a @ xf
    pf = design.p_filtered
    ks = pf @ design.a.T @ np.linalg.inv(design.a @ pf @ design.a.T + design.qd)
    xs = post[t + lag]
    for k in range(t + lag - 1, t - 1, -1):
        xs = post[k] + ks @ (xs - design.a @ post[k])
    return float(design.disturbance[0] @ xs)


@benchmark("estimation.kalman_speed")
def _kalman_speed() -> list[Metric]:
    feed = _feed_designs()
    spindle = _spindle_design()
    n = int(SECONDS * FS_HZ)
    rng = np.random.default_rng(0)
    data = {ax: rng.normal(size=n) for ax in [*feed, "spindle"]}
    smoothers = {ax: FixedLagSmoother(d, LAG) for ax, d in feed.items()}
    observer = StreamingFilter(spindle.filter("filtered"))
    for ax, sm in smoothers.items():  # compile and warm up
        sm.process(data[ax][:CHUNK])
        sm.reset()
    observer.process(data["spindle"][:CHUNK])
    observer.reset()

    t0 = time.perf_counter()
    for i in range(0, n, CHUNK):
        for ax, sm in smoothers.items():
            sm.process(data[ax][i : i + CHUNK])
        observer.process(data["spindle"][i : i + CHUNK])
    wall = time.perf_counter() - t0

    filters = {ax: StreamingFilter(d.filter("filtered")) for ax, d in feed.items()}
    for ax, f in filters.items():
        f.process(data[ax][:CHUNK])
        f.reset()
    t0 = time.perf_counter()
    for i in range(0, n, CHUNK):
        for ax, f in filters.items():
            f.process(data[ax][i : i + CHUNK])
        observer.process(data["spindle"][i : i + CHUNK])
    wall_filters = time.perf_counter() - t0

    # delay: find the output sample that carries the RTS estimate of sample t
    d = feed["x"]
    y = data["x"][:600]
    out = FixedLagSmoother(d, LAG).process(y)[:, 0]
    t = 200
    ref = _rts_estimate(d, y, t, LAG)
    shift = int(np.argmin(np.abs(out[t : t + 200] - ref)))
    delay_ms = shift * DT * 1e3

    states = ", ".join(f"{ax.upper()} {dd.n_states}" for ax, dd in feed.items())
    kernels = ", ".join(
        sorted({sm.realisation for sm in smoothers.values()} | {observer.realisation})
    )
    note = (
        f"feed axes ({states} states) each with a {LAG}-sample fixed-lag smoother + spindle "
        f"{spindle.n_states}-state observer; {SECONDS:g} s at {FS_HZ:g} Hz in {CHUNK}-sample "
        f"chunks, {kernels} kernel; wall {wall * 1e3:.1f} ms; filters alone "
        f"{SECONDS / wall_filters:.0f}x real time"
    )
    return [
        Metric("x_realtime", SECONDS / wall, "x", target=100.0, note=note),
        Metric(
            "smoother_delay_ms",
            delay_ms,
            "ms",
            target=6.0,
            higher_is_better=False,
            note=f"output index carrying the RTS (Eq. B.1-B.2) estimate of sample {t}, minus {t}",
        ),
    ]
