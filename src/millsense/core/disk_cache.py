"""Results of pure, costly computations kept on disk across processes (decision 2006).

A search whose result is a pure function of its arguments and of the code that runs it (the
spindle observer's Q_s tuning: hundreds of Riccati solutions, about 1 s) need not be repeated
by every process that needs it: every ``millsense estimate``, ``run`` and every batch worker of
a machine would otherwise pay it again. The cache keeps small JSON values under a key that
hashes

- the arguments (their exact bytes and the ``repr`` of floats, which round-trips), and
- the source files of the modules that compute the value and the versions of the libraries it
  calls (:func:`code_digest`), so that a changed search never meets an old result.

Where: ``$MILLSENSE_CACHE_DIR`` if set (``off`` or empty: no cache), else
``$XDG_CACHE_HOME/millsense``, else ``~/.cache/millsense``. Entries are written atomically
(a temporary file renamed into place: two processes storing the same key write the same
bytes); an unreadable, corrupt or unwritable entry is treated as missing, never as an error —
the computation then simply runs. Delete the folder to clear it.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["CACHE_DIR_ENV", "cache_dir", "code_digest", "key_digest", "load", "store"]

#: Environment variable naming the cache folder (``off`` or empty: no cache).
CACHE_DIR_ENV = "MILLSENSE_CACHE_DIR"

_CODE: dict[tuple[str, ...], str] = {}


def cache_dir() -> Path | None:
    """The cache folder, or None when caching is off."""
    env = os.environ.get(CACHE_DIR_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "off") else Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "millsense"


def code_digest(*modules: str) -> str:
    """Digest of the named modules' source files and of numpy's and scipy's versions (per
    process: the files do not change under a running process)."""
    hit = _CODE.get(modules)
    if hit is None:
        h = hashlib.sha256()
        for name in modules:
            path = getattr(sys.modules[name], "__file__", None)
            h.update(name.encode())
            h.update(Path(path).read_bytes() if path else b"?")
        for lib in ("numpy", "scipy"):
            mod = sys.modules.get(lib)
            h.update(f"{lib}={getattr(mod, '__version__', '-')}".encode())
        hit = _CODE[modules] = h.hexdigest()
    return hit


def key_digest(*parts: object) -> str:
    """Digest of arguments: bytes as they are, floats by ``repr`` (exact), the rest by ``repr``
    (tuples, ints, strings)."""
    h = hashlib.sha256()
    for p in parts:
        b = p if isinstance(p, bytes) else repr(p).encode()
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


def _entry(namespace: str, key: str) -> Path | None:
    root = cache_dir()
    return None if root is None else root / namespace / f"{key}.json"


def load(namespace: str, key: str) -> dict[str, Any] | None:
    """The value stored under ``key``, or None (no cache, no entry, an unreadable entry)."""
    path = _entry(namespace, key)
    if path is None:
        return None
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return value if isinstance(value, dict) else None


def store(namespace: str, key: str, value: dict[str, Any]) -> bool:
    """Store ``value`` (JSON: floats round-trip exactly) under ``key``; False if it could not
    be written (no cache, a read-only folder), which is not an error."""
    path = _entry(namespace, key)
    if path is None:
        return False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".json")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                json.dump(value, fh, allow_nan=True)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        return False
    return True
