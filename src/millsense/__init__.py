"""millsense: sensorless monitoring and control of milling from CNC drive signals.

Packages (lower layers never import higher ones)::

    core        recordings in memory, configuration models, units, errors
    io          recording files (crash-safe HDF5), plan files
    process     tool geometry, chip thickness, mechanistic cutting forces
    stability   modal FRFs, stability lobes (ZOA, semi-discretisation), time-domain chatter
    virtual     G-code, stock, engagement, virtual plan
    machine     virtual machine tool: drives, friction, servo loops, spindle, kinematics
    ident       system identification from recordings
    estimation  force and torque estimators (Kalman toolkit, observers)
    monitoring  chatter, breakage, engagement monitoring
    control     adaptive control, chatter avoidance
    online      the block-streaming engine and its sources
    validation  registry of validation cases against references nobody tuned to
    cli         the ``millsense`` command
"""

__version__ = "0.1.0"

# numba's compiled kernels in a folder per state of these sources, before any kernel module is
# imported: numba's own cache follows a kernel's file only, not the kernels it calls (1722)
from millsense.core.numba_cache import configure as _configure_numba_cache

_configure_numba_cache()
