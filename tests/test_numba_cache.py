"""numba's compiled kernels in a folder per state of the sources (decision 1722)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from millsense.core import numba_cache
from millsense.core.numba_cache import NUMBA_CACHE_ENV, configure, sources_digest


def _tree(root: Path) -> None:
    (root / "sub").mkdir(parents=True)
    (root / "a.py").write_text("A = 1\n")
    (root / "sub" / "b.py").write_text("B = 2\n")


def test_digest_follows_every_source_file_and_nothing_else(tmp_path: Path) -> None:
    """A source file's new modification time or a new source file gives a new digest; the same
    state gives the same digest; data files and ``__pycache__`` do not count."""
    _tree(tmp_path)
    b = tmp_path / "sub" / "b.py"
    st = b.stat()
    d0 = sources_digest(tmp_path)
    assert sources_digest(tmp_path) == d0
    os.utime(b, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    d1 = sources_digest(tmp_path)
    assert d1 != d0
    os.utime(b, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert sources_digest(tmp_path) == d0
    (tmp_path / "data.toml").write_text("x = 1\n")
    (tmp_path / "sub" / "__pycache__").mkdir()
    (tmp_path / "sub" / "__pycache__" / "stale.py").write_text("")
    assert sources_digest(tmp_path) == d0
    (tmp_path / "c.py").write_text("")
    assert sources_digest(tmp_path) not in (d0, d1)


def test_configure_keeps_the_users_folder_and_the_cache_switched_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A user's ``NUMBA_CACHE_DIR`` is kept; with ``MILLSENSE_CACHE_DIR=off`` numba keeps its
    default; otherwise the folder is ``<millsense cache>/numba/<digest>``, in the environment
    (for the commands a process starts) and in numba's configuration."""
    import numba.core.config

    _tree(tmp_path / "pkg")
    monkeypatch.setattr(numba.core.config, "CACHE_DIR", numba.core.config.CACHE_DIR)
    monkeypatch.setenv(NUMBA_CACHE_ENV, "/somewhere/of/mine")
    assert configure(tmp_path / "pkg") is None
    assert os.environ[NUMBA_CACHE_ENV] == "/somewhere/of/mine"

    monkeypatch.delenv(NUMBA_CACHE_ENV)
    monkeypatch.setenv("MILLSENSE_CACHE_DIR", "off")
    assert configure(tmp_path / "pkg") is None
    assert NUMBA_CACHE_ENV not in os.environ

    monkeypatch.setenv("MILLSENSE_CACHE_DIR", str(tmp_path / "cache"))
    folder = configure(tmp_path / "pkg")
    assert folder == tmp_path / "cache" / "numba" / sources_digest(tmp_path / "pkg")[:16]
    assert os.environ[NUMBA_CACHE_ENV] == str(folder)
    assert numba.core.config.CACHE_DIR == str(folder)


def test_importing_millsense_points_numba_at_its_sources_folder(tmp_path: Path) -> None:
    """A fresh process that imports millsense has numba's folder set to that of the package's
    sources' state, before any kernel module is imported."""
    env = {k: v for k, v in os.environ.items() if k != NUMBA_CACHE_ENV}
    env["MILLSENSE_CACHE_DIR"] = str(tmp_path)
    code = ("import millsense, os, sys; import numba.core.config as c; "
            "print(os.environ['NUMBA_CACHE_DIR']); print(c.CACHE_DIR)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=300).stdout.split()  # fmt: skip
    want = str(tmp_path / "numba" / sources_digest(numba_cache.PACKAGE_ROOT)[:16])
    assert out == [want, want]


_CALLEE = "import numba\n\n@numba.njit(cache=True)\ndef value():\n    return {}\n"
_CALLER = (
    "import numba\nfrom callee import value\n\n@numba.njit(cache=True)\n"
    "def through():\n    return value()\n"
)


def _run(pkg: Path, cache: Path | None) -> int:
    """``caller.through()`` in a fresh process, numba's cache in ``cache`` (None: beside the
    sources, numba's default)."""
    env = {k: v for k, v in os.environ.items() if k != NUMBA_CACHE_ENV}
    env["PYTHONPATH"] = str(pkg)
    if cache is not None:
        env[NUMBA_CACHE_ENV] = str(cache)
    out = subprocess.run(
        [sys.executable, "-c", "import caller; print(caller.through())"],
        env=env, capture_output=True, text=True, check=True, timeout=300,
    )  # fmt: skip
    return int(out.stdout.strip())


def _change_callee(pkg: Path) -> None:
    callee = pkg / "callee.py"
    st = callee.stat()
    callee.write_text(_CALLEE.format(2))  # the same size: only the time tells the change
    os.utime(callee, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))


@pytest.mark.parametrize("per_state", [False, True])
def test_a_changed_callee_reaches_its_cached_caller(tmp_path: Path, per_state: bool) -> None:
    """The hazard and its cure: with numba's own cache a caller compiled with the callee's old
    body keeps it after the callee's module changes (1 instead of 2); with the folder of the
    sources' state the caller compiles afresh and returns the new value."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "callee.py").write_text(_CALLEE.format(1))
    (pkg / "caller.py").write_text(_CALLER)

    def folder() -> Path | None:
        return tmp_path / "cache" / sources_digest(pkg)[:16] if per_state else None

    assert _run(pkg, folder()) == 1
    assert _run(pkg, folder()) == 1  # from the cache
    _change_callee(pkg)
    assert _run(pkg, folder()) == (2 if per_state else 1)


def test_a_new_folder_removes_the_long_unused_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """When the sources' state is new, the folders no process used for 14 days go; a folder
    used within them stays, and so does one in use whatever its age (it is marked at use)."""
    import numba.core.config

    monkeypatch.setattr(numba.core.config, "CACHE_DIR", numba.core.config.CACHE_DIR)
    monkeypatch.delenv(NUMBA_CACHE_ENV, raising=False)
    monkeypatch.setenv("MILLSENSE_CACHE_DIR", str(tmp_path / "cache"))
    _tree(tmp_path / "pkg")
    now = __import__("time").time()

    def fresh() -> Path | None:  # a new process: no folder in its environment yet
        monkeypatch.delenv(NUMBA_CACHE_ENV, raising=False)
        return configure(tmp_path / "pkg")

    kept = fresh()
    assert kept is not None and kept.is_dir()
    numba_dir = tmp_path / "cache" / "numba"
    for name, age_days in (("old", 15.0), ("recent", 13.0)):
        (numba_dir / name / "sub").mkdir(parents=True)
        os.utime(numba_dir / name, (now - age_days * 86400, now - age_days * 86400))
    os.utime(kept, (now - 30 * 86400, now - 30 * 86400))
    assert fresh() == kept  # the same state: marked used, nothing removed
    assert kept.stat().st_mtime > now - 60
    assert {p.name for p in numba_dir.iterdir()} == {kept.name, "old", "recent"}
    (tmp_path / "pkg" / "c.py").write_text("")
    new = fresh()
    assert new is not None and new != kept
    assert {p.name for p in numba_dir.iterdir()} == {kept.name, new.name, "recent"}
