"""The acceptance bench: simulated commissioning tests on the virtual machine, identified into
the estimators' models (feed axis, position-scheduled bank, spindle observer).

It sits above both the simulator and the estimators, so that neither imports the other; the
validation cases and tests use it. On a real machine the same identification runs from
recordings (``millsense commission`` / ``identify`` / ``merge``).
"""
