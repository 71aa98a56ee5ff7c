"""Issue 7 performance: five feed-axis force estimators plus the spindle observer at 10 kHz.

The full streaming pipelines as the engine runs them, 10 s of CNC data per channel in chunks of
1000 samples (0.1 s; also reported at 100 samples = 10 ms): per feed axis
:class:`~millsense.estimation.feed.estimator.FeedAxisEstimator`
(C3 torque with LuGre friction and the Butterworth low-pass, the disturbance Kalman filter over
the axis's Table 3.4 modes in series with the low-pass — 15/27/19/15/13 states for X/Y/Z/A/C —
and the 60-sample fixed-lag smoother, Eq. 3.11/3.12 outputs), then the
:class:`~millsense.estimation.feed.estimator.ToolForceBlock` (Eq. 3.51 per sample), and the
21-state :class:`~millsense.estimation.spindle_observer.SpindleTorqueObserver` identified from a
simulated sweep (it runs on every second sample, where the 0.2 ms velocity loop updates I_nom).
The feed models use the preset's modes rather than an identification to keep the set-up short;
the per-sample cost depends only on the state counts. Single core (sequential numba/numpy).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from _harness import Metric, benchmark
from millsense.bench.spindle_commissioning import identify_spindle
from millsense.estimation.feed.estimator import FeedAxisEstimator, FeedAxisModel, ToolForceBlock
from millsense.estimation.feed.rigid_body import DriveModel
from millsense.estimation.kalman.rational_fit import RationalFit
from millsense.estimation.spindle_observer import SpindleTorqueObserver, design_observer
from millsense.models.friction import CoulombViscous
from millsense.models.kinematics import TrunnionACKinematics
from millsense.models.lugre import LuGre
from millsense.models.spindle_plant import SpindleDriveParams
from millsense.simulator.feed_drive import FeedDriveParams
from millsense.simulator.machine_file import simulator_machine
from millsense.streaming.block import Block, Chunk

FS_HZ = 10_000.0
SECONDS = 10.0
CHUNK = 100
AXES = ("x", "y", "z", "a", "c")


def _feed_blocks() -> list[FeedAxisEstimator]:
    cfg = simulator_machine("quaser-ux600")
    blocks = []
    for ax in AXES:
        a = cfg.axis(ax)
        p = FeedDriveParams.from_config(a)
        assert p.modes is not None and isinstance(p.friction, LuGre)
        fr = CoulombViscous(
            a.friction.coulomb_nm[0],
            a.friction.coulomb_nm[1],
            a.friction.viscous_nm_s_rad[0],
            a.friction.viscous_nm_s_rad[1],
            0.3,
        )
        drive = DriveModel(a.inertia_kg_m2, p.torque_constant, p.transmission, p.efficiency, fr)
        model = FeedAxisModel(
            ax,
            a.kind,
            drive,
            RationalFit.from_modes(p.modes),
            600.0,
            0.05,
            3000.0,
            FS_HZ,
            0.2 if a.kind == "rotary" else None,
            p.friction,
        )
        blocks.append(FeedAxisEstimator(model))
    return blocks


def _spindle_block() -> SpindleTorqueObserver:
    ident = identify_spindle(SpindleDriveParams.aslan_quaser(), current_noise_a=0.01)
    design = design_observer(ident.model, 1e-14, 100.0, ident.r)
    return SpindleTorqueObserver(design, FS_HZ, 0.01)


def _run(blocks: list[Block], data: dict[str, np.ndarray], n: int, chunk_n: int = CHUNK) -> float:
    for b in blocks:
        b.reset(FS_HZ)
    t0 = time.perf_counter()
    for s in range(0, n, chunk_n):
        chunk = {k: v[s : s + chunk_n] for k, v in data.items()}
        for b in blocks:
            out = b.process(Chunk(s, FS_HZ, 0.0, {k: chunk[k] for k in b.inputs}))
            chunk.update(out.channels)
    return time.perf_counter() - t0


@benchmark("estimation.estimators_speed")
def _estimators_speed() -> list[Metric]:
    feed = _feed_blocks()
    spindle = _spindle_block()
    tool = ToolForceBlock(TrunnionACKinematics(), AXES, [b.model.drive.transmission for b in feed])
    n = int(SECONDS * FS_HZ)
    rng = np.random.default_rng(0)
    data: dict[str, np.ndarray] = {"spindle/current_cmd": rng.normal(size=n)}
    for ax in AXES:
        data[f"{ax}/current_cmd"] = rng.normal(size=n)
        data[f"{ax}/motor_speed"] = 5.0 + 0.1 * rng.normal(size=n)
        data[f"{ax}/motor_angle"] = np.cumsum(data[f"{ax}/motor_speed"]) / FS_HZ
    blocks: list[Block] = [*feed, spindle]
    _run([*blocks, tool], {k: v[: 10 * CHUNK] for k, v in data.items()}, 10 * CHUNK)  # compile
    # best of 3: the figure is the cost of the code, not of other jobs on the machine
    wall = min(_run(blocks, data, n) for _ in range(3))
    wall_1000 = min(_run(blocks, data, n, 10 * CHUNK) for _ in range(3))
    wall_tool = min(_run([*blocks, tool], data, n, 10 * CHUNK) for _ in range(3))
    states = "/".join(str(b.design.n_states) for b in feed)
    return [
        Metric(
            "x_realtime",
            SECONDS / wall_1000,
            "x",
            target=100.0,
            note=f"5 feed-axis estimators ({states} states, LuGre C3, Kalman, 60-sample "
            f"smoother) + {spindle.design.n_states}-state spindle observer, 10 s at 10 kHz, "
            "1000-sample (0.1 s) chunks as the demo engine and seed 000's 0.1 s decision "
            "period, one core, best of 3",
        ),
        Metric(
            "x_realtime_10ms_chunks",
            SECONDS / wall,
            "x",
            note="the same in 100-sample (10 ms) chunks: per-chunk Python overhead is ~1/3 "
            "of the cost there; the issue sets no chunk size, the stricter figure is kept",
        ),
        Metric(
            "x_realtime_with_tool_force",
            SECONDS / wall_tool,
            "x",
            note="0.1 s chunks plus the Eq. 3.51 tool-force block ([Jᵀ·T]⁺ every 10 samples); "
            "the issue sets no target for it",
        ),
        Metric(
            "smoother_delay",
            feed[0].delay_samples / FS_HZ * 1e3,
            "ms",
            target=6.0,
            higher_is_better=False,
            note="output delay of the feed estimators: exactly the 60-sample smoother lag",
        ),
    ]


@benchmark("estimation.feed_axis_harmonic_speed")
def _feed_axis_harmonic_speed() -> list[Metric]:
    """One feed axis with the tooth-harmonic design (Aslan Eq. 3.16–3.20) at 10 kHz.

    The Y axis (the largest model, 27 states) at 1000 rev/min, 2 teeth: six harmonic pairs
    (33–200 Hz), 39 states, the most the 200 Hz limit gives for the V1 speeds; the commanded
    spindle speed is constant, so after the 10 ms hold one cached design runs (the per-speed
    design time is reported separately).
    """
    from millsense.estimation.feed.estimator import SPINDLE_SPEED_CMD, tooth_harmonics
    from millsense.estimation.kalman.smoother import FixedLagSmoother

    base = next(b for b in _feed_blocks() if b.model.axis == "y")
    block = FeedAxisEstimator(base.model, teeth=2)
    n = int(SECONDS * FS_HZ)
    rng = np.random.default_rng(0)
    data = {
        "y/current_cmd": rng.normal(size=n),
        "y/motor_speed": 5.0 + 0.1 * rng.normal(size=n),
        SPINDLE_SPEED_CMD: np.full(n, 1000 * 2 * np.pi / 60),
    }
    _run([block], {k: v[: 10 * CHUNK] for k, v in data.items()}, 10 * CHUNK)  # compile, design
    states = block.harmonic_design.n_states
    wall = min(_run([block], data, n) for _ in range(3))
    wall_1000 = min(_run([block], data, n, 10 * CHUNK) for _ in range(3))
    wall_rw = min(_run([base], data, n, 10 * CHUNK) for _ in range(3))
    t0 = time.perf_counter()
    FixedLagSmoother(base.model.design(harmonics_hz=tooth_harmonics(1000 / 30)), block.lag)
    t_design = time.perf_counter() - t0
    return [
        Metric(
            "x_realtime",
            SECONDS / wall_1000,
            "x",
            target=100.0,
            note=f"Y feed estimator with 6 tooth-harmonic pairs ({states} states, LuGre C3, "
            "Kalman, 60-sample smoother), 10 s at 10 kHz in 1000-sample chunks, one core, "
            "best of 3",
        ),
        Metric(
            "x_realtime_10ms_chunks",
            SECONDS / wall,
            "x",
            target=100.0,
            note="the same in 100-sample (10 ms) chunks",
        ),
        Metric(
            "x_realtime_random_walk",
            SECONDS / wall_rw,
            "x",
            note=f"the same axis on the random-walk design ({base.design.n_states} states), "
            "1000-sample chunks, for comparison",
        ),
        Metric(
            "design_time",
            t_design,
            "s",
            target=0.2,
            higher_is_better=False,
            note="design of one new spindle speed: DARE, smoother gains, modal form (made once "
            "per 0.1 % bin, cached); the block stalls this long on the first chunk at a new "
            "speed",
        ),
    ]


@benchmark("estimation.feed_axis_scheduled_speed")
def _feed_axis_scheduled_speed() -> list[Metric]:
    """One position-scheduled feed axis (issue 7): a bank of N = 3 and N = 5 Y estimators.

    :class:`~millsense.estimation.feed.schedule.ScheduledFeedEstimator`: members are the Y
    model (27 states) with its modes scaled by 0.99…1.01; the commanded position ramps across
    the whole bank in 10 s at 10 kHz, so members start (with their 1 s warm-up replay) and stop
    during the run; one shared C3 stage, at most two or three smoothers running at a time.
    """
    from millsense.estimation.feed.schedule import FeedModelBank, ScheduledFeedEstimator

    base = next(b for b in _feed_blocks() if b.model.axis == "y").model
    n = int(SECONDS * FS_HZ)
    rng = np.random.default_rng(0)
    data = {
        "y/current_cmd": rng.normal(size=n),
        "y/motor_speed": 5.0 + 0.1 * rng.normal(size=n),
        "y/position_cmd": np.linspace(-0.2, 0.2, n),
    }
    out: list[Metric] = []
    for n_bank in (3, 5):
        scales = np.linspace(0.99, 1.01, n_bank)
        models = tuple(
            replace(base, disturbance=base.disturbance.with_modes_scaled(k)) for k in scales
        )
        bank = FeedModelBank(tuple(np.linspace(-0.2, 0.2, n_bank)), models, (0.005,) * n_bank)
        block = ScheduledFeedEstimator(bank)
        _run([block], {k: v[: 10 * CHUNK] for k, v in data.items()}, 10 * CHUNK)  # compile
        wall = min(_run([block], data, n) for _ in range(3))
        wall_1000 = min(_run([block], data, n, 10 * CHUNK) for _ in range(3))
        out += [
            Metric(
                f"x_realtime_n{n_bank}",
                SECONDS / wall_1000,
                "x",
                target=100.0,
                note=f"Y axis, bank of {n_bank} estimators (27 states each, shared LuGre C3, "
                "Kalman, 60-sample smoother; members within their support run, warm-up replay "
                "on start), scheduled on the commanded position ramping across the bank; 10 s "
                "at 10 kHz in 1000-sample chunks, one core, best of 3",
            ),
            Metric(
                f"x_realtime_n{n_bank}_10ms_chunks",
                SECONDS / wall,
                "x",
                note="the same in 100-sample (10 ms) chunks (per-chunk Python overhead of the "
                "schedule and of one smoother call per running member)",
            ),
        ]
    return out


@benchmark("estimation.feed_axis_condition_speed")
def _feed_axis_condition_speed() -> list[Metric]:
    """One feed axis following its operating condition (moving / at rest, issue 7).

    :class:`~millsense.estimation.feed.condition.OperatingConditionFeedEstimator` with two Y
    estimators (27 states each, the at-rest one with its modes 3 % lower) running side by side,
    the commanded position holding for 5 s and moving for 5 s; the at-rest weight from the
    commanded speed over a 5 ms window. The baseline is one Y estimator on the same data.
    """
    from millsense.estimation.feed.condition import OperatingConditionFeedEstimator

    base = next(b for b in _feed_blocks() if b.model.axis == "y").model
    rest = replace(base, disturbance=base.disturbance.with_modes_scaled(0.97), condition="at_rest")
    n = int(SECONDS * FS_HZ)
    rng = np.random.default_rng(0)
    v = np.where(np.arange(n) < n // 2, 0.0, 5.0)
    data = {
        "y/current_cmd": rng.normal(size=n),
        "y/motor_speed": v + 0.1 * rng.normal(size=n),
        "y/position_cmd": np.cumsum(v) / FS_HZ * base.drive.transmission,
    }
    block = OperatingConditionFeedEstimator(
        FeedAxisEstimator(base), FeedAxisEstimator(rest), base.drive.transmission
    )
    single = FeedAxisEstimator(base)
    small = {k: x[: 10 * CHUNK] for k, x in data.items()}
    _run([block], small, 10 * CHUNK)  # compile
    _run([single], small, 10 * CHUNK)
    wall = min(_run([block], data, n, 10 * CHUNK) for _ in range(3))
    wall_single = min(_run([single], data, n, 10 * CHUNK) for _ in range(3))
    return [
        Metric(
            "x_realtime",
            SECONDS / wall,
            "x",
            target=100.0,
            note="Y axis, moving + at-rest estimators blended by the commanded speed; 10 s at "
            "10 kHz in 1000-sample chunks, one core, best of 3",
        ),
        Metric(
            "cost_vs_one_estimator",
            wall / wall_single,
            "ratio",
            higher_is_better=False,
            baseline="one FeedAxisEstimator (Y) on the same data, run side by side",
            note="wall time against one Y estimator on the same data, side by side (two "
            "estimators and the blend: about 2)",
        ),
    ]
