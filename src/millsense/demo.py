"""The end-to-end demo: simulate a slot cut, estimate the force from the current, report.

``millsense demo`` runs :func:`run_demo`:

1. a live source (:class:`~millsense.simulator.slot_cut.SlotCutSource`) simulates the X drive of
   the ``quaser-ux600`` preset cutting a slot in Al7050 with the Ø20 mm 2-flute end mill of
   Aslan V1 (3000 rev/min, 0.2 mm/tooth; air, 2 mm, 4 mm, air);
2. commissioning: simulated constant-velocity air moves identify the drive friction (the
   estimator never receives the simulator's friction parameters);
3. the streaming engine runs the rigid-body force estimator on the CNC channels only
   (current command and motor speed), chunk by chunk, as it would on a live machine;
4. every chunk, with the estimate, goes to a crash-safe recording while running;
5. the recording is read back from disk and the error of the estimate against the ground truth
   is computed from it; a PNG compares estimate and truth; a summary (JSON) gives the figures.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from millsense import __version__
from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.core.recording import Recording
from millsense.estimation.feed.rigid_body import DriveModel, RigidBodyForceEstimator
from millsense.ident.friction import coulomb_viscous_from_moves
from millsense.io.recording_file import RecordingWriter, read_recording
from millsense.io.safe_output import write_text
from millsense.simulator.rigid_drive import RigidDriveParams, constant_velocity_move
from millsense.simulator.slot_cut import DepthSegment, SlotCutSource
from millsense.streaming.block import Chunk, Event
from millsense.streaming.engine import Pipeline, run

SPINDLE_RPM = 3000.0  #: Aslan V1 speed set includes 3000 rev/min (tooth frequency 100 Hz)
FEED_PER_TOOTH_MM = 0.2  #: Aslan V1
DURATION_S = 2.0
SCHEDULE = (
    DepthSegment(0.0, 0.0),
    DepthSegment(0.4, 2e-3),
    DepthSegment(1.1, 4e-3),
    DepthSegment(1.7, 0.0),
)
ESTIMATOR_CUTOFF_HZ = 300.0
CHUNK_SAMPLES = 1000  #: 0.1 s, the CNC oscilloscope block of a live link


@dataclass(frozen=True)
class SegmentError:
    """Mean force over a steady segment: truth, estimate and their difference."""

    depth_mm: float
    start_s: float
    end_s: float
    truth_mean_n: float
    estimate_mean_n: float
    error_percent: float


@dataclass(frozen=True)
class DemoSummary:
    """Figures of the demo, all computed from the recording read back from disk."""

    recording: str
    plot: str
    duration_s: float
    samples: int
    segments: list[SegmentError]
    rms_error_lowpassed_n: float
    rms_truth_lowpassed_n: float
    rms_error_raw_n: float
    peak_truth_n: float
    estimator_cutoff_hz: float

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def default_configs() -> tuple[MachineConfig, ToolConfig, MaterialConfig]:
    """The embedded default: the simulator's Quaser UX600, Ø20 mm 2-flute end mill, Al7050."""
    from millsense.simulator.machine_file import simulator_machine

    return (
        simulator_machine("quaser-ux600"),
        load_preset(ToolConfig, "aslan-d20-2flute"),
        load_preset(MaterialConfig, "al7050"),
    )


COMMISSIONING_SPEEDS_RAD_S = (-16.0, -12.0, -8.0, -4.0, 4.0, 8.0, 12.0, 16.0)


#: Known table force of the force-gain calibration (a calibrated weight or spring balance), N.
CALIBRATION_FORCE_N = 200.0


def commissioned_drive_model(
    machine: MachineConfig, axis: str, seed: int = 100, nameplate: MachineConfig | None = None
) -> DriveModel:
    """The drive model the estimator uses, identified on the simulated machine.

    ``machine`` is the simulated machine (only driven); J_e, r_g and η are the nameplate's
    (``nameplate``, default the ``quaser-ux600`` preset: catalogue values with their errors,
    docs/decisions/0991-nameplate-machine-files.md). Nothing else is handed over from the
    simulator:

    - the force gain K_t·η/r_g, which a catalogue K_t (±5 %) and η get wrong by several per
      cent, is calibrated with a known table force (:data:`CALIBRATION_FORCE_N`, e.g. a
      calibrated weight) at ±8 rad/s against the same moves in air; the product is what the
      rigid-body estimate needs, so the error is put into K_t with the nameplate η and r_g
      (decision 0994);
    - Coulomb + viscous friction is fitted per direction from the mean torque of
      constant-velocity air moves at ±4…16 rad/s over the steady second half of each move
      (:func:`millsense.ident.friction.coulomb_viscous_from_moves`).
    """
    a = (nameplate or load_preset(MachineConfig, "quaser-ux600")).axis(axis)
    params = RigidDriveParams.from_config(machine.axis(axis))
    fs = machine.sample_rate_hz

    def mean_current(w: float, k: int, force_n: float) -> tuple[float, float]:
        move = constant_velocity_move(params, w, 0.6, fs, seed=seed + k, table_force_n=force_n)
        steady = slice(len(move["speed"]) // 2, None)
        return float(np.mean(move["speed"][steady])), float(np.mean(move["current_cmd"][steady]))

    # force gain: F = −η K_t Δi / r_g for the known force (the estimator's sign convention)
    gains = []
    for k, w in enumerate((-8.0, 8.0)):
        d_i = mean_current(w, 50 + k, CALIBRATION_FORCE_N)[1] - mean_current(w, 60 + k, 0.0)[1]
        gains.append(-CALIBRATION_FORCE_N / d_i)
    torque_constant = float(np.mean(gains)) * a.transmission_m_rad / a.efficiency
    speeds, torques = [], []
    for k, w in enumerate(COMMISSIONING_SPEEDS_RAD_S):
        speed, current = mean_current(w, k, 0.0)
        speeds.append(speed)
        torques.append(torque_constant * current)
    friction = coulomb_viscous_from_moves(np.array(speeds), np.array(torques))
    return DriveModel(
        inertia=a.inertia_kg_m2,
        torque_constant=torque_constant,
        transmission=a.transmission_m_rad,
        efficiency=a.efficiency,
        friction=friction,
    )


def build_source(seed: int = 0) -> SlotCutSource:
    machine, tool, material = default_configs()
    return SlotCutSource(
        machine.axis("x"),
        tool,
        material,
        spindle_rpm=SPINDLE_RPM,
        feed_per_tooth_m=FEED_PER_TOOTH_MM * 1e-3,
        duration_s=DURATION_S,
        depth_schedule=SCHEDULE,
        sample_rate_hz=machine.sample_rate_hz,
        seed=seed,
    )


def build_pipeline() -> Pipeline:
    machine, _, _ = default_configs()
    est = RigidBodyForceEstimator("x", commissioned_drive_model(machine, "x"), ESTIMATOR_CUTOFF_HZ)
    return Pipeline([est])


@dataclass(frozen=True)
class ForceErrors:
    """Errors of the estimate in the cut (N); ``truth_causal`` is the truth through the
    estimator's own causal low-pass, the fair reference for a band-limited estimate."""

    segments: list[SegmentError]
    rms_error_lowpassed_n: float
    rms_truth_lowpassed_n: float
    rms_error_raw_n: float
    peak_truth_n: float
    truth_causal: np.ndarray


def evaluate(rec: Recording, cutoff_hz: float = ESTIMATOR_CUTOFF_HZ) -> ForceErrors:
    """Errors of ``x/force_est`` against ``truth/x/force`` (this reads truth: evaluation only).

    Segment means skip the first 0.1 s after every depth change (drive transient and filter
    settling) and average over whole spindle revolutions.
    """
    fs = rec.sample_rate_hz
    t = rec.time_s
    est = rec.channel("x/force_est")
    truth = rec.channel("truth/x/force")
    depth = rec.channel("truth/x/depth")
    rev_s = 60.0 / SPINDLE_RPM
    segments: list[SegmentError] = []
    bounds = [s.start_s for s in SCHEDULE] + [rec.duration_s + rec.t0_s]
    for seg, end in zip(SCHEDULE, bounds[1:], strict=True):
        if seg.depth_m <= 0:
            continue
        start = seg.start_s + 0.1
        n_rev = math.floor((end - start) / rev_s)
        stop = start + n_rev * rev_s
        sel = (t >= start) & (t < stop)
        tm, em = float(truth[sel].mean()), float(est[sel].mean())
        segments.append(
            SegmentError(
                depth_mm=seg.depth_m * 1e3,
                start_s=start,
                end_s=stop,
                truth_mean_n=tm,
                estimate_mean_n=em,
                error_percent=100.0 * (em - tm) / abs(tm),
            )
        )
    sos = signal.butter(2, cutoff_hz, fs=fs, output="sos")
    truth_lp = signal.sosfiltfilt(sos, truth)
    # the estimate's own filter is causal: compare with the causally filtered truth
    truth_causal = signal.sosfilt(sos, truth, zi=signal.sosfilt_zi(sos) * truth[0])[0]
    incut = depth > 0
    return ForceErrors(
        segments=segments,
        rms_error_lowpassed_n=float(np.sqrt(np.mean((est - truth_causal)[incut] ** 2))),
        rms_truth_lowpassed_n=float(np.sqrt(np.mean(truth_lp[incut] ** 2))),
        rms_error_raw_n=float(np.sqrt(np.mean((est - truth)[incut] ** 2))),
        peak_truth_n=float(np.max(np.abs(truth))),
        truth_causal=truth_causal,
    )


def run_demo(
    out_dir: str | Path,
    *,
    on_progress: Callable[[int, int], None] | None = None,
    seed: int = 0,
) -> DemoSummary:
    """Run the demo; writes ``demo.h5``, ``demo_force.png`` and ``summary.json`` in out_dir."""
    from millsense.report.plots import plot_estimate_vs_truth

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec_path = out / "demo.h5"
    source = build_source(seed)
    pipeline = build_pipeline()
    channels = source.channel_info + pipeline.output_channels()
    machine, tool, material = default_configs()
    metadata = {
        "machine": machine.name,
        "tool": tool.name,
        "material": material.name,
        "program": (
            f"slot on X, {SPINDLE_RPM:g} rev/min, {FEED_PER_TOOTH_MM:g} mm/tooth, "
            "depth 0 / 2 / 4 / 0 mm"
        ),
        "units": "SI",
        "software_version": __version__,
        "source": "millsense demo (simulated)",
        "seed": seed,
    }
    writer = RecordingWriter(
        rec_path, source.sample_rate_hz, channels, metadata=metadata, flush_every_s=0.5
    )
    total = source.n_total

    def sink(chunk: Chunk, outputs: dict[str, np.ndarray], events: list[Event]) -> None:
        writer.append({**chunk.data, **outputs})

    with writer:
        run(
            source,
            pipeline,
            CHUNK_SAMPLES,
            sink=sink,
            on_progress=(lambda n: on_progress(n, total)) if on_progress else None,
        )
    rec = read_recording(rec_path)
    figures = evaluate(rec)
    plot_path = out / "demo_force.png"
    plot_estimate_vs_truth(
        rec.time_s,
        rec.channel("truth/x/force"),
        rec.channel("x/force_est"),
        plot_path,
        truth_filtered=figures.truth_causal,
        title=(
            f"X-axis cutting force from the current command (rigid-body inverse dynamics, "
            f"{ESTIMATOR_CUTOFF_HZ:g} Hz low-pass)"
        ),
        zoom_s=(1.40, 1.46),
    )
    summary = DemoSummary(
        recording=str(rec_path),
        plot=str(plot_path),
        duration_s=rec.duration_s,
        samples=rec.n_samples,
        segments=figures.segments,
        rms_error_lowpassed_n=figures.rms_error_lowpassed_n,
        rms_truth_lowpassed_n=figures.rms_truth_lowpassed_n,
        rms_error_raw_n=figures.rms_error_raw_n,
        peak_truth_n=figures.peak_truth_n,
        estimator_cutoff_hz=ESTIMATOR_CUTOFF_HZ,
    )
    write_text(out / "summary.json", json.dumps(summary.as_dict(), indent=2) + "\n")
    return summary
