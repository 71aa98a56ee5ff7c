"""``millsense split-passes``: seed 002's depth reduction as a command (issue 16 item 3)."""

from __future__ import annotations

from pathlib import Path

import pytest
from tests.cli_run import run_cli

from millsense.control.depth_reduction import cutting_passes

PROGRAM = "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-12 Y40 Z5\nG1 Z-6 F400\nX60\nG0 Z5\nM30\n"


def test_split_passes_writes_passes_at_or_below_the_limit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 6 mm pass with a 2.5 mm limit: ⌈6/2.5⌉ = 3 passes at 2, 4 and 6 mm (equal steps, the
    last the programmed one)."""
    src = tmp_path / "deep.nc"
    src.write_text(PROGRAM)
    out = tmp_path / "split.nc"
    code, text, err = run_cli(
        ["split-passes", str(src), "--max-depth-mm", "2.5", "-o", str(out)], capsys
    )
    assert code == 0, err
    assert "1 passes -> 3" in text
    depths = [p.depth_mm for p in cutting_passes(out.read_text())]
    assert depths == pytest.approx([2.0, 4.0, 6.0], abs=1e-9)
    assert src.read_text() == PROGRAM  # the input untouched


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--max-depth-mm", "0"], "--max-depth-mm: must be > 0"),
        (["--max-depth-mm", "2", "-o", "{src}"], "never overwritten"),
    ],
)
def test_split_passes_bad_input_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    src = tmp_path / "deep.nc"
    src.write_text(PROGRAM)
    argv = ["split-passes", str(src), *[a.format(src=src) for a in args]]
    if "-o" not in argv:
        argv += ["-o", str(tmp_path / "out.nc")]
    code, _out, err = run_cli(argv, capsys)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert src.read_text() == PROGRAM
