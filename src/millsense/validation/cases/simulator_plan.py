"""Validation cases of the plan-driven virtual machine (issues 4 and 5 joined).

A virtual plan (:func:`millsense.plan.virtual_plan.plan_program`) drives the simulator: its rows
are the path, :class:`~millsense.plan.plan_engagement.PlanEngagement` the engagement, the
plan's metadata the tool and coefficients. The simulated truth channels are compared with the
plan's predictions, and the simulated 333 Hz TCP stream is matched back to the plan
(:meth:`~millsense.plan.virtual_plan.VirtualPlan.match`, seed 000 C15).

Machine: ``quaser-ux600`` reduced to its X, Y, Z drives (the demo part and the slot are
3-axis programs at A = C = 0; the level trunnion table is the 3-axis machine, decision
"Trunnion frames: G-code and drives"), which keeps the 326 s demo part at ≈ 25 s of wall
time; seed 0, no realism layer.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millsense.core.config import MachineConfig, MaterialConfig, ToolConfig
from millsense.core.presets import load_preset
from millsense.core.units import MM
from millsense.plan.gcode import interpret, interpret_file
from millsense.plan.plan_engagement import PlanEngagement, plan_path
from millsense.plan.stock import ZMapStock
from millsense.plan.virtual_plan import (
    VirtualPlan,
    coefficients_from_metadata,
    plan_program,
    tool_from_metadata,
)
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill
from millsense.simulator.machine import Job, MachineSimulator, SimulatorOptions
from millsense.simulator.machine_file import simulator_machine
from millsense.simulator.process_coupling import ProcessCoupling
from millsense.validation import Measured, case

FS = 10000.0
DEMO = Path(__file__).resolve().parents[4] / "examples" / "demo_part"

#: A Ø20 mm slot 2 mm deep at 1000 rev/min, 400 mm/min (0.2 mm/tooth, seed 000 V9 conditions),
#: entering a 60 × 80 mm block from x = −15 mm; steady from x = 0 (front half in material).
SLOT_PROGRAM = (
    "(steady slot for the plan-driven simulator)\n"
    "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-15 Y40 Z5\nG1 Z-2 F400\nX35\nG0 Z5\nM30\n"
)
#: Steady window of the slot, tool-centre x [m].
SLOT_WINDOW = (0.010, 0.030)


def machine_3axis() -> MachineConfig:
    """``quaser-ux600`` with its X, Y, Z drives only (3-axis kinematics)."""
    m = simulator_machine("quaser-ux600")
    return m.with_axes("xyz", "3-axis")


@dataclass
class PlanRun:
    """A plan, the simulated channels (selected) and the 333 Hz stream rows."""

    plan: VirtualPlan
    source: PlanEngagement
    data: dict[str, np.ndarray]
    stream: dict[str, np.ndarray]


def simulate_plan(
    plan: VirtualPlan,
    machine: MachineConfig,
    channels: tuple[str, ...] | None = None,
    seed: int = 0,
) -> PlanRun:
    """Run the virtual machine on a plan (tool and coefficients from its metadata)."""
    pp = plan_path(plan, five_axis=machine.kinematics == "5-axis-trunnion-ac")
    job = Job(pp.path, pp.feed_m_s, pp.spindle_rad_s, pp.nc_line, pp.rapid)
    src = PlanEngagement(plan)
    proc = ProcessCoupling(
        tool_from_metadata(plan.metadata),
        coefficients_from_metadata(plan.metadata),
        src,
        n_discs=int(plan.metadata.get("n_discs", 10)),
        sample_rate_hz=machine.sample_rate_hz,
    )
    sim = MachineSimulator(machine, job, proc, SimulatorOptions(seed=seed))
    parts: dict[str, list[np.ndarray]] = {}
    rows: dict[str, list[np.ndarray]] = {}
    while (c := sim.read(10000)) is not None:
        for k, v in c.data.items():
            if channels is None or k in channels:
                parts.setdefault(k, []).append(v)
        for k, v in sim.take_stream_rows().items():
            rows.setdefault(k, []).append(v)
    return PlanRun(
        plan,
        src,
        {k: np.concatenate(v) for k, v in parts.items()},
        {k: np.concatenate(v) for k, v in rows.items()},
    )


def _tool_coeffs() -> tuple[EndMill, CuttingCoefficients]:
    tool = EndMill.from_config(load_preset(ToolConfig, str(DEMO / "tool.toml")))
    coeffs = CuttingCoefficients.from_config(
        load_preset(MaterialConfig, str(DEMO / "material.toml"))
    )
    return tool, coeffs


@functools.lru_cache(maxsize=1)
def slot_run() -> PlanRun:
    """The steady slot: plan on a 0.1 mm z-map, then the plan-driven simulation (≈ 9 s)."""
    tool, coeffs = _tool_coeffs()
    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.06, 0.08, 0.0], 0.1 * MM)
    plan = plan_program(interpret(SLOT_PROGRAM, source="slot.nc"), stock, tool, coeffs)
    return simulate_plan(plan, machine_3axis())


@functools.lru_cache(maxsize=1)
def demo_run() -> PlanRun:
    """The demo part (``examples/demo_part``): 6 293 rows, 326 s of machining."""
    tool, coeffs = _tool_coeffs()
    stock = ZMapStock.from_box([0.0, 0.0, -0.03], [0.1, 0.08, 0.0], 0.1 * MM)
    plan = plan_program(interpret_file(DEMO / "program.nc"), stock, tool, coeffs)
    keep = (
        "truth/spindle/torque",
        "truth/spindle/speed",
        "truth/process/engagement",
    )
    return simulate_plan(plan, machine_3axis(), keep)


def tooth_period_means(
    signal: np.ndarray, spindle_speed_rad_s: np.ndarray, n_flutes: int, fs_hz: float = FS
) -> tuple[np.ndarray, np.ndarray]:
    """Means over complete tooth periods (integrated true spindle angle) and their centre
    times [s] (the tooth-period average of seed 000 §6, the breakage monitor's quantity)."""
    angle = np.cumsum(spindle_speed_rad_s) / fs_hz
    # the truth spindle's rotor ripple turns a standing tool back by ~1e-8 rad (decision
    # 1210): a negative angle before the start belongs to the first period
    period = np.maximum(np.floor(angle / (2 * math.pi / n_flutes)).astype(np.int64), 0)
    n_p = int(period.max()) + 1
    cnt = np.bincount(period, minlength=n_p)
    mean = np.bincount(period, weights=signal, minlength=n_p) / np.maximum(cnt, 1)
    t_sum = np.bincount(period, weights=np.arange(signal.size) / fs_hz, minlength=n_p)
    tc = t_sum / np.maximum(cnt, 1)
    ok = cnt > 0
    ok[0] = ok[-1] = False
    return mean[ok], tc[ok]


def _slot_window(run: PlanRun) -> tuple[np.ndarray, np.ndarray]:
    """Sample mask of the steady window (whole tooth periods) and plan-row mask."""
    d = run.data
    x = d["truth/x/position"]
    lo, hi = SLOT_WINDOW
    inside = (x >= lo) & (x < hi)
    # whole tooth periods only: trim to the first and last tooth-period boundary inside
    n_fl = int(run.plan.metadata["tool"]["flutes"])
    per = np.floor(np.cumsum(d["truth/spindle/speed"]) / FS / (2 * math.pi / n_fl))
    idx = np.nonzero(inside)[0]
    first = idx[0] + int(np.argmax(per[idx] > per[idx[0]]))
    last = idx[-1] - int(np.argmax(per[idx][::-1] < per[idx[-1]]))
    win = np.zeros(x.size, dtype=bool)
    win[first : last + 1] = True
    px = run.plan["x_mm"] * MM
    rows = (px >= lo) & (px < hi) & run.plan["in_cut"].astype(bool)
    return win, rows


@case(
    "simulator.plan_slot_average_force",
    source="issue 4/5 joint acceptance: plan prediction (benchmarks.md §3 closed form, 1 %)",
    reference=0.0,
    unit="relative error",
    abs_tol=0.02,
    quick=True,
    description="Plan-driven simulation of a steady Ø20 mm slot, 2 mm, 0.2 mm/tooth on "
    "quaser-ux600 (X/Y/Z): largest relative difference of the truth mean F_x, F_y, mean XY "
    "resultant and mean torque from the plan's fx_avg, fy_avg, fres_avg, torque_avg",
    self_check=True,
)
def _slot_average() -> Measured:
    run = slot_run()
    win, rows = _slot_window(run)
    d, p = run.data, run.plan
    fx = float(d["truth/tool/force_x"][win].mean())
    fy = float(d["truth/tool/force_y"][win].mean())
    tq = float(d["truth/spindle/torque"][win].mean())
    sim = {"F_x": fx, "F_y": fy, "F_res(mean)": math.hypot(fx, fy), "torque": tq}
    ref = {
        "F_x": float(p["fx_avg_n"][rows].mean()),
        "F_y": float(p["fy_avg_n"][rows].mean()),
        "F_res(mean)": float(p["fres_avg_n"][rows].mean()),
        "torque": float(p["torque_avg_nm"][rows].mean()),
    }
    err = {k: sim[k] / ref[k] - 1.0 for k in sim}
    worst = max(err.values(), key=abs)
    lines = ", ".join(f"{k} {sim[k]:.3f} vs {ref[k]:.3f} ({err[k]:+.2%})" for k in sim)
    return Measured(
        abs(worst), f"simulated vs plan (N, N·m) over {int(win.sum())} samples: {lines}"
    )


@case(
    "simulator.plan_slot_peak_resultant",
    source="issue 4/5 joint acceptance (plan peak XY resultant, Aslan Eq. 5.33)",
    reference=0.0,
    unit="relative error",
    abs_tol=0.05,
    quick=True,
    description="Plan-driven steady slot: median over tooth periods of the peak truth XY "
    "resultant against the plan's fres_peak",
    self_check=True,
)
def _slot_peak() -> Measured:
    run = slot_run()
    win, rows = _slot_window(run)
    d = run.data
    fres = np.hypot(d["truth/tool/force_x"], d["truth/tool/force_y"])[win]
    n_fl = int(run.plan.metadata["tool"]["flutes"])
    per = np.floor(np.cumsum(d["truth/spindle/speed"]) / FS / (2 * math.pi / n_fl))[win]
    per = (per - per[0]).astype(np.int64)
    peaks = np.full(int(per.max()) + 1, -np.inf)
    np.maximum.at(peaks, per, fres)
    sim = float(np.median(peaks))
    ref = float(run.plan["fres_peak_n"][rows].mean())
    return Measured(
        abs(sim / ref - 1.0),
        f"median tooth-period peak {sim:.2f} N (range {peaks.min():.2f}–{peaks.max():.2f} N over "
        f"{peaks.size} periods), plan {ref:.2f} N",
    )


def _carried_rows(rows: np.ndarray) -> np.ndarray:
    """The last match carried forward (−1 before the first)."""
    pos = np.where(rows >= 0, np.arange(rows.size), -1)
    np.maximum.accumulate(pos, out=pos)
    return np.where(pos >= 0, rows[np.maximum(pos, 0)], -1)


def torque_comparison(run: PlanRun, max_lag_s: float = 0.3) -> dict[str, float]:
    """Truth tooth-period mean torque vs the plan's ``torque_avg_nm`` along the path.

    Each 333 Hz stream sample is matched to a plan row (``VirtualPlan.match``, last match
    carried through unmatched samples); the simulated tooth-period means are interpolated at
    the stream times. Compared where the matched row is a feed row in cut and the simulated
    tool is in material. Lag: the shift of the simulated series (3 ms grid, ±``max_lag_s``)
    that minimises the RMS difference; positive = the simulation runs behind the plan.
    """
    d, p, st = run.data, run.plan, run.stream
    n_fl = int(p.metadata["tool"]["flutes"])
    mean, tc = tooth_period_means(d["truth/spindle/torque"], d["truth/spindle/speed"], n_fl, FS)
    ts = st["time_s"]
    tcp = np.column_stack([st["tcp_x"], st["tcp_y"], st["tcp_z"]])
    rows = _carried_rows(p.match(tcp))
    ok = rows >= 0
    r = np.maximum(rows, 0)
    eng = d["truth/process/engagement"]
    in_mat = eng[np.minimum(np.round(ts * FS).astype(np.int64), eng.size - 1)] >= 0
    sel = ok & p["in_cut"][r].astype(bool) & ~p["rapid"][r].astype(bool) & in_mat
    plan_t = p["torque_avg_nm"][r][sel]
    sim_t = np.interp(ts[sel], tc, mean)
    err = sim_t - plan_t
    lags = np.arange(-round(max_lag_s / 3e-3), round(max_lag_s / 3e-3) + 1) * 3e-3
    rms_lag = [
        float(np.sqrt(np.mean((np.interp(ts[sel] + lag, tc, mean) - plan_t) ** 2))) for lag in lags
    ]
    best = int(np.argmin(rms_lag))
    return {
        "rms_nm": float(np.sqrt(np.mean(err**2))),
        "mean_nm": float(err.mean()),
        "p99_abs_nm": float(np.percentile(np.abs(err), 99)),
        "max_abs_nm": float(np.abs(err).max()),
        "plan_mean_nm": float(plan_t.mean()),
        "n": float(sel.sum()),
        "lag_s": float(lags[best]),
        "rms_at_lag_nm": rms_lag[best],
    }


@case(
    "simulator.plan_demo_torque_rms",
    source="issue 4/5 joint acceptance; seed 000 §6 (expected tooth-period mean torque)",
    reference=0.0,
    unit="N·m",
    abs_tol=0.05,
    quick=False,
    description="Demo part on the plan-driven virtual machine: RMS difference between the "
    "truth tooth-period mean torque and the plan's torque_avg_nm along the matched path "
    "(in cut); tolerance 0.05 N·m = 5 % of the mean in-cut torque, about twice the measured "
    "0.027 N·m, which comes from the transients at engagement changes",
    self_check=True,
)
def _demo_torque() -> Measured:
    c = torque_comparison(demo_run())
    return Measured(
        c["rms_nm"],
        f"{int(c['n'])} stream samples in cut; plan mean torque {c['plan_mean_nm']:.3f} N·m; "
        f"difference mean {c['mean_nm']:+.4f}, RMS {c['rms_nm']:.4f}, 99th percentile "
        f"{c['p99_abs_nm']:.3f}, max {c['max_abs_nm']:.3f} N·m (at engagement changes within "
        f"a tooth period); best lag {c['lag_s'] * 1e3:+.0f} ms (RMS there "
        f"{c['rms_at_lag_nm']:.4f} N·m)",
    )


@case(
    "simulator.plan_demo_torque_lag",
    source="issue 4/5 joint acceptance; decision 'Simulator process coupling' (one block lag)",
    reference=0.0,
    unit="ms",
    abs_tol=6.0,
    quick=False,
    description="Demo part: the time shift of the simulated tooth-period torque that best "
    "fits the plan's torque_avg_nm along the matched path (3 ms grid); tolerance two "
    "interpolation periods",
    self_check=True,
)
def _demo_lag() -> Measured:
    c = torque_comparison(demo_run())
    return Measured(
        c["lag_s"] * 1e3,
        f"RMS {c['rms_nm']:.4f} N·m at 0 ms, {c['rms_at_lag_nm']:.4f} N·m at the best lag",
    )


def match_statistics(run: PlanRun) -> dict[str, float]:
    """Fraction of in-material 333 Hz TCP samples matched monotonically within ±10 µm.

    A sample counts when ``VirtualPlan.match`` (from row 0, whole stream, tolerance ±10 µm
    per axis, seed 000 C15) returns a row that is not behind an earlier match.
    """
    d, p, st = run.data, run.plan, run.stream
    ts = st["time_s"]
    tcp = np.column_stack([st["tcp_x"], st["tcp_y"], st["tcp_z"]])
    rows = p.match(tcp)
    eng = d["truth/process/engagement"]
    in_mat = eng[np.minimum(np.round(ts * FS).astype(np.int64), eng.size - 1)] >= 0
    running = np.maximum.accumulate(np.where(rows >= 0, rows, -1))
    prev_max = np.concatenate([[-1], running[:-1]])
    good = (rows >= 0) & (rows >= prev_max)
    matched = rows[rows >= 0]
    return {
        "fraction": float(good[in_mat].mean()),
        "n_in_material": float(in_mat.sum()),
        "unmatched_in_material": float(((rows < 0) & in_mat).sum()),
        "monotonic": float(bool(np.all(np.diff(matched) >= 0))),
        "last_row": float(matched[-1]) if matched.size else -1.0,
        "n_rows": float(len(p)),
    }


@case(
    "simulator.plan_demo_match_fraction",
    source="seed 000 C15 (±10 µm per axis synchronisation); issue 4/5 joint acceptance",
    reference=1.0,
    unit="fraction",
    abs_tol=0.01,
    quick=False,
    description="Demo part: fraction of the simulated 333 Hz TCP samples in material that "
    "VirtualPlan.match finds (monotonically, within ±10 µm per axis) — ≥ 99 %",
    gap=(
        "on the truth plant (default since decision 1062) the encoders' TCP leaves the "
        "programmed path by more than ±10 µm (servo lag and compliance of the coupled drives) "
        "on about a fifth of the in-material samples (0.78 measured on 2026-11-25); the "
        "on-line session synchronises on the CNC's commanded position instead "
        "(online.plan_sync, decision 1622)"
    ),
    issue=12,
    self_check=True,
)
def _demo_match() -> Measured:
    m = match_statistics(demo_run())
    return Measured(
        m["fraction"],
        f"{int(m['n_in_material'])} samples in material, {int(m['unmatched_in_material'])} "
        f"unmatched; matched rows monotonic: {bool(m['monotonic'])}; last matched row "
        f"{int(m['last_row'])} of {int(m['n_rows'])}",
    )
