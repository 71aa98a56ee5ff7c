"""``millsense split-passes``: the seed 002 chatter remedy as a program rewrite."""

from __future__ import annotations

from pathlib import Path

import typer

from millsense.cli.main import app


@app.command("split-passes")
def split_passes(
    program: Path = typer.Argument(..., help="Part program (G-code, G90 G21)."),
    max_depth_mm: float = typer.Option(
        ..., "--max-depth-mm", help="Stable axial depth [mm]: deeper passes are split."
    ),
    top_z_mm: float = typer.Option(0.0, "--top-z-mm", help="Stock top [mm] (program frame)."),
    output: Path = typer.Option(..., "-o", "--output", help="Rewritten program (.nc)."),
) -> None:
    """Rewrite a program so that no pass cuts deeper than --max-depth-mm (Munasinghe's depth
    reduction against chatter): every deeper pass becomes ⌈depth / limit⌉ passes, the last
    one the programmed pass, so the geometry reached is the programmed one."""
    import math

    from millsense.control.depth_reduction import write_split_program
    from millsense.core.errors import ConfigError

    if not (max_depth_mm > 0 and math.isfinite(max_depth_mm)):
        raise ConfigError(f"--max-depth-mm: must be finite and > 0, got {max_depth_mm:g}")
    if not math.isfinite(top_z_mm):
        raise ConfigError(f"--top-z-mm: must be finite, got {top_z_mm:g}")
    res = write_split_program(program, output, max_depth_mm, top_z_mm)
    for p, k in res.split:
        typer.echo(
            f"{program}:{p.first_line}-{p.last_line}: pass {p.depth_mm:g} mm deep -> {k} passes"
        )
    typer.echo(
        f"wrote {output}: {len(res.passes_before)} passes -> {len(res.passes_after)} "
        f"(limit {max_depth_mm:g} mm)"
    )
