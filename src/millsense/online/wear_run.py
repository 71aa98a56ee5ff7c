"""The wear monitor's sums of one recording: the spindle torque observer, the plan beside the
machine and :class:`~millsense.monitoring.wear.WearBlock` on the stream (issue 20, item 2).

The same blocks as an on-line session's front end (:func:`~millsense.online.session.
session_blocks`: the machine file's spindle observer, the spindle-at-speed gate, the
tool-centre point and :class:`~millsense.online.plan_sync.PlanSync` with its air-cut
reference), then the wear block; nothing of the session's controllers.
"""

from __future__ import annotations

from typing import Any

from millsense.core.config import MachineConfig
from millsense.core.errors import InputDataError
from millsense.monitoring.wear import WearBlock, WearSums
from millsense.online.gates import SpindleAtSpeed
from millsense.online.plan_sync import PlanSync, TcpFromAxes
from millsense.online.session import TORQUE_CHANNEL
from millsense.plan.virtual_plan import VirtualPlan
from millsense.streaming.block import Block
from millsense.streaming.engine import Pipeline, run
from millsense.streaming.sources import RecordingSource, Source

__all__ = ["recording_wear_sums", "source_wear_sums", "wear_blocks"]


def wear_blocks(
    plan: VirtualPlan, machine: MachineConfig, sample_rate_hz: float, *, where: str = "machine file"
) -> tuple[list[Block], WearBlock]:
    """The blocks that turn CNC channels into the wear block's inputs, and the wear block."""
    from millsense.estimation.from_config import build_estimators
    from millsense.models.kinematics import kinematics_for

    built = build_estimators(machine, ["spindle"], [], sample_rate_hz, where=where)
    blocks: list[Block] = [*built.blocks, SpindleAtSpeed()]
    blocks.append(TcpFromAxes(kinematics_for(machine.kinematics),
                              [f"{a}/position_cmd" for a in machine.axes]))  # fmt: skip
    blocks.append(
        PlanSync(plan, torque_channel=TORQUE_CHANNEL, at_speed_channel="spindle/at_speed")
    )
    wear = WearBlock(plan)
    blocks.append(wear)
    return blocks, wear


def recording_wear_sums(
    rec: Any, plan: VirtualPlan, machine: MachineConfig, *, chunk: int = 2000, where: str = ""
) -> WearSums:
    """Run the wear blocks over a recording (CNC channels only) and return its sums.

    Raises
    ------
    InputDataError
        A channel the blocks need is not in the recording (named).
    """
    return source_wear_sums(rec, plan, machine, chunk=chunk, where=where)


def source_wear_sums(
    source: Any, plan: VirtualPlan, machine: MachineConfig, *, chunk: int = 2000, where: str = ""
) -> WearSums:
    """The same on a recording or a live :class:`~millsense.streaming.sources.Source` (the
    virtual machine): anything with ``channel_names``, ``metadata`` and ``sample_rate_hz``; a
    recording is replayed with only the channels the blocks read."""
    names = list(source.channel_names)
    axes = [a for a in machine.axes if f"{a}/position_cmd" in names]
    cfg = machine.with_axes(axes, str(source.metadata.get("kinematics", machine.kinematics)))
    blocks, wear = wear_blocks(plan, cfg, source.sample_rate_hz, where=where or "machine file")
    made = {c.name for b in blocks for c in b.output_channels()}
    needed = {c for b in blocks for c in b.inputs if c not in made}
    missing = sorted(needed - set(names))
    if missing:
        raise InputDataError(
            f"{where or 'recording'}: wear needs channel(s) {', '.join(missing)}"
        )
    src = source if isinstance(source, Source) else RecordingSource(
        source, name=where or "recording", channels=sorted(needed)
    )
    run(src, Pipeline(blocks), chunk, collect=False)
    return wear.sums
