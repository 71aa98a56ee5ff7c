"""One BLAS thread for millsense's small linear algebra (decisions 0907, 2004).

The matrices of millsense are small (Kalman designs of 5–40 states, monodromy matrices of a
few hundred): a multi-threaded OpenBLAS only adds spinning threads — the spindle observer's
tuning took 3.3 times the CPU time on the default threads than on one, for the same result.
:func:`default_to_one_thread` sets the thread variables to 1 where the user has not set them;
it must run before numpy is imported (``millsense.cli.main`` calls it first).
:func:`limit_blas_threads` sets the count on an OpenBLAS already loaded (``lobes --threads``).
"""

from __future__ import annotations

import ctypes
import os
import re
from pathlib import Path

__all__ = ["THREAD_VARS", "default_to_one_thread", "limit_blas_threads"]

#: The variables OpenBLAS, OpenMP and MKL read at load.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def default_to_one_thread() -> None:
    """Set every unset :data:`THREAD_VARS` to 1 (effective for libraries not loaded yet, and
    for child processes such as ``batch`` workers)."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, "1")


def limit_blas_threads(threads: int | None) -> int | None:
    """Set the thread count of every OpenBLAS already loaded in this process (None: only read).

    Returns the count the library reports afterwards (None if no OpenBLAS is loaded).
    """
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    libs = sorted(set(re.findall(r"(/\S*openblas\S*\.so\S*)", maps)))
    got = None
    for lib in libs:
        try:
            handle = ctypes.CDLL(lib)
        except OSError:
            continue
        for prefix in ("", "scipy_"):
            for suffix in ("", "64_"):
                setter = getattr(handle, f"{prefix}openblas_set_num_threads{suffix}", None)
                getter = getattr(handle, f"{prefix}openblas_get_num_threads{suffix}", None)
                if setter is not None and threads is not None:
                    setter(ctypes.c_int(threads))
                if getter is not None:
                    got = int(getter())
    return got
