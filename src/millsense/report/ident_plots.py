"""Plots of identification results (PNG): FRF with fitted model and coherence, stabilisation
diagram, Stribeck curve, dual-inertia fit, spindle residual and G_dτ, idling table. Uses
matplotlib's Agg backend (no screen)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike

from millsense.ident.drive import DriveFit
from millsense.ident.frf import FrfEstimate
from millsense.ident.friction import LuGreFit
from millsense.ident.idle_table import IdleTable
from millsense.ident.modal_fit import ModalFit
from millsense.ident.spindle import SpindleFit
from millsense.report.plots import _save


def plot_frf_fit(
    data: FrfEstimate | tuple[ArrayLike, ArrayLike],
    fit: ModalFit | None,
    path: str | Path,
    *,
    truth: tuple[ArrayLike, ArrayLike] | None = None,
    title: str = "",
    unit: str = "",
    overlay: tuple[ArrayLike, ArrayLike, str] | None = None,
) -> None:
    """Magnitude [dB], phase [deg] and (for an estimate) coherence against frequency [Hz].

    Parameters
    ----------
    data : measured FRF (estimate with coherence, or ``(freq_hz, h)``).
    fit : fitted model drawn over the data, with its band shaded and mode frequencies marked.
    path : PNG file written.
    truth : optional reference ``(freq_hz, h)`` (simulation truth).
    title, unit : figure title and FRF unit for the magnitude label.
    overlay : another model ``(freq_hz, h, label)`` drawn like the fit (e.g. a rational fit).
    """
    if isinstance(data, FrfEstimate):
        f, h, coh = data.freq_hz, data.h1, data.coherence
    else:
        f, h, coh = np.asarray(data[0], float), np.asarray(data[1], complex), None
    n = 3 if coh is not None else 2
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(9, 2.4 * n + 0.8))
    axes[0].plot(f, 20 * np.log10(np.abs(h)), lw=0.8, color="0.5", label="measured H1")
    axes[1].plot(f, np.degrees(np.angle(h)), lw=0.8, color="0.5")
    if truth is not None:
        ft, ht = np.asarray(truth[0], float), np.asarray(truth[1], complex)
        axes[0].plot(ft, 20 * np.log10(np.abs(ht)), "g--", lw=0.9, label="truth")
        axes[1].plot(ft, np.degrees(np.angle(ht)), "g--", lw=0.9)
    if overlay is not None:
        fo, ho = np.asarray(overlay[0], float), np.asarray(overlay[1], complex)
        axes[0].plot(fo, 20 * np.log10(np.abs(ho)), "r", lw=1.0, label=overlay[2])
        axes[1].plot(fo, np.degrees(np.angle(ho)), "r", lw=1.0)
    if fit is not None:
        lo, hi = fit.band_hz
        fb = np.linspace(lo, hi, 3000)
        hf = fit.frf(fb)
        axes[0].plot(fb, 20 * np.log10(np.abs(hf)), "r", lw=1.0,
                     label=f"fit, {len(fit.modes)} modes")  # fmt: skip
        axes[1].plot(fb, np.degrees(np.angle(hf)), "r", lw=1.0)
        for ax in axes:
            ax.axvspan(lo, hi, color="y", alpha=0.08)
            for m in fit.modes:
                ax.axvline(m.natural_frequency_hz, color="r", lw=0.4, alpha=0.5)
    axes[0].set_ylabel(f"|H| [dB {unit}]".replace(" ]", "]"))
    axes[1].set_ylabel("phase [deg]")
    axes[0].legend(loc="best", fontsize=8)
    if coh is not None:
        axes[2].plot(f, coh, lw=0.8)
        axes[2].set_ylim(0, 1.05)
        axes[2].set_ylabel("coherence γ²")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("frequency [Hz]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    _save(fig, path)


def plot_stabilisation(
    fit: ModalFit,
    path: str | Path,
    data: FrfEstimate | tuple[ArrayLike, ArrayLike] | None = None,
    title: str = "",
) -> None:
    """Stabilisation diagram: poles per model order (× new, ○ stable in frequency, ● stable in
    frequency and damping), the selected order, and the measured |H| behind on a second axis.
    """
    if fit.diagram is None:
        raise ValueError("the fit has no stabilisation diagram (the order was given)")
    dg = fit.diagram
    fig, ax = plt.subplots(figsize=(9, 5))
    style = {"o": ("x", "0.6"), "f": ("o", "tab:blue"), "s": ("o", "tab:red")}
    for order, poles, labels in zip(dg.orders, dg.poles, dg.labels, strict=True):
        fn = np.abs(poles) / (2 * np.pi)
        for lab in ("o", "f", "s"):
            sel = np.array([lb == lab for lb in labels], dtype=bool)
            if sel.any():
                mk, col = style[lab]
                ax.plot(fn[sel], np.full(sel.sum(), order), mk, color=col, ms=4,
                        mfc=col if lab == "s" else "none")  # fmt: skip
    ax.axhline(dg.selected, color="k", lw=0.6, ls=":")
    for m in fit.modes:
        ax.axvline(m.natural_frequency_hz, color="r", lw=0.4, alpha=0.5)
    lo, hi = fit.band_hz
    ax.set_xlim(lo, hi)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order (mode pairs)")
    if data is not None:
        if isinstance(data, FrfEstimate):
            f, h = data.freq_hz, data.h1
        else:
            f, h = np.asarray(data[0], float), np.asarray(data[1], complex)
        ax2 = ax.twinx()
        sel = (f >= lo) & (f <= hi)
        ax2.plot(f[sel], 20 * np.log10(np.abs(h[sel])), color="0.7", lw=0.7)
        ax2.set_ylabel("|H| [dB]")
    ax.set_title(title or f"stabilisation diagram: order {dg.selected} selected, "
                 f"{len(fit.modes)} modes (× new, ○ f ±1 %, ● f ±1 % and ζ ±5 %)")  # fmt: skip
    fig.tight_layout()
    _save(fig, path)


def plot_stribeck(
    speed_rad_s: ArrayLike,
    torque_nm: ArrayLike,
    fit: LuGreFit,
    path: str | Path,
    *,
    std_error_nm: ArrayLike | None = None,
    title: str = "",
) -> None:
    """Stribeck curve: mean friction torque of the constant-velocity moves against speed with
    the fitted ``g(v) + σ2·v`` per direction (log speed axis, both directions folded)."""
    w = np.asarray(speed_rad_s, dtype=float)
    tau = np.asarray(torque_nm, dtype=float)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    se = None if std_error_nm is None else np.asarray(std_error_nm, dtype=float)
    for sel, part, col, name in (
        (w > 0, fit.positive, "tab:blue", "+"),
        (w < 0, fit.negative, "tab:red", "−"),
    ):
        if not sel.any():
            continue
        ax.errorbar(np.abs(w[sel]), np.abs(tau[sel]), yerr=None if se is None else se[sel],
                    fmt="o", color=col, ms=4, label=f"moves ({name})")  # fmt: skip
        grid = np.geomspace(np.abs(w[sel]).min() * 0.5, np.abs(w[sel]).max() * 1.5, 300)
        lab = (
            f"fit ({name}): τc {part.coulomb:.3g}, τs {part.static:.3g} N·m, "
            f"vs {part.stribeck_velocity:.3g} rad/s, σ2 {part.viscous:.3g} N·m·s/rad"
        )
        ax.plot(grid, part.torque(grid), color=col, lw=1.0, label=lab)
    ax.set_xscale("log")
    ax.set_xlabel("|motor speed| [rad/s]")
    ax.set_ylabel("|friction torque| [N·m]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(title or "Stribeck curve (Aslan Eq. 3.4)")
    fig.tight_layout()
    _save(fig, path)


def plot_drive_fit(fit: DriveFit, path: str | Path, *, title: str = "") -> None:
    """Accelerance FRFs current command → motor and → table acceleration with the fitted
    dual-inertia model (magnitude and phase)."""
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    f = fit.freq_hz
    for h, m, col, name in (
        (fit.motor_accel, fit.model_motor, "tab:blue", "motor [rad/s²/A]"),
        (fit.table_accel, fit.model_table, "tab:red", "table [m/s²/A]"),
    ):
        axes[0].semilogx(f, 20 * np.log10(np.abs(h)), ".", color=col, ms=2, label=name)
        axes[0].semilogx(f, 20 * np.log10(np.abs(m)), "-", color=col, lw=0.9)
        axes[1].semilogx(f, np.degrees(np.unwrap(np.angle(h))), ".", color=col, ms=2)
        axes[1].semilogx(f, np.degrees(np.unwrap(np.angle(m))), "-", color=col, lw=0.9)
    axes[0].set_ylabel("|H| [dB]")
    axes[1].set_ylabel("phase [deg]")
    axes[1].set_xlabel("frequency [Hz]")
    axes[0].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    p = fit.params
    fig.suptitle(
        title
        or (
            f"dual inertia: J_r {p.screw_inertia:.3g} kg·m², M_t {p.table_mass:.3g} kg, "
            f"K_r {p.axial_stiffness * 1e-6:.3g} N/µm; T_s+T_m {fit.motor_delay * 1e3:.3f} ms, "
            f"T_s+T_t {fit.table_delay * 1e3:.3f} ms"
        ),
        fontsize=9,
    )
    fig.tight_layout()
    _save(fig, path)


def plot_spindle_fit(
    fit: SpindleFit,
    path: str | Path,
    *,
    truth: tuple[ArrayLike, ArrayLike] | None = None,
    title: str = "",
) -> None:
    """Measured and fitted residual R, and the formed G_dτ (magnitude and phase)."""
    f = fit.freq_hz
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 8))
    axes[0].semilogx(f, 20 * np.log10(np.abs(fit.residual_measured)), ".", ms=2, color="0.5",
                     label="R measured")  # fmt: skip
    axes[0].semilogx(f, 20 * np.log10(np.abs(fit.residual.frf(f))), "r", lw=0.9,
                     label=f"R fit, {len(fit.residual.modes)} modes")  # fmt: skip
    axes[0].set_ylabel("|R| [dB]")
    g = fit.disturbance_frf(f)
    axes[1].semilogx(f, 20 * np.log10(np.abs(g)), "b", lw=0.9, label="G_dτ identified")
    axes[2].semilogx(f, np.degrees(np.angle(g)), "b", lw=0.9)
    if truth is not None:
        ft, ht = np.asarray(truth[0], float), np.asarray(truth[1], complex)
        axes[1].semilogx(ft, 20 * np.log10(np.abs(ht)), "g--", lw=0.9, label="truth")
        axes[2].semilogx(ft, np.degrees(np.angle(ht)), "g--", lw=0.9)
    axes[1].set_ylabel("|G_dτ| [dB A/(N·m)]")
    axes[2].set_ylabel("phase [deg]")
    axes[2].set_xlabel("frequency [Hz]")
    for ax in axes[:2]:
        ax.legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    fig.suptitle(title or "spindle: residual modes (Aslan App. E form) and G_dτ (Eq. 5.12)")
    fig.tight_layout()
    _save(fig, path)


def plot_idle_table(
    table: IdleTable,
    path: str | Path,
    runs: list[tuple[np.ndarray, np.ndarray]] | None = None,
    *,
    title: str = "",
) -> None:
    """The idling table against position with the runs it averages."""
    fig, ax = plt.subplots(figsize=(9, 4))
    for k, (x, y) in enumerate(runs or []):
        ax.plot(np.asarray(x) * 1e3, y, lw=0.4, alpha=0.5, label=f"air cut {k + 1}")
    ax.plot(table.position_m * 1e3, table.value, "k", lw=0.9, label="table (mean)")
    ax.set_xlabel("position [mm]")
    ax.set_ylabel(f"{table.quantity} [{table.unit}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or f"idling table, {table.n_runs} runs (Yamada §2.9)")
    fig.tight_layout()
    _save(fig, path)
