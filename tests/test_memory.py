"""``core.memory.keep_freed_memory`` (decision 2003): a batch worker reuses the arrays it
frees. Its effect is measured by the ``batch.scaling`` benchmark (2.3 million page faults and
7 s of system time per 100 recordings before, docs/batch.md); page-fault counts of a probe
depend too much on the kernel (transparent huge pages) to be asserted here."""

from __future__ import annotations

import ctypes
import ctypes.util
import subprocess
import sys

import pytest

PROBE = """
import sys
from millsense.core import memory
first = memory.keep_freed_memory()
print(first, memory.keep_freed_memory(), memory._DONE)
"""


def _glibc() -> bool:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return hasattr(libc, "gnu_get_libc_version")
    except OSError:
        return False


@pytest.mark.skipif(not (sys.platform.startswith("linux") and _glibc()), reason="glibc only")
def test_keep_freed_memory_sets_the_thresholds_once() -> None:
    """glibc accepts both thresholds (mallopt returns 1 for each); a second call changes
    nothing and answers the same (run in a fresh process: the setting is process-wide)."""
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         check=True)  # fmt: skip
    assert out.stdout.split() == ["True", "True", "[True]"]
