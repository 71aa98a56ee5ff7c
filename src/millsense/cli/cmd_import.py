"""``millsense import``, ``check``, ``export`` and ``example-data``: measurements made outside
millsense in and out (issue 17, decision 1701)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError, InputDataError

#: Warnings of one kind printed before the rest of that kind is summarised in one line (all
#: of them stay in the report: --json, the recording's quality_json, --plot).
MAX_PRINTED_PER_KIND = 5


def _print_report(report: Any, err: bool = True) -> None:
    """Every refusal, and up to :data:`MAX_PRINTED_PER_KIND` warnings of each kind, then one
    line counting the rest of that kind."""
    shown: dict[str, int] = {}
    for f in report.findings:
        if f.refuse:
            typer.echo(f"millsense: refused: {f.message}", err=err)
            continue
        shown[f.kind] = shown.get(f.kind, 0) + 1
        if shown[f.kind] <= MAX_PRINTED_PER_KIND:
            typer.echo(f"millsense: warning: {f.message}", err=err)
    for kind, n in shown.items():
        if n > MAX_PRINTED_PER_KIND:
            typer.echo(
                f"millsense: warning: ... and {n - MAX_PRINTED_PER_KIND} more '{kind}' findings "
                "(all of them in --json and --plot)",
                err=err,
            )


def _json(report: Any, target: str | None) -> None:
    from millsense.io.safe_output import write_text

    if target is None:
        return
    text = report.to_json() + "\n"
    if target == "-":
        typer.echo(text, nl=False)
    else:
        write_text(target, text)


@app.command("import")
def import_(
    files: list[Path] = typer.Argument(
        ...,
        help="Files: .csv .tsv .txt .mat .tdms .wav .flac "
        ".mp3 .parquet (several at different rates: the fastest "
        "become channels, the others streams).",
    ),
    map_file: Path = typer.Option(..., "--map", help="Map file (TOML): column → channel, unit."),
    out: Path = typer.Option(..., "-o", "--output", help="Recording to write (.h5)."),
    rate_hz: float | None = typer.Option(
        None,
        "--rate-hz",
        help="Stated sample rate [Hz] for files with no time column and no "
        "rate in the map or the file's header.",
    ),
    machine: str | None = typer.Option(None, "--machine", help="Metadata: machine."),
    tool: str | None = typer.Option(None, "--tool", help="Metadata: tool."),
    spindle_rpm: float | None = typer.Option(None, "--spindle-rpm", help="Metadata [rev/min]."),
    feed_mm_min: float | None = typer.Option(None, "--feed-mm-min", help="Metadata [mm/min]."),
    flutes: int | None = typer.Option(None, "--flutes", help="Metadata: teeth of the tool."),
    plot: Path | None = typer.Option(None, "--plot", help="PNG of what the check found."),
    json_out: str | None = typer.Option(
        None, "--json", help="Quality report as JSON (- = stdout)."
    ),
) -> None:
    """Import measurements into a millsense recording, with a data-quality report.

    The map names which column of which file is which channel (x/current_cmd, spindle/speed,
    dynamometer/x/force ...) with its unit; values are converted to SI. The effective rate is
    measured (time column, or encoder angle/speed pairs) and used when the stated one is off
    by more than 0.1 %; gaps are filled by linear interpolation; repeated samples, clipping,
    NaN, constant channels, mains hum and drifting offsets are reported. Data that cannot be
    used (time going backwards, long NaN runs, more than 10 % missing) are refused (exit 2).
    """
    from millsense.io.importers import import_files, load_map
    from millsense.io.recording_file import write_recording
    from millsense.io.safe_output import check_outputs

    inputs = [(f"input file {p}", p) for p in files] + [("the map", map_file)]
    check_outputs(inputs, {"-o": out, "--plot": plot, "--json": json_out})
    if out.suffix != ".h5":
        raise ConfigError(f"-o {out}: a recording is written as .h5")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(f"--rate-hz {rate_hz:g}: must be finite and > 0")
    mapping = load_map(map_file)
    meta: dict[str, object] = {
        "machine": machine,
        "tool": tool,
        "spindle_rpm": spindle_rpm,
        "feed_mm_min": feed_mm_min,
        "flutes": flutes,
    }
    from rich.console import Console
    from rich.progress import Progress

    console = Console(stderr=True)
    # not on a terminal (a log, a pipe) no bar: rich left an empty line there
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        tasks: dict[Path, Any] = {}

        def update(path: Path, done: int, total: int) -> None:
            if path not in tasks:
                tasks[path] = bar.add_task(f"read {path.name}", total=total)
            bar.update(tasks[path], completed=done, total=total)

        res = import_files(
            files,
            mapping,
            rate_hz=rate_hz,
            metadata=meta,
            map_source=str(map_file),
            source=str(out),
            progress=update,
        )
    rec = res.recording
    write_recording(out, rec)
    _print_report(res.report)
    if plot is not None:
        from millsense.report.quality_plots import plot_quality

        plot_quality(rec, res.report, plot)
    _json(res.report, json_out)
    typer.echo(
        f"wrote {out}: {len(rec.channel_names)} channels, {len(rec.stream_names)} streams, "
        f"{rec.n_samples} samples at {rec.sample_rate_hz:.7g} Hz ({rec.duration_s:.4g} s); "
        f"{len(res.report.findings)} findings",
        err=json_out == "-",
    )


@app.command()
def check(
    recording: Path = typer.Argument(..., help="Recording (.h5)."),
    plot: Path | None = typer.Option(None, "--plot", help="PNG of what was found."),
    json_out: str | None = typer.Option(None, "--json", help="Report as JSON (- = stdout)."),
) -> None:
    """Data quality of a recording: measured vs stated rate, repeated samples, clipping, NaN,
    constant channels, mains hum, drifting offsets (plus the gaps and time findings of its
    import). Exit status 2 when something makes the data unusable."""
    from millsense.io.quality import QualityReport, check_recording
    from millsense.io.recording_file import read_recording
    from millsense.io.safe_output import check_outputs

    check_outputs({"the recording": recording}, {"--plot": plot, "--json": json_out})
    rec = read_recording(recording)
    report = QualityReport()
    stored = rec.metadata.get("quality_json")
    if isinstance(stored, str):
        old = QualityReport.from_json(stored)
        for f in old.findings:
            if f.kind in ("gap", "time") or (
                f.kind == "rate" and f.data.get("how") == "time column"
            ):
                report.add(f)
        report.rates.update(
            {k: v for k, v in old.rates.items() if k in {f.where for f in report.findings}}
        )
    check_recording(rec, report)
    _print_report(report, err=json_out == "-")
    if plot is not None:
        from millsense.report.quality_plots import plot_quality

        plot_quality(rec, report, plot)
    _json(report, json_out)
    for where, (stated, measured) in report.rates.items():
        s = f"{stated:.7g}" if stated is not None else "-"
        typer.echo(f"rate: {where}: stated {s} Hz, measured {measured:.7g} Hz", err=json_out == "-")
    typer.echo(
        f"{recording}: {len(report.findings)} findings ({len(report.refusals)} refusals)",
        err=json_out == "-",
    )
    if report.refusals:
        raise InputDataError(f"{recording}: {report.refusals[0].message}")


@app.command()
def export(
    recording: Path = typer.Argument(..., help="Recording (.h5)."),
    fmt: str = typer.Option(
        ..., "--format", help="csv, tsv, mat, mat73, tdms, wav, flac, mp3 or parquet."
    ),
    out: Path = typer.Option(..., "-o", "--output", help="File to write."),
    channel: list[str] | None = typer.Option(
        None, "--channel", "-c", help="Channel to export (repeat; default all)."
    ),
    map_out: Path | None = typer.Option(
        None,
        "--map-out",
        help="The map that imports the file back (default: OUTPUT with .map.toml).",
    ),
) -> None:
    """Export a recording's channels to another format, with the map that imports it back."""
    from millsense.io.importers.export import EXPORT_FORMATS, export_recording
    from millsense.io.recording_file import read_recording
    from millsense.io.safe_output import atomic_path, check_outputs, write_text

    if fmt not in EXPORT_FORMATS:
        raise ConfigError(f"--format {fmt!r}: one of {', '.join(EXPORT_FORMATS)}")
    if out.suffix.lower() != EXPORT_FORMATS[fmt]:
        raise ConfigError(f"-o {out}: the {fmt} format is written as {EXPORT_FORMATS[fmt]}")
    map_path = map_out or out.with_name(out.stem + ".map.toml")
    check_outputs({"the recording": recording}, {"-o": out, "--map-out": map_path})
    rec = read_recording(recording)
    with atomic_path(out) as tmp:
        text = export_recording(rec, tmp, fmt, channel or None, name=out.name)
    write_text(map_path, text)
    typer.echo(f"wrote {out} and {map_path}")
    if rec.stream_names:  # said, not silently dropped
        streams = ", ".join(f"{s} ({', '.join(rec.stream(s).fields)})" for s in rec.stream_names)
        typer.echo(f"millsense: note: streams are not exported: {streams}", err=True)


@app.command("example-data")
def example_data(
    out: Path = typer.Option(..., "-o", "--output", help="Folder to write (created)."),
    duration_s: float = typer.Option(1.3, "--duration-s", help="Simulated time [s]."),
) -> None:
    """The example data set of the README: a simulated slot on the quaser-ux600 exported as a
    Servo-Trace-like CSV with the flaws of real files added (wrong stated rate, repeated
    samples, a clipped channel, a gap, a drifting dynamometer offset, mains hum, field units in
    a header row), its map, and what was injected (quirks.json). Generated, not shipped."""
    from millsense.cli.example_data import make_example

    written = make_example(out, duration_s)
    for p in written:
        typer.echo(f"wrote {p}")
