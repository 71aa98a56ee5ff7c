"""No command can destroy an input (issue 21, decision 0921).

Every command with an input and an output refuses an output that is one of its inputs (the
same name, a symbolic link to it, a hard link to it) with exit status 2 and one line, before
it computes anything; the inputs' SHA-256 are unchanged afterwards. Writers replace an existing
output only whole: a writer failing or killed mid-write leaves the previous output intact.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cli_run import run_cli
from millsense.core.errors import ConfigError
from millsense.io import read_recording, write_recording
from millsense.io.recording_file import partial_dir
from millsense.io.safe_output import atomic_path, check_outputs, write_text

REPO = Path(__file__).resolve().parents[1]
PROGRAM = REPO / "examples" / "demo_part" / "program.nc"
STOCK = REPO / "examples" / "demo_part" / "stock.toml"
CASE = REPO / "examples" / "stability" / "insperger_1dof_slot.toml"


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _files(tmp: Path) -> dict[str, Path]:
    """Inputs of every kind, as copies (the guard runs before any is parsed)."""
    import shutil

    from millsense.core.recording import Recording

    rec = Recording(1000.0)
    rec.add_channel("x/current_cmd", np.arange(50.0), "A")
    write_recording(tmp / "run.h5", rec)
    shutil.copy(PROGRAM, tmp / "part.nc")
    shutil.copy(STOCK, tmp / "stock.toml")
    shutil.copy(CASE, tmp / "case.toml")
    (tmp / "frag.toml").write_text("[axes.x.friction]\ncoulomb_nm = [0.1, 0.1]\n")
    (tmp / "base.toml").write_text('name = "m"\n')
    (tmp / "plan.parquet").write_bytes(b"PAR1 not really a plan PAR1")
    return {p.name: p for p in tmp.iterdir()}


# (command line with {name} for the files above, the input the output collides with)
CASES = [
    ("estimate {run.h5} --machine quaser-ux600 -o {run.h5}", "run.h5"),
    ("estimate {run.h5} --machine quaser-ux600 -o {out.h5} --plot {run.h5}", "run.h5"),
    ("estimate {run.h5} --machine quaser-ux600 -o {out.h5} --json {run.h5}", "run.h5"),
    ("estimate {run.h5} --machine {base.toml} -o {base.toml}", "base.toml"),
    ("estimate {out.h5} --machine quaser-ux600 --idle {run.h5} -o {run.h5}", "run.h5"),
    (
        "schedule {part.nc} --stock {stock.toml} --tool aslan-d20-2flute --material al7050 "
        "--limit-force-n 300 -o {part.nc}",
        "part.nc",
    ),
    (
        "schedule {part.nc} --stock {stock.toml} --tool aslan-d20-2flute --material al7050 "
        "--limit-force-n 300 -o {o.nc} --plot {stock.toml}",
        "stock.toml",
    ),
    (
        "plan {part.nc} --stock {stock.toml} --tool aslan-d20-2flute --material al7050 "
        "-o {part.nc}",
        "part.nc",
    ),
    (
        "plan {part.nc} --stock {stock.toml} --tool {base.toml} --material al7050 "
        "-o {p.parquet} --plot {base.toml}",
        "base.toml",
    ),
    ("simulate --program {part.nc} -o {part.nc}", "part.nc"),
    ("simulate --plan {plan.parquet} -o {plan.parquet}", "plan.parquet"),
    ("simulate --program {part.nc} --tool-modes {case.toml} -o {case.toml}", "case.toml"),
    ("simulate --machine {base.toml} --program {part.nc} -o {base.toml}", "base.toml"),
    ("identify friction {run.h5} -o {run.h5}", "run.h5"),
    (
        "identify frf {run.h5} --input-channel a --output-channel b -o {f.toml} --plot {run.h5}",
        "run.h5",
    ),
    ("identify idle {run.h5} -o {run.h5}", "run.h5"),
    ("merge {base.toml} {frag.toml} -o {frag.toml}", "frag.toml"),
    ("merge {base.toml} {frag.toml} -o {base.toml}", "base.toml"),
    ("plot {run.h5} -c x/current_cmd -o {run.h5}", "run.h5"),
    ("lobes {case.toml} --json {case.toml}", "case.toml"),
    ("lobes {case.toml} --plot {case.toml}", "case.toml"),
    ("commission --machine {base.toml} -o {base.toml}", "base.toml"),
]


@pytest.mark.parametrize(("line", "victim"), CASES, ids=[c[0].split()[0] for c in CASES])
def test_output_that_is_an_input_is_refused_and_inputs_unchanged(
    line: str, victim: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = _files(tmp_path)
    before = {n: _sha(p) for n, p in files.items()}
    args = [
        str(tmp_path / w[1:-1]) if w.startswith("{") and w.endswith("}") else w
        for w in line.split()
    ]
    code, out, err = run_cli(args, capsys)
    assert code == 2, (out, err)
    assert len(err.strip().splitlines()) == 1, err
    assert "an input, which is never overwritten" in err and victim in err, err
    assert "Traceback" not in err
    after = {p.name: _sha(p) for p in tmp_path.iterdir()}
    assert after == before  # every input byte for byte, and nothing new written


def test_symbolic_and_hard_links_to_an_input_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = _files(tmp_path)
    run = files["run.h5"]
    before = _sha(run)
    (tmp_path / "sym.h5").symlink_to(run)
    os.link(run, tmp_path / "hard.h5")
    sub = tmp_path / "sub"
    sub.symlink_to(tmp_path, target_is_directory=True)
    for out in (tmp_path / "sym.h5", tmp_path / "hard.h5", sub / "run.h5"):
        code, _, err = run_cli(
            ["estimate", str(run), "--machine", "quaser-ux600", "-o", str(out)], capsys
        )
        assert code == 2 and "is the recording" in err, (out, err)
    # the link as the input, the real file as the output
    code, _, err = run_cli(
        ["estimate", str(tmp_path / "hard.h5"), "--machine", "quaser-ux600", "-o", str(run)],
        capsys,
    )
    assert code == 2 and "is the recording" in err
    assert _sha(run) == before


def test_check_outputs_rules(tmp_path: Path) -> None:
    a = tmp_path / "a.h5"
    a.write_bytes(b"x")
    # a preset name is no file: ignored; a different file passes
    check_outputs({"the machine file": "quaser-ux600"}, {"-o": tmp_path / "quaser-ux600"})
    check_outputs({"the recording": a}, {"-o": tmp_path / "b.h5", "--json": "-"})
    with pytest.raises(ConfigError, match="--plot and --json name the same file"):
        check_outputs({}, {"--plot": tmp_path / "p", "--json": tmp_path / "p"})
    # an interrupted recording (only its .partial/ folder) is an input under its own name
    partial_dir(tmp_path / "c.h5").mkdir()
    with pytest.raises(ConfigError, match="is the recording"):
        check_outputs({"the recording": tmp_path / "c.h5"}, {"-o": tmp_path / "c.h5"})


def test_atomic_writer_failing_mid_write_leaves_the_old_output(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    write_text(out, "old\n")
    with pytest.raises(RuntimeError), atomic_path(out) as tmp:
        tmp.write_text("half of the new ")
        raise RuntimeError("disk full")
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]  # no temporary left
    write_text(out, "new\n")
    assert out.read_text() == "new\n"


WRITER = r"""
import sys, time
import numpy as np
from millsense.core.recording import ChannelInfo
from millsense.io import RecordingWriter

w = RecordingWriter(sys.argv[1], 1000.0, [ChannelInfo("a", "A")], flush_every_s=0.02)
k = 0
while True:
    w.append({"a": np.arange(k, k + 10, dtype=float)})
    k += 10
    time.sleep(0.002)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX SIGKILL")
def test_recording_writer_killed_mid_write_leaves_the_old_recording(tmp_path: Path) -> None:
    from millsense.core.recording import Recording

    path = tmp_path / "run.h5"
    old = Recording(100.0)
    old.add_channel("b", np.linspace(0.0, 1.0, 7), "N")
    write_recording(path, old)
    before = _sha(path)
    script = tmp_path / "w.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60.0
        while not list(partial_dir(path).glob("seg-*.bin")) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            time.sleep(0.02)
        time.sleep(0.2)  # several segments
        # while the writer runs, readers see the new recording in progress
        assert read_recording(path).channel_names == ["a"]
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stderr:
            proc.stderr.close()
    assert _sha(path) == before  # the previous recording, whole
    back = read_recording(path)
    assert back.channel_names == ["b"] and back.n_samples == 7


def test_stale_temporaries_are_removed_and_nothing_else(tmp_path: Path) -> None:
    """A writer killed between writing and renaming leaves ``temporary_sibling``'s hidden file;
    ``remove_stale_temporaries`` removes exactly those, in sub-folders too (a batch's runs/)."""
    from millsense.io.safe_output import remove_stale_temporaries, temporary_sibling

    (tmp_path / "seg-000").mkdir()
    left = [temporary_sibling(tmp_path / "T1_r003.parquet"),
            temporary_sibling(tmp_path / "seg-000" / "events.parquet"),
            temporary_sibling(tmp_path / "a.b.h5")]  # fmt: skip
    kept = [tmp_path / "T1_r003.parquet", tmp_path / ".hidden", tmp_path / ".x.tmp.parquet",
            tmp_path / "seg-000" / "events.parquet"]  # fmt: skip
    for p in left + kept:
        p.write_bytes(b"x")
    removed = remove_stale_temporaries(tmp_path)
    assert sorted(removed) == sorted(left)
    assert all(p.is_file() for p in kept) and not any(p.exists() for p in left)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["lobes", "{tmp}/case.toml", "--plot", "{tmp}/x.txt"],
         "--plot {tmp}/x.txt: the file is written as PNG"),
        (["monitor", "{tmp}/r.h5", "-o", "{tmp}/e.parquet", "--plot", "{tmp}/x.jpg"],
         "give a .png file name"),
        (["simulate", "--program", "{tmp}/p.nc", "-o", "{tmp}/x.txt"],
         "written as a recording (HDF5); give a .h5"),
        (["report", "{tmp}/r.h5", "-o", "{tmp}/r.png"], "written as an HTML page; give a .html"),
        (["identify", "modal", "{tmp}/r.h5", "--input-channel", "a", "--output-channel", "b",
          "-o", "{tmp}/f.h5"], "written as TOML; give a .toml"),
        (["run", "--plan", "{tmp}/p.parquet", "-o", "{tmp}/x.txt"],
         "-o {tmp}/x.txt: the file is written as a recording (HDF5); give a .h5"),
        (["run", "--plan", "{tmp}/p.parquet", "-o", "{tmp}/r.h5", "--events", "{tmp}/e.csv"],
         "--events {tmp}/e.csv: the file is written as Parquet; give a .parquet"),
        (["run", "--plan", "{tmp}/p.parquet", "-o", "{tmp}/r.h5", "--plan-out", "{tmp}/p.nc"],
         "--plan-out {tmp}/p.nc: the file is written as Parquet"),
        (["run", "--plan", "{tmp}/p.parquet", "-o", "{tmp}/r.h5", "--report", "{tmp}/r.htm"],
         "--report {tmp}/r.htm: the file is written as an HTML page"),
        (["replay", "{tmp}/r.h5", "--plan", "{tmp}/p.parquet", "--events", "{tmp}/e.txt"],
         "--events {tmp}/e.txt: the file is written as Parquet"),
        (["replay", "{tmp}/r.h5", "--plan", "{tmp}/p.parquet", "--events", "{tmp}/e.parquet",
          "-o", "{tmp}/o.txt"], "-o {tmp}/o.txt: the file is written as a recording"),
        (["monitor", "{tmp}/r.h5", "-o", "{tmp}/e.txt"], "-o {tmp}/e.txt: the file is written "
         "as Parquet; give a .parquet"),
        (["record", "opc.tcp://127.0.0.1:1", "-o", "{tmp}/raw.txt"],
         "-o {tmp}/raw.txt: the file is written as a recording"),
        (["estimate", "{tmp}/r.h5", "--machine", "quaser-ux600", "-o", "{tmp}/est.txt"],
         "-o {tmp}/est.txt: the file is written as a recording (HDF5); give a .h5"),
    ],
)  # fmt: skip
def test_outputs_named_as_what_they_hold(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    """Every --plot writes a PNG, simulate's -o a recording, report's an HTML page, identify's
    a TOML fragment: a file name saying otherwise (found by exploratory QA: PNG bytes in x.txt,
    a recording in x.txt) is refused in one line before anything is read or written; so are
    the on-line commands' recording, event log, plan and report, and estimate's recording
    (found by the qa4 helper: run, replay and estimate wrote a recording into x.txt, monitor an
    event log into e.txt)."""
    from cli_run import run_cli

    argv = [a.format(tmp=tmp_path) for a in args]
    code, _out, err = run_cli(argv, capsys)
    assert code == 2
    assert needle.format(tmp=tmp_path) in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_run_default_event_log_never_replaces_an_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``run -o r.h5`` writes its event log to ``r.events.parquet`` when --events is not given:
    a plan of that name (an input) was overwritten by the event log (found by the qa4 helper);
    it is refused in one line, and the plan's bytes are unchanged (compared exactly)."""
    from cli_run import run_cli

    plan = tmp_path / "r.events.parquet"
    plan.write_bytes(b"PAR1 plan bytes")
    code, _out, err = run_cli(["run", "--plan", str(plan), "-o", str(tmp_path / "r.h5")], capsys)
    assert code == 2
    assert f"--events {plan}: is the plan ({plan}), an input" in err
    assert len(err.strip().splitlines()) == 1
    assert plan.read_bytes() == b"PAR1 plan bytes"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.events.parquet"]
