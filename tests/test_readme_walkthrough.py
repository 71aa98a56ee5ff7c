"""The README is a test (issue 21, decision 0925).

Every ``sh`` block of the README's "Walkthrough" section runs verbatim, in order, in one bash
shell (``set -e``: the first failing command fails the test), in a temporary copy of the
repository whose ``.venv`` is the project's own (linked, so that ``make`` finds it installed
and ``. .venv/bin/activate`` works as it does after ``make`` on a fresh clone). Afterwards every
file the walkthrough says it writes exists: each ``-o``/``--output``/``--plot``/``--json``
argument, and every file named in a ``# writes ...`` comment.

The walkthrough runs for about 4 minutes of wall time: ``make test-readme`` runs it (with
``MILLSENSE_README=1``; CI runs it after ``make test``, decision 1713), and ``make test`` skips
it with that reason. The "Identification workflow" section runs for several minutes more; it is
run the same way only with ``MILLSENSE_README_LONG=1`` (which runs the walkthrough too). The
"Command reference" section uses placeholders (``RUN.h5``, ``P.nc``) and is not meant to run.
"""

from __future__ import annotations

import itertools
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: the virtual environment running the tests (never a base interpreter: its pyvenv.cfg)
VENV = Path(sys.prefix) if (Path(sys.prefix) / "pyvenv.cfg").is_file() else None

_OUT_OPTS = ("-o", "--output", "--plot", "--json")
#: wall-clock bound of one section's run (the Walkthrough needs about 1.5 min of CPU)
WALKTHROUGH_TIMEOUT_S = 1500


def section(text: str, title: str) -> str:
    """The Markdown of the ``## title`` section (up to the next ``## ``)."""
    m = re.search(rf"^## {re.escape(title)}\b.*?$(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m is not None, f"README has no '## {title}' section"
    return m.group(1)


def sh_blocks(markdown: str) -> list[str]:
    """The ``sh`` code blocks of ``markdown``, in order."""
    return re.findall(r"^```sh\n(.*?)^```", markdown, re.M | re.S)


def named_outputs(blocks: list[str]) -> list[str]:
    """Files the blocks say they write: output options and ``# writes A, B`` comments."""
    out: list[str] = []
    for block in blocks:
        for line in block.replace("\\\n", " ").splitlines():
            code, _, comment = line.partition("#")
            words = shlex.split(code) if code.strip() else []
            for opt, val in itertools.pairwise(words):
                if opt in _OUT_OPTS and val != "-":
                    out.append(val)
            m = re.search(r"\bwrites ([^;]+)", comment)
            if m:
                out += [w.strip(" .") for w in m.group(1).split(",") if "/" in w or "." in w]
    return out


def test_walkthrough_extraction_finds_the_steps() -> None:
    """The extraction itself: the walkthrough has its activation step and named outputs."""
    blocks = sh_blocks(section(README.read_text(encoding="utf-8"), "Walkthrough"))
    assert len(blocks) >= 5
    assert ". .venv/bin/activate" in blocks[0] or ". .venv/bin/activate" in blocks[1]
    outs = named_outputs(blocks)
    for f in ("demo-output/demo.h5", "run.h5", "estimates.h5", "run_b.h5", "lobes.json"):
        assert f in outs, outs


def _copy_repo(dest: Path) -> None:
    ignore = shutil.ignore_patterns(
        ".venv", ".git", "*.egg-info", "__pycache__", ".*_cache", "demo-output"
    )
    shutil.copytree(REPO, dest, ignore=ignore, copy_function=shutil.copy2)
    assert VENV is not None
    (dest / ".venv").symlink_to(VENV, target_is_directory=True)


def _run_section(title: str, tmp_path: Path) -> None:
    blocks = sh_blocks(section(README.read_text(encoding="utf-8"), title))
    work = tmp_path / "clone"
    _copy_repo(work)
    # the linked environment must look installed to make: never let a step install into it
    dry = subprocess.run(["make", "-n", "demo"], cwd=work, capture_output=True, text=True)
    assert "pip install" not in dry.stdout, f"make would install into {VENV}: {dry.stdout}"
    steps = [f'echo "### README {title} block {i + 1} at $SECONDS s" >&2\n{b}'
             for i, b in enumerate(blocks)]  # fmt: skip
    script = "set -e\n" + "".join(steps) + 'echo "### README done at $SECONDS s" >&2\n'
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    assert VENV is not None
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["COLUMNS"] = "120"
    # output to files, not pipes, and the shell in its own process group: a step left running
    # in the background (the walkthrough's `serve-machine ... &`) can neither hold the test
    # until the timeout after the script ended nor outlive it
    out_f, err_f = tmp_path / "walkthrough.out", tmp_path / "walkthrough.err"
    with out_f.open("w") as out, err_f.open("w") as err:
        proc = subprocess.Popen(["bash", "-c", script], cwd=work, env=env, stdout=out,
                                stderr=err, text=True, start_new_session=True)  # fmt: skip
        timed_out = False
        try:
            proc.wait(timeout=WALKTHROUGH_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            timed_out = True
        finally:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()
    stderr = err_f.read_text(errors="replace")
    marks = re.findall(r"### README .*", stderr)
    print("\n".join(marks))  # the blocks' start times, with -s
    if timed_out:
        stdout = out_f.read_text(errors="replace")
        pytest.fail(
            f"README {title} timed out after {WALKTHROUGH_TIMEOUT_S} s; blocks begun: {marks}\n"
            f"last stderr:\n{chr(10).join(stderr.splitlines()[-15:])}\n"
            f"last stdout:\n{chr(10).join(stdout.splitlines()[-15:])}",
            pytrace=False,
        )
    tail = "\n".join(stderr.splitlines()[-15:])
    assert proc.returncode == 0, f"exit {proc.returncode}:\n{tail}"
    assert "Traceback" not in stderr, tail
    missing = [f for f in named_outputs(blocks) if not (work / f).exists()]
    assert not missing, f"files the README says are written do not exist: {missing}"


@pytest.mark.slow  # about 1.5 min of CPU, 3.5-4 min of wall time on 2 cores
@pytest.mark.skipif(VENV is None, reason="needs to run in the project's virtual environment")
@pytest.mark.skipif(
    os.environ.get("MILLSENSE_README") != "1" and os.environ.get("MILLSENSE_README_LONG") != "1",
    reason="the walkthrough runs for about 4 minutes: `make test-readme` runs it (CI does, after "
    "make test; decision 1713)",
)
def test_readme_walkthrough_runs_verbatim(tmp_path: Path) -> None:
    _run_section("Walkthrough", tmp_path)


@pytest.mark.skipif(
    os.environ.get("MILLSENSE_README_LONG") != "1",
    reason="the identification workflow simulates and identifies for several minutes; "
    "run it with MILLSENSE_README_LONG=1",
)
def test_readme_identification_workflow_runs_verbatim(tmp_path: Path) -> None:
    _run_section("Identification workflow", tmp_path)
