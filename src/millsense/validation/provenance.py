"""Where a validation run came from: the date and the git commit of the code it ran.

``docs/validation.md`` carries this as its first line under the title so that a reader can tell
which code produced the figures (issue 12). The commit is read from the checkout that holds the
imported ``millsense`` package; outside a git checkout it is reported as unknown, never guessed.
"""

from __future__ import annotations

import datetime as _dt
import subprocess
from pathlib import Path


def _git(args: list[str], cwd: Path) -> str | None:
    try:
        out = subprocess.run(
            ["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def source_commit(package_dir: Path | None = None) -> tuple[str | None, bool]:
    """(full commit hash or None, True if ``src/`` has uncommitted changes to tracked files)."""
    if package_dir is None:
        import millsense

        package_dir = Path(millsense.__file__).resolve().parent
    commit = _git(["rev-parse", "HEAD"], package_dir)
    if commit is None:
        return None, False
    top = _git(["rev-parse", "--show-toplevel"], package_dir)
    dirty = _git(["status", "--porcelain", "--untracked-files=no", "--", "src"], Path(top or "."))
    return commit, bool(dirty)


def provenance_line(now: _dt.datetime | None = None, package_dir: Path | None = None) -> str:
    """``Generated 2026-11-25 14:02 UTC from commit 0123abcd… (…)`` for the document header."""
    now = now or _dt.datetime.now(_dt.UTC)
    commit, dirty = source_commit(package_dir)
    when = now.astimezone(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    if commit is None:
        return f"Generated {when}; git commit unknown (not run from a git checkout)."
    note = " plus uncommitted changes under src/" if dirty else ""
    return f"Generated {when} from commit `{commit[:12]}`{note}."
