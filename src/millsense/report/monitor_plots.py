"""The figure of ``millsense monitor --plot`` (issue 15 item 6): the monitored signal's
spectrogram with the detected chatter, the chatter criteria's ratios, each breakage detector's
residuals against their thresholds, and the engagement monitor's depth-of-cut tracks; the
panels of the monitors that ran."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from millsense.report.labels import unit_label

#: Outputs of the monitors the figure draws (suffixes of ``{monitor}/...``).
CHATTER_KEYS = ("chatter_hz", "energy_ratio")
BREAKAGE_KEYS = ("tooth_avg", "residual1", "limit1", "residual2", "limit2", "band")
ENGAGEMENT_KEYS = ("axial_depth", "radial_depth", "reliability", "kt", "axial_depth_sd")


def plotted(key: str) -> bool:
    """Whether a monitor output channel is drawn (kept by the command's sink)."""
    tail = key.rsplit("/", 1)[-1]
    return tail in CHATTER_KEYS or tail in BREAKAGE_KEYS or tail in ENGAGEMENT_KEYS


def monitor_panels(data: dict[str, np.ndarray], monitors: Sequence[str]) -> list[tuple[str, Any]]:
    """The figure's panels, top down: ``("spectrogram", None)`` where chatter monitors ran (or
    nothing else did), ``("ratio", [chatter monitors])``, ``("breakage", name)`` per breakage
    detector, ``("engagement", name)``."""
    chatter = [m for m in monitors if f"{m}/energy_ratio" in data]
    breakage = [m for m in monitors if f"{m}/residual1" in data]
    engagement = [m for m in monitors if f"{m}/axial_depth" in data]
    panels: list[tuple[str, Any]] = []
    if data.get("signal") is not None and (chatter or not (breakage or engagement)):
        panels.append(("spectrogram", None))
    if chatter:
        panels.append(("ratio", chatter))
    panels += [("breakage", m) for m in breakage]
    panels += [("engagement", m) for m in engagement]
    return panels or [("spectrogram", None)]


def plot_monitor(
    path: Path,
    data: dict[str, np.ndarray],
    fs: float,
    step: int,
    t0: float,
    signal: str,
    monitors: Sequence[str],
    events: Sequence[Any],
    units: Mapping[str, str] | None = None,
) -> None:
    """Write the PNG of :func:`monitor_figure`."""
    import matplotlib.pyplot as plt

    from millsense.io.safe_output import atomic_path

    fig = monitor_figure(data, fs, step, t0, signal, monitors, events, units)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)


def monitor_figure(
    data: dict[str, np.ndarray],
    fs: float,
    step: int,
    t0: float,
    signal: str,
    monitors: Sequence[str],
    events: Sequence[Any],
    units: Mapping[str, str] | None = None,
) -> Any:
    """The figure: ``data['signal']`` at ``fs``; the monitors' outputs ``data[name/key]``
    every ``step`` samples (from the stream's first sample); ``units``: monitor name → the
    unit of the signal it judges (a breakage detector's torque, ``N*m``), shown on its axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = monitor_panels(data, monitors)
    heights = [3 if kind == "spectrogram" else 1.3 for kind, _ in panels]
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.2 + 1.6 * sum(heights) / 1.3),
                             sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": heights})  # fmt: skip
    for ax, (kind, what) in zip(axes[:, 0], panels, strict=True):
        if kind == "spectrogram":
            _spectrogram(ax, data, fs, t0, signal, monitors, step, events)
        elif kind == "ratio":
            _ratios(ax, data, step, fs, t0, what, events)
        elif kind == "breakage":
            _breakage(ax, data, step, fs, t0, what, events, (units or {}).get(what, ""))
        else:
            _engagement(ax, data, step, fs, t0, what)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def _time(x: np.ndarray, step: int, fs: float, t0: float) -> np.ndarray:
    return t0 + step * np.arange(len(x)) / fs


def _spectrogram(ax: Any, data: dict[str, np.ndarray], fs: float, t0: float, signal: str,
                 monitors: Sequence[str], step: int, events: Sequence[Any]) -> None:  # fmt: skip
    from scipy.signal import spectrogram

    x = data.get("signal")
    if x is not None and len(x) >= 512:
        f, t, s = spectrogram(x - np.mean(x), fs=fs, nperseg=1024, noverlap=768)
        ax.pcolormesh(t + t0, f, 10 * np.log10(s + 1e-30), shading="auto", cmap="viridis")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title(f"{signal}: spectrogram, chatter detections marked")
    drawn = False
    for name in monitors:
        hz = data.get(f"{name}/chatter_hz")
        if hz is None:
            continue
        sel = np.isfinite(hz)
        every = max(1, int(fs * 0.05 / step))
        ax.plot(_time(hz, step, fs, t0)[sel][::every], hz[sel][::every], ".", ms=4,
                label=f"{name} chatter")  # fmt: skip
        drawn = True
    for e in events:
        if e.name == "chatter":
            ax.axvline(e.time_s, color="r", lw=0.8)
    if drawn:
        ax.legend(loc="upper right", fontsize=8)


def _ratios(ax: Any, data: dict[str, np.ndarray], step: int, fs: float, t0: float,
            names: Sequence[str], events: Sequence[Any]) -> None:  # fmt: skip
    for name in names:
        r = data[f"{name}/energy_ratio"]
        ax.plot(_time(r, step, fs, t0), r, label=name)
    for e in events:
        if e.name == "chatter":
            th = e.values.get("threshold")
            if th is not None:
                ax.axhline(th, color="r", lw=0.5, ls="--")
    ax.set_ylabel("chatter ratio")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.legend(loc="upper left", fontsize=8)


def _breakage(ax: Any, data: dict[str, np.ndarray], step: int, fs: float, t0: float,
              name: str, events: Sequence[Any], unit: str = "") -> None:  # fmt: skip
    """Residual 1 against ±limit 1; for the virtual and constant thresholds the tooth average's
    deviation from its reference against ±band (what confirms), else residual 2 against
    ±limit 2 (seed 002's dual residual); ``unit``: the judged signal's ("": not known)."""
    from millsense.monitoring.breakage import SIGMA_TB  # limits are σ_TB × the reference
    g = {k: data[f"{name}/{k}"] for k in BREAKAGE_KEYS if f"{name}/{k}" in data}
    t = _time(g["residual1"], step, fs, t0)
    ax.plot(t, g["residual1"], lw=0.7, color="tab:blue", label="residual 1")
    ax.plot(t, g["limit1"], lw=0.7, ls="--", color="tab:blue", label="±limit 1")
    ax.plot(t, -g["limit1"], lw=0.7, ls="--", color="tab:blue")
    band = g.get("band")
    if band is not None and np.isfinite(band).any():
        dev = g["tooth_avg"] - g["limit1"] / SIGMA_TB
        ax.plot(t, dev, lw=0.7, color="tab:orange", label="tooth average − reference")
        ax.plot(t, band, lw=0.7, ls=":", color="tab:orange", label="±band")
        ax.plot(t, -band, lw=0.7, ls=":", color="tab:orange")
    else:
        ax.plot(t, g["residual2"], lw=0.7, color="tab:orange", label="residual 2")
        ax.plot(t, g["limit2"], lw=0.7, ls="--", color="tab:orange", label="±limit 2")
        ax.plot(t, -g["limit2"], lw=0.7, ls="--", color="tab:orange")
    for e in events:
        if e.source == name and e.name == "breakage":
            ax.axvline(e.time_s, color="r", lw=0.9)
        elif e.source == name and e.name == "breakage_blind":
            ax.axvline(e.time_s, color="0.5", lw=0.7, ls="-.")
    ax.set_ylabel(f"{name}\n[{unit_label(unit) if unit else 'N·m or N'}]", fontsize=8)
    ax.legend(loc="upper left", fontsize=7, ncol=3)


def _engagement(ax: Any, data: dict[str, np.ndarray], step: int, fs: float, t0: float,
                name: str) -> None:  # fmt: skip
    from millsense.monitoring.engagement import RELIABLE_SIGMA  # dots below (decision 1807)

    axial = 1e3 * data[f"{name}/axial_depth"]
    radial = 1e3 * data.get(f"{name}/radial_depth", np.full(len(axial), np.nan))
    rel = data.get(f"{name}/reliability", np.ones(len(axial)))
    kt = data.get(f"{name}/kt", np.ones(len(axial)))
    t = _time(axial, step, fs, t0)
    # the revolutions the command's summary reports (decision 1807: σ, K_t > 0, K_e ≥ 0 and
    # the plan's steady cut), else σ and K_t alone
    good = data.get(f"{name}/reported")
    if good is None:
        good = (rel >= RELIABLE_SIGMA) & (kt > 0)
    good = np.asarray(good, dtype=bool)
    sd = data.get(f"{name}/axial_depth_sd")
    if sd is not None:  # ± one standard deviation of a revolution's d_a (decision 1558)
        band = np.where(good, 1e3 * sd, np.nan)
        ax.fill_between(t, axial - band, axial + band, color="tab:green", alpha=0.2, lw=0,
                        label="axial depth ± 1 s.d.")  # fmt: skip
    for y, label, color in ((axial, "axial depth", "tab:green"),
                            (radial, "radial depth", "tab:purple")):  # fmt: skip
        ax.plot(t, np.where(good, y, np.nan), lw=1.0, color=color, label=label)
        # one hollow marker per unreported revolution (where its held value starts): a
        # marker per sample drew them as lines, like results
        first = np.concatenate([[True], y[1:] != y[:-1]]) & np.isfinite(y) & ~good
        ax.plot(t[first], y[first], "o", ms=3, mfc="none", mew=0.6, color=color, alpha=0.5)
    extra = _averaged_band(ax, data, t, name)
    top = np.nanmax(np.concatenate([axial[good], radial[good], extra, [1.0]]))
    ax.set_ylim(0.0, 1.3 * top)
    ax.set_ylabel("depth of cut [mm]", fontsize=8)
    title = (
        "circles: revolutions (none reported alone)"
        if extra.size
        else f"circles: revolutions not reported (σ < {RELIABLE_SIGMA:g}, K_t ≤ 0 or K_e < 0)"
    )
    ax.legend(loc="upper left", fontsize=7, title=title, title_fontsize=7)  # fmt: skip


def _averaged_band(ax: Any, data: dict[str, np.ndarray], t: np.ndarray, name: str) -> np.ndarray:
    """Where the command's summary reports the cut's averaged harmonics (decisions 1698,
    1704: ``{name}/averaged_depth``, ``_low``, ``_high`` over the averaged revolutions' steps),
    their axial depth as a line and its profile interval as a band (their radial depth as a
    line, ``_radial``); where they do not determine
    the depth (depth NaN), the depths they allow as a hatched band. Returns the depths drawn
    (mm) for the axis' range (empty: nothing drawn)."""
    lo = data.get(f"{name}/averaged_low")
    hi = data.get(f"{name}/averaged_high")
    if lo is None or hi is None:
        return np.zeros(0)
    depth = 1e3 * np.asarray(data.get(f"{name}/averaged_depth", np.full(len(lo), np.nan)))
    span = np.isfinite(lo) | np.isfinite(hi) | np.isfinite(depth)
    if not span.any():
        return np.zeros(0)
    lo_mm = np.where(span, 1e3 * np.nan_to_num(lo, nan=0.0), np.nan)
    finite_hi = np.isfinite(hi)
    hi_mm = np.where(span & finite_hi, 1e3 * np.where(finite_hi, hi, 0.0), np.nan)
    if not np.isfinite(hi_mm).any():
        return np.zeros(0)
    d = float(depth[span][0])
    l_s, h_s = float(np.nanmin(lo_mm)), float(np.nanmax(hi_mm))
    if np.isfinite(d):
        band = f"averaged harmonics' profile interval {l_s:.3f}–{h_s:.3f} mm"
        ax.fill_between(t, lo_mm, hi_mm, color="tab:green", alpha=0.3, lw=0, label=band)
        ax.plot(t, np.where(span, depth, np.nan), lw=1.6, color="tab:green",
                label=f"axial depth of the averaged harmonics {d:.3f} mm")  # fmt: skip
        radial = 1e3 * np.asarray(data.get(f"{name}/averaged_radial", np.full(len(lo), np.nan)))
        if np.isfinite(radial).any():
            r = float(radial[np.isfinite(radial)][0])
            ax.plot(t, radial, lw=1.6, color="tab:purple",
                    label=f"radial depth of the averaged harmonics {r:.3f} mm")  # fmt: skip
            h_s = max(h_s, r)
    else:
        ax.fill_between(t, lo_mm, hi_mm, facecolor="none", edgecolor="tab:green", hatch="//",
                        lw=0, label=f"not determined: averaged harmonics allow "
                        f"{l_s:.2f}–{h_s:.2f} mm")  # fmt: skip
    return np.array([h_s, d if np.isfinite(d) else h_s])
