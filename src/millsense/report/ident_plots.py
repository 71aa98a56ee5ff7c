"""Plots of identification results (PNG): FRF with fitted model and coherence, stabilisation
diagram. Uses matplotlib's Agg backend (no screen)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike

from millsense.ident.frf import FrfEstimate
from millsense.ident.modal_fit import ModalFit
from millsense.report.plots import _save


def plot_frf_fit(
    data: FrfEstimate | tuple[ArrayLike, ArrayLike],
    fit: ModalFit | None,
    path: str | Path,
    *,
    truth: tuple[ArrayLike, ArrayLike] | None = None,
    title: str = "",
    unit: str = "",
) -> None:
    """Magnitude [dB], phase [deg] and (for an estimate) coherence against frequency [Hz].

    Parameters
    ----------
    data : measured FRF (estimate with coherence, or ``(freq_hz, h)``).
    fit : fitted model drawn over the data, with its band shaded and mode frequencies marked.
    path : PNG file written.
    truth : optional reference ``(freq_hz, h)`` (simulation truth).
    title, unit : figure title and FRF unit for the magnitude label.
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
