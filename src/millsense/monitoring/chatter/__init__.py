"""Chatter detection (issue 15 item 1): seed 000 comb filter, seed 001 SDFT + moving variance,
seed 002 fixed spectrum threshold, behind one streaming block (:class:`ChatterMonitor`)."""

from millsense.monitoring.chatter.block import ChatterGroup, ChatterMonitor, ChatterSettings
from millsense.monitoring.chatter.comb import comb_coefficients
from millsense.monitoring.chatter.methods import METHODS

__all__ = ["METHODS", "ChatterGroup", "ChatterMonitor", "ChatterSettings", "comb_coefficients"]
