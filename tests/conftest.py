"""The test process runs BLAS on one thread, as the CLI does (decision 2004), and keeps the
disk cache of costly searches (decision 2006) in a folder of its own, removed at the end: the
tests never read or fill the user's cache, and the commands they start share the session's."""

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
