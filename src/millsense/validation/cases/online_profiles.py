"""A CAM program of profiles in the XZ and YZ planes with a ball end mill, through the
integrated session: no false alarm on an intact tool.

`examples/gcode/mastercam_planes_g55.nc` (Mastercam style: G18 and G19 arcs with absolute and
incremental centres, G55, G28 to a reference at X0 Y0 Z100 mm) with its Ø6 mm 2-flute ball end
mill (`examples/gcode/ball_d6_2flute.toml`) at 9000 rev/min in the demo part's Al7050 block, run
as ``millsense run --program … --home-mm 0,0,100`` runs it (the same library calls) on the
quaser-ux600 virtual machine with its default session. The virtual tool has the runout the plan
does not know, and the ball descends along its arcs to 10 mm deep: where the chip thins one
flute loses its chip to the runout while the other keeps its own, and the plan over-predicts
the revolution by 25-35 %. Before decision 1742 the breakage monitor took that for a broken
flute of two and held the feed at 8.50 s (line 134).
"""

from __future__ import annotations

import functools

from millsense.streaming.block import Event
from millsense.validation import Measured, case
from millsense.validation.cases._program_session import EXAMPLE
from millsense.validation.cases.online_shop import FALSE_ALARMS

#: The program's G28 reference position, mm (``--home-mm``).
HOME_MM = (0.0, 0.0, 100.0)


@functools.lru_cache(maxsize=1)
def profile_events() -> tuple[Event, ...]:
    """The session's events of the ball-nose profile program (intact tool)."""
    from millsense.validation.cases._program_session import program_session

    gcode = EXAMPLE / "gcode"
    res = program_session(gcode / "mastercam_planes_g55.nc", gcode / "ball_d6_2flute.toml",
                          home_mm=HOME_MM).result  # fmt: skip
    return tuple(res.events)


@case(
    "online.ball_nose_profiles_false_alarms",
    source="issues 15 and 16: no false alarm, speed change or feed hold on stable cutting (a "
    "CAM program of XZ and YZ profiles with a 2-flute ball end mill, the tool intact and rigid)",
    reference=0.0,
    unit="events",
    abs_tol=0.0,
    quick=False,
    description=(
        "examples/gcode/mastercam_planes_g55.nc with a Ø6 mm 2-flute ball end mill through "
        "millsense run's default session on the quaser-ux600: breakage, chatter and input "
        "alarms, feed holds and spindle-speed commands, counted"
    ),
    issue=15,
)
def _false_alarms() -> Measured:
    events = profile_events()
    bad = [e for e in events if e.name in FALSE_ALARMS or e.name == "spindle_override"]
    rows = [f"| {e.time_s:.3f} | {e.name} | {e.nc_line} | {e.message[:100]} |" for e in events
            if e.name != "feed_override"]  # fmt: skip
    table = "| t [s] | event | line | message |\n|---|---|---|---|\n" + "\n".join(rows)
    return Measured(float(len(bad)), table)
