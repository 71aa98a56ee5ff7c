"""Process monitoring (issue 15): streaming monitors that watch estimated process states or
sensor channels and raise events; registered by name in :data:`MONITORS`."""

from millsense.monitoring.registry import MONITORS, MonitorContext, register

__all__ = ["MONITORS", "MonitorContext", "register"]
