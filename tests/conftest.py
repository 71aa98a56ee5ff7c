"""The test process runs BLAS on one thread, as the CLI does (decision 2004), and keeps the
disk cache of costly searches (decision 2006) in a folder of its own, removed at the end: the
tests never read or fill the user's cache, and the commands they start share the session's.

The session-scoped fixtures of the helper modules (tests/commissioned.py, tests/slot_run.py) are
registered here, once: a test module that imported one got a session fixture of its own, so the
machine file commissioned on the truth was built once per module that used it (three times)."""

import atexit
import os
import shutil
import tempfile

from millsense.core.blas import default_to_one_thread, limit_blas_threads
from millsense.core.disk_cache import CACHE_DIR_ENV

_CACHE = tempfile.mkdtemp(prefix="millsense-test-cache-")
os.environ[CACHE_DIR_ENV] = _CACHE
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)

default_to_one_thread()
limit_blas_threads(1)

# after the environment above is set (they import millsense's CLI, numpy and its BLAS)
from commissioned import commissioned_fixture  # noqa: E402, F401  (fixture)
from slot_run import slot_run_fixture, slot_xy_feed_fixture  # noqa: E402, F401  (fixtures)
