"""``millsense monitor``: run process monitors over a recording and write the event log.

Monitors are chosen by name from :data:`millsense.monitoring.MONITORS` (``--methods``); they
run in the same streaming engine as live runs. With ``--machine`` and a spindle current in the
recording the spindle torque observer of the machine file runs first, so the chatter monitors
read the compensated spindle torque (seed 000 §2.7); ``--channel`` chooses any other channel
(a feed-drive force estimate, ``accel/x``, ``mic/pressure``).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import typer

from millsense.cli.main import app

if TYPE_CHECKING:
    from millsense.online.gates import TorqueCutGate

#: Spindle-speed channels, preferred first.
SPEED_CHANNELS = ("spindle/speed", "spindle/speed_cmd")
#: A session recording's "the plan's tool is in the cut".
IN_CUT = "plan/in_cut"


@app.command()
def monitor(
    recording: Path = typer.Argument(..., help="Recording to monitor (.h5)."),
    out: Path = typer.Option(..., "-o", "--output", help="Event log to write (.parquet)."),
    plan: Path | None = typer.Option(
        None, "--plan", help="Virtual plan (.parquet): NC line and x/y/z of each event."
    ),
    machine: str | None = typer.Option(
        None, "--machine", help="Machine preset or .toml: runs its spindle torque observer."
    ),
    methods: str = typer.Option(
        "chatter-comb", "--methods", help="Comma-separated monitors (see --list), or 'all'."
    ),
    channel: str | None = typer.Option(
        None,
        "--channel",
        help="Signal channel (default: compensated spindle torque, current, "
        "accelerometer, microphone: the first present).",
    ),
    flutes: int | None = typer.Option(None, "--flutes", help="Teeth (default: metadata or 2)."),
    spindle_rpm: float | None = typer.Option(
        None,
        "--spindle-rpm",
        help="Spindle speed [rev/min] when the recording has no speed channel (default: the "
        "recording's metadata spindle_rpm, else the plan's programmed speed); the engagement "
        "monitor refines it from the torque's own revolutions.",
    ),
    plot: Path | None = typer.Option(None, "--plot", help="PNG: spectrogram with chatter marked."),
    chunk: int = typer.Option(1000, "--chunk", help="Samples per chunk."),
    tool: str | None = typer.Option(
        None, "--tool", help="Tool preset or .toml (engagement; default: the plan's tool)."
    ),
    feed_per_tooth: float | None = typer.Option(
        None, "--feed-per-tooth-mm", help="Feed per tooth [mm] (engagement; default: the plan's)."
    ),
    air_s: str | None = typer.Option(
        None, "--air-s", help="Air-cut motion's time window A:B [s] (contact reference)."
    ),
    air_torque: float | None = typer.Option(
        None,
        "--air-torque-nm",
        help="The torque channel's mean with the tool out of the cut [N·m] (engagement: 0 for "
        "a tared dynamometer; default: learnt from the recording's air revolutions).",
    ),
    cut_s: float | None = typer.Option(
        None, "--cut-s", help="Start of the cut motion [s] (contact; default: end of --air-s)."
    ),
    position: str | None = typer.Option(
        None, "--position", help="Axis-position channel of the contact (default: x/scale...)."
    ),
) -> None:
    """Detect chatter (and further registered monitors) in a recording; write the event log."""
    from millsense.io.safe_output import check_outputs

    check_outputs(
        {"the recording": recording, "the plan": plan, "the machine file": machine,
         "the tool file": tool},
        {"-o": out, "--plot": plot}, {"-o": ".parquet"},
    )  # fmt: skip
    from millsense.cli.progress import progress_bar

    with progress_bar("monitoring", 1.0) as update:
        summary = run_monitor(
            recording=recording, out=out, plan=plan, machine=machine, methods=methods,
            channel=channel, flutes=flutes, spindle_rpm=spindle_rpm, plot=plot, chunk=chunk,
            tool=tool, feed_per_tooth=feed_per_tooth, air_s=air_s, cut_s=cut_s,
            position=position, air_torque=air_torque, on_progress=update,
        )  # fmt: skip
    for line in summary["lines"]:
        typer.echo(line)


def _methods(text: str) -> list[str]:
    from millsense.core.errors import ConfigError
    from millsense.monitoring import MONITORS

    if text.strip() == "all":
        return list(MONITORS)
    out = [m.strip() for m in text.split(",") if m.strip()]
    for m in out:
        if m not in MONITORS:
            raise ConfigError(
                f"--methods: unknown monitor '{m}' (one of {', '.join(MONITORS)}, all)"
            )
    if not out:
        raise ConfigError("--methods: empty")
    return out


def _speed_unit(unit: str, name: str, where: str) -> str:
    from millsense.core.errors import InputDataError

    u = unit.strip().lower().replace(" ", "")
    if u in ("rad/s", "rad*s^-1", "1/s*rad"):
        return "rad/s"
    if u in ("rev/min", "rpm", "1/min", "min^-1"):
        return "rev/min"
    raise InputDataError(f"{where}: channel '{name}' has unit '{unit}' (need rad/s or rev/min)")


def run_monitor(
    *,
    recording: Path,
    out: Path,
    plan: Path | None = None,
    machine: str | None = None,
    methods: str = "chatter-comb",
    channel: str | None = None,
    flutes: int | None = None,
    spindle_rpm: float | None = None,
    plot: Path | None = None,
    chunk: int = 1000,
    tool: str | None = None,
    feed_per_tooth: float | None = None,
    air_s: str | None = None,
    cut_s: float | None = None,
    position: str | None = None,
    segment: tuple[int, int] | None = None,
    air_torque: float | None = None,
    on_progress: Callable[[float], None] | None = None,
) -> dict[str, Any]:
    """Run the monitors over ``recording``; write the event log ``out`` (and ``plot``).

    Returns a summary: ``events`` (list of Event), ``lines`` (printed summary), ``wall_s``.
    ``segment``: samples ``[start, stop)`` only (``millsense batch``). ``on_progress``: the
    fraction of the recording monitored so far, after every chunk.

    Raises
    ------
    ConfigError, InputDataError, RecordingError
        One-line user errors: unknown monitor, missing channel, a plan of another program, a
        spindle that never turns.
    """
    from millsense.core.errors import InputDataError
    from millsense.io.recording_reader import open_recording

    if chunk < 1:
        raise InputDataError(f"--chunk: must be ≥ 1, got {chunk}")
    names = _methods(methods)
    options = _monitor_options(feed_per_tooth, air_s, cut_s, position, air_torque)
    tool_cfg = None
    if tool is not None:
        from millsense.core.config import ToolConfig
        from millsense.core.presets import load_preset

        tool_cfg = load_preset(ToolConfig, tool)
    with contextlib.ExitStack() as stack:
        rec = open_recording(recording, segment)
        if hasattr(rec, "close"):
            stack.callback(rec.close)
        return _run(rec, recording, out, plan, machine, names, channel, flutes, spindle_rpm,
                    plot, chunk, tool_cfg, options, on_progress)  # fmt: skip


def _monitor_options(
    feed_per_tooth: float | None,
    air_s: str | None,
    cut_s: float | None,
    position: str | None,
    air_torque: float | None = None,
) -> dict[str, Any]:
    """The options of the engagement and contact monitors, checked (one-line errors)."""
    from millsense.core.errors import ConfigError

    opts: dict[str, Any] = {}
    if air_torque is not None:
        if not np.isfinite(air_torque):
            raise ConfigError(f"--air-torque-nm: must be a finite torque in N·m, got {air_torque}")
        opts["engagement.air_torque_nm"] = float(air_torque)
    if feed_per_tooth is not None:
        if not (feed_per_tooth > 0 and np.isfinite(feed_per_tooth)):
            raise ConfigError(f"--feed-per-tooth-mm: must be > 0, got {feed_per_tooth}")
        opts["engagement.feed_per_tooth_mm"] = float(feed_per_tooth)
    if air_s is not None:
        parts = air_s.split(":")
        try:
            a, b = (float(p) for p in parts)
        except ValueError:
            raise ConfigError(
                f"--air-s: expected A:B in seconds (e.g. 0.5:1.5), got '{air_s}'"
            ) from None
        if not (np.isfinite(a) and np.isfinite(b) and b > a):
            raise ConfigError(f"--air-s: need A < B, got '{air_s}'")
        opts["contact.air_s"] = (a, b)
    if cut_s is not None:
        opts["contact.cut_s"] = float(cut_s)
    if position is not None:
        opts["contact.position_channel"] = position
    return opts


def _run(
    rec: Any,
    recording: Path,
    out: Path,
    plan: Path | None,
    machine: str | None,
    names: list[str],
    channel: str | None,
    flutes: int | None,
    spindle_rpm: float | None,
    plot: Path | None,
    chunk: int,
    tool_cfg: Any = None,
    options: dict[str, Any] | None = None,
    on_progress: Callable[[float], None] | None = None,
) -> dict[str, Any]:
    from millsense.core.errors import InputDataError
    from millsense.io.recording_reader import channel_window
    from millsense.monitoring import MONITORS, MonitorContext
    from millsense.streaming import EventKind, Pipeline, RecordingSource, run, write_event_log

    where = str(recording)
    fs = float(rec.sample_rate_hz)
    channels = {c: rec.info(c).unit for c in rec.channel_names}
    if channel is not None and channel not in channels:
        raise InputDataError(
            f"{where}: --channel '{channel}' is not in the recording (it holds: "
            f"{', '.join(sorted(channels))})"
        )
    if channel is not None and channel.startswith("truth/"):
        raise InputDataError(
            f"{where}: --channel '{channel}' is the simulator's ground truth, which monitors "
            "may not read (only what a CNC or an added sensor records)"
        )
    vp = None
    locate = None
    if plan is not None:
        from millsense.cli.plan_match import check_plan_matches
        from millsense.monitoring.locate import PlanLocator
        from millsense.plan.virtual_plan import VirtualPlan

        vp = VirtualPlan.read(plan)
        check_plan_matches(vp, plan, rec, recording)
        locate = PlanLocator(vp)
    # spindle speed: a channel, else --spindle-rpm, else the plan's programmed speed
    speed_channel = next((c for c in SPEED_CHANNELS if c in channels), None)
    speed_unit = "rad/s"
    if spindle_rpm is not None and not spindle_rpm > 0:
        # refused even where a speed channel makes it unused: a bad value is never passed over
        raise InputDataError(f"--spindle-rpm: must be > 0, got {spindle_rpm:g}")
    if speed_channel is not None:
        speed_unit = _speed_unit(channels[speed_channel], speed_channel, where)
        spd = np.asarray(channel_window(rec, speed_channel, 0, rec.n_samples), dtype=float)
        top = float(np.max(np.abs(spd))) if len(spd) else 0.0
        top_rpm = top * (60.0 / (2 * np.pi) if speed_unit == "rad/s" else 1.0)
        if top_rpm < 1.0:
            raise InputDataError(
                f"{where}: spindle speed is zero throughout (channel '{speed_channel}'): "
                "nothing to monitor"
            )
    elif spindle_rpm is None and (md_rpm := _metadata_rpm(rec)) is not None:
        if not md_rpm > 0:
            raise InputDataError(
                f"{where}: metadata spindle_rpm is {md_rpm:g}: give --spindle-rpm (> 0)"
            )
        spindle_rpm = md_rpm
    elif spindle_rpm is None and vp is not None:
        rpm = np.abs(np.asarray(vp["spindle_rpm"], dtype=float))
        spindle_rpm = float(np.median(rpm[rpm > 0])) if (rpm > 0).any() else None
    n_flutes = _flutes(flutes, rec, vp)
    from millsense.monitoring.registry import OBSERVER_ESTIMATE as OBSERVER_CHANNEL

    pre: list[Any] = []
    signal = channel
    # what the breakage detectors average where it is not `signal` (decision 1728)
    breakage_signal: str | None = None
    dob_resolution = 0.0  # the DOB's tooth-period resolution, N·m·s (decision 1732)
    # the plan-free breakage detectors' gate from the torque (decision 1706), if built
    torque_gate: TorqueCutGate | None = None
    if (
        machine is not None
        and "spindle/current_cmd" in channels
        and channel in (None, OBSERVER_CHANNEL)
    ):
        from millsense.core.config import MachineConfig
        from millsense.core.presets import load_preset
        from millsense.estimation.from_config import spindle_observer_from_config

        if "spindle/speed" not in channels or "spindle/speed_cmd" not in channels:
            raise InputDataError(
                f"{where}: the spindle observer needs channels 'spindle/speed' and "
                "'spindle/speed_cmd' besides 'spindle/current_cmd'"
            )
        mcfg = load_preset(MachineConfig, machine)
        pre.append(spindle_observer_from_config(mcfg, machine, fs))
        channels[OBSERVER_CHANNEL] = "N*m"
        signal = OBSERVER_CHANNEL
        observer_machine: tuple[Any, str] | None = (mcfg, machine)
        if any(n.startswith("breakage-") for n in names):
            # the breakage detectors average the spindle DOB's torque: the encoder's
            # quantisation averaged out of the tooth periods' mean (decisions 1726, 1728)
            from millsense.estimation.from_config import spindle_dob_from_config
            from millsense.estimation.spindle_dob import DOB_TORQUE

            dob = spindle_dob_from_config(mcfg, machine)
            pre.append(dob)
            channels[DOB_TORQUE] = "N*m"
            breakage_signal = DOB_TORQUE
            # its tooth-period means move in steps of an encoder count (decision 1732)
            dob_resolution = dob.mean_resolution_nms(fs)
    else:
        observer_machine = _session_machine(rec) if OBSERVER_CHANNEL in channels else None
    spindle_file = observer_machine[0] if observer_machine is not None else None
    if spindle_file is None and machine is not None:
        from millsense.core.config import MachineConfig
        from millsense.core.presets import load_preset

        spindle_file = load_preset(MachineConfig, machine)
    counts = getattr(getattr(spindle_file, "spindle", None), "encoder_counts_rev", None)
    if counts is not None:
        # where the spindle drive's quantisation lines can stand (decision 1697)
        options = {**(options or {}), "chatter.encoder_counts_rev": int(counts)}
    if "engagement" in names and observer_machine is not None:
        # the observer's estimate seen through its machine file's response (decision 1554)
        options = {**(options or {}),
                   "engagement.response": _observer_response(*observer_machine, fs)}  # fmt: skip
    from millsense.monitoring.registry import (
        AT_SPEED,
        BREAKAGE_GATE,
        BREAKAGE_STEADY_GATE,
        SESSION_EXPECTED,
    )

    if (
        AT_SPEED not in channels
        and "spindle/speed" in channels
        and "spindle/speed_cmd" in channels
        and _speed_unit(channels["spindle/speed"], "spindle/speed", where) == "rad/s"
    ):
        # the breakage monitors judge no tooth period the spindle spends off its commanded
        # speed (a run-up's or a speed change's acceleration torque, decision 1550)
        from millsense.online.gates import SpindleAtSpeed

        pre.append(SpindleAtSpeed())
        channels[AT_SPEED] = "1"
    if breakage_signal is not None and IN_CUT in channels and AT_SPEED in channels:
        # a session's recording: the DOB's torque less its air where the plan says air, as the
        # session's (decisions 1726, 1728), for the plan's expected torque
        from millsense.online.gates import AirReference
        from millsense.online.session import DOB_CUTTING_TORQUE

        pre.append(AirReference(breakage_signal, IN_CUT, AT_SPEED, out=DOB_CUTTING_TORQUE,
                                name="monitor/dob_air"))  # fmt: skip
        channels[DOB_CUTTING_TORQUE] = "N*m"
        breakage_signal = DOB_CUTTING_TORQUE
    if AT_SPEED in channels and IN_CUT in channels:
        # a session's recording: breakage is judged where the plan has the tool in the cut too
        # (the dual and constant detectors learn their thresholds and reference on the cut,
        # not on the air before it; decision 1550)
        from millsense.online.gates import AllOf

        pre.append(AllOf((AT_SPEED, IN_CUT), BREAKAGE_GATE))  # the registry's gate
        channels[BREAKAGE_GATE] = "1"
        if SESSION_EXPECTED in channels:
            # the dual and constant detectors, which know no plan, learn and judge where the
            # plan is steady in the cut: its entries, steps and ramps gave them their false
            # alarms (decision 1676)
            steady = AllOf((AT_SPEED, SESSION_EXPECTED), BREAKAGE_STEADY_GATE, name="steady",
                           above=(0.5, 0.0))  # fmt: skip
            pre.append(steady)
            channels[BREAKAGE_STEADY_GATE] = "1"
    elif AT_SPEED in channels and {"breakage-dual", "breakage-constant"} & set(names):
        # no plan: the dual and constant detectors learn and judge where the torque has risen
        # from the air after the spindle's start and is steady (decision 1706); learnt on the
        # air before the cut, seed 002's thresholds made the entry an alarm
        from millsense.monitoring.registry import BREAKAGE_SIGNALS_SESSION
        from millsense.online.gates import TorqueCutGate

        known = next((c for c in BREAKAGE_SIGNALS_SESSION if c in channels), None)
        torque = breakage_signal or signal or known
        if torque is not None and speed_channel is not None and speed_unit == "rad/s":
            torque_gate = TorqueCutGate(torque, speed_channel, AT_SPEED, BREAKAGE_STEADY_GATE)
            pre.append(torque_gate)
            channels[BREAKAGE_STEADY_GATE] = "1"
    nc_channel = "cnc/nc_line" if "cnc/nc_line" in channels else None
    if tool_cfg is None and vp is not None and isinstance(vp.metadata.get("tool"), dict):
        from millsense.core.config import ToolConfig, parse_config

        t = vp.metadata["tool"]
        tool_cfg = parse_config(
            ToolConfig,
            {k: t[k] for k in ("diameter_mm", "flutes", "helix_deg") if k in t},
            f"{plan} (tool)",
        )
    if tool_cfg is not None and flutes is None:
        n_flutes = int(tool_cfg.flutes)

    def read(name: str, i0: int, i1: int) -> np.ndarray:
        return np.asarray(channel_window(rec, name, i0, i1), dtype=np.float64)

    if breakage_signal is not None:
        options = {**(options or {}), "breakage.signal": breakage_signal,
                   "breakage.mean_resolution": dob_resolution}  # fmt: skip
    ctx = MonitorContext(
        channels=channels, sample_rate_hz=fs, signal=signal, speed_channel=speed_channel,
        speed_unit=speed_unit, speed_rpm=spindle_rpm, n_flutes=n_flutes,
        nc_line_channel=nc_channel, locate=locate, plan=vp, source=where,
        options=dict(options or {}), tool=tool_cfg, read=read, t0_s=float(rec.t0_s),
        n_samples=int(rec.n_samples),
    )  # fmt: skip
    # 'all': every registered monitor the recording can feed; those it cannot are named
    every = set(names) == set(MONITORS) and len(names) > 1
    blocks, skipped = [], []
    for n in names:
        try:
            blocks.append(MONITORS[n](ctx))
        except InputDataError as exc:
            if not every:
                raise
            skipped.append(f"  {n}: skipped ({str(exc).removeprefix(where + ': ')})")
    if not blocks:
        raise InputDataError(f"{where}: no monitor can run on this recording")
    names = [b.name for b in blocks]
    pipeline = Pipeline([*pre, *_grouped(blocks)])
    needed = sorted({c for b in pipeline.blocks for c in b.inputs if c in rec.channel_names})
    source = RecordingSource(rec, name=where, channels=needed)
    sig_name = getattr(blocks[0], "settings", None)
    sig_name = getattr(sig_name, "signal", None)
    keep: dict[str, list[np.ndarray]] = {}
    if plot is not None:  # (the figure's module only where there is a figure: batch tasks)
        from millsense.report.monitor_plots import plotted
    else:

        def plotted(key: str) -> bool:
            return False

    # the monitors' held outputs are kept every `step` samples (≈ 2 kHz) for the figure
    step = max(1, int(fs // 2000))

    # samples at speed and in the torque gate's steady cut, where the plan-free breakage
    # detectors judge (the summary says how much of the recording they saw)
    gated = [0, 0]

    def sink(ch: Any, outputs: dict[str, np.ndarray], _ev: Any) -> None:
        if torque_gate is not None:  # the at-speed gate is a block's output or a recorded channel
            at_speed = outputs.get(AT_SPEED, ch.data.get(AT_SPEED))
            gated[0] += int(np.count_nonzero(np.asarray(at_speed) > 0.5))
            gated[1] += int(np.count_nonzero(outputs[BREAKAGE_STEADY_GATE] > 0.5))
        if plot is None:
            return
        if sig_name is not None:
            src = outputs.get(sig_name, ch.data.get(sig_name))
            if src is not None:
                keep.setdefault("signal", []).append(np.asarray(src))
        first = (-ch.start) % step
        for k, v in outputs.items():
            if plotted(k):
                keep.setdefault(k, []).append(np.asarray(v)[first::step])

    t0 = time.perf_counter()
    total = max(rec.n_samples, 1)
    res = run(source, pipeline, chunk, sink=sink, collect=False,
              on_progress=(lambda k: on_progress(k / total)) if on_progress else None)  # fmt: skip
    wall = time.perf_counter() - t0
    write_event_log(out, res.events, recording=recording)
    seconds = rec.n_samples / fs
    speed = seconds / max(wall, 1e-9)
    lines = [
        f"wrote {out}: {len(res.events)} events from {', '.join(names)} on "
        f"{seconds:.1f} s of {recording.name} in {wall:.2f} s "
        f"({speed:.{0 if speed >= 10 else 1}f}x real time)"
    ]
    verdicts: dict[str, _EngagementVerdict] = {}  # what the summary reports, for the plot
    for b in blocks:
        alarms = [e for e in res.events if e.source == b.name and e.kind == EventKind.ALARM]
        contacts = [e for e in res.events if e.source == b.name and e.name == "contact"]
        if contacts:
            e = contacts[0]
            lines.append(f"  {b.name}: contact at {e.time_s:.5f} s, position {e.value:.6g}")
        elif b.name == "engagement":
            verdicts[b.name] = _engagement_verdict(b, _steady_cut(rec), fs)
            lines.append(_engagement_summary(b, fs=fs, verdict=verdicts[b.name]))
        elif alarms:
            unit = {"chatter": " Hz"}
            f = ", ".join(
                f"{e.time_s:.2f} s"
                + ("" if e.value is None else f" {e.value:.0f}{unit.get(e.name, '')}")
                for e in alarms[:5]
            )
            more = f" (+{len(alarms) - 5} more)" if len(alarms) > 5 else ""
            kinds = "/".join(sorted({e.name for e in alarms}))
            lines.append(f"  {b.name}: {len(alarms)} {kinds} alarm(s): {f}{more}")
        else:
            lines.append(f"  {b.name}: no alarm")
        blind = [e for e in res.events if e.source == b.name and e.name == "breakage_blind"]
        if blind:
            at = ", ".join(f"{e.time_s:.2f} s" for e in blind[:5])
            lines.append(f"  {b.name}: blind (noise band ≥ the expected torque) from {at}"
                         f"{f' (+{len(blind) - 5} more)' if len(blind) > 5 else ''}")  # fmt: skip
    if torque_gate is not None:
        lines.append(_torque_gate_line(gated[1] / fs, gated[0] / fs,
                                       torque_gate.premise_samples / fs,
                                       torque_gate.inputs[0]))  # fmt: skip
    lines += skipped
    if plot is not None:
        from millsense.report.monitor_plots import plot_monitor

        data = {k: np.concatenate(v) for k, v in keep.items()}
        for b in blocks:  # what the summary reports, for the depth panel (decision 1704)
            if f"{b.name}/axial_depth" in data and hasattr(b, "estimates"):
                n_steps = len(data[f"{b.name}/axial_depth"])
                verdict = verdicts.get(b.name) or _engagement_verdict(b, _steady_cut(rec), fs)
                data.update(_depth_panel(b, verdict, n_steps, step, fs))
        # a breakage detector's axis in the unit of the torque it judges (phased: its members')
        judged = {b.name: getattr(getattr(b, "members", [b])[0], "signal_channels", ())
                  for b in blocks}  # fmt: skip
        units = {name: channels.get(sig[0], "") for name, sig in judged.items() if sig}
        plot_monitor(plot, data, fs, step, res.t0_s, str(sig_name), [b.name for b in blocks],
                     res.events, units)  # fmt: skip
        lines.append(f"wrote {plot}")
    return {"events": res.events, "lines": lines, "wall_s": wall}


def _torque_gate_line(
    open_s: float, at_speed_s: float, premise_s: float = 0.0, torque: str = ""
) -> str:
    """The summary's line on where the plan-free breakage detectors judged: the torque gate's
    steady cut (decisions 1706, 1723) against the time at speed, and on which torque
    (``torque``, the channel: with ``--machine`` the spindle DOB's, decision 1728). A gate that
    never opened is said as such: 'no alarm' would otherwise read as an intact tool. Time
    judged on seed 002's premise (``premise_s``: the recording started with the spindle at
    speed, so its first revolutions were taken as cut, in the air or not) is said apart
    (decision 1725): the torque did not show a cut there."""
    steady_s = max(open_s - premise_s, 0.0)
    on = f" on {torque}" if torque else ""
    line = (f"  breakage without a plan{on}: judged where the torque showed a steady cut, "
            f"{steady_s:.1f} s of {at_speed_s:.1f} s at speed")  # fmt: skip
    if premise_s > 0.0:
        line += (f"; {premise_s:.1f} s judged from the start on seed 002's premise (the "
                 "recording starts with the spindle at speed: its first revolutions were taken "
                 "as cut, in the air or not, and the thresholds learnt there)")  # fmt: skip
        return line
    if open_s == 0.0 and at_speed_s > 0.0:
        line += (" (no steady cut seen after air: nothing judged; a cut from the spindle's "
                 "first revolutions at speed reads as its drag; `millsense replay` with the "
                 "part's plan judges it)")  # fmt: skip
    return line


def _reliable(e: Any) -> bool:
    """A revolution's estimate is reported: σ ≥ RELIABLE_SIGMA and physical coefficients
    (K_t > 0, K_e ≥ 0: a cutting force never pulls the tool along; decision 1807), on a side
    cut's window (decision 1738)."""
    from millsense.monitoring.engagement import RELIABLE_SIGMA, side_cut_window

    return bool(e.reliability >= RELIABLE_SIGMA and e.kt_n_m2 > 0 and e.edge_n_m >= 0
                and side_cut_window(e.entry_rad, e.exit_rad))  # fmt: skip


def _steady_cut(rec: Any) -> np.ndarray | None:
    """Where a session's recording says the plan is steady in the cut (``plan/judged_torque``
    > 0: in cut, at speed, away from entries, steps and exits; decision 1622), or None."""
    if "plan/judged_torque" not in rec.channel_names:
        return None
    return np.asarray(rec.channel("plan/judged_torque"), dtype=np.float64) > 0


@dataclass(frozen=True)
class _EngagementVerdict:
    """What :func:`_engagement_summary` reports of an engagement block's revolutions
    (decisions 1807, 1558, 1698): the evaluated revolutions it counts (index into the block's
    estimates, end time s, estimate), the reliable ones among them, the averaged harmonics'
    estimate (None: fewer than AVERAGED_MIN_REVS revolutions), and ``kind``: ``"medians"``
    (the reliable revolutions' medians), ``"averaged"`` (the averaged fit, determined),
    ``"undetermined"`` or ``"none"`` (no revolution evaluated); ``where`` qualifies the
    counts (the plan's steady cut)."""

    timed: list[tuple[int, float, Any]]
    reliable: list[Any]
    avg: Any
    kind: str
    where: str


def _engagement_verdict(
    block: Any, steady: np.ndarray | None = None, fs: float = 1.0
) -> _EngagementVerdict:
    """:class:`_EngagementVerdict` of ``block``. With ``steady`` (per sample,
    :func:`_steady_cut`) only the revolutions that end where the plan is steady count: an
    entry's or an exit's revolutions are a changing engagement, not the cut's (decision 1558).

    The medians of the reliable revolutions (:func:`_reliable`) where at least half are and
    the revolutions' averaged harmonics (√n less noise than one revolution's) allow their
    median depth: within their depth interval (one interval: no second basin) widened by three
    standard errors of the median; else the averaged harmonics' estimate where they determine
    the depth; else not determined (a few revolutions of noise can pass the test by chance;
    decision 1807)."""
    from millsense.monitoring.engagement import depth_summary, determined
    from millsense.monitoring.torque_spectrum import AVERAGED_MIN_REVS

    timed = [(i, t, e) for i, (t, e) in enumerate(getattr(block, "estimates", []))
             if e is not None]  # fmt: skip
    where = ""
    if steady is not None and steady.any():
        n = steady.size
        timed = [(i, t, e) for i, t, e in timed if steady[min(max(round(t * fs), 0), n - 1)]]
        where = " in the plan's steady cut"
    every = [e for _, _, e in timed]
    if not every:
        return _EngagementVerdict(timed, [], None, "none", where)
    if getattr(block, "frame_unresolved", None) is not None:
        # the record's zero is not flute 0's and no offset fixes the depths (decision 1738)
        return _EngagementVerdict(timed, [], None, "misaligned", where)
    est = [e for e in every if _reliable(e)]
    avg = block.averaged([i for i, _, _ in timed]) if len(every) >= AVERAGED_MIN_REVS else None
    if 2 * len(est) >= len(every):
        if avg is None:
            return _EngagementVerdict(timed, est, avg, "medians", where)
        depth = depth_summary(est)
        se3 = 3 * depth.standard_error_m
        if avg.connected and (
            (not math.isfinite(avg.depth_low_m) or avg.depth_low_m - se3 <= depth.median_m)
            and depth.median_m <= avg.depth_high_m + se3
        ):  # fmt: skip
            return _EngagementVerdict(timed, est, avg, "medians", where)
    kind = "averaged" if avg is not None and determined(avg) else "undetermined"
    return _EngagementVerdict(timed, est, avg, kind, where)


def _depth_panel(
    block: Any, verdict: _EngagementVerdict, n_steps: int, step: int, fs: float
) -> dict[str, np.ndarray]:
    """Per plotted step (every ``step`` samples), what the depth panel marks as the summary's
    result (decision 1704): ``{name}/reported``, whether the revolution held there is one whose
    value the summary's medians take (``verdict.kind`` "medians": counted and
    :func:`_reliable`); where the summary reports the averaged harmonics (``"averaged"``) or
    the depths they allow (``"undetermined"``), no revolution is reported alone and
    ``{name}/averaged_depth`` and ``{name}/averaged_radial`` (the averaged fit's axial and
    radial depth; NaN where not determined), ``{name}/averaged_low`` and
    ``{name}/averaged_high`` (m; NaN/inf at the search range's ends) are given over the steps
    the averaged revolutions hold."""
    name = block.name
    out = {f"{name}/reported": np.zeros(n_steps, dtype=bool)}
    revs = list(getattr(block, "estimates", []))
    if not verdict.timed or not revs:
        return out
    t_end = np.array([t for t, _ in revs], dtype=np.float64)
    counted = np.zeros(t_end.size, dtype=bool)
    counted[[i for i, _, _ in verdict.timed]] = True
    held = np.searchsorted(t_end, np.arange(n_steps) * step / fs, side="right") - 1
    at = np.maximum(held, 0)
    if verdict.kind == "medians":
        ok = counted & np.array([e is not None and _reliable(e) for _, e in revs], dtype=bool)
        out[f"{name}/reported"] = (held >= 0) & ok[at]
        return out
    avg = verdict.avg
    if avg is None:
        return out
    span = (held >= 0) & counted[at]
    ok = verdict.kind == "averaged"
    depth = avg.estimate.axial_depth_m if ok else math.nan
    radial = avg.estimate.radial_depth_m if ok else math.nan
    for key, val in (("averaged_depth", depth), ("averaged_low", avg.depth_low_m),
                     ("averaged_high", avg.depth_high_m), ("averaged_radial", radial)):  # fmt: skip
        out[f"{name}/{key}"] = np.where(span, val, np.nan)
    return out


def _engagement_summary(
    block: Any,
    steady: np.ndarray | None = None,
    fs: float = 1.0,
    verdict: _EngagementVerdict | None = None,
) -> str:
    """One line: revolutions evaluated and the engagement over them (decisions 1807, 1558,
    1698), as :func:`_engagement_verdict` decides (``verdict``: already decided)."""
    v = verdict if verdict is not None else _engagement_verdict(block, steady, fs)
    return _engagement_line(block, v) + _harmonics_note(block, fs)


def _harmonics_note(block: Any, fs: float) -> str:
    """What the summary adds where the harmonics were limited by the Nyquist frequency
    (decision 1734): the harmonics fitted where fewer than the default, and the revolutions
    left unevaluated because theirs reached it; flute 0's angle where it was found (decision
    1738); and where the spindle angle came from (decision 1737)."""
    from millsense.monitoring.engagement import DEFAULT_HARMONICS

    note = ""
    k = int(getattr(block, "n_harmonics", DEFAULT_HARMONICS))
    if k < DEFAULT_HARMONICS:
        note += (f"; fitted on {k} tooth harmonics, those below the Nyquist frequency "
                 f"({0.5 * fs:g} Hz) at the recording's top speed")  # fmt: skip
    offset = float(getattr(block, "angle_offset_rad", 0.0))
    if offset != 0.0:
        note += (f"; flute 0 at {np.degrees(offset):.1f}° at the record's first sample, from the "
                 "steady cut's harmonics (decision 1738)")  # fmt: skip
    angle = getattr(block, "angle_channel", None)
    index = getattr(block, "index_channel", None)
    if angle is not None:
        note += f"; the spindle angle from the channel {angle}"
    elif index is not None:
        note += (f"; the spindle angle from the index pulse {index} (the line through its "
                 "last 8 marks)")  # fmt: skip
    rpm = getattr(block, "speed_rpm", None)
    if rpm is not None:
        source = getattr(block, "speed_source", "") or f"the set speed of {rpm:g} rev/min"
        note += f"; no speed channel: the spindle angle from {source}"
    aliased = int(getattr(block, "aliased_revolutions", 0))
    if aliased:
        note += (f"; {aliased} revolutions in the cut not evaluated: their tooth harmonics "
                 f"reach the Nyquist frequency ({0.5 * fs:g} Hz)")  # fmt: skip
    return note


def _times_words(ratio: float) -> str:
    """A misfit ratio in the summary's words."""
    return f"{ratio:.0f} times" if ratio < 1000 else "over 1000 times"


def _notch_words(index: float) -> str:
    """A notch index in the summary's words (the fit caps a depth too small to place it)."""
    return f"{index:.0f}" if index < 100 else "above 100"


def _engagement_line(block: Any, v: _EngagementVerdict) -> str:
    """The summary's line on the engagement as ``v`` decides it."""
    from millsense.monitoring.engagement import RELIABLE_SIGMA, depth_summary, side_cut_window

    where, est, avg = v.where, v.reliable, v.avg
    every = [e for _, _, e in v.timed]
    if v.kind == "misaligned":
        found = block.frame_unresolved
        return (
            f"  {block.name}: engagement not determined: the record's spindle-angle zero is not "
            f"flute 0's (the steady cut's harmonics fit {np.degrees(found.offset_rad):.0f}° "
            f"further on {_times_words(found.misfit_at_zero / max(found.misfit, 1e-300))} "
            "better), "
            f"and the depth's notch (harmonic {_notch_words(found.notch_index)}) lies beyond the "
            f"{block.n_harmonics} fitted, where an angle offset and a depth trade phase: only a "
            "spindle angle whose zero is flute 0 fixes the depths here (decision 1738)"
        )
    if v.kind == "none":
        if getattr(block, "aliased_revolutions", 0):
            return f"  {block.name}: no revolution evaluated{where}"
        return f"  {block.name}: no revolution evaluated{where} (no cut, or the torque is too low)"

    def med(v: list[float]) -> float:
        return float(np.median(v))

    head = f"  {block.name}: {len(est)} of {len(every)} revolutions{where} reliable"
    if v.kind == "medians":
        depth = depth_summary(est)
        return (
            f"{head} (σ ≥ {RELIABLE_SIGMA}): median axial depth "
            f"{1e3 * depth.median_m:.3f} mm (standard error "
            f"{1e3 * depth.standard_error_m:.3f} mm, a revolution's scatter "
            f"{1e3 * depth.scatter_m:.3f} mm), "
            + _engagement_values([e.radial_depth_m for e in est], [e.kt_n_m2 for e in est],
                                 [e.runout_m for e in est], [e.reliability for e in est],
                                 [e.edge_n_m for e in est], [e.edge_source for e in est])
        )  # fmt: skip
    if v.kind == "averaged":
        a = avg.estimate
        return (
            f"{head} alone; the {avg.n} revolutions' harmonics averaged: axial depth "
            f"{1e3 * a.axial_depth_m:.3f} mm "
            f"(profile interval {1e3 * avg.depth_low_m:.3f}–{1e3 * avg.depth_high_m:.3f} mm), "
            + _engagement_values([a.radial_depth_m], [a.kt_n_m2], [a.runout_m],
                                 [a.reliability], [a.edge_n_m], [a.edge_source])
        )  # fmt: skip
    allowed = ""
    if avg is not None:
        lo, hi = avg.depth_low_m, avg.depth_high_m
        basin = "" if avg.connected else " or in another basin"
        allowed = (f"; averaged over the {avg.n} revolutions the axial depth lies anywhere "
                   f"{depth_span(lo, hi)}{basin}")  # fmt: skip
    inside = [e for e in every if not side_cut_window(e.entry_rad, e.exit_rad)]
    why = ("the torque's tooth harmonics do not fix the engagement here (e.g. a full slot with 3 "
           "or more flutes, or a light cut in the signal's noise)")  # fmt: skip
    if 2 * len(inside) > len(every):
        # decision 1738: most windows inside the half-turn
        entry = float(np.degrees(med([e.entry_rad for e in inside])))
        exit_ = float(np.degrees(med([e.exit_rad for e in inside])))
        why = (f"most revolutions' engagement window lies inside the half-turn (median "
               f"{entry:.0f}° to {exit_:.0f}°), which no steady side cut gives: a transient, "
               "or a spindle angle whose zero is not the tool's reference (decision 1738)")
    return (
        f"  {block.name}: engagement not determined: {len(est)} of {len(every)} "
        f"revolutions{where} reliable (σ ≥ {RELIABLE_SIGMA}, K_t > 0, K_e ≥ 0, a side cut's "
        f"window; median σ {med([e.reliability for e in every]):.2f}){allowed}; {why}"
    )


def depth_span(low_m: float, high_m: float) -> str:
    """The depths an undetermined engagement allows, in words (an infinite bound: the search's
    own end)."""
    if math.isfinite(low_m) and math.isfinite(high_m):
        return f"from {1e3 * low_m:.2f} to {1e3 * high_m:.2f} mm"
    if math.isfinite(low_m):
        return f"from {1e3 * low_m:.2f} mm to the largest depth searched"
    if math.isfinite(high_m):
        return f"from the smallest depth searched to {1e3 * high_m:.2f} mm"
    return "in the whole range searched"


def _engagement_values(
    dr: list[float], kt: list[float], runout: list[float], sigma: list[float],
    ke: list[float], source: list[float],
) -> str:  # fmt: skip
    """The summary's radial depth, K_t, runout, reliability and K_e (medians), in words."""

    def med(v: list[float]) -> float:
        return float(np.median(v))

    return (
        f"radial depth {1e3 * med(dr):.3f} mm, K_t {1e-6 * med(kt):.0f} N/mm², runout "
        f"{1e6 * med(runout):.1f} µm, reliability {med(sigma):.3f}, K_e "
        f"{1e-3 * med(ke):.1f} N/mm ({_edge_source(source)})"
    )


#: Where the engagement monitor's K_e came from (``EngagementEstimate.edge_source``, decision
#: 1806), as the summary line says it.
_EDGE_SOURCES = {
    0: "not fitted",
    1: "from the tooth harmonics",
    2: "from the mean torque",
    3: "harmonics only, no air torque known: less reliable",
}


def _edge_source(sources: list[float]) -> str:
    """The most frequent source of K_e over the revolutions, in words."""
    vals, counts = np.unique(np.asarray(sources, dtype=int), return_counts=True)
    return _EDGE_SOURCES.get(int(vals[np.argmax(counts)]), "unknown")


def _grouped(blocks: list[Any]) -> list[Any]:
    """Chatter monitors on the same signal run as one :class:`ChatterGroup` (one comb filter
    for all criteria) and breakage detectors on one speed channel as one
    :class:`BreakageGroup` (one compiled call per chunk for all, decision 1536): same outputs
    and events, less work; other monitors unchanged."""
    from millsense.monitoring.breakage import BreakageBlock, BreakageGroup
    from millsense.monitoring.breakage_phased import PhasedBreakage
    from millsense.monitoring.chatter import ChatterGroup, ChatterMonitor

    chatter = [b for b in blocks if isinstance(b, ChatterMonitor)]
    breakage = [b for b in blocks if isinstance(b, BreakageBlock)]
    phased = [b for b in blocks if isinstance(b, PhasedBreakage)]
    tooth: list[BreakageBlock | PhasedBreakage] = [*breakage, *phased]
    if len({(b.speed_channel, b.n_flutes) for b in tooth}) > 1:
        breakage, phased = [], []  # detectors on different speeds or tools stay apart
    groups: list[Any] = []
    inside: list[Any] = []
    if len(chatter) >= 2:
        groups.append(ChatterGroup(chatter))
        inside += chatter
    if len(phased) == 1 and breakage:  # the others in the phased detector's compiled call
        groups.append(phased[0].with_companions(breakage))
        inside += [phased[0], *breakage]
    elif len(breakage) >= 2:
        groups.append(BreakageGroup(breakage))
        inside += breakage
    grouped = {id(b) for b in inside}
    return [*groups, *(b for b in blocks if id(b) not in grouped)]


def _session_machine(rec: Any) -> tuple[Any, str] | None:
    """The machine file a session recording's observer ran on: metadata ``machine_file`` where
    it is a file, else the commissioned file shipped for its ``machine`` (what ``run`` and
    ``replay`` take without ``--machine-file``), or None."""
    from millsense.core.config import MachineConfig
    from millsense.core.presets import commissioned_machine, load_preset

    name = rec.metadata.get("machine_file")
    if not isinstance(name, str) or not name:
        return None
    if Path(name).is_file():
        return load_preset(MachineConfig, name), name
    machine = rec.metadata.get("machine")
    return commissioned_machine(machine) if isinstance(machine, str) and machine else None


def _observer_response(machine: Any, where: str, fs: float) -> Any:
    """The spindle observer's response of ``machine`` tabulated to the Nyquist frequency
    (:func:`~millsense.estimation.from_config.spindle_estimate_response`, decision 1554)."""
    from millsense.estimation.from_config import spindle_estimate_response
    from millsense.monitoring.engagement import OBSERVER_RESPONSE_REL_ERROR, TorqueResponse

    response, switch = spindle_estimate_response(machine, where)
    return TorqueResponse.from_function(response, fs / 2.0, switch,
                                        rel_error=OBSERVER_RESPONSE_REL_ERROR)  # fmt: skip


def _metadata_rpm(rec: Any) -> float | None:
    """The recording's stated spindle speed (metadata ``spindle_rpm``, e.g. from an import map's
    ``[metadata]`` or ``--spindle-rpm`` of ``millsense import``), if it is a number."""
    md = rec.metadata.get("spindle_rpm")
    if isinstance(md, (int, float)) and not isinstance(md, bool) and math.isfinite(md):
        return float(md)
    return None


def _flutes(flutes: int | None, rec: Any, vp: Any) -> int:
    from millsense.core.errors import InputDataError

    n = flutes
    if n is None:
        md = rec.metadata.get("flutes")
        if isinstance(md, (int, float)):
            n = int(md)
        elif vp is not None and isinstance(vp.metadata.get("tool"), dict):
            n = int(vp.metadata["tool"].get("flutes", 2))
        else:
            n = 2
    if n < 1:
        raise InputDataError(f"--flutes: must be ≥ 1, got {n}")
    return n
