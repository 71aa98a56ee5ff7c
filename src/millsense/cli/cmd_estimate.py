"""``millsense estimate``: replay a recording through the estimators built from a machine file."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Any

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError


def _methods(text: str) -> list[str]:
    from millsense.estimation.from_config import METHODS

    if text == "all":
        return list(METHODS)
    out = [m.strip() for m in text.split(",") if m.strip()]
    for m in out:
        if m not in METHODS:
            raise ConfigError(f"--method: unknown method '{m}' (one of {', '.join(METHODS)}, all)")
    if not out:
        raise ConfigError("--method: empty")
    return out


@app.command()
def estimate(
    recording: Path = typer.Argument(..., help="Recording to replay (.h5)."),
    machine: str = typer.Option(..., "--machine", help="Machine preset or .toml (identified)."),
    method: str = typer.Option("feed", "--method", help="feed, raw, medob, spindle or all."),
    axes: str | None = typer.Option(None, "--axes", help="Axes, e.g. x,y,z (default: all)."),
    out: Path = typer.Option(..., "-o", "--output", help="Estimates recording to write (.h5)."),
    plot: Path | None = typer.Option(
        None, "--plot", help="PNG of estimate vs truth (or the measured force)."
    ),
    flutes: int | None = typer.Option(None, "--flutes", help="Teeth (default: metadata or 2)."),
    chunk: int = typer.Option(1000, "--chunk", help="Samples per chunk."),
    idle: str = typer.Option(
        "none",
        "--idle",
        help="Idle (air-cut) compensation: none; auto (the air phase at cutting feed before "
        "the cut, from the recording's metadata or --air-s); or an air-run recording FILE.h5. "
        "The estimates' mean in air per direction of motion is subtracted.",
    ),
    air_s: str | None = typer.Option(
        None, "--air-s", help="Air phase START:END [s] (of the recording or the --idle FILE)."
    ),
    harmonics: bool = typer.Option(
        False,
        "--harmonics",
        help="feed: add the tooth harmonics (<= 200 Hz) of the commanded spindle speed "
        "(spindle/speed_cmd) to the disturbance model (Aslan Eq. 3.16-3.20); teeth from "
        "--flutes or the recording's metadata.",
    ),
    json_out: str | None = typer.Option(
        None,
        "--json",
        help="Write the estimates and the comparison with truth as JSON (- = stdout).",
    ),
    reference: str = typer.Option(
        "auto",
        "--reference",
        help="Compare with: truth (truth/<axis>/load of a simulation), dynamometer (a measured "
        "force channel dynamometer/<axis>/force, N, the load on the axis), or auto (truth if "
        "recorded, else the dynamometer).",
    ),
    band_hz: float | None = typer.Option(
        None,
        "--band-hz",
        help="feed [Hz]: tune each estimator for the least noise that keeps its compensated FRF "
        "within ±1 dB up to this band on the identified model (default: the widest ±3 dB band "
        "under the noise limit); overrides the machine file's estimator q_nm2_s/band_hz.",
    ),
) -> None:
    """Estimate cutting loads from drive signals (same streaming engine as live runs)."""
    from millsense.cli.progress import progress_bar
    from millsense.io.safe_output import check_outputs, write_text

    inputs: dict[str, str | Path] = {
        "the recording": recording,
        "the machine file": machine,
        "the --idle recording": idle,
    }
    check_outputs(inputs, {"-o": out, "--plot": plot, "--json": json_out}, {"-o": ".h5"})
    if json_out not in (None, "-"):
        target = Path(str(json_out))
        if target.is_dir() or not target.parent.is_dir():
            raise ConfigError(f"--json {json_out}: not a file in an existing folder")

    with progress_bar("estimating", 1.0) as update:
        summary = run_estimate(
            recording=recording,
            machine=machine,
            method=method,
            axes=axes,
            out=out,
            plot=plot,
            flutes=flutes,
            chunk=chunk,
            idle=idle,
            air_s=air_s,
            harmonics=harmonics,
            band_hz=band_hz,
            reference=reference,
            on_progress=update,
        )
    for note in summary["notes"]:
        typer.echo(f"millsense: note: {note}", err=True)
    for warning in summary["warnings"]:
        typer.echo(f"millsense: warning: {warning}", err=True)
    if json_out is not None:
        text = json.dumps(summary_json(summary, out)) + "\n"
        if json_out == "-":
            typer.echo(text, nl=False)
        else:
            write_text(json_out, text)
        if json_out == "-":
            return
    if summary["comparisons"]:
        _print_table(summary["comparisons"], summary["units"], summary.get("references", {}))
    typer.echo(
        f"wrote {out}: {len(summary['estimates'])} estimates, {summary['samples']} samples "
        f"in {summary['wall_s']:.2f} s "
        f"({summary['seconds'] / max(summary['wall_s'], 1e-9):.1f}x real time, after "
        f"{summary['setup_s']:.1f} s building the estimators)"
    )


def summary_json(summary: dict[str, Any], out: Path) -> dict[str, Any]:
    """The run as JSON-ready data: estimates, comparison with truth, notes, timing.

    ``comparisons`` rows carry the amplitudes (N or N·m) at the tooth harmonics beside the
    relative errors, so that a script can apply its own significance rule.
    """
    rows = []
    for c in summary["comparisons"]:
        rows.append(
            {
                "method": c.method,
                "axis": c.axis,
                "unit": summary["units"].get(c.axis, ""),
                "reference": summary.get("references", {}).get(c.axis, ""),
                "tooth_hz": c.tooth_hz,
                "window_samples": [int(c.window[0]), int(c.window[1])],
                "mean_est": c.mean_est,
                "mean_truth": c.mean_true,
                "mean_error": c.mean_error,
                "harmonics": [int(k) for k in c.harmonics],
                "amplitude_est": [float(v) for v in c.est_amp],
                "amplitude_truth": [float(v) for v in c.true_amp],
                "error": [float(v) for v in c.error],
            }
        )
    return {
        "out": str(out),
        "samples": summary["samples"],
        "seconds": summary["seconds"],
        "wall_s": summary["wall_s"],
        "setup_s": summary["setup_s"],
        "estimates": [
            {"method": m, "axis": a, "channel": ch, "delay_samples": d}
            for m, a, ch, d in summary["estimates"]
        ],
        "comparisons": rows,
        "notes": list(summary["notes"]),
        "warnings": list(summary.get("warnings", [])),
    }


#: A relative error is shown only where the truth is at least this fraction of the largest
#: truth quantity (mean or harmonic amplitude) of its unit: a relative error of a force that
#: is not there (Z of a flat slot, a harmonic of ~0 N) says nothing.
SIGNIFICANT_FRACTION = 0.01


def _print_table(
    comparisons: list[Any], units: dict[str, str], refs: dict[str, str] | None = None
) -> None:
    from rich.console import Console
    from rich.table import Table

    n = len(comparisons[0].harmonics)
    largest: dict[str, float] = {}
    for c in comparisons:
        u = units.get(c.axis, "")
        top = max(abs(c.mean_true), float(max(c.true_amp, default=0.0)))
        largest[u] = max(largest.get(u, 0.0), top)

    def rel(err: float, truth: float, unit: str, fmt: str) -> str:
        if abs(truth) < SIGNIFICANT_FRACTION * largest[unit] or largest[unit] == 0.0:
            return "–"
        return f"{100 * err:{fmt}} %"

    measured = sorted({r for r in (refs or {}).values() if not r.startswith("truth/")})
    against = f"measured ({', '.join(measured)})" if measured else "truth"
    table = Table(
        title=f"estimate vs {against} (steady cut): amplitude error per tooth harmonic",
        caption="– : reference below 1 % of the largest of its unit (no relative error)",
    )
    ref_col = "mean ref" if measured else "mean truth"
    for col in ("axis", "unit", "method", "tooth Hz", "mean est", ref_col, "mean err"):
        table.add_column(col, justify="right")
    for k in range(1, n + 1):
        table.add_column(f"{k}×", justify="right")
    for c in comparisons:
        u = units.get(c.axis, "")
        table.add_row(
            c.axis,
            u,
            c.method,
            f"{c.tooth_hz:.1f}",
            f"{c.mean_est:.2f}",
            f"{c.mean_true:.2f}",
            rel(c.mean_error, c.mean_true, u, "+.1f"),
            *(rel(e, t, u, ".0f") for e, t in zip(c.error, c.true_amp, strict=True)),
        )
    con = Console()
    if not con.is_terminal:
        con = Console(width=160)
    con.print(table)


def run_estimate(
    *,
    recording: Path,
    machine: str,
    method: str,
    axes: str | None,
    out: Path,
    plot: Path | None = None,
    flutes: int | None = None,
    chunk: int = 1000,
    idle: str = "none",
    air_s: str | None = None,
    harmonics: bool = False,
    band_hz: float | None = None,
    reference: str = "auto",
    on_progress: Any = None,
    segment: tuple[int, int] | None = None,
) -> dict[str, Any]:
    """Build the estimators, replay ``recording`` and write ``out`` while running.

    Returns a summary: samples, seconds, wall_s, estimates (method, axis, channel, delay),
    comparisons (:class:`~millsense.report.estimate_metrics.HarmonicComparison`, empty without
    truth), notes and idle ((method, axis) → :class:`~millsense.ident.idle_table.DirectionIdle`
    subtracted, empty with ``idle="none"``).

    ``harmonics``: the ``feed`` estimators add the tooth harmonics of the commanded spindle
    speed (teeth: ``flutes``, else the recording's ``flutes`` metadata, else 2).

    ``band_hz``: the ``feed`` estimators get the least-noise Q that keeps this band
    (:func:`~millsense.estimation.from_config.with_feed_band`); None keeps the machine file's rule.

    ``reference``: what the estimates are compared with (:func:`reference_channel`, decision
    1702): ``truth``, ``dynamometer`` or ``auto``.

    ``idle``: ``none``; ``auto`` — the air phase of ``recording`` itself
    (:func:`~millsense.estimation.feed.idle_compensation.find_air_window`, or ``air_s``); a path —
    an air-run recording (its air phase found the same way, or ``air_s``). The same estimators
    run over the air phase first; their mean there per direction of the commanded velocity is
    subtracted from the estimates (decision "Idle compensation in estimate").

    ``segment``: samples ``[start, stop)`` only (a
    :class:`~millsense.io.recording_reader.RecordingSegment`; ``millsense batch``).

    Raises
    ------
    ConfigError, InputDataError, RecordingError
        One-line user errors (bad preset or key, unknown method or axis, missing channel).
    """
    from millsense.core.config import MachineConfig
    from millsense.core.errors import InputDataError
    from millsense.core.presets import load_preset
    from millsense.io.recording_reader import open_recording

    if chunk < 1:
        raise InputDataError(f"--chunk: must be ≥ 1, got {chunk}")
    if reference not in REFERENCES:
        raise ConfigError(f"--reference {reference!r}: one of {', '.join(REFERENCES)}")
    methods = _methods(method)
    mcfg = load_preset(MachineConfig, machine)
    with contextlib.ExitStack() as stack:
        rec = open_recording(recording, segment)
        if hasattr(rec, "close"):
            stack.callback(rec.close)
        return _run_estimate(
            rec,
            stack,
            recording=recording,
            machine=machine,
            mcfg=mcfg,
            methods=methods,
            method=method,
            axes=axes,
            out=out,
            plot=plot,
            flutes=flutes,
            chunk=chunk,
            idle=idle,
            air_s=air_s,
            harmonics=harmonics,
            band_hz=band_hz,
            reference=reference,
            on_progress=on_progress,
        )


#: What ``--reference`` accepts.
REFERENCES = ("auto", "truth", "dynamometer")


def dynamometer_channel(axis: str) -> str:
    """The measured-force channel compared with an estimate of ``axis`` (decision 1702):
    ``dynamometer/<axis>/force``, or ``dynamometer/tool/force_x`` for ``tool_x``."""
    if axis.startswith("tool_"):
        return f"dynamometer/tool/force_{axis.removeprefix('tool_')}"
    return f"dynamometer/{axis}/force"


def reference_channel(axis: str, have: set[str], reference: str = "auto") -> str | None:
    """The channel an estimate of ``axis`` is compared with, or None: the simulator's truth
    (``truth``), a measured force (``dynamometer``), or the truth if recorded, else the
    dynamometer (``auto``)."""
    from millsense.estimation.from_config import truth_channel

    order = {
        "truth": [truth_channel(axis)],
        "dynamometer": [dynamometer_channel(axis)],
        "auto": [truth_channel(axis), dynamometer_channel(axis)],
    }[reference]
    return next((c for c in order if c in have), None)


def _run_estimate(
    rec: Any,
    stack: contextlib.ExitStack,
    *,
    recording: Path,
    machine: str,
    mcfg: Any,
    methods: list[str],
    method: str,
    axes: str | None,
    out: Path,
    plot: Path | None,
    flutes: int | None,
    chunk: int,
    idle: str,
    air_s: str | None,
    harmonics: bool,
    band_hz: float | None,
    on_progress: Any,
    reference: str = "auto",
) -> dict[str, Any]:
    """:func:`run_estimate` on an opened recording (``rec``: a windowed reader or, for an
    interrupted recording, the recovered one in memory); files it opens are closed by
    ``stack``. Nothing per sample of the whole record is held (decision 0961)."""
    import time

    import numpy as np

    from millsense.core.errors import InputDataError
    from millsense.core.plausibility import HeldLoad
    from millsense.estimation.from_config import build_estimators
    from millsense.ident.idle_table import DIRECTIONS
    from millsense.io import RecordingWriter
    from millsense.streaming.engine import Pipeline, run
    from millsense.streaming.sources import RecordingSource

    if axes is None:
        axis_list = [a for a in mcfg.axes if f"{a}/current_cmd" in rec.channel_names]
        if not axis_list:
            raise InputDataError(
                f"{recording}: no channel '<axis>/current_cmd' for any axis of {mcfg.name}"
            )
    else:
        axis_list = [a.strip() for a in axes.split(",") if a.strip()]
    t_setup = time.perf_counter()
    if band_hz is not None:
        from millsense.estimation.from_config import with_feed_band

        mcfg = with_feed_band(mcfg, axis_list, band_hz)
    air = _air_phase(idle, air_s, rec, recording, stack)
    idle_notes: list[str] = []
    if air is not None and "feed" in methods:
        from millsense.estimation.feed.idle_compensation import with_air_r

        mcfg, r_air = with_air_r(mcfg, axis_list, air[0], air[1], air[2])
        idle_notes += [
            f"idle: feed {a}: R from the air phase {r:.3g} N²·m²" for a, r in r_air.items()
        ]
    built = build_estimators(
        mcfg,
        methods,
        axis_list,
        rec.sample_rate_hz,
        where=machine,
        skip_unavailable=method == "all",
        harmonic_teeth=_teeth(flutes, rec) if harmonics else None,
    )
    idle_tables: dict[tuple[str, str], Any] = {}
    if air is not None:
        idle_tables, notes = _idle_tables(air, built, chunk)
        idle_notes += notes
    setup_s = time.perf_counter() - t_setup
    blocks: list[Any] = list(built.blocks)
    all_estimates = built.estimates + built.derived_estimates
    if idle_tables:
        from millsense.estimation.feed.idle_compensation import IdleCompensatedBlock

        blocks = [
            IdleCompensatedBlock(b, a, c, idle_tables[(m, a)], d)
            for b, (m, a, c, d) in zip(built.blocks, built.estimates, strict=True)
        ]
    blocks += built.derived
    pipeline = Pipeline(blocks)
    pipeline.check_inputs(rec.channel_names, str(recording))
    have = set(rec.channel_names)
    copies = sorted({c for b in blocks for c in b.inputs if c in have})
    est_axes = list(dict.fromkeys(a for _, a, _, _ in all_estimates))
    refs = {a: r for a in est_axes if (r := reference_channel(a, have, reference)) is not None}
    extra = [*refs.values(), "spindle/speed", "truth/spindle/torque", "truth/process/engagement"]
    copies += [c for c in extra if c in have and c not in copies]
    # only the channels written or read are replayed; the others are never read
    source = RecordingSource(rec, name=str(recording), channels=copies)
    streamed, traces = None, None
    pre_warnings: list[str] = []
    if plot is not None or refs:
        try:
            streamed, traces = _compare_setup(rec, all_estimates, axis_list, flutes, plot, refs)
        except InputDataError as exc:
            # a recording whose truth cannot be compared (it never cuts, the steady cut is too
            # short) is still estimated, with a warning, unless a plot was asked for
            if plot is not None:
                raise InputDataError(f"{recording}: --plot: {exc}") from None
            pre_warnings.append(f"{recording}: no comparison with the reference: {exc}")
    infos = [rec.info(c) for c in copies] + pipeline.output_channels()
    meta = {
        "source": "millsense estimate",
        "recording": str(recording),
        "machine": mcfg.name,
        "machine_file": machine,
        "methods": ",".join(methods),
        "estimate_delays_samples": json.dumps({c: d for _, _, c, d in all_estimates}),
        "idle": idle,
    }
    if idle_tables:
        meta["idle_tables"] = json.dumps(
            {
                f"{m}/{a}": {
                    d: (None if np.isnan(v) else v)
                    for d, v in zip(DIRECTIONS, t.value, strict=True)
                }
                for (m, a), t in idle_tables.items()
            }
        )
    writer = RecordingWriter(out, rec.sample_rate_hz, infos, metadata=meta, flush_every_s=0.5)
    total = max(rec.n_samples, 1)
    # the largest |mean| of each estimate over 10 ms windows (and its time, s) and its
    # non-finite count, for the plausibility checks (decision 1690)
    held = {c: HeldLoad(rec.sample_rate_hz) for _, _, c, _ in all_estimates}
    bad: dict[str, int] = {}

    def sink(ch: Any, outputs: dict[str, np.ndarray], _ev: Any) -> None:
        data = {c: ch.data[c] for c in copies}
        data.update(outputs)
        writer.append(data)
        for _, _, c, _ in all_estimates:
            v = outputs.get(c)
            if v is None or not len(v):
                continue
            fin = np.isfinite(v)
            bad[c] = bad.get(c, 0) + int(v.size - fin.sum())
            held[c].add(ch.start, np.where(fin, v, 0.0))
        if streamed is not None:
            streamed.add(ch.start, data)
        if traces is not None:
            traces.add(ch.start, data)

    t0 = time.perf_counter()
    try:
        res = run(
            source,
            pipeline,
            chunk,
            sink=sink,
            on_progress=(lambda d: on_progress(d / total)) if on_progress else None,
            collect=False,
        )
    finally:
        writer.close()
    wall = time.perf_counter() - t0
    peaks = {c: (h.peak, rec.t0_s + h.at / rec.sample_rate_hz) for c, h in held.items()
             if h.at >= 0}  # fmt: skip
    findings = _estimate_findings(mcfg, all_estimates, peaks, bad, str(recording))
    for w in pre_warnings:
        findings.warn(w)
    comparisons = streamed.results() if streamed is not None else []
    if plot is not None and traces is not None:
        from millsense.report.estimate_plots import plot_traces

        units = {e.axis: rec.info(e.truth).unit for e in streamed.estimates} if streamed else {}
        plot_traces(plot, rec.sample_rate_hz, traces, comparisons, units, refs)
    return {
        "samples": rec.n_samples,
        "seconds": rec.n_samples / rec.sample_rate_hz,
        "wall_s": wall,
        "setup_s": setup_s,
        "estimates": all_estimates,
        "units": {a: rec.info(r).unit for a, r in refs.items()},
        "references": refs,
        "comparisons": comparisons,
        "notes": built.notes + idle_notes,
        "warnings": findings.warnings,
        "idle": idle_tables,
        "events": res.events,
    }


def _estimate_findings(
    mcfg: Any,
    estimates: list[Any],
    peaks: dict[str, tuple[float, float]],
    bad: dict[str, int],
    where: str,
) -> Any:
    """Plausibility of the estimates (decision 0941): non-finite samples, and the load a
    linear axis holds (``peaks``: the largest |mean| over 10 ms and its time, decision 1690)
    against the machine's ``limits.axis_force_n`` (an estimate beyond what the drives can push
    points at a wrong machine file: K_t, lead, or the recording of another machine)."""
    from millsense.core.plausibility import Findings, check_against_limits

    findings = Findings()
    for m, a, c, _ in estimates:
        if bad.get(c, 0):
            findings.warn(f"{where}: {m} estimate of {a} has {bad[c]} non-finite samples")
        cfg = mcfg.axes.get(a)
        if cfg is not None and cfg.kind == "linear" and c in peaks:
            check_against_limits(
                mcfg.limits,
                f"{where}: {m} estimate of axis {a} (over 10 ms, largest at "
                f"{peaks[c][1]:.3f} s)",
                findings,
                peak_force_n=peaks[c][0],
            )
    return findings


def _air_phase(
    idle: str, air_s: str | None, rec: Any, recording: Path, stack: contextlib.ExitStack
) -> tuple[Any, slice, str] | None:
    """(recording holding the air phase, its samples, its name) for ``--idle``, or None; an
    air-run file is opened for windowed reads and closed by ``stack``."""
    from millsense.core.errors import InputDataError
    from millsense.estimation.feed.idle_compensation import find_air_window, parse_air_window
    from millsense.io.recording_reader import open_recording

    if idle == "none":
        if air_s is not None:
            raise InputDataError("--air-s: needs --idle auto or --idle FILE.h5")
        return None
    if idle == "auto":
        src, where = rec, str(recording)
    else:
        path = Path(idle)
        if path.suffix != ".h5":
            raise InputDataError(f"--idle {idle!r}: none, auto or an air-run recording (.h5)")
        if not path.is_file():
            raise InputDataError(f"--idle: no file {path}")
        src, where = open_recording(path), str(path)
        if hasattr(src, "close"):
            stack.callback(src.close)
        if src.sample_rate_hz != rec.sample_rate_hz:
            raise InputDataError(
                f"--idle {path}: sampled at {src.sample_rate_hz:g} Hz, the recording at "
                f"{rec.sample_rate_hz:g} Hz"
            )
    window = parse_air_window(air_s, src, where) if air_s else find_air_window(src, where)
    return src, window, where


def _idle_tables(
    air: tuple[Any, slice, str], built: Any, chunk: int
) -> tuple[dict[tuple[str, str], Any], list[str]]:
    """Idle tables of every estimate over the air phase (copies of the built, unused
    estimator blocks: they are reset before the run), and notes."""
    import copy

    from millsense.estimation.feed.idle_compensation import measure_idle

    src, window, where = air
    fresh = copy.deepcopy(built)
    tables = measure_idle(src, fresh.blocks, fresh.estimates, window, where, chunk)
    fs = src.sample_rate_hz
    notes = [f"idle: air phase {window.start / fs:.3f}-{window.stop / fs:.3f} s of {where}"]
    for (m, a), t in tables.items():
        vals = ", ".join(
            f"{d} {v:+.4g} {t.unit}"
            for d, v, n in zip(("v<0:", "at rest:", "v>0:"), t.value, t.samples, strict=True)
            if n > 0
        )
        notes.append(f"idle {m} {a}: {vals or 'no direction seen (not compensated)'}")
    return tables, notes


def _teeth(flutes: int | None, rec: Any) -> int:
    """Cutter teeth: ``--flutes``, else the recording's ``flutes`` metadata, else 2."""
    from millsense.core.errors import InputDataError

    n_teeth = flutes
    if n_teeth is None:
        md = rec.metadata.get("flutes", 2)
        n_teeth = int(md) if isinstance(md, (int, float)) else 2
    if n_teeth < 1:
        raise InputDataError(f"--flutes: must be ≥ 1, got {n_teeth}")
    return n_teeth


def _compare_setup(
    rec: Any,
    estimates: list[tuple[str, str, str, int]],
    axis_list: list[str],
    flutes: int | None,
    plot: Path | None,
    refs: dict[str, str],
) -> tuple[Any, Any]:
    """The streamed estimate-vs-reference comparison and plot traces, set up before the run
    (cut window and spindle speed read in blocks), or (None, None) without a reference
    (``refs``: axis → truth or dynamometer channel). The cut window is that of
    ``truth/process/engagement`` when recorded, else that of the first measured force
    (:func:`~millsense.report.estimate_stream.scan_force_window`, decision 1702).

    The figures are those of :func:`~millsense.report.estimate_metrics.compare` on the whole
    arrays (decision 0961); errors are raised before anything is written.
    """
    import math

    from millsense.core.errors import InputDataError
    from millsense.io.recording_reader import channel_window
    from millsense.report.estimate_stream import (
        PlotTraces,
        StreamedComparison,
        StreamedEstimate,
        scan_cut_window,
        scan_force_window,
        window_mean,
    )

    have = set(rec.channel_names)
    est_axes = list(dict.fromkeys(a for _, a, _, _ in estimates))
    truth_axes = [a for a in est_axes if a in refs]
    if not truth_axes:
        if plot is not None:
            raise InputDataError(
                f"--plot: the recording has no truth channel 'truth/{axis_list[0]}/load' "
                f"nor a measured force 'dynamometer/{axis_list[0]}/force'"
            )
        return None, None
    if "spindle/speed" not in have:
        raise InputDataError("estimate vs truth: the recording has no channel 'spindle/speed'")
    n_teeth = _teeth(flutes, rec)
    n = rec.n_samples
    fs = rec.sample_rate_hz

    def reader(name: str) -> Any:
        return lambda a, b: channel_window(rec, name, a, b)

    speed = reader("spindle/speed")
    if "truth/process/engagement" in have:
        window = scan_cut_window(reader("truth/process/engagement"), n)
    elif all(r.startswith("truth/") for r in refs.values()):
        window = scan_cut_window(None, n)
    else:
        omega = abs(window_mean(speed, 0, n))
        if omega <= 0:
            raise InputDataError("estimate vs reference: the spindle does not turn")
        period = round(2 * math.pi / omega * fs)
        force = next(r for r in refs.values() if not r.startswith("truth/"))
        window = scan_force_window(reader(force), n, period)
    chosen = [StreamedEstimate(m, a, c, d, refs[a]) for m, a, c, d in estimates if a in refs]
    streamed = StreamedComparison(
        chosen, fs, n, window, lambda i0, i1: window_mean(speed, i0, i1), n_teeth
    )
    traces = None
    if plot is not None:
        centre: dict[str, float] = {}
        tooth = 0.0
        for e in chosen:
            i0, i1 = streamed.windows[e.delay]
            if e.axis not in centre:
                centre[e.axis] = 0.5 * (i0 + i1)
            tooth = tooth or streamed.tooth_hz[e.delay]
        traces = PlotTraces(chosen, n, fs, centre, tooth)
    return streamed, traces
