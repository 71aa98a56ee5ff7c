"""Run the ``millsense`` command in-process for tests: (exit status, stdout, stderr)."""

from __future__ import annotations

import pytest

from millsense.cli.main import main


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``millsense ARGS`` as the shell would run it; user errors exit 2 with one line."""
    code: int | str | None = 0
    try:
        main(args)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return (0 if code is None else int(code)), out, err
