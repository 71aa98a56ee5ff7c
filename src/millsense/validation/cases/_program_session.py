"""A part program through the on-line session as ``millsense run`` builds it (its library
calls, without the command line, which validation may not import): the session's plan on a
0.2 mm z-map, the virtual machine cutting its own plan of the same program (decision 1740),
the shipped commissioned machine file and the default session options."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

EXAMPLE = Path(__file__).resolve().parents[4] / "examples"
MACHINE = "quaser-ux600"
STOCK = EXAMPLE / "demo_part/stock.toml"


@dataclass
class ProgramSession:
    result: Any  # online.session.SessionResult
    plan: Any  # plan.virtual_plan.VirtualPlan


def _program_machine(
    program: Path, tool: Any, material: str, stock: Path, events: Sequence[Any], seed: int,
    duration_s: float | None, home_mm: tuple[float, float, float] | None = None,
) -> tuple[Any, Any, Any]:  # fmt: skip
    """The session's plan of ``program`` (0.2 mm z-map), the virtual quaser-ux600 cutting its
    own plan of it (decision 1740) with the process ``events``, and the tool's ``ToolConfig``
    (``home_mm``: the machine reference position of a program's G28, ``--home-mm``)."""
    from millsense.core.config import MaterialConfig, StockConfig, ToolConfig, load_config
    from millsense.core.presets import load_preset
    from millsense.core.units import MM
    from millsense.plan.gcode import interpret_file
    from millsense.plan.stock import ZMapStock
    from millsense.plan.virtual_plan import plan_program
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.machine import MachineSimulator, SimulatorOptions
    from millsense.simulator.machine_file import simulator_machine
    from millsense.simulator.plan_job import plan_job
    from millsense.simulator.plant_plan import plant_plan

    box = load_config(StockConfig, stock)
    lo, hi = box.min_mm, box.max_mm
    assert lo is not None and hi is not None

    def make_stock(cell_m: float) -> ZMapStock:
        return ZMapStock.from_box([v * MM for v in lo], [v * MM for v in hi], cell_m)

    tool_cfg = tool if isinstance(tool, ToolConfig) else load_preset(ToolConfig, tool)
    end_mill = EndMill.from_config(tool_cfg)
    coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, material))
    plan = plan_program(interpret_file(program, home_mm=home_mm), make_stock(0.2 * MM),
                        end_mill, coeffs)  # fmt: skip
    plant = plant_plan([interpret_file(program, home_mm=home_mm)], make_stock, end_mill, coeffs)
    sim_cfg = simulator_machine(MACHINE)
    job, proc, _, _ = plan_job(plant, sim_cfg, program.name, events=list(events))
    sim = MachineSimulator(sim_cfg, job, proc, SimulatorOptions(seed=seed), duration_s=duration_s)
    return plan, sim, tool_cfg


def program_session(
    program: Path,
    tool: Any,
    *,
    material: str = "al7050",
    stock: Path = STOCK,
    events: Sequence[Any] = (),
    seed: int = 0,
    duration_s: float | None = None,
    out: Path | None = None,
    keep: Sequence[str] | None = (),
    options: Any = None,
    observer: Any = None,
    home_mm: tuple[float, float, float] | None = None,
) -> ProgramSession:
    """Run ``program`` with ``tool`` (a tool TOML path, a preset name or a ``ToolConfig``)
    through the session of ``options`` (a ``SessionOptions``; None: the default) on the
    virtual quaser-ux600; ``events``: process events of the virtual machine (a
    :class:`~millsense.simulator.process_coupling.ToothBreak`); ``observer``: called with
    every chunk as ``run_session``'s (reads the simulator's truth); ``home_mm``: the machine
    reference position of a program's G28."""
    from millsense.core.presets import commissioned_machine
    from millsense.online.session import SessionOptions, run_session, session_blocks

    plan, sim, _ = _program_machine(program, tool, material, stock, events, seed, duration_s,
                                    home_mm)  # fmt: skip
    shipped = commissioned_machine(MACHINE)
    assert shipped is not None
    belief, where = shipped
    opts = options if options is not None else SessionOptions()
    built = session_blocks(plan, belief, sim.sample_rate_hz, opts, where=where,
                           channels=sim.channel_names)  # fmt: skip
    return ProgramSession(
        run_session(sim, built.blocks, out=out, keep=keep, observer=observer), plan
    )


def program_recording(
    program: Path,
    tool: Any,
    out: Path,
    *,
    material: str = "al7050",
    stock: Path = STOCK,
    events: Sequence[Any] = (),
    seed: int = 0,
    observer: Any = None,
) -> None:
    """The virtual quaser-ux600 running ``program`` open loop (no session, the CNC as
    programmed) with the process ``events``, recorded to ``out`` as a CNC records it: every
    channel but the simulator's truth, no plan; ``observer``: called with every chunk (reads
    the truth)."""
    from millsense.io.recording_file import write_recording

    _, sim, tool_cfg = _program_machine(program, tool, material, stock, events, seed, None)
    write_recording(out, cnc_recording(sim, {"program": program.name,
                                             "flutes": int(tool_cfg.flutes)},
                                      observer))  # fmt: skip


def cnc_recording(sim: Any, metadata: dict[str, Any], observer: Any = None) -> Any:
    """The virtual machine ``sim`` (a ``MachineSimulator``) run to its end and recorded as a
    CNC records it: every channel but the simulator's truth (a ``core.recording.Recording``
    with ``metadata``); ``observer``: called with every chunk (the truth included)."""
    import numpy as np

    from millsense.core.recording import Recording

    keep = [c for c in sim.channel_info if not c.name.startswith("truth/")]
    parts: dict[str, list[np.ndarray]] = {c.name: [] for c in keep}
    while (chunk := sim.read(10000)) is not None:
        if observer is not None:
            observer(chunk, {}, [])
        for c in keep:
            parts[c.name].append(np.asarray(chunk.data[c.name], dtype=np.float64))
    rec = Recording(sim.sample_rate_hz, 0.0, metadata)
    for c in keep:
        rec.add_channel(c.name, np.concatenate(parts[c.name]), c.unit)
    return rec
