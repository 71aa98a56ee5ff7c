"""G-code programs on the 5-axis preset (decision "Trunnion frames: G-code and drives")."""

from __future__ import annotations

import numpy as np

from millsense.core.config import MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.models.kinematics import TrunnionACMachine
from millsense.plan.gcode import interpret
from millsense.plan.path import Toolpath, sample_path
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import EngagementSchedule, ProcessCoupling

FS = 10000.0


def _run(
    program: str, depth_m: float, start_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> tuple[MachineSimulator, dict[str, np.ndarray], Job]:
    assert simulator_machine("quaser-ux600").kinematics == "5-axis-trunnion-ac"
    return _run_tp(interpret(program, initial_position_mm=start_mm), depth_m)


def _run_tp(tp: Toolpath, depth_m: float) -> tuple[MachineSimulator, dict[str, np.ndarray], Job]:
    m = simulator_machine("quaser-ux600")
    job = Job.from_sampled_path(sample_path(tp), five_axis=True)
    tool = EndMill.from_config(load_preset(ToolConfig, "aslan-d20-2flute"))
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, "al7050"))
    assert job.rapid is not None
    sched = EngagementSchedule.along_cutting_moves(
        EngagementSchedule.from_spec("slot", tool.diameter_m, depth_m).table[0],
        depth_m,
        job.arc_length(),
        job.rapid,
    )
    proc = ProcessCoupling(tool, coeffs, sched)
    sim = MachineSimulator(m, job, proc, SimulatorOptions(seed=4, spindle_accel_rad_s2=20000.0))
    parts: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(2000)) is not None:
        for k, v in c.data.items():
            parts.setdefault(k, []).append(v)
    return sim, {k: np.concatenate(v) for k, v in parts.items()}, job


def test_three_axis_slot_along_y_moves_the_y_drive() -> None:
    # a plain XY-plane program, no A/C words: 6 mm slot along +Y at 1200 mm/min, 6000 rev/min
    prog = "G21 G90 G17\nS6000 M3\nG1 X0 Y0 Z0 F1200\nG1 Y6\nM30\n"
    _, d, _ = _run(prog, 2e-3)
    y = d["truth/y/position"]
    # the Y drive travels the programmed 6 mm (servo error at rest < 1 µm)
    assert abs((y[-1] - y[0]) - 6e-3) < 1e-6
    # X and Z hold (cutting-force deflection of the servo only: measured ≈ 1 µm), the rotary
    # axes stay level (< 0.1 mrad)
    for ax in ("x", "z"):
        assert np.ptp(d[f"truth/{ax}/position"]) < 10e-6, ax
    for ax in ("a", "c"):
        assert np.max(np.abs(d[f"truth/{ax}/position"])) < 1e-4, ax
    # the tool cuts sideways: the chip load is the programmed 0.1 mm/tooth (20 mm/s, 2 flutes,
    # 100 rev/s) in the steady part, not the zero of a plunge along the tool axis
    c = d["truth/process/feed_per_tooth"]
    steady = d["cnc/feed"] > 0.999 * 0.02
    assert steady.sum() > 1000
    assert abs(np.median(c[steady]) - 0.1e-3) < 0.002e-3
    # the slot force lies in the XY plane; the feed-direction force loads the Y drive
    assert np.median(np.abs(d["truth/y/load"][steady])) > 50.0
    assert np.median(np.abs(d["truth/z/load"][steady])) < 0.5 * np.median(
        np.abs(d["truth/y/load"][steady])
    )


def test_five_axis_program_goes_through_the_trunnion() -> None:
    # A/C words: the rotary drives turn and the linear drives follow the inverse kinematics,
    # so the forward kinematics of the axes is the programmed tool tip
    prog = "G21 G90 G17\nS6000 M3\nG1 X4 Y2 Z5 A-15 C30 F1200\nM30\n"
    sim, d, job = _run(prog, 2e-3, start_mm=(0.0, 0.0, 5.0))
    kin = sim.kin
    assert isinstance(kin, TrunnionACMachine)
    q_cmd = np.column_stack([d[f"{ax}/position_cmd"] for ax in ("x", "y", "z", "a", "c")])
    # the rotary drives are commanded to the programmed words (no re-solved branch)
    np.testing.assert_allclose(q_cmd[-1, 3:], np.radians([-15.0, 30.0]), atol=1e-15)
    # the commanded axes put the tip on the programmed line (0, 0, 5) → (4, 2, 5) mm at every
    # sample while the table turns: exact inverse for the given angles, round-off only
    tip = kin.forward(q_cmd)
    np.testing.assert_allclose(tip[:, 2], 5e-3, atol=1e-12)
    np.testing.assert_allclose(tip[:, 1], 0.5 * tip[:, 0], atol=1e-12)
    np.testing.assert_allclose(tip[-1], job.path[-1, :3], atol=1e-12)
    # the linear drives differ from the tip because the table turned (by millimetres)
    assert np.max(np.abs(q_cmd[-1, :3] - job.path[-1, :3])) > 1e-3
    # the actual axes follow: their forward kinematics stays within the servo error of the
    # line (A and C overshoot ≈ 20 mrad on the preset's rotary drives at the end of the move;
    # the lever arm to the tip is ≈ 0.1 m, so ≤ 3 mm)
    q_act = np.column_stack([d[f"truth/{ax}/position"] for ax in ("x", "y", "z", "a", "c")])
    dev = np.linalg.norm(kin.forward(q_act) - tip, axis=1)
    assert np.max(dev) < 3e-3


def test_tilted_cut_loads_are_virtual_work_of_the_tool_force() -> None:
    # a slot along +X with the table at A = 20°, C = 30° (rotary axes stationary): the drive
    # loads are −Jᵀ·T·F of the tool force (Aslan Eq. 3.49 in the drive frames)
    # the rotary-only G0 holds no path sample: the sampled path starts tilted
    sim, d, job = _run("G21 G90 G17\nS6000 M3\nG0 A20 C30\nG1 X6 F1200\nM30\n", 2e-3)
    np.testing.assert_allclose(job.path[:, 3:], np.radians([[20.0, 30.0]] * len(job.path)))
    kin = sim.kin
    assert isinstance(kin, TrunnionACMachine)
    cut = np.abs(d["truth/tool/force_x"]) + np.abs(d["truth/tool/force_y"]) > 10.0
    assert cut.sum() > 1000
    q = np.column_stack([d[f"truth/{ax}/position"] for ax in ("x", "y", "z", "a", "c")])[cut]
    f = np.column_stack([d[f"truth/tool/force_{c}"] for c in "xyz"])[cut]
    loads = np.column_stack([d[f"truth/{ax}/load"] for ax in ("x", "y", "z", "a", "c")])[cut]
    expect = -kin.drive_loads(q, f)
    # the simulator maps with the estimated axes (reference − last tracking error): their
    # difference to the true axes (µm, µrad) changes the loads by < 0.1 % of the force scale
    scale = np.max(np.abs(f))
    np.testing.assert_allclose(loads[:, :3], expect[:, :3], atol=1e-3 * scale)
    np.testing.assert_allclose(loads[:, 3:], expect[:, 3:], atol=1e-3 * scale * 0.3)
    # the tool frame is the drive frame (spindle along Z); in the workpiece frame the tilted
    # tool gives the slot force a z part (sin 20° of the force across the tool, ≈ 0.34)
    f_w = np.einsum("nij,nj->ni", kin.rotation(q[:, 3], q[:, 4]), f)
    assert np.median(np.abs(f_w[:, 2])) > 0.1 * np.median(np.linalg.norm(f, axis=1))


def test_rotary_positioning_before_a_cut_does_not_cut() -> None:
    # G0 A30 C45 turns the table while the tip stays put: the interpolator's path parameter
    # advances by the rotation (0.94 rad) but the tip's arc length does not, and the engagement
    # schedule is laid out on the tip's arc length (decision "Path parameter and tip arc
    # length"). Before the fix the 0.94 "m" of rotation put the tool 'in the cut' from the
    # first rapid on (±5 kN on the drives while positioning).
    prog = "G21 G90 G17\nS6000 M3\nG0 A30 C45\nG0 X-5 Y0 Z0\nG1 X8 F1200\nM30\n"
    _, d, _ = _run(prog, 2e-3)
    line = d["cnc/nc_line"]
    eng = d["truth/process/engagement"]
    rapid = line < 5  # the G0 lines (3 and 4) and before
    assert rapid.sum() > 1000 and (~rapid).sum() > 1000
    # no cutting while positioning: air on every rapid sample, zero load on every drive
    assert np.all(eng[rapid] < 0)
    for ax in "xyzac":
        assert np.max(np.abs(d[f"truth/{ax}/load"][rapid])) == 0.0, ax
    # the slot begins once the feed move reaches the stock (the whole G1 cuts here): within
    # the first 0.1 s of line 5, and then the force is the slot's (hundreds of N)
    first = int(np.argmax(line == 5))
    cut = np.flatnonzero(eng >= 0)
    assert first <= cut[0] < first + 1000
    assert np.median(np.abs(d["truth/tool/force_x"][cut[0] + 2000 :])) > 50.0


def test_tip_arc_length_does_not_advance_over_rotary_positioning() -> None:
    # path: 10 mm along X, then A 0 → 0.5 rad in place, then 5 mm along Y (closed form)
    from millsense.simulator.interpolator import Interpolator

    path = np.array(
        [[0, 0, 0, 0, 0], [0.01, 0, 0, 0, 0], [0.01, 0, 0, 0.5, 0], [0.01, 0.005, 0, 0.5, 0]],
        dtype=float,
    )
    ip = Interpolator(path, np.full(3, 0.02), 2.0)
    s = np.array([0.0, 0.005, 0.01, 0.26, 0.51, 0.5125, 0.515])
    np.testing.assert_allclose(
        ip.tip_arc_length(s), [0.0, 0.005, 0.01, 0.01, 0.01, 0.0125, 0.015], atol=1e-15
    )
