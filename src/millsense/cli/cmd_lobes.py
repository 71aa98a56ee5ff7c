"""``millsense lobes``: stability lobe diagram of a case file (ZOA or semi-discretisation)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import typer

from millsense.cli.main import app
from millsense.core.blas import limit_blas_threads
from millsense.core.errors import ConfigError

#: Spectral radii a chart may need at most (speeds × scan depths); beyond it the command
#: refuses with a message instead of running for hours (decision 0906).
MAX_EVALUATIONS = 400_000


def _parse_rpm(text: str) -> tuple[float, float, float] | float:
    parts = text.split(":")
    if len(parts) == 1:
        try:
            n = float(parts[0])
        except ValueError:
            raise ConfigError(f"--rpm {text!r}: expected N or MIN:MAX:STEP in rev/min") from None
        if not (0 < n <= 200000):
            raise ConfigError(f"--rpm {text!r}: allowed 0 < N <= 200000 rev/min")
        return n
    try:
        lo, hi, step = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--rpm {text!r}: expected N or MIN:MAX:STEP in rev/min") from None
    if not (0 < lo < hi and step > 0 and math.isfinite(hi) and math.isfinite(step)):
        raise ConfigError(f"--rpm {text!r}: allowed 0 < MIN < MAX and STEP > 0, finite")
    return lo, hi, step


def _finite_or_none(v: float, scale: float = 1.0, digits: int = 6) -> float | None:
    return round(v * scale, digits) if math.isfinite(v) else None


def _mm_pairs(pairs: list[tuple[float, float]]) -> list[list[float | None]]:
    return [[_finite_or_none(a, 1e3), _finite_or_none(b, 1e3)] for a, b in pairs]


def _scan_depths(case: Any) -> int:
    """Depths of one scan from the small-gain depth to depth_max (an upper bound)."""
    from millsense.stability.milling import milling_dde
    from millsense.stability.scan import SCAN_RATIO, small_gain_depth

    fam = milling_dde(
        case.structure,
        case.flutes,
        case.kt,
        case.kr,
        case.phi_st,
        case.phi_ex,
        float(case.rpm[0]),
        case.steps_per_period,
        case.pitch,
    )
    w0 = min(small_gain_depth(fam), case.depth_max)
    return int(math.log(case.depth_max / w0) / math.log(SCAN_RATIO)) + 2


@app.command()
def lobes(
    case_file: Path = typer.Argument(..., help="Stability case (TOML), see examples/stability/."),
    method: str | None = typer.Option(None, "--method", help="zoa or sdm (default: the case's)."),
    rpm: str | None = typer.Option(
        None, "--rpm", help="N (one speed: every band) or MIN:MAX:STEP [rev/min]."
    ),
    steps_per_period: int | None = typer.Option(
        None, "--steps-per-period", help="SDM steps per tooth period (default: the case's)."
    ),
    extrapolate: bool | None = typer.Option(
        None,
        "--extrapolate/--no-extrapolate",
        help="Richardson extrapolation from M and 2M steps (default: the case's).",
    ),
    tolerance: float = typer.Option(
        0.01,
        "--tolerance",
        help="Relative error bound each SDM depth must meet (adaptive M) [fraction, 0.01 = 1 %].",
    ),
    threads: int = typer.Option(1, "--threads", help="BLAS threads (1 is fastest here)."),
    plot: Path | None = typer.Option(None, "--plot", help="Write the lobe diagram as PNG."),
    json_out: str | None = typer.Option(None, "--json", help="Write results as JSON (- = stdout)."),
) -> None:
    """Critical depth, chatter frequency and bifurcation type over spindle speed."""
    import numpy as np
    from rich.console import Console
    from rich.progress import Progress

    from millsense.io.safe_output import check_outputs, write_text
    from millsense.stability.cases import compute_lobes, load_case
    from millsense.stability.zoa import flip_lobes_expected

    check_outputs({"the case file": case_file}, {"--plot": plot, "--json": json_out})
    if not 1 <= threads <= 256:
        raise ConfigError(f"--threads {threads}: allowed 1..256")
    limit_blas_threads(threads)
    case = load_case(case_file)
    if method is not None and method not in ("zoa", "sdm"):
        raise ConfigError(f"--method {method!r}: allowed 'sdm' or 'zoa'")
    if steps_per_period is not None and not 4 <= steps_per_period <= 2000:
        raise ConfigError(f"--steps-per-period {steps_per_period}: allowed 4..2000")
    if not 1e-4 <= tolerance <= 0.2:
        raise ConfigError(f"--tolerance {tolerance}: allowed 1e-4..0.2")
    meth = method or case.method
    speeds = case.rpm
    if rpm is not None:
        parsed = _parse_rpm(rpm)
        if isinstance(parsed, float):
            speeds = np.array([parsed])
        else:
            lo, hi, step = parsed
            count = math.floor((hi - lo) / step + 0.5) + 1
            if count > 4001:
                raise ConfigError(
                    f"--rpm {rpm!r}: {count} speeds; allowed at most 4001 per chart "
                    "(minima are refined to 1 rev/min anyway): use a larger STEP"
                )
            speeds = np.arange(lo, hi + 0.5 * step, step)
    if meth == "sdm":
        per_speed = _scan_depths(case)
        if speeds.size * per_speed > MAX_EVALUATIONS:
            raise ConfigError(
                f"{speeds.size} speeds x {per_speed} scan depths = {speeds.size * per_speed} "
                f"spectral radii exceeds the ceiling {MAX_EVALUATIONS}: use fewer speeds "
                "(--rpm or lobes.rpm_step) or a smaller lobes.depth_max_mm"
            )
    low_immersion = flip_lobes_expected(case.flutes, case.phi_st, case.phi_ex)
    console = Console(stderr=True, soft_wrap=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task(f"lobes {case.name}", total=len(speeds))
        res = compute_lobes(
            case,
            method=method,
            rpm=speeds,
            steps_per_period=steps_per_period,
            extrapolate=extrapolate,
            progress=lambda i: bar.update(task, completed=i + 1),
            tol=tolerance,
        )
    ceiling_mm = case.depth_max * 1e3
    sols = getattr(res, "solutions", [])
    searched = [s.ceiling * 1e3 for s in sols] if sols else [ceiling_mm] * len(res.rpm)
    status = [
        "limit"
        if 0 < d < math.inf
        else ("unstable at any depth" if d == 0 else f"no limit below {c:.4g} mm")
        for d, c in zip(res.critical_depth_m, searched, strict=True)
    ]
    out: dict[str, Any] = {
        "case": case.name,
        "method": meth,
        "rpm": [float(v) for v in res.rpm],
        "critical_depth_mm": [_finite_or_none(v, 1e3) for v in res.critical_depth_m],
        "status": status,
        "chatter_hz": [_finite_or_none(v, 1.0, 3) for v in res.chatter_hz],
        "bifurcation": list(res.bifurcation),
    }
    if sols:
        out["tolerance"] = [_finite_or_none(s.tolerance, 1.0, 5) for s in sols]
        out["steps_per_period"] = [s.steps for s in sols]
        out["stable_bands_mm"] = [_mm_pairs(s.stable_bands()) for s in sols]
        out["unstable_bands_mm"] = [_mm_pairs(s.bands) for s in sols]
        out["bands_searched_to_mm"] = [round(c, 6) for c in searched]
        out["minima"] = [
            {
                "rpm": mn.rpm,
                "depth_mm": round(mn.depth * 1e3, 6),
                "bifurcation": mn.bifurcation,
                "chatter_hz": _finite_or_none(mn.chatter_hz, 1.0, 3),
                "rpm_resolution": mn.step,
            }
            for mn in getattr(res, "minima", [])
        ]
    finite = np.isfinite(res.critical_depth_m) & (res.critical_depth_m > 0)
    if finite.any():
        out["min_depth_mm"] = _finite_or_none(res.min_depth_m, 1e3)
        out["min_depth_rpm"] = res.min_depth_rpm
    else:
        out["min_depth_mm"] = None
        out["min_depth_rpm"] = None
        out["no_limit_below_mm"] = round(min(searched), 6)
    warnings: list[str] = []
    if meth == "zoa" and low_immersion:
        warnings.append(
            "low radial immersion: period-doubling (flip) lobes are expected and ZOA cannot "
            "show them; the ZOA limit may be far above the true one, use --method sdm"
        )
    out["warnings"] = warnings
    for w in warnings:
        console.print(f"warning: {w}", highlight=False)
    if finite.any():
        k = int(np.nanargmin(np.where(finite, res.critical_depth_m, np.inf)))
        mins = getattr(res, "minima", [])
        if mins and mins[0].depth <= res.critical_depth_m[k]:
            f_c, kind = mins[0].chatter_hz, mins[0].bifurcation
        else:
            f_c, kind = res.chatter_hz[k], res.bifurcation[k]
        console.print(
            f"{case.name}: minimum critical depth {res.min_depth_m * 1e3:.4f} mm at "
            f"{res.min_depth_rpm:.0f} rev/min, chatter {f_c:.1f} Hz ({kind})",
            highlight=False,
        )
    else:
        console.print(
            f"{case.name}: no limit below {min(searched):.4g} mm at any speed", highlight=False
        )
    if len(res.rpm) == 1 and sols:
        s = sols[0]
        for a, b in s.bands:
            top = f"{b * 1e3:.4f} mm" if math.isfinite(b) else f"{s.ceiling * 1e3:.4g} mm+"
            console.print(f"  unstable {a * 1e3:.4f} .. {top}", highlight=False)
        for a, b in s.stable_bands():
            console.print(f"  stable island {a * 1e3:.4f} .. {b * 1e3:.4f} mm", highlight=False)
    if json_out is not None:
        text = json.dumps(out) + "\n"
        if json_out == "-":
            sys.stdout.write(text)
        else:
            write_text(json_out, text)
    if plot is not None:
        _plot(plot, res, case.name, meth, sols)


def _plot(path: Path, res: Any, name: str, meth: str, sols: list[Any]) -> None:
    import matplotlib

    from millsense.io.safe_output import atomic_path

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(8, 4.5))
    d = res.critical_depth_m * 1e3
    fin = d[np.isfinite(d)]
    top = float(np.nanmax(fin)) * 1.05 if fin.size else 1.0
    ax.plot(res.rpm, d, "k-", lw=1, label="critical depth")
    flip = np.array([b == "flip" for b in res.bifurcation])
    if flip.any():
        ax.plot(res.rpm[flip], d[flip], "r.", ms=4, label="period doubling (flip)")
    ax.fill_between(res.rpm, d, top, color="0.9")
    # stable islands above the limit: white bands inside the grey unstable region
    step = float(np.median(np.diff(res.rpm))) if len(res.rpm) > 1 else 1.0
    labelled = False
    for n, s in zip(res.rpm, sols, strict=False):
        for a, b in s.stable_bands():
            ax.fill_between(
                [n - step / 2, n + step / 2],
                a * 1e3,
                min(b * 1e3, top),
                color="tab:green",
                alpha=0.35,
                lw=0,
                label=None if labelled else "stable island",
            )
            labelled = True
    for mn in getattr(res, "minima", [])[:1]:
        ax.plot([mn.rpm], [mn.depth * 1e3], "bv", ms=6, label="refined minimum")
    ax.set_xlabel("spindle speed [rev/min]")
    ax.set_ylabel("axial depth of cut [mm]")
    ax.set_title(f"{name} ({meth})")
    ax.set_ylim(0, top)
    ax.legend(loc="upper left")
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    finally:
        plt.close(fig)
