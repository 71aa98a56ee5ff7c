"""Every CLI process runs BLAS on one thread unless the user says otherwise (decision 2004)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from millsense.core.blas import THREAD_VARS

PROBE = (
    "import millsense.cli.main, numpy as np; np.linalg.eigvals(np.eye(3)); "
    "from millsense.core.blas import limit_blas_threads; print(limit_blas_threads(None))"
)


def _threads(extra: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    env.update(extra)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                         check=True, timeout=120)  # fmt: skip
    return out.stdout.strip()


def test_the_cli_loads_openblas_on_one_thread() -> None:
    got = _threads({})
    if got == "None":
        pytest.skip("no OpenBLAS in this numpy")
    assert got == "1"


def test_a_thread_count_the_user_set_is_kept() -> None:
    got = _threads({"OPENBLAS_NUM_THREADS": "2"})
    if got == "None":
        pytest.skip("no OpenBLAS in this numpy")
    assert got == "2"
