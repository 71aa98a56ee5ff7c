"""The report of a run (``millsense report``; written by ``run``, ``replay`` and ``demo``): one
self-contained HTML file (plotly, plotly.js and the data embedded; opens offline).

Sections: the run's figures (:class:`~millsense.report.run_scan.RunFigures`, the numbers of
the demo's summary); estimated against true forces and torque where the recording has truth,
over the whole run (min/max envelopes), raw over 12 tooth periods and at the tooth harmonics
(:func:`~millsense.report.estimate_metrics.compare`); the tool path coloured by force with the
chatter, breakage and hold events where they happened; the breakage residual against its
threshold; the adaptive control's feed override and regulated quantity; the spindle speed with
its changes; the event table; the machine file with its identified sections; the validation
status of the estimators and monitors used (given by the caller: ``millsense.validation`` sits
above this layer); given a batch's summary table, the fleet view with this run's tool and row
marked (per tool and machine: runs, VB, wear rate, remaining life; the wear trend;
:mod:`~millsense.report.fleet_report`).

Every whole-run trace is a min/max envelope (:mod:`~millsense.report.run_scan`): a one-hour
recording at 10 kHz becomes 5000 bins per trace and its largest peaks stay visible.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import plotly.graph_objects as go
from numpy.typing import NDArray
from plotly.offline import get_plotlyjs
from plotly.subplots import make_subplots

from millsense.core.errors import InputDataError
from millsense.io.recording_reader import channel_window
from millsense.report.estimate_metrics import compare
from millsense.report.estimate_stream import ZOOM_PERIODS, scan_cut_window
from millsense.report.html_parts import CSS, html_table
from millsense.report.labels import regulated_label, unit_label
from millsense.report.run_scan import FXY_TRUE, RunFigures, RunScan, scan_run
from millsense.streaming.block import Event

RPM = 60.0 / (2.0 * math.pi)
#: Estimate → truth pairs compared (estimate channel, truth channel, label, unit).
PAIRS = (
    ("est/spindle/spindle/load", "truth/spindle/torque", "spindle torque", "N·m"),
    ("est/tool/force_x", "truth/tool/force_x", "force X", "N"),
    ("est/tool/force_y", "truth/tool/force_y", "force Y", "N"),
    ("est/feed/x/load", "truth/tool/force_x", "force X (X drive)", "N"),
    ("est/feed/y/load", "truth/tool/force_y", "force Y (Y drive)", "N"),
)
#: The longest steady window the harmonics are fitted on, s.
HARMONIC_WINDOW_S = 4.0
#: Events marked on the plots: name → (colour, label).
MARKS = {
    "chatter": ("#d62728", "chatter"),
    "breakage": ("#000000", "breakage"),
    "feed_hold": ("#9467bd", "feed hold"),
    "spindle_override": ("#ff7f0e", "spindle change"),
    "input_fault": ("#8c564b", "input fault"),
    "source_lost": ("#8c564b", "source lost"),
}
#: Events listed at most in the table (an hour of adaptive control has thousands of overrides).
MAX_EVENT_ROWS = 2000
#: Recorded channels the report reads (derived ones in :mod:`~millsense.report.run_scan`).
SHOWN = (
    *{p[0] for p in PAIRS},
    *{p[1] for p in PAIRS},
    FXY_TRUE,
    "supervisor/feed_override",
    "cnc/feed_override",
    "adaptive_feed/peak",
    "adaptive_feed/reference",
    "spindle/speed",
    "breakage/residual1",
    "breakage/limit1",
    "breakage/residual2",
    "breakage/limit2",
    "chatter-comb/energy_ratio",
    "tcp/x",
    "tcp/y",
)


@dataclass
class RunReport:
    """A built report: its figures (plotly), the run's figures and the HTML text."""

    figures: dict[str, go.Figure]
    run: RunFigures
    html: str
    harmonics: list[dict[str, Any]] = field(default_factory=list)


def build_report(
    recording: str | Path,
    *,
    events: Sequence[Event] = (),
    plan: Any = None,
    machine: Any = None,
    machine_where: str = "",
    validation: Sequence[Mapping[str, str]] | None = None,
    validation_where: str = "",
    title: str = "",
    bins: int | None = None,
    runs: Mapping[str, RunFigures] | None = None,
    fleet: Sequence[dict[str, Any]] | None = None,
    fleet_where: str = "",
    wear_limit_mm: float = 0.3,
) -> RunReport:
    """Read ``recording`` once and build its report.

    Parameters
    ----------
    events : the run's events (its event log).
    plan : the :class:`~millsense.plan.virtual_plan.VirtualPlan` (the programmed path, the
        tool's flutes), or None.
    machine, machine_where : the estimators' :class:`~millsense.core.config.MachineConfig`
        and where it came from, or None.
    validation : rows (``case``, ``reference``, ``measured``, ``tolerance``, ``status``) of
        the validation cases of the estimators and monitors used; None: not known;
        ``validation_where``: where that status was recorded (file, date, commit).
    bins : envelope bins per trace (default :data:`~millsense.report.run_scan.DISPLAY_BINS`).
    runs : figures of several runs shown side by side (the demo: controlled and open), or None.
    fleet, fleet_where : the rows of a batch's summary table (``millsense batch``) and the file
        they came from: the report shows the fleet view with this run's tool and row marked
        (:func:`~millsense.report.fleet_report.fleet_sections`); ``wear_limit_mm`` the VB limit.
    """
    from millsense.io.recording_reader import opened_recording

    kw = {} if bins is None else {"bins": bins}
    with opened_recording(recording) as rec:
        scan = scan_run(rec, events, SHOWN, **kw)
        flutes = _flutes(plan)
        harm, zoom = _harmonics(rec, scan, flutes)
        meta = dict(rec.metadata)
        where = _event_positions(rec, events)
        units = {c: rec.info(c).unit for c in ("adaptive_feed/peak", "breakage/residual1")
                 if c in rec.channel_names}  # fmt: skip
    figs: dict[str, go.Figure] = {}
    pairs = [p for p in PAIRS if p[0] in scan.present and p[1] in scan.present]
    if pairs:
        figs["estimates"] = _estimates_figure(scan, pairs, zoom, events)
    if harm:
        figs["harmonics"] = _harmonics_figure(harm)
    path = _path_figure(scan, plan, events, where)
    if path is not None:
        figs["path"] = path
    if "breakage/residual1" in scan.present:
        figs["breakage"] = _breakage_figure(scan, events, units.get("breakage/residual1", ""))
    if "cnc/feed_override" in scan.present or "supervisor/feed_override" in scan.present:
        figs["control"] = _control_figure(scan, events, units.get("adaptive_feed/peak", ""))
    if "spindle/speed" in scan.present:
        figs["spindle"] = _spindle_figure(scan, events)
    text = _html(
        title or f"millsense run report: {Path(recording).name}",
        figs, scan, events, meta, harm, machine, machine_where, validation, validation_where,
        runs, _fleet_parts(recording, fleet, fleet_where, wear_limit_mm),
    )  # fmt: skip
    return RunReport(figs, scan.figures, text, harm)


def _fleet_parts(recording: str | Path, fleet: Sequence[dict[str, Any]] | None, where: str,
                 limit_mm: float) -> list[str]:  # fmt: skip
    """The fleet section of the run report (empty without a summary table)."""
    from millsense.report.fleet_report import find_run, fleet_sections

    if fleet is None:
        return []
    name = Path(recording).name
    run = find_run(fleet, name[:-3] if name.endswith(".h5") else Path(name).stem)
    parts = ["<h2>Fleet: tools and wear</h2>",
             f'<p class="note">summary table {html.escape(where)}; '
             + ("this run is marked." if run is not None else
                f"this run ({html.escape(name)}) is not in it.") + "</p>"]  # fmt: skip
    return parts + fleet_sections(fleet, limit_mm=limit_mm, run=run, level=3)


def write_report(path: str | Path, recording: str | Path, **kwargs: Any) -> RunReport:
    """Build the report of ``recording`` (arguments of :func:`build_report`) and write it
    atomically to ``path``."""
    from millsense.io.safe_output import write_text

    rep = build_report(recording, **kwargs)
    write_text(path, rep.html)
    return rep


# ---------------------------------------------------------------- the data of the figures
def _event_positions(rec: Any, events: Sequence[Event]) -> dict[int, tuple[float, float]]:
    """Where each marked event happened on the part, mm: its own position if it has one, else
    the recorded tool-centre point at its sample (``id`` of the event → (x, y))."""
    out: dict[int, tuple[float, float]] = {}
    tcp = {"tcp/x", "tcp/y"} <= set(rec.channel_names)
    for e in events:
        if e.name not in MARKS:
            continue
        if e.x_mm is not None and e.y_mm is not None:
            out[id(e)] = (e.x_mm, e.y_mm)
        elif tcp and 0 <= e.sample < rec.n_samples:
            x = channel_window(rec, "tcp/x", e.sample, e.sample + 1)
            y = channel_window(rec, "tcp/y", e.sample, e.sample + 1)
            out[id(e)] = (float(x[0]) * 1e3, float(y[0]) * 1e3)
    return out


def _flutes(plan: Any) -> int:
    if plan is None:
        return 2
    return int(plan.metadata.get("tool", {}).get("flutes", 2))


def envelope_xy(scan: RunScan, name: str, scale: float = 1.0) -> tuple[NDArray, NDArray]:
    """Times and values of the zig-zag through each bin's minimum and maximum of ``name``
    (``scale`` > 0 applied), float32 for the page."""
    x, y = scan.envelopes[name].xy(scan.fs)
    return x.astype(np.float32), (y * scale).astype(np.float32)


def _harmonics(
    rec: Any, scan: RunScan, flutes: int
) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """Tooth-harmonic comparison of each estimate with its truth on the middle
    :data:`HARMONIC_WINDOW_S` of the longest cut, and the raw samples of
    :data:`~millsense.report.estimate_stream.ZOOM_PERIODS` tooth periods there."""
    names = set(rec.channel_names)
    pairs = [p for p in PAIRS if p[0] in names and p[1] in names]
    if not pairs or "spindle/speed" not in names:
        return [], None
    eng = next((c for c in ("truth/process/engagement", "plan/in_cut") if c in names), None)
    n, fs = scan.n, scan.fs
    if eng == "plan/in_cut":
        def read(a: int, b: int) -> NDArray[np.float64]:
            return np.where(channel_window(rec, eng, a, b) > 0.5, 1.0, -1.0)
    elif eng is not None:
        def read(a: int, b: int) -> NDArray[np.float64]:
            return np.asarray(channel_window(rec, eng, a, b), dtype=np.float64)
    try:
        i0, i1 = scan_cut_window(read if eng else None, n, trim=0.0)
    except InputDataError:  # never in cut: nothing to compare at the tooth harmonics
        return [], None
    half = int(HARMONIC_WINDOW_S * fs / 2)
    mid = (i0 + i1) // 2
    a, b = max(i0, mid - half), min(i1, mid + half)
    speed = np.asarray(channel_window(rec, "spindle/speed", a, b), dtype=np.float64)
    out: list[dict[str, Any]] = []
    zoom: dict[str, Any] | None = None
    for est, tru, label, unit in pairs:
        e = np.asarray(channel_window(rec, est, a, b), dtype=np.float64)
        x = np.asarray(channel_window(rec, tru, a, b), dtype=np.float64)
        try:
            c = compare("estimate", label, e, x, speed, fs, flutes)
        except InputDataError:
            continue
        out.append({"label": label, "unit": unit, "tooth_hz": c.tooth_hz,
                    "harmonics": c.harmonics.tolist(), "estimate": c.est_amp.tolist(),
                    "truth": c.true_amp.tolist(), "error": c.error.tolist(),
                    "mean_estimate": c.mean_est, "mean_truth": c.mean_true,
                    "window_s": ((a + c.window[0]) / fs, (a + c.window[1]) / fs)})  # fmt: skip
        if zoom is None:
            zoom = {"span": round(ZOOM_PERIODS * fs / c.tooth_hz), "start": a + c.window[0],
                    "traces": {}}  # fmt: skip
        z0 = zoom["start"]
        z1 = z0 + zoom["span"]
        zoom["traces"][label] = (channel_window(rec, est, z0, z1), channel_window(rec, tru, z0, z1))
    return out, zoom


# ---------------------------------------------------------------- figures
def _layout(fig: go.Figure, title: str, height: int) -> go.Figure:
    fig.update_layout(title=title, height=height, margin={"l": 60, "r": 20, "t": 50, "b": 40},
                      legend={"orientation": "h", "y": -0.12}, template="plotly_white")  # fmt: skip
    return fig


def _mark_events(fig: go.Figure, events: Sequence[Event], rows: int) -> None:
    """Vertical lines at the marked events (one legend entry per kind)."""
    for e in events:
        mark = MARKS.get(e.name)
        if mark is None:
            continue
        for r in range(1, rows + 1):
            fig.add_vline(x=e.time_s, line={"color": mark[0], "width": 1, "dash": "dash"},
                          row=r, col=1)  # fmt: skip


def _trace(scan: RunScan, name: str, label: str, scale: float = 1.0, **kw: Any) -> go.Scatter:
    x, y = envelope_xy(scan, name, scale)
    return go.Scatter(x=x, y=y, name=label, mode="lines", line={"width": 1}, **kw)


def _estimates_figure(
    scan: RunScan,
    pairs: Sequence[tuple[str, str, str, str]],
    zoom: dict[str, Any] | None,
    events: Sequence[Event],
) -> go.Figure:
    rows = len(pairs) + (1 if zoom else 0)
    titles = [f"{lab} [{u}]: estimate and truth (min/max per bin)" for _, _, lab, u in pairs]
    if zoom:
        titles.append(f"raw samples over {ZOOM_PERIODS:g} tooth periods (first pair)")
    fig = make_subplots(rows=rows, cols=1, subplot_titles=titles, vertical_spacing=0.08)
    for i, (est, tru, lab, _) in enumerate(pairs, start=1):
        fig.add_trace(_trace(scan, est, f"estimated {lab}", opacity=0.6), row=i, col=1)
        fig.add_trace(_trace(scan, tru, f"true {lab}", opacity=0.9), row=i, col=1)
    if zoom:
        label, (e, x) = next(iter(zoom["traces"].items()))
        t = (zoom["start"] + np.arange(len(x))) / scan.fs
        fig.add_trace(go.Scatter(x=t, y=e, name=f"estimated {label} (raw)", mode="lines",
                                 opacity=0.6), row=rows, col=1)  # fmt: skip
        fig.add_trace(go.Scatter(x=t, y=x, name=f"true {label} (raw)", mode="lines"),
                      row=rows, col=1)  # fmt: skip
    _mark_events(fig, events, len(pairs))
    fig.update_xaxes(title_text="time [s]", row=rows, col=1)
    return _layout(fig, "Estimated against true forces and torque", 280 * rows)


def _harmonics_figure(harm: Sequence[dict[str, Any]]) -> go.Figure:
    fig = make_subplots(rows=1, cols=len(harm),
                        subplot_titles=[f"{h['label']} [{h['unit']}] at "
                                        f"{h['tooth_hz']:.1f} Hz × k" for h in harm])  # fmt: skip
    for i, h in enumerate(harm, start=1):
        k = [str(v) for v in h["harmonics"]]
        fig.add_trace(go.Bar(x=k, y=h["truth"], name=f"true {h['label']}"), row=1, col=i)
        fig.add_trace(go.Bar(x=k, y=h["estimate"], name=f"estimated {h['label']}"), row=1, col=i)
        fig.update_xaxes(title_text="tooth harmonic k", row=1, col=i)
    return _layout(fig, "Amplitudes at the tooth harmonics (steady cut)", 380)


def _path_figure(
    scan: RunScan, plan: Any, events: Sequence[Event], where: Mapping[int, tuple[float, float]]
) -> go.Figure | None:
    """The tool path (tool-centre point at each bin's start) coloured by the bin's largest
    force (true |F_xy|, else the regulated quantity), the plan's path beneath, events on it."""
    fig = go.Figure()
    if plan is not None:
        px = np.asarray(plan["x_mm"], dtype=np.float32)
        py = np.asarray(plan["y_mm"], dtype=np.float32)
        fig.add_trace(go.Scatter(x=px, y=py, mode="lines", name="programmed path",
                                 line={"color": "#bbbbbb", "width": 1}))
    if {"tcp/x", "tcp/y"} <= scan.present:
        colour_by = next((c for c in (FXY_TRUE, "adaptive_feed/peak") if c in scan.present), None)
        x = scan.starts["tcp/x"] * 1e3
        y = scan.starts["tcp/y"] * 1e3
        marker: dict[str, Any] = {"size": 4}
        if colour_by is not None:
            c = scan.envelopes[colour_by].hi
            label = "true |F_xy| [N]" if colour_by == FXY_TRUE else "regulated (per rev.)"
            top = float(np.nanpercentile(c, 99.5)) if np.isfinite(c).any() else 1.0
            # the scale ends at the 99.5th percentile: a start transient does not flatten it
            marker.update(color=c.astype(np.float32), colorscale="Viridis", cmin=0.0, cmax=top,
                          colorbar={"title": label}, showscale=True)  # fmt: skip
        fig.add_trace(go.Scatter(x=x.astype(np.float32), y=y.astype(np.float32),
                                 mode="markers", marker=marker, name="tool-centre point"))
    elif plan is None:
        return None
    for name, (colour, label) in MARKS.items():
        es = [e for e in events if e.name == name and id(e) in where]
        if es:
            fig.add_trace(go.Scatter(
                x=[where[id(e)][0] for e in es], y=[where[id(e)][1] for e in es],
                mode="markers", name=label,
                marker={"color": colour, "size": 14, "symbol": "x"},
                text=[f"{e.time_s:.3f} s: {e.message}" for e in es]))  # fmt: skip
    fig.update_xaxes(title_text="X [mm]")
    fig.update_yaxes(title_text="Y [mm]", scaleanchor="x", scaleratio=1)
    return _layout(fig, "Tool path coloured by force, events where they happened", 560)


def _breakage_figure(scan: RunScan, events: Sequence[Event], unit: str = "") -> go.Figure:
    """The residuals against their thresholds, titled with their unit (the torque's, N·m)."""
    two = "breakage/residual2" in scan.present
    rows = 2 if two else 1
    u = f" [{unit_label(unit)}]" if unit else ""
    titles = [f"first residual against its threshold{u}",
              f"second residual against its threshold{u}"]  # fmt: skip
    fig = make_subplots(rows=rows, cols=1, shared_xaxes=True, subplot_titles=titles[:rows])
    for r in range(1, rows + 1):
        for ch, lab in ((f"breakage/residual{r}", f"residual {r}"),
                        (f"breakage/limit{r}", f"threshold {r}")):  # fmt: skip
            if ch in scan.present:
                fig.add_trace(_trace(scan, ch, lab), row=r, col=1)
        if f"breakage/limit{r}" in scan.present:  # the alarm is on |residual|
            fig.add_trace(_trace(scan, f"breakage/limit{r}", f"− threshold {r}", -1.0), row=r,
                          col=1)  # fmt: skip
    _mark_events(fig, events, rows)
    fig.update_xaxes(title_text="time [s]", row=rows, col=1)
    return _layout(fig, "Breakage monitor: residual against threshold", 300 * rows)


def _control_figure(scan: RunScan, events: Sequence[Event], unit: str = "") -> go.Figure:
    """Feed override, the regulated quantity (named with its unit, from ``adaptive_feed/peak``)
    against its reference, and the true resultant force."""
    fig = make_subplots(rows=3, cols=1, shared_xaxes=True,
                        subplot_titles=["feed override [%]",
                                        f"{regulated_label(unit)} per control interval and "
                                        "reference",
                                        "true resultant force |F_xy| [N]"])  # fmt: skip
    for ch, lab in (("supervisor/feed_override", "commanded"), ("cnc/feed_override", "in effect")):
        if ch in scan.present:
            fig.add_trace(_trace(scan, ch, lab, 100.0), row=1, col=1)
    for ch, lab in (("adaptive_feed/peak", "regulated"), ("adaptive_feed/reference", "reference")):
        if ch in scan.present:
            fig.add_trace(_trace(scan, ch, lab), row=2, col=1)
    if FXY_TRUE in scan.present:
        fig.add_trace(_trace(scan, FXY_TRUE, "true |F_xy|", opacity=0.8), row=3, col=1)
    _mark_events(fig, events, 3)
    fig.update_xaxes(title_text="time [s]", row=3, col=1)
    return _layout(fig, "Adaptive control: feed override and force", 780)


def _spindle_figure(scan: RunScan, events: Sequence[Event]) -> go.Figure:
    fig = make_subplots(rows=1, cols=1)
    fig.add_trace(_trace(scan, "spindle/speed", "spindle speed [rev/min]", RPM), row=1, col=1)
    ch = [e for e in events if e.name == "spindle_override"]
    if ch:
        fig.add_trace(go.Scatter(x=[e.time_s for e in ch], y=[e.value for e in ch],
                                 mode="markers", name="spindle override [%]", yaxis="y2",
                                 marker={"symbol": "diamond", "size": 10}))  # fmt: skip
        fig.update_layout(yaxis2={"overlaying": "y", "side": "right", "title": "override [%]"})
    _mark_events(fig, events, 1)
    fig.update_xaxes(title_text="time [s]")
    fig.update_yaxes(title_text="rev/min")
    return _layout(fig, "Spindle speed and its changes", 340)


# ---------------------------------------------------------------- HTML
def figures_rows(f: RunFigures) -> list[tuple[str, str, Any]]:
    """The run's figures as (key, label, value) rows (the keys of the demo's summary)."""
    return [
        ("seconds", "signal recorded [s]", f.seconds),
        ("program_end_s", "program ended [s]", f.program_end_s),
        ("peak_force_intact_n", "peak true |F_xy|, tool intact [N]", f.peak_force_intact_n),
        ("peak_force_n", "peak true |F_xy| [N]", f.peak_force_n),
        ("mean_power_w", "mean spindle power in cut [W]", f.mean_power_w),
        ("breakage_alarm_s", "breakage alarm [s]", f.breakage_alarm_s),
        ("feed_hold_s", "feed hold [s]", f.feed_hold_s),
        ("cut_with_broken_tool_s", "cut with a broken tool [s]", f.cut_with_broken_tool_s),
    ]


#: Figures of the true tool forces (a simulation's ``truth/tool/force_x``, ``_y``), and of
#: the power from the plan's cutting torque as well: on a measured recording they are none.
_TRUTH_FIGURES = {"peak_force_intact_n", "peak_force_n", "cut_with_broken_tool_s"}
_POWER_FIGURES = {"mean_power_w"}


def _shown(key: str, value: Any, scan: RunScan) -> Any:
    """A figure as the report shows it: "–" with the reason where the recording lacks what
    it is computed from (an imported measurement showed "peak true |F_xy| [N] 0")."""
    if key in _TRUTH_FIGURES and not scan.truth:
        return "– (no true tool forces: a measured recording)"
    if key in _POWER_FIGURES and not (scan.truth and scan.power):
        return "– (needs the true forces and the plan's cutting torque)"
    return value


def _meta_value(key: str, value: Any) -> Any:
    """A metadata value in the recording table; an import's quality report as its counts
    (the findings follow in their own table)."""
    if key == "quality_json" and isinstance(value, str):
        from millsense.io.quality import finding_counts

        counts = finding_counts(value)
        return value if counts is None else f"{counts} (below)"
    return value if isinstance(value, int | float | str) else json.dumps(value)


def _quality_parts(meta: Mapping[str, Any]) -> list[str]:
    """The import's data-quality findings (``quality_json``), one row each."""
    text = meta.get("quality_json")
    try:
        findings = json.loads(text)["findings"] if isinstance(text, str) else []
        rows = [[f.get("kind"), "refused" if f.get("refuse") else "warning", f.get("message")]
                for f in findings[:MAX_EVENT_ROWS]]  # fmt: skip
    except (ValueError, KeyError, TypeError, AttributeError):
        return []
    if not rows:
        return []
    return ["<h3>Data quality of the import</h3>",
            html_table(["kind", "status", "finding"], rows, "quality")]  # fmt: skip


def _runs_table(runs: Mapping[str, RunFigures] | None) -> list[str]:
    """The figures of several runs side by side (the demo's summary table)."""
    if not runs:
        return []
    keys = list(runs)
    rows = [[lab, *(getattr(runs[k], key) for k in keys)]
            for key, lab, _ in figures_rows(next(iter(runs.values())))]  # fmt: skip
    return ["<h3>Runs side by side (the summary)</h3>",
            html_table(["figure", *keys], rows, "runs")]  # fmt: skip


def _event_rows(events: Sequence[Event]) -> list[list[Any]]:
    return [
        [round(e.time_s, 4), e.kind.value, e.severity.value, e.name, e.source,
         e.value, e.nc_line,
         None if e.x_mm is None else round(e.x_mm, 2),
         None if e.y_mm is None else round(e.y_mm, 2), e.message]
        for e in events[:MAX_EVENT_ROWS]
    ]  # fmt: skip


def identification_rows(machine: Any) -> list[list[str]]:
    """Each section of a machine file that names its ``source`` (nameplate, ``millsense
    identify ...``) with its scalar figures."""
    rows: list[list[str]] = []

    def walk(d: Mapping[str, Any], where: str) -> None:
        scal = [
            f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
            for k, v in d.items()
            if k != "source" and isinstance(v, int | float | str) and not isinstance(v, bool)
        ]
        arrays = [
            f"{k} = [{', '.join(f'{x:.6g}' for x in v)}]" if len(v) <= 4 else f"{k}[{len(v)}]"
            for k, v in d.items()
            if isinstance(v, list | tuple) and v and all(isinstance(x, int | float) for x in v)
        ]
        if d.get("source"):
            rows.append([where or "(machine)", str(d["source"]), ", ".join(scal[:8] + arrays)])
        for k, v in d.items():
            if isinstance(v, Mapping):
                walk(v, f"{where}.{k}" if where else k)

    walk(machine.model_dump(exclude_none=True), "")
    return rows


def _html(
    title: str,
    figs: Mapping[str, go.Figure],
    scan: RunScan,
    events: Sequence[Event],
    meta: Mapping[str, Any],
    harm: Sequence[dict[str, Any]],
    machine: Any,
    machine_where: str,
    validation: Sequence[Mapping[str, str]] | None,
    validation_where: str,
    runs: Mapping[str, RunFigures] | None = None,
    fleet_parts: Sequence[str] = (),
) -> str:
    f = scan.figures
    parts = [f"<h1>{html.escape(title)}</h1>",
             f'<p class="note">{scan.n} samples at {scan.fs:g} Hz ({scan.n / scan.fs:.2f} s); '
             f"whole-run traces are min/max envelopes of {scan.width} samples per bin (no peak "
             "dropped); zoom in with the mouse.</p>",
             "<h2>Run figures</h2>",
             html_table(["figure", "value"], [[lab, _shown(key, v, scan)]
                                              for key, lab, v in figures_rows(f)],
                    "figures"),
             html_table(["events", "count"], sorted(f.events.items()), "event-counts"),
             *_runs_table(runs),
             *fleet_parts,
             "<h2>Recording</h2>",
             html_table(["key", "value"], [[k, _meta_value(k, v)] for k, v in meta.items()]),
             *_quality_parts(meta)]  # fmt: skip
    sections = {
        "estimates": "Estimated against true forces and torque",
        "harmonics": "Tooth harmonics",
        "path": "Tool path",
        "breakage": "Breakage residual",
        "control": "Adaptive control",
        "spindle": "Spindle speed",
    }
    for key, head in sections.items():
        if key not in figs:
            continue
        parts.append(f"<h2>{head}</h2>")
        div = figs[key].to_html(full_html=False, include_plotlyjs=False, div_id=f"plot-{key}",
                                config={"responsive": True})  # fmt: skip
        parts.append(div)
        if key == "harmonics":
            rows = [[h["label"], k, a, b, 100 * e] for h in harm
                    for k, a, b, e in zip(h["harmonics"], h["estimate"], h["truth"], h["error"],
                                          strict=True)]  # fmt: skip
            parts.append(html_table(["signal", "harmonic", "estimated", "true", "error [%]"], rows))
    if not figs.get("estimates"):
        parts.append('<p class="note">No truth channels in this recording: no comparison of '
                     "estimates with truth.</p>")  # fmt: skip
    parts.append("<h2>Events</h2>")
    if len(events) > MAX_EVENT_ROWS:
        parts.append(f'<p class="note">first {MAX_EVENT_ROWS} of {len(events)} events</p>')
    cols = ["time [s]", "kind", "severity", "name", "source", "value", "NC line", "x [mm]",
            "y [mm]", "message"]  # fmt: skip
    parts.append(html_table(cols, _event_rows(events), "events"))
    parts.append("<h2>Machine file and identification</h2>")
    if machine is None:
        parts.append(f"<p>{html.escape(str(meta.get('machine_file', 'not known')))}</p>")
    else:
        parts.append(f"<p>{html.escape(machine_where)}</p>")
        parts.append(html_table(["section", "source", "figures"], identification_rows(machine)))
    parts.append("<h2>Validation status of the estimators and monitors used</h2>")
    if validation is None:
        parts.append('<p class="note">not known (run <code>millsense validate</code>).</p>')
    else:
        parts.append(f'<p class="note">as recorded in {html.escape(validation_where)}</p>')
        parts.append(html_table(["case", "reference", "measured", "tolerance", "status"],
                            [[r["case"], r["reference"], r["measured"], r["tolerance"],
                              r["status"]] for r in validation], "validation"))  # fmt: skip
    data = {"figures": asdict(f), "harmonics": list(harm),
            "runs": {k: asdict(v) for k, v in (runs or {}).items()}}  # fmt: skip
    blob = json.dumps(data, default=float).replace("</", "<\\/")
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{CSS}</style>"
        f"<script type='text/javascript'>{get_plotlyjs()}</script></head><body>"
        + "\n".join(parts)
        + f"<script type='application/json' id='millsense-report-data'>{blob}</script>"
        "</body></html>"
    )
