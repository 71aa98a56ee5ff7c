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
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import typer

from millsense.cli.main import app
from millsense.cli.monitor_engagement import (
    EngagementCut,
    Place,
    depth_panel_of_cuts,
    engagement_cuts,
    engagement_events,
    engagement_lines,
    steady_cut_mask,
)

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
    flute0: float | None = typer.Option(
        None,
        "--flute0-deg",
        help="Engagement: flute 0's angle [deg] where the spindle-angle channel reads 0 or at "
        "the index mark (a clamping's constant: the 'flute 0 at' of an earlier record's "
        "summary); default: found from the steady cut's harmonics.",
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
            position=position, air_torque=air_torque, flute0_deg=flute0, on_progress=update,
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
    flute0_deg: float | None = None,
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
    options = _monitor_options(feed_per_tooth, air_s, cut_s, position, air_torque, flute0_deg)
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
    flute0_deg: float | None = None,
) -> dict[str, Any]:
    """The options of the engagement and contact monitors, checked (one-line errors)."""
    from millsense.core.errors import ConfigError

    opts: dict[str, Any] = {}
    if flute0_deg is not None:
        if not np.isfinite(flute0_deg):
            raise ConfigError(f"--flute0-deg: must be a finite angle in degrees, got {flute0_deg}")
        opts["engagement.flute0_deg"] = float(flute0_deg)
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
    # the engagement's steady cuts, each judged apart (decision 1739): summary lines and events
    cuts: dict[str, list[EngagementCut]] = {}
    place = _cut_place(rec, nc_channel, locate, fs)
    for b in blocks:
        if b.name == "engagement" and hasattr(b, "estimates"):
            cuts[b.name] = engagement_cuts(b, steady_cut_mask(rec), fs)
            res.events.extend(engagement_events(b, cuts[b.name], fs, float(rec.t0_s), place))
    write_event_log(out, res.events, recording=recording)
    seconds = rec.n_samples / fs
    speed = seconds / max(wall, 1e-9)
    lines = [
        f"wrote {out}: {len(res.events)} events from {', '.join(names)} on "
        f"{seconds:.1f} s of {recording.name} in {wall:.2f} s "
        f"({speed:.{0 if speed >= 10 else 1}f}x real time)"
    ]
    for b in blocks:
        alarms = [e for e in res.events if e.source == b.name and e.kind == EventKind.ALARM]
        contacts = [e for e in res.events if e.source == b.name and e.name == "contact"]
        if contacts:
            e = contacts[0]
            lines.append(f"  {b.name}: contact at {e.time_s:.5f} s, position {e.value:.6g}")
        elif b.name in cuts:
            lines += engagement_lines(b, cuts[b.name], fs, float(rec.t0_s), place)
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
            lines.append(f"  {b.name}: no alarm{_chatter_seen(b)}")
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
            if f"{b.name}/axial_depth" in data and b.name in cuts:
                n_steps = len(data[f"{b.name}/axial_depth"])
                data.update(depth_panel_of_cuts(b, cuts[b.name], n_steps, step, fs))
        # a breakage detector's axis in the unit of the torque it judges (phased: its members')
        judged = {b.name: getattr(getattr(b, "members", [b])[0], "signal_channels", ())
                  for b in blocks}  # fmt: skip
        units = {name: channels.get(sig[0], "") for name, sig in judged.items() if sig}
        plot_monitor(plot, data, fs, step, res.t0_s, str(sig_name), [b.name for b in blocks],
                     res.events, units)  # fmt: skip
        lines.append(f"wrote {plot}")
    return {"events": res.events, "lines": lines, "wall_s": wall}


def _chatter_seen(b: object) -> str:
    """What a chatter monitor without an alarm judged (decision 1689): nothing where no
    window was decided or its cutting gate never opened ("no alarm" alone would read as a
    stable cut), the windows judged where the gate closed on some; "" for another monitor or
    where every window was judged."""
    decided = getattr(b, "windows_decided", None)
    judged = getattr(b, "windows_judged", 0)
    if decided is None or (decided > 0 and judged == decided):
        return ""
    if decided == 0:
        return (" (no window decided: the spindle speed was never steady over a window, or the "
                "record is shorter than one)")  # fmt: skip
    if judged == 0:
        return (f", but nothing judged: in none of its {decided} windows did the tooth-passing "
                "line stand out of the spectrum or the mean off the air (the cutting gate, "
                "decision 1531): no cut, or a cut in the signal's noise")  # fmt: skip
    hop = float(getattr(getattr(b, "settings", None), "hop_s", math.nan))
    return (f" (judged {judged * hop:.1f} s of the {decided * hop:.1f} s decided: the windows "
            "the cutting gate took for a cut)")  # fmt: skip


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


def _cut_place(rec: Any, nc_channel: str | None, locate: Any, fs: float) -> Place | None:
    """Where an engagement cut lies (decision 1739): the recorded NC line at a sample, and the
    plan's tool-tip position on that line nearest the sample's time (``locate``); None where
    the recording has no NC line and there is no plan."""
    if nc_channel is None and locate is None:
        return None
    n = int(rec.n_samples)

    def place(sample: int) -> tuple[int | None, float | None, float | None, float | None]:
        k = min(max(sample, 0), max(n - 1, 0))
        from millsense.io.recording_reader import channel_window

        nc = None
        if nc_channel is not None and n > 0:
            line = float(np.asarray(channel_window(rec, nc_channel, k, k + 1))[0])
            nc = int(line) if math.isfinite(line) and line >= 0 else None
        if locate is None:
            return nc, None, None, None
        return locate(float(rec.t0_s) + k / fs, nc)

    return place


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
