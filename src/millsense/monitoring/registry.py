"""Monitors by name: the ``--methods`` of ``millsense monitor``.

A monitor is registered as ``name → factory(context) → Block``; the CLI builds the
:class:`MonitorContext` from the recording, the plan and the options, and every factory takes
what it needs from it (raising a one-line :class:`~millsense.core.errors.InputDataError` when
something is missing). Further monitors (breakage, engagement, contact) are added with
:func:`register`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from millsense.core.errors import InputDataError
from millsense.streaming.block import Block


@dataclass(frozen=True)
class MonitorContext:
    """What a monitor factory may use.

    Attributes
    ----------
    channels : channels of the recording (name → unit).
    sample_rate_hz : stream rate, Hz.
    signal : channel chosen with ``--channel`` (None: each monitor's default).
    speed_channel, speed_unit : spindle-speed channel and its unit (``rad/s``, ``rev/min``),
        or None.
    speed_rpm : constant spindle speed when there is no speed channel, rev/min.
    n_flutes : teeth of the tool.
    nc_line_channel : the CNC's NC-line channel, or None.
    locate : (time s, NC line) → (NC line, x, y, z mm) on the plan's path, or None.
    plan : the virtual plan (:class:`~millsense.plan.virtual_plan.VirtualPlan`), or None.
    source : name of the recording (for messages).
    options : further named settings for specific monitors.
    """

    channels: dict[str, str]
    sample_rate_hz: float
    signal: str | None = None
    speed_channel: str | None = None
    speed_unit: str = "rad/s"
    speed_rpm: float | None = None
    n_flutes: int = 2
    nc_line_channel: str | None = None
    locate: Callable[..., Any] | None = None
    plan: Any = None
    source: str = "recording"
    options: dict[str, Any] = field(default_factory=dict)

    def require(self, names: Sequence[str], monitor: str) -> None:
        """One-line error if a channel ``monitor`` needs is not in the recording."""
        for c in names:
            if c not in self.channels:
                raise InputDataError(
                    f"{self.source}: monitor '{monitor}' needs channel '{c}', which the "
                    f"recording does not hold (it holds: {', '.join(sorted(self.channels))})"
                )


Factory = Callable[[MonitorContext], Block]
MONITORS: dict[str, Factory] = {}


def register(name: str, factory: Factory) -> None:
    """Add a monitor under ``name`` (a later registration replaces an earlier one)."""
    MONITORS[name] = factory


#: Signal channels a chatter monitor uses when none is chosen, best first: the compensated
#: spindle torque (seed 000), the raw spindle current, then external sensors.
CHATTER_SIGNALS = (
    "est/spindle/spindle/load",
    "spindle/torque_est",
    "spindle/current_cmd",
    "spindle/current",
    "accel/x",
    "accel/y",
    "mic/pressure",
)


def _chatter_factory(method: str) -> Factory:
    def make(ctx: MonitorContext) -> Block:
        from millsense.monitoring.chatter import ChatterMonitor, ChatterSettings

        signal = ctx.signal
        if signal is None:
            signal = next((c for c in CHATTER_SIGNALS if c in ctx.channels), None)
            if signal is None:
                raise InputDataError(
                    f"{ctx.source}: monitor '{method}' needs a signal channel (one of "
                    f"{', '.join(CHATTER_SIGNALS)}, or --channel); the recording holds: "
                    f"{', '.join(sorted(ctx.channels))}"
                )
        ctx.require([signal], method)
        if ctx.speed_channel is not None:
            ctx.require([ctx.speed_channel], method)
        elif not (ctx.speed_rpm and ctx.speed_rpm > 0):
            raise InputDataError(
                f"{ctx.source}: monitor '{method}' needs the spindle speed: no spindle-speed "
                "channel (spindle/speed, spindle/speed_cmd) in the recording; give --spindle-rpm"
            )
        return ChatterMonitor(
            ChatterSettings(
                method=method,
                signal=signal,
                n_flutes=ctx.n_flutes,
                speed_channel=ctx.speed_channel,
                speed_unit=ctx.speed_unit,
                speed_rpm=ctx.speed_rpm,
                nc_line_channel=ctx.nc_line_channel,
                threshold=ctx.options.get(f"{method}.threshold"),
            ),
            locate=ctx.locate,
        )

    return make


for _m in ("chatter-comb", "chatter-sdft", "chatter-threshold"):
    register(_m, _chatter_factory(_m))


#: Torque channels a breakage monitor uses when none is chosen, best first: the spindle
#: observer's compensated load (``monitor --machine``), an estimated spindle torque.
BREAKAGE_SIGNALS = ("est/spindle/spindle/load", "spindle/torque_est")


def _breakage_factory(method: str) -> Factory:
    name = f"breakage-{method}"

    def make(ctx: MonitorContext) -> Block:
        from millsense.monitoring.breakage import BreakageBlock

        signal = ctx.signal or next((c for c in BREAKAGE_SIGNALS if c in ctx.channels), None)
        if signal is None:
            raise InputDataError(
                f"{ctx.source}: monitor '{name}' needs a spindle torque channel (one of "
                f"{', '.join(BREAKAGE_SIGNALS)}: give --machine for the spindle observer, or "
                "--channel)"
            )
        ctx.require([signal], name)
        if ctx.speed_channel is None or ctx.speed_unit != "rad/s":
            raise InputDataError(
                f"{ctx.source}: monitor '{name}' needs a spindle-speed channel in rad/s "
                "(spindle/speed) to cut the signal into tooth periods"
            )
        ctx.require([ctx.speed_channel], name)
        expected = ctx.options.get("breakage.expected_channel")
        if method == "virtual":
            if expected is None:
                raise InputDataError(
                    f"{ctx.source}: monitor '{name}' needs the plan's expected torque per "
                    "sample (option breakage.expected_channel); use breakage-constant or "
                    "breakage-dual without it"
                )
            ctx.require([expected], name)
        return BreakageBlock(
            ctx.n_flutes,
            method=method,  # type: ignore[arg-type]
            signal_channels=(signal,),
            speed_channel=ctx.speed_channel,
            expected_channel=expected if method == "virtual" else None,
            name=name,
        )

    return make


for _b in ("virtual", "constant", "dual"):
    register(f"breakage-{_b}", _breakage_factory(_b))
