"""Unit conversions used at the edges (configuration files, CLI) — SI inside.

Field units appear in key names (``diameter_mm``, ``feed_mm_min``, ``ktc_n_mm2``,
``spindle_rpm``); each is converted once, on load, with the factors below.
"""

from __future__ import annotations

import math

MM = 1e-3  #: metres per millimetre
UM = 1e-6  #: metres per micrometre
MM_PER_MIN = 1e-3 / 60.0  #: (m/s) per (mm/min)
RPM = 2.0 * math.pi / 60.0  #: (rad/s) per (rev/min)
N_PER_MM2 = 1e6  #: (N/m^2) per (N/mm^2)
N_PER_MM = 1e3  #: (N/m) per (N/mm)
DEG = math.pi / 180.0  #: rad per degree
PERCENT = 1e-2


def rpm_to_rad_s(rpm: float) -> float:
    """Spindle speed in rev/min to rad/s."""
    return rpm * RPM


def rad_s_to_rpm(omega: float) -> float:
    """Angular speed in rad/s to rev/min."""
    return omega / RPM


def mm_min_to_m_s(feed: float) -> float:
    """Feed rate in mm/min to m/s."""
    return feed * MM_PER_MIN


def m_s_to_mm_min(v: float) -> float:
    """Speed in m/s to mm/min."""
    return v / MM_PER_MIN
