"""``millsense batch`` on Dask and ``simulate-fleet`` (issue 20 item 1; decision 2003)."""

from __future__ import annotations

import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from tests.cli_run import run_cli as _cli

from millsense.cli.batch_run import run_batch
from millsense.cli.cmd_fleet import simulate_fleet
from millsense.core.recording import Recording
from millsense.io import write_recording


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fleet")
    made = simulate_fleet(folder, tools=2, runs=3, part_cut_min=25.0, seed=3)
    assert len(made) == 6
    return folder


def _table(out: Path) -> list[dict[str, object]]:
    return sorted(pq.read_table(out / "summary.parquet").to_pylist(), key=lambda r: str(r["run"]))


def test_batch_wear_is_the_same_on_one_and_two_workers(
    fleet: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tables = []
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        code, stdout, err = _cli(["batch", str(fleet), "-o", str(out), "--do", "wear,summary",
                                  "--workers", str(workers)], capsys)  # fmt: skip
        assert code == 0, err
        assert "6 runs (6 run on" in stdout and "0 failed" in stdout
        tables.append(_table(out))
    cols = ("wear_vb_mm", "wear_ratio", "raw_torque_nm", "tool_run_index", "tool_cutting_time_s")
    for a, b in zip(*tables, strict=True):
        assert a["status"] == "ok", a["error"]
        assert {c: a[c] for c in cols} == {c: b[c] for c in cols}
    rows = tables[0]
    for r in rows:
        truth = float(r.get("truth_wear_vb_mm") or 0.0)
        if r["wear_reference"]:
            assert r["tool_run_index"] == 0 and r["wear_vb_mm"] == 0.0
        else:
            # the belief reads the truth's wear within 0.03 mm + 30 % (decision 2002)
            assert abs(float(r["wear_vb_mm"]) - truth) <= 0.03 + 0.3 * truth, r
    import duckdb

    q = (
        f"SELECT tool_id, max(wear_vb_mm) FROM '{tmp_path / 'w1' / 'summary.parquet'}' "
        "GROUP BY tool_id ORDER BY tool_id"
    )
    got = duckdb.sql(q).fetchall()
    assert [g[0] for g in got] == ["T1", "T2"] and all(g[1] > 0 for g in got)


def test_bad_recordings_are_rows_and_the_batch_finishes(
    fleet: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("T1_r000.h5", "T2_r001.h5"):
        shutil.copy(fleet / name, folder / name)
    (folder / "corrupt.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + os.urandom(4000))
    rec = Recording(1e4, metadata={"machine": "quaser-ux600"})
    rec.add_channel("x/current_cmd", np.zeros(1000), "A")
    write_recording(folder / "bare.h5", rec)
    out = tmp_path / "out"
    code, stdout, err = _cli(["batch", str(folder), "-o", str(out), "--do",
                              "monitor,wear,summary", "--plan",
                              str(fleet / "plans" / "slot2.parquet")], capsys)  # fmt: skip
    assert code == 0, err
    rows = {r["run"]: r for r in _table(out)}
    assert rows["T1_r000"]["status"] == "ok"
    assert rows["corrupt"]["status"] == "error" and "corrupt.h5" in str(rows["corrupt"]["error"])
    assert rows["bare"]["status"] == "error" and "channel" in str(rows["bare"]["error"])
    # T2_r001 cut side4w5.nc (tool 2, run 1 of the cycled programs): the plan of slot2.nc is
    # not its plan: its wear was judged on that plan, status ok, before the check
    assert rows["T2_r001"]["status"] == "error"
    assert "plan of program 'slot2.nc', but" in str(rows["T2_r001"]["error"])
    assert "recorded running 'side4w5.nc'" in str(rows["T2_r001"]["error"])
    assert "3 failed" in stdout
    assert err.count("millsense: warning:") == 3
    # each line names the recording once (its reason may start with it already)
    for name in ("corrupt.h5", "bare.h5", "T2_r001.h5"):
        line = next(ln for ln in err.splitlines() if name in ln)
        assert line.count(str(folder / name)) == 1, line
    # a second batch into the same folder reuses the finished runs and retries the failed
    code, stdout, _ = _cli(["batch", str(folder), "-o", str(out), "--do",
                            "monitor,wear,summary", "--plan",
                            str(fleet / "plans" / "slot2.parquet")], capsys)  # fmt: skip
    assert code == 0 and "(3 run on" in stdout and "1 from an earlier batch" in stdout


@pytest.mark.parametrize(
    ("address", "why"),
    [("notaurl", "missing port number"), ("http://127.0.0.1:8786", "unknown address scheme")],
)
def test_a_malformed_scheduler_address_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], address: str, why: str
) -> None:
    """``--scheduler notaurl`` (or an http:// address) was Dask's ValueError traceback, exit
    1: one line naming the option and Dask's reason, exit 2, nothing written."""
    folder = tmp_path / "in"
    folder.mkdir()
    rec = Recording(1e4, metadata={"machine": "quaser-ux600"})
    rec.add_channel("x/current_cmd", np.zeros(1000), "A")
    write_recording(folder / "r.h5", rec)
    out = tmp_path / "o"
    code, _, err = _cli(["batch", str(folder), "-o", str(out), "--scheduler", address], capsys)
    assert code == 2 and err.strip().count("\n") == 0
    assert f"--scheduler '{address}'" in err and why in err
    assert not (out / "summary.parquet").exists()


def test_an_empty_folder_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty").mkdir()
    code, _, err = _cli(["batch", str(tmp_path / "empty"), "-o", str(tmp_path / "o")], capsys)
    assert code == 2
    assert err.strip().count("\n") == 0 and "holds no recording" in err
    code, _, err = _cli(["batch", str(tmp_path), "-o", str(tmp_path / "o"), "--do", "lunch"],
                        capsys)  # fmt: skip
    assert code == 2 and "--do" in err


def test_a_worker_killed_mid_batch_loses_nothing(fleet: Path, tmp_path: Path) -> None:
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address="127.0.0.1:0")  # fmt: skip
    try:
        pids = list(Client(cluster).run(os.getpid).values())
        killed: list[int] = []

        def progress(done: int, _total: int) -> None:
            if done >= 1 and not killed:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])

        recs = sorted(fleet.glob("*.h5"))
        res = run_batch(recs, tmp_path / "out", do="monitor,summary",
                        scheduler=cluster.scheduler_address, on_progress=progress)  # fmt: skip
    finally:
        cluster.close()
    assert killed
    assert [r["status"] for r in res.rows] == ["ok"] * len(recs), [r.get("error") for r in res.rows]
    runs = tmp_path / "out" / "runs"
    assert len(list(runs.glob("*.parquet"))) == len(recs)  # the rows, and no temporary left
    assert not [p for p in runs.rglob(".*") if p.is_file()]


def test_a_long_recording_runs_as_segments_with_the_whole_runs_figures(
    fleet: Path, tmp_path: Path
) -> None:
    """Decision 2005: a recording split into segments (each from a 2 s warm-up) and a wear part
    gives the row of the recording run whole — the wear sums exactly (the same task), the
    channel means and RMS from the segments' sums to round-off, the maxima exactly, the
    estimated load's mean within 0.2 % (each segment's observer settles in its warm-up: the
    spindle observer's transient is milliseconds) — and a part lost by a killed batch is the
    only one run again."""
    recs = sorted(fleet.glob("T1_r00[01].h5"))
    whole = run_batch(recs, tmp_path / "whole", do="estimate,monitor,wear,summary", workers=1,
                      segment_s=None)  # fmt: skip
    split = run_batch(recs, tmp_path / "split", do="estimate,monitor,wear,summary", workers=2,
                      segment_s=4.0)  # fmt: skip
    assert split.ran == 2
    for a, b in zip(whole.rows, split.rows, strict=True):
        assert a["status"] == b["status"] == "ok", (a["error"], b["error"])
        assert b["segments"] == 2 and "segments" not in a
        for k in [k for k in a if k.startswith("wear_")] + ["raw_torque_nm", "cut_s"]:
            assert a[k] == b[k], k
        for pre in ("spindle_current", "spindle_speed"):
            assert b[f"{pre}_mean"] == pytest.approx(a[f"{pre}_mean"], rel=1e-12, abs=1e-12)
            assert b[f"{pre}_rms"] == pytest.approx(a[f"{pre}_rms"], rel=1e-12)
            assert b[f"{pre}_maxabs"] == a[f"{pre}_maxabs"]
            # the 99th percentile of the run lies within the segments' largest
            assert a[f"{pre}_p99abs"] <= b[f"{pre}_p99abs"] * (1 + 1e-12)
        est = "est_spindle_spindle_load"
        assert b[f"{est}_mean"] == pytest.approx(a[f"{est}_mean"], rel=2e-3)
        assert b[f"{est}_maxabs"] == pytest.approx(a[f"{est}_maxabs"], rel=2e-2)
        assert b["alarms"] == a["alarms"] and b["events"] == a["events"]
        assert not any(k.endswith(("_sum", "_sumsq")) or k.startswith("segment_") for k in b)
        assert set(a) - set(b) == set() and set(b) - set(a) == {"segments"}
    # one event log for the run, from the segments' own events
    from millsense.streaming.event_log import read_event_log

    for a, r in zip(whole.rows, recs, strict=True):
        log = tmp_path / "split" / "runs" / r.name[:-3] / "events.parquet"
        assert len(read_event_log(log)) == a["events"]
    # the parts' rows are kept; losing one part and the run's row reruns that part alone
    parts = tmp_path / "split" / "runs" / f"{recs[0].name[:-3]}.parts"
    assert sorted(p.name for p in parts.iterdir()) == [
        "seg-000.parquet", "seg-001.parquet", "wear.parquet"]  # fmt: skip
    (parts / "seg-001.parquet").unlink()
    (tmp_path / "split" / "runs" / f"{recs[0].name[:-3]}.parquet").unlink()
    again = run_batch(recs, tmp_path / "split", do="estimate,monitor,wear,summary", workers=1,
                      segment_s=4.0)  # fmt: skip
    assert (again.ran, again.reused) == (1, 1)
    assert (parts / "seg-001.parquet").is_file()
    assert again.rows[0]["spindle_current_mean"] == split.rows[0]["spindle_current_mean"]


def test_the_local_cluster_runs_one_thread_workers_without_the_profiler() -> None:
    """Decision 2003: the workers of ``batch``'s local cluster run one BLAS and one HDF5-codec
    thread, listen on 127.0.0.1 and have Dask's statistical profiler off (its 10 ms sampling
    thread took 15 % of the tasks' time with a worker per core)."""
    from dask.distributed import Client

    from millsense.cli.batch_run import local_cluster

    cluster = local_cluster(1)
    try:
        with Client(cluster) as client:
            got = client.run(lambda: (
                __import__("dask").config.get("distributed.worker.profile.enabled"),
                os.environ.get("OPENBLAS_NUM_THREADS"),
                __import__("millsense.io.hdf5_chunks", fromlist=["io_threads"]).io_threads(),
            ))  # fmt: skip
            assert list(got.values()) == [(False, "1", 1)]
            assert all(a.startswith("tcp://127.0.0.1:") for a in got)
            assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
    finally:
        cluster.close()
    # decision 2009: Dask's INFO stays off after the close (its comms close after it; a
    # "Batched Comm Closed" INFO with its traceback reached the batch's stderr in a CI run)
    import logging

    assert not logging.getLogger("distributed.batched").isEnabledFor(logging.INFO)


def test_batch_process_exits_fast_after_writing_everything(fleet: Path, tmp_path: Path) -> None:
    # decision 2007: `millsense batch` as a process leaves by os._exit after its last line; what
    # it wrote must be whole: every run in the table, the fleet page closed, the exit status 0
    import subprocess
    import sys

    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "millsense", "batch", str(fleet), "-o", str(out), "--do",
         "wear,summary", "--workers", "1"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "6 runs (6 run on" in done.stdout
    assert len(_table(out)) == 6
    assert (out / "fleet.html").read_text().rstrip().endswith("</html>")
    assert (out / "fleet.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_worker_told_to_leave_skips_the_teardown() -> None:
    # decision 2007: after _leave_without_teardown the process ends at its first exit handler
    # (status 0); handlers registered before it, and the module teardown, do not run
    import subprocess
    import sys

    code = (
        "import atexit\n"
        "atexit.register(lambda: print('earlier handler', flush=True))\n"
        "from millsense.cli.batch_run import _leave_without_teardown\n"
        "_leave_without_teardown()\n"
        "print('done', flush=True)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["done"]


def test_batch_inputs_leave_out_earlier_batch_outputs(tmp_path: Path) -> None:
    """An earlier batch's output folder inside the input (its summary.parquet beside runs/)
    holds runs/*/estimates.h5: they are the batch's results, not recordings of the machine,
    and are left out with the current -o's (found by exploratory QA: they were run as
    recordings). A folder named runs without a summary beside it is input like any other."""
    from millsense.cli.batch_run import batch_inputs

    def touch(p: Path) -> Path:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"")
        return p

    rec = touch(tmp_path / "in" / "r001.h5")
    touch(tmp_path / "in" / "old_out" / "summary.parquet")
    touch(tmp_path / "in" / "old_out" / "runs" / "r001" / "estimates.h5")
    plain = touch(tmp_path / "in" / "cell2" / "runs" / "r002.h5")  # no summary beside it
    touch(tmp_path / "in" / "new_out" / "runs" / "r001" / "estimates.h5")
    found, skipped = batch_inputs(str(tmp_path / "in"), tmp_path / "in" / "new_out")
    assert found == sorted([rec, plain]) and skipped == 2
