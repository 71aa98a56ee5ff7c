"""``millsense info``, ``millsense plot`` and ``millsense recover``: look into a recording, and
turn an interrupted one into a plain HDF5 file (decision 0922)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from millsense.cli.main import app
from millsense.core.errors import UserError


@app.command()
def info(recording: Path = typer.Argument(..., help="Recording file (.h5).")) -> None:
    """Channels, rates, duration and metadata of a recording.

    A recording cut off by a crash (only RECORDING.partial/ exists) is first recovered into
    RECORDING, a plain HDF5 file, as `millsense recover` does.
    """
    from millsense.io.recording_file import (
        partial_dir,
        read_recording,
        recording_status,
        writer_alive,
    )

    console = Console()
    if not recording.exists() and partial_dir(recording).is_dir() and not writer_alive(recording):
        _print_recovered(recording, None)
    status = recording_status(recording)
    rec = read_recording(recording)
    # the file's own text is escaped: rich took "[rad]" of a stream field's unit for a style
    console.print(f"[bold]{escape(str(recording))}[/]", markup=True)
    console.print(
        f"{rec.n_samples} samples at {rec.sample_rate_hz:g} Hz = {rec.duration_s:.4g} s "
        f"from t0 = {rec.t0_s:g} s"
    )
    if not status.complete:
        console.print(f"[yellow]{escape(status.message)}[/]")
    meta = Table(title="metadata", show_header=False)
    for k, v in rec.metadata.items():
        meta.add_row(escape(str(k)), escape(_metadata_text(str(k), v, recording)))
    console.print(meta)
    table = Table(title="channels")
    for col in ("channel", "unit", "min", "max", "description"):
        table.add_column(col)
    for name in rec.channel_names:
        ci = rec.info(name)
        x = rec.channel(name)
        lo, hi = (f"{x.min():.4g}", f"{x.max():.4g}") if len(x) else ("", "")
        table.add_row(escape(name), escape(ci.unit), lo, hi, escape(ci.description))
    console.print(table)
    for sname in rec.stream_names:
        st = rec.stream(sname)
        rate = (len(st) - 1) / (st.time_s[-1] - st.time_s[0]) if len(st) > 1 else 0.0
        fields = ", ".join(f"{f} [{st.info[f].unit}]" for f in st.fields)
        console.print(
            f"stream [bold]{escape(sname)}[/]: {len(st)} rows, ~{rate:.4g} Hz: {escape(fields)}"
        )


#: Metadata values longer than this are shortened in ``info`` (the file keeps them whole).
MAX_METADATA_CHARS = 200


def _metadata_text(key: str, value: object, recording: Path) -> str:
    """A metadata value as ``info`` shows it: the import's quality report as its count of
    findings per kind, any other value cut to :data:`MAX_METADATA_CHARS` characters."""
    text = str(value)
    if key == "quality_json" and isinstance(value, str):
        from millsense.io.quality import finding_counts

        counts = finding_counts(value)
        if counts is not None:
            return f"{counts}: millsense check {recording}"
    if len(text) > MAX_METADATA_CHARS:
        return f"{text[: MAX_METADATA_CHARS - 40]} … ({len(text)} characters)"
    return text


@app.command()
def plot(
    recording: Path = typer.Argument(..., help="Recording file (.h5)."),
    channel: list[str] = typer.Option(
        ...,
        "--channel",
        "-c",
        help="Channel, or a stream's field as STREAM/FIELD, or a whole STREAM (repeat; "
        "`millsense info` lists them).",
    ),
    out: Path = typer.Option(..., "-o", "--output", help="PNG file to write."),
    t_start: float | None = typer.Option(None, "--from-s", help="Start time [s]."),
    t_end: float | None = typer.Option(None, "--to-s", help="End time [s]."),
) -> None:
    """Plot channels and stream fields of a recording against time into a PNG (one panel per
    unit; a slower stream's rows marked)."""
    from millsense.io.recording_file import read_recording
    from millsense.io.safe_output import check_outputs
    from millsense.report.plots import plot_channels, recording_series

    check_outputs({"the recording": recording}, {"-o": out}, suffixes={"-o": ".png"})
    rec = read_recording(recording)
    window = None
    if t_start is not None or t_end is not None:
        t0 = rec.t0_s if t_start is None else t_start
        t1 = rec.t0_s + rec.duration_s if t_end is None else t_end
        if t1 <= t0:
            raise UserError(f"--from-s {t0:g} must be before --to-s {t1:g}")
        window = (t0, t1)
    for sr in recording_series(rec, channel, window):  # unknown name -> one line naming it
        n = sr.time_s.size
        if n >= 2:
            continue
        # nothing to draw a line through
        where = "" if window is None else f"--from-s {window[0]:g} --to-s {window[1]:g} "
        if sr.stream is None:
            held = f"{n} sample{'' if n == 1 else 's'}"
            span = f"the recording spans t = {rec.t0_s:g} to {rec.t0_s + rec.duration_s:g} s"
        else:
            t = rec.stream(sr.stream).time_s
            held = f"{n} row{'' if n == 1 else 's'} of stream '{sr.stream}'"
            span = f"the stream spans t = {t[0]:g} to {t[-1]:g} s" if t.size else "it has no rows"
        raise UserError(f"{recording}: {where}holds {held} for '{sr.label}'; {span}")
    plot_channels(rec, channel, out, window)
    Console().print(f"wrote {out}")


def _print_recovered(recording: Path, output: Path | None) -> None:
    """Recover ``recording`` into a plain file and say so, with what was lost (plain lines)."""
    from millsense.io.recovery import recover as recover_file

    r = recover_file(recording, output)
    typer.echo(
        f"recovered {r.duration_s:.6g} s ({r.n_samples} samples) of the interrupted recording "
        f"{recording} into {r.output} (plain HDF5)"
    )
    typer.echo(r.lost)
    if not r.partial_removed:
        typer.echo(f"kept {recording}.partial/ (remove it once {r.output} is checked)")


@app.command()
def recover(
    recording: Path = typer.Argument(
        ..., help="Interrupted recording (RUN.h5, data in RUN.h5.partial/)."
    ),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="File to write (default: RECORDING itself)."
    ),
) -> None:
    """Write an interrupted recording as a plain HDF5 file, with a note of what was lost.

    The note is printed and stored in the file (root attributes recovered, recovery_lost).
    """
    from millsense.io.safe_output import check_outputs

    if output is not None:
        check_outputs({"the recording": recording}, {"-o": output})
    _print_recovered(recording, output)
