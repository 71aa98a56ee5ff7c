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
        (["--max-depth-mm", "0"], "--max-depth-mm: must be finite and > 0"),
        (["--max-depth-mm", "inf"], "--max-depth-mm: must be finite and > 0, got inf"),
        # nan: every comparison with the top false, "0 passes", the program written unchanged
        (["--max-depth-mm", "2", "--top-z-mm", "nan"], "--top-z-mm: must be finite, got nan"),
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


def test_split_passes_reads_the_walkthrough_slot_with_percent_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every shipped program opens and closes with '%' (RS274/NGC demarcation, read by the
    interpreter): split-passes refused them ("unexpected character '%'"). The walkthrough's
    2 mm slot with a 1 mm limit: ⌈2/1⌉ = 2 passes at 1 and 2 mm, and the rewritten program is
    still one the interpreter reads, ending where the programmed one ends."""
    import numpy as np

    from millsense.plan.gcode import interpret

    src = Path(__file__).parents[1] / "examples" / "walkthrough" / "slot.nc"
    out = tmp_path / "slot_split.nc"
    code, text, err = run_cli(
        ["split-passes", str(src), "--max-depth-mm", "1", "-o", str(out)], capsys
    )
    assert code == 0, err
    assert "1 passes -> 2" in text
    new = out.read_text()
    assert [p.depth_mm for p in cutting_passes(new)] == pytest.approx([1.0, 2.0], abs=1e-9)
    assert new.splitlines()[0] == "%" and new.splitlines()[-1] == "%"
    a, b = interpret(src.read_text()), interpret(new)
    np.testing.assert_allclose(b.end[-1], a.end[-1], atol=1e-12)
    assert float(b.end[:, 2].min()) == pytest.approx(-2e-3, abs=1e-12)


def test_split_passes_reads_a_cp1252_program_and_keeps_its_comment(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A program saved by a Windows editor (cp1252 'Ä', 'Ø' in a comment) is read as the
    interpreter reads it (latin-1 when not UTF-8); it was a UnicodeDecodeError traceback. The
    comment comes out in the input's encoding, byte for byte; the 6 mm pass at a 2.5 mm
    limit is 3 passes (2, 4, 6 mm)."""
    src = tmp_path / "fräser.nc"
    raw = ("(FRÄSER Ø20)\n" + PROGRAM).encode("cp1252")
    src.write_bytes(raw)
    out = tmp_path / "split.nc"
    code, _text, err = run_cli(
        ["split-passes", str(src), "--max-depth-mm", "2.5", "-o", str(out)], capsys
    )
    assert code == 0, err
    assert out.read_bytes().startswith("(FRÄSER Ø20)\n".encode("cp1252"))
    depths = [p.depth_mm for p in cutting_passes(out.read_bytes().decode("latin-1"))]
    assert depths == pytest.approx([2.0, 4.0, 6.0], abs=1e-9)
    assert src.read_bytes() == raw


@pytest.mark.parametrize("text", ["", "%\n(ONLY A COMMENT)\nG21 G90\nM30\n%\n"])
def test_split_passes_refuses_a_program_without_motion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str
) -> None:
    """An empty program, or one without a move, is refused as `plan` refuses it (one line,
    exit 2, no output): an empty output would pass for a rewritten program (found by the qa3
    helper: "wrote out.nc: 0 passes -> 0")."""
    src = tmp_path / "empty.nc"
    src.write_text(text)
    out = tmp_path / "out.nc"
    code, _out, err = run_cli(["split-passes", str(src), "--max-depth-mm", "2", "-o", str(out)],
                              capsys)  # fmt: skip
    assert code == 2
    assert "empty.nc: program has no motion to split" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
