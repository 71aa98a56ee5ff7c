"""``millsense lobes``: stability lobe diagram of a case file (ZOA or semi-discretisation)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import typer

from millsense.cli.main import app
from millsense.core.errors import ConfigError


def _parse_rpm(text: str) -> tuple[float, float, float]:
    parts = text.split(":")
    try:
        lo, hi, step = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--rpm {text!r}: expected MIN:MAX:STEP in rev/min") from None
    if not (0 < lo < hi and step > 0):
        raise ConfigError(f"--rpm {text!r}: allowed 0 < MIN < MAX and STEP > 0")
    return lo, hi, step


def _finite_or_none(v: float, scale: float = 1.0, digits: int = 6) -> float | None:
    return round(v * scale, digits) if math.isfinite(v) else None


@app.command()
def lobes(
    case_file: Path = typer.Argument(..., help="Stability case (TOML), see examples/stability/."),
    method: str | None = typer.Option(None, "--method", help="zoa or sdm (default: the case's)."),
    rpm: str | None = typer.Option(None, "--rpm", help="Speeds MIN:MAX:STEP [rev/min]."),
    steps_per_period: int | None = typer.Option(
        None, "--steps-per-period", help="SDM steps per tooth period (default: the case's)."
    ),
    extrapolate: bool | None = typer.Option(
        None,
        "--extrapolate/--no-extrapolate",
        help="Richardson extrapolation from M and 2M steps (default: the case's).",
    ),
    plot: Path | None = typer.Option(None, "--plot", help="Write the lobe diagram as PNG."),
    json_out: str | None = typer.Option(None, "--json", help="Write results as JSON (- = stdout)."),
) -> None:
    """Critical depth, chatter frequency and bifurcation type over spindle speed."""
    import numpy as np
    from rich.console import Console
    from rich.progress import Progress

    from millsense.io.safe_output import atomic_path, check_outputs, write_text
    from millsense.stability.cases import compute_lobes, load_case

    check_outputs({"the case file": case_file}, {"--plot": plot, "--json": json_out})
    case = load_case(case_file)
    if method is not None and method not in ("zoa", "sdm"):
        raise ConfigError(f"--method {method!r}: allowed 'sdm' or 'zoa'")
    if steps_per_period is not None and not 4 <= steps_per_period <= 2000:
        raise ConfigError(f"--steps-per-period {steps_per_period}: allowed 4..2000")
    speeds = case.rpm
    if rpm is not None:
        lo, hi, step = _parse_rpm(rpm)
        speeds = np.arange(lo, hi + 0.5 * step, step)
    console = Console(stderr=True, soft_wrap=True)
    with Progress(console=console, transient=True) as bar:
        task = bar.add_task(f"lobes {case.name}", total=len(speeds))
        res = compute_lobes(
            case,
            method=method,
            rpm=speeds,
            steps_per_period=steps_per_period,
            extrapolate=extrapolate,
            progress=lambda i: bar.update(task, completed=i + 1),
        )
    out = {
        "case": case.name,
        "method": method or case.method,
        "rpm": [float(v) for v in res.rpm],
        "critical_depth_mm": [_finite_or_none(v, 1e3) for v in res.critical_depth_m],
        "chatter_hz": [_finite_or_none(v, 1.0, 3) for v in res.chatter_hz],
        "bifurcation": list(res.bifurcation),
        "min_depth_mm": _finite_or_none(res.min_depth_m, 1e3),
        "min_depth_rpm": res.min_depth_rpm,
    }
    console.print(
        f"{case.name}: minimum critical depth {res.min_depth_m * 1e3:.4f} mm at "
        f"{res.min_depth_rpm:.0f} rev/min, chatter {res.chatter_hz[res.min_index]:.1f} Hz "
        f"({res.bifurcation[res.min_index]})",
        highlight=False,
    )
    if json_out is not None:
        text = json.dumps(out) + "\n"
        if json_out == "-":
            sys.stdout.write(text)
        else:
            write_text(json_out, text)
    if plot is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 4.5))
        d = res.critical_depth_m * 1e3
        ax.plot(res.rpm, d, "k-", lw=1, label="critical depth")
        flip = np.array([b == "flip" for b in res.bifurcation])
        if flip.any():
            ax.plot(res.rpm[flip], d[flip], "r.", ms=4, label="period doubling (flip)")
        ax.fill_between(res.rpm, d, np.nanmax(d[np.isfinite(d)]) * 1.05, color="0.9")
        ax.set_xlabel("spindle speed [rev/min]")
        ax.set_ylabel("axial depth of cut [mm]")
        ax.set_title(f"{case.name} ({out['method']})")
        ax.legend(loc="upper left")
        fig.tight_layout()
        try:
            with atomic_path(plot) as tmp:
                fig.savefig(tmp, dpi=120, format="png")
        finally:
            plt.close(fig)
