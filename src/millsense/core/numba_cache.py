"""Where numba keeps millsense's compiled kernels: one folder per state of the sources
(decision 1722).

numba's ``cache=True`` keys a compiled function on its own source file only (modification time
and size). A kernel that calls a kernel of another module keeps the callee it was compiled
with: after a ``git pull`` or a branch switch that changes only the callee's module, the caller
loads its old machine code, callee included, and computes with code that is no longer in the
tree, without an error. The on-line stack's kernels call across modules everywhere (the feed
bank calls the C3 torque and LuGre's friction, the breakage group calls the noise medians).

So the cache folder is named after the state of every source file of the package (path,
modification time in ns and size; a stat per file, no read): a changed file anywhere gives a
new folder, where every kernel compiles afresh once (``millsense warm-up`` does it ahead of a
session), and an unchanged tree keeps loading what it compiled. The folder lies under
:func:`~millsense.core.disk_cache.cache_dir` (``$MILLSENSE_CACHE_DIR``, else
``$XDG_CACHE_HOME/millsense``, else ``~/.cache/millsense``) in ``numba/``. A user's own
``NUMBA_CACHE_DIR`` is kept, and with the millsense cache off numba keeps its default (beside
the sources). Each process that uses a folder marks it (its modification time); when a new
folder is made, the folders not used for :data:`UNUSED_DAYS` days are removed (a developer's
tree leaves one per pull, a CI machine one per clean clone). Delete ``numba/`` to clear them
all.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

from millsense.core.disk_cache import cache_dir

__all__ = ["NUMBA_CACHE_ENV", "configure", "sources_digest"]

#: numba's environment variable for its cache folder (read when numba is imported).
NUMBA_CACHE_ENV = "NUMBA_CACHE_DIR"

#: Days after which a folder no process has used is removed when a new one is made.
UNUSED_DAYS = 14.0

#: The package's root folder (``src/millsense`` or the installed package).
PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def sources_digest(root: Path) -> str:
    """Digest of the state of every ``*.py`` file under ``root``: its path relative to
    ``root``, modification time (ns) and size, in path order."""
    rows = []
    for folder, dirs, files in os.walk(root):  # os.walk's stat per entry: a few ms, no read
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        rel = os.path.relpath(folder, root).replace(os.sep, "/")
        for name in files:
            if name.endswith(".py"):
                st = os.stat(os.path.join(folder, name))
                rows.append(f"{rel}/{name}\0{st.st_mtime_ns}\0{st.st_size}\n")
    return hashlib.sha256("".join(sorted(rows)).encode()).hexdigest()


def configure(root: Path = PACKAGE_ROOT) -> Path | None:
    """Point numba's cache at the folder of the sources' state (:func:`sources_digest` of
    ``root``) and return it; None where the user chose numba's folder (``NUMBA_CACHE_DIR``
    set) or the millsense cache is off. Called when :mod:`millsense` is imported, before any
    kernel module: numba reads the folder when a kernel is defined. Where numba was imported
    first, its configuration is set too."""
    if os.environ.get(NUMBA_CACHE_ENV):
        return None
    base = cache_dir()
    if base is None:
        return None
    folder = base / "numba" / sources_digest(root)[:16]
    _mark_used(folder)
    os.environ[NUMBA_CACHE_ENV] = str(folder)
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]
    return folder


def _mark_used(folder: Path) -> None:
    """Make ``folder`` if it is new (and then remove its siblings unused for
    :data:`UNUSED_DAYS`), else mark it used now. A folder that cannot be made or marked is left
    to numba, which then keeps its default."""
    try:
        if folder.is_dir():
            os.utime(folder)
            return
        folder.mkdir(parents=True)
    except OSError:
        return
    cutoff = time.time() - UNUSED_DAYS * 86400.0
    for old in folder.parent.iterdir():
        try:
            if old != folder and old.is_dir() and old.stat().st_mtime < cutoff:
                shutil.rmtree(old, ignore_errors=True)
        except OSError:
            continue
