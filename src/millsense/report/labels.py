"""Axis and title labels shared by the run's PNG (:mod:`millsense.report.online_plots`) and
its HTML report (:mod:`millsense.report.run_report`): every quantity named with its unit."""

from __future__ import annotations

#: The regulated quantity of the adaptive feed by the unit of its channel.
_REGULATED = {"W": "spindle power", "N*m": "cutting torque", "N": "resultant force"}


def unit_label(unit: str) -> str:
    """A channel's SI unit as an axis shows it (``N*m`` → ``N·m``)."""
    return unit.replace("*", "·")


def regulated_label(unit: str) -> str:
    """The adaptive feed's regulated quantity with its unit, from the unit of
    ``adaptive_feed/peak``: ``spindle power [W]``; ``regulated`` where the unit is not known."""
    what = _REGULATED.get(unit, "regulated")
    return f"{what} [{unit_label(unit)}]" if unit else what
