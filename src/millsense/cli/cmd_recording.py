"""``millsense info`` and ``millsense plot``: look into a recording."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from millsense.cli.main import app
from millsense.core.errors import UserError


@app.command()
def info(recording: Path = typer.Argument(..., help="Recording file (.h5).")) -> None:
    """Channels, rates, duration and metadata of a recording (recovers cut-off files)."""
    from millsense.io.recording_file import read_recording, recording_status

    status = recording_status(recording)
    rec = read_recording(recording)
    console = Console()
    console.print(f"[bold]{recording}[/]")
    console.print(
        f"{rec.n_samples} samples at {rec.sample_rate_hz:g} Hz = {rec.duration_s:.4g} s "
        f"from t0 = {rec.t0_s:g} s"
    )
    if not status.complete:
        console.print(f"[yellow]{status.message}[/]")
    meta = Table(title="metadata", show_header=False)
    for k, v in rec.metadata.items():
        meta.add_row(str(k), str(v))
    console.print(meta)
    table = Table(title="channels")
    for col in ("channel", "unit", "min", "max", "description"):
        table.add_column(col)
    for name in rec.channel_names:
        ci = rec.info(name)
        x = rec.channel(name)
        lo, hi = (f"{x.min():.4g}", f"{x.max():.4g}") if len(x) else ("", "")
        table.add_row(name, ci.unit, lo, hi, ci.description)
    console.print(table)
    for sname in rec.stream_names:
        st = rec.stream(sname)
        rate = (len(st) - 1) / (st.time_s[-1] - st.time_s[0]) if len(st) > 1 else 0.0
        fields = ", ".join(f"{f} [{st.info[f].unit}]" for f in st.fields)
        console.print(f"stream [bold]{sname}[/]: {len(st)} rows, ~{rate:.4g} Hz: {fields}")


@app.command()
def plot(
    recording: Path = typer.Argument(..., help="Recording file (.h5)."),
    channel: list[str] = typer.Option(..., "--channel", "-c", help="Channel to plot (repeat)."),
    out: Path = typer.Option(..., "-o", "--out", help="PNG file to write."),
    t_start: float | None = typer.Option(None, "--from", help="Start time, s."),
    t_end: float | None = typer.Option(None, "--to", help="End time, s."),
) -> None:
    """Plot channels of a recording against time into a PNG (one panel per unit)."""
    from millsense.io.recording_file import read_recording
    from millsense.report.plots import plot_channels

    if out.suffix.lower() != ".png":
        raise UserError(f"{out}: the plot is written as PNG; give a .png file name")
    rec = read_recording(recording)
    for c in channel:
        rec.channel(c)  # unknown channel -> one-line error naming it
    t_range = None
    if t_start is not None or t_end is not None:
        t0 = rec.t0_s if t_start is None else t_start
        t1 = rec.t0_s + rec.duration_s if t_end is None else t_end
        if t1 <= t0:
            raise UserError(f"--from {t0:g} s must be before --to {t1:g} s")
        t_range = (t0, t1)
    plot_channels(rec, channel, out, t_range)
    Console().print(f"wrote {out}")
