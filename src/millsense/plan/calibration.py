"""Calibration of K_tc from the measured mean torque (or tangential force) of a steady cut.

Seed 000 C16 calibrates K_tc over the first 10 revolutions "from the CWE information and the
measured tangential force" without a formula; V9 suggests F_res = K_tc c Gain_CWE.
millsense uses the mean torque, which is exactly linear in the shear coefficients
(docs/decisions/0064-k-tc-calibration-seed-000-c16.md):

    T̄ = s T̄_shear + T̄_edge,   s = K_tc,new / K_tc,plan,

where T̄_shear and T̄_edge = T̄ − T̄_shear are the plan's predicted shear and edge parts
(columns ``torque_avg_shear_nm``, ``torque_avg_nm``) averaged over the rows of the window, so

    K_tc,new = K_tc,plan (T̄_meas − T̄_edge) / T̄_shear.

The shear coefficients K_tc, K_rc, K_ac are scaled together (their ratios, e.g. Aslan's
K_rc = 0.5 K_tc, are kept) and the edge coefficients are kept. A measured mean tangential
force converts to torque as T = F_t R (Aslan Eq. 5.31).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError
from millsense.core.units import MM
from millsense.plan.predict import STAT_NAMES, evaluate
from millsense.plan.virtual_plan import VirtualPlan

IntArray = NDArray[np.int64]

#: Revolutions averaged by default (seed 000 C16: the first 10).
DEFAULT_REVOLUTIONS = 10


@dataclass(frozen=True)
class Calibration:
    """Result of a K_tc calibration.

    Attributes
    ----------
    ktc_plan_n_mm2, ktc_n_mm2 : float
        K_tc of the plan and the calibrated K_tc [N/mm²].
    scale : float
        Ratio applied to the shear coefficients.
    rows : (k,) int
        Rows averaged.
    torque_pred_nm, torque_meas_nm : float
        Mean predicted (plan) and measured torque over the window [N·m].
    """

    ktc_plan_n_mm2: float
    ktc_n_mm2: float
    scale: float
    rows: IntArray
    torque_pred_nm: float
    torque_meas_nm: float


def steady_window(
    plan: VirtualPlan, start_row: int, revolutions: float = DEFAULT_REVOLUTIONS
) -> IntArray:
    """Rows covering ``revolutions`` spindle turns from ``start_row`` (in cut, predicted).

    Parameters
    ----------
    plan : VirtualPlan
        The plan.
    start_row : int
        First row of the window (e.g. the first in-cut row of a steady cut).
    revolutions : float
        Number of revolutions; the time of a row is its step over the programmed feed.

    Returns
    -------
    (k,) int
        Rows from ``start_row`` while the accumulated spindle angle is below the target,
        stopping at the first row out of cut.
    """
    n = len(plan)
    if not (0 <= start_row < n):
        raise InputDataError(f"calibration: start_row {start_row} outside 0..{n - 1}")
    t = plan["t_s"]
    rev = np.concatenate(([0.0], np.cumsum(np.diff(t) * plan["spindle_rpm"][:-1] / 60.0)))
    rev = rev - rev[start_row]
    stop = int(np.searchsorted(rev, revolutions, side="left"))
    rows = np.arange(start_row, max(min(stop, n), start_row + 1))
    cut = plan["in_cut"][rows] & (plan["ktc_n_mm2"][rows] > 0)
    if not cut[0]:
        raise InputDataError(f"calibration: row {start_row} is not a predicted cutting row")
    end = int(np.argmin(cut)) if not cut.all() else rows.size
    return rows[:end].astype(np.int64)


def calibrate_ktc(
    plan: VirtualPlan,
    rows: IntArray,
    *,
    measured_torque_nm: float | None = None,
    measured_tangential_force_n: float | None = None,
) -> Calibration:
    """K_tc from the measured mean torque (or tangential force) over plan rows.

    Parameters
    ----------
    plan : VirtualPlan
        Plan whose rows the measurement covers.
    rows : (k,) int
        Rows of the window (:func:`steady_window`).
    measured_torque_nm : float, optional
        Mean measured cutting torque over the window [N·m].
    measured_tangential_force_n : float, optional
        Mean measured tangential force [N] (T = F_t R, Aslan Eq. 5.31), if no torque.

    Returns
    -------
    Calibration

    Notes
    -----
    K_tc,new = K_tc,plan (T̄_meas − T̄_edge)/T̄_shear (module docstring).
    """
    idx = np.asarray(rows, dtype=np.int64)
    if idx.size == 0:
        raise InputDataError("calibration: no rows in the window")
    if (measured_torque_nm is None) == (measured_tangential_force_n is None):
        raise InputDataError("calibration: give exactly one of torque or tangential force")
    if measured_torque_nm is not None:
        t_meas = float(measured_torque_nm)
    else:
        radius = 0.5 * float(plan.metadata["tool"]["diameter_mm"]) * MM
        t_meas = float(measured_tangential_force_n) * radius  # type: ignore[arg-type]
    if not math.isfinite(t_meas):
        raise InputDataError("calibration: measured value is not finite")
    ktc = plan["ktc_n_mm2"][idx]
    if np.any(ktc <= 0) or np.ptp(ktc) > 1e-9 * float(ktc.max()):
        raise InputDataError("calibration: window rows must be predicted cut rows of one K_tc")
    total = float(np.mean(plan["torque_avg_nm"][idx]))
    shear = float(np.mean(plan["torque_avg_shear_nm"][idx]))
    if not shear > 0:
        raise InputDataError("calibration: predicted shear torque is zero in the window")
    scale = (t_meas - (total - shear)) / shear
    if not scale > 0:
        raise InputDataError(
            f"calibration: measured torque {t_meas:.4g} N·m is below the predicted edge "
            f"torque {total - shear:.4g} N·m"
        )
    k0 = float(ktc[0])
    return Calibration(k0, k0 * scale, scale, idx, total, t_meas)


def rescale_plan(plan: VirtualPlan, ktc_n_mm2: float) -> VirtualPlan:
    """A copy of the plan with predictions for a new K_tc (shear coefficients scaled).

    Parameters
    ----------
    plan : VirtualPlan
        Plan (from a file or in memory).
    ktc_n_mm2 : float
        New K_tc [N/mm²].

    Returns
    -------
    VirtualPlan

    Notes
    -----
    Means (forces, torque, power) are linear in the shear scale s: Q = Q + (s − 1) Q_shear,
    exact. Peaks: with the in-memory force basis they are recomputed exactly; for a plan read
    from a file they are re-evaluated at the spindle angle of the stored peak,
    F = F + (s − 1) F_shear there, which is a lower bound of the new peak whose error is
    second order in the angle shift (the peak is a maximum); tested within 0.5 % for s = 1.19.
    """
    if not (math.isfinite(ktc_n_mm2) and ktc_n_mm2 > 0):
        raise InputDataError(f"calibration: K_tc must be > 0, got {ktc_n_mm2!r}")
    cols: dict[str, Any] = {k: np.array(v, copy=True) for k, v in plan.columns.items()}
    ktc = cols["ktc_n_mm2"]
    act = ktc > 0
    s = np.where(act, ktc_n_mm2 / np.where(act, ktc, 1.0), 1.0)
    if plan.basis is not None:
        base_ktc = float(plan.metadata["material"]["ktc_n_mm2"])
        if np.any(np.abs(ktc[act] - ktc[act][0]) > 1e-9 * ktc_n_mm2):
            raise InputDataError("calibration: plan rows have several K_tc values")
        stats = evaluate(
            plan.basis,
            cols["chip_load_mm"] * MM,
            np.radians(cols["feed_angle_deg"]),
            ktc_n_mm2 / base_ktc,
        )
        for name in STAT_NAMES:
            unit = "nm" if name.startswith("torque") else "n"
            cols[f"{name}_{unit}"] = stats[name]
    else:
        for q in ("fx_avg", "fy_avg", "fz_avg", "fx_peak", "fy_peak", "fz_peak"):
            cols[f"{q}_n"] = cols[f"{q}_n"] + (s - 1) * cols[f"{q}_shear_n"]
            cols[f"{q}_shear_n"] = s * cols[f"{q}_shear_n"]
        for q in ("torque_avg", "torque_peak"):
            cols[f"{q}_nm"] = cols[f"{q}_nm"] + (s - 1) * cols[f"{q}_shear_nm"]
            cols[f"{q}_shear_nm"] = s * cols[f"{q}_shear_nm"]
        for ax in ("x", "y"):
            cols[f"fres_peak_{ax}_n"] = (
                cols[f"fres_peak_{ax}_n"] + (s - 1) * cols[f"fres_peak_shear_{ax}_n"]
            )
            cols[f"fres_peak_shear_{ax}_n"] = s * cols[f"fres_peak_shear_{ax}_n"]
        cols["fres_peak_n"] = np.hypot(cols["fres_peak_x_n"], cols["fres_peak_y_n"])
    cols["fres_avg_n"] = np.hypot(cols["fx_avg_n"], cols["fy_avg_n"])
    cols["power_w"] = cols["torque_avg_nm"] * cols["spindle_rpm"] * (2 * math.pi / 60.0)
    cols["ktc_n_mm2"] = np.where(act, ktc_n_mm2, 0.0)
    meta = dict(plan.metadata)
    meta["ktc_calibrated_n_mm2"] = ktc_n_mm2
    return VirtualPlan(cols, meta, plan.basis, plan.layers)
