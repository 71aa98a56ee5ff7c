"""The local cluster's workers are forked from a server that imported the tasks' modules
(decision 2008)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from millsense.cli.cmd_fleet import simulate_fleet

#: Packages whose modules a task must find imported in a forked worker (the costly imports).
HEAVY = ("millsense", "scipy", "h5py", "pyarrow", "distributed", "llvmlite")


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fleet")
    made = simulate_fleet(folder, tools=1, runs=1, part_cut_min=25.0, seed=3)
    return Path(str(made[0]["path"]))


def _python(code: str) -> dict[str, object]:
    """Run ``code`` in a fresh interpreter (the test session's environment) and return the JSON
    it prints last."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ))  # fmt: skip
    assert done.returncode == 0, done.stderr
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def test_a_task_imports_nothing_costly_beyond_the_task_modules(
    recording: Path, tmp_path: Path
) -> None:
    """A step that imports a module where it is used must list it in TASK_MODULES, or the
    forked workers import it at their first task again (this test fails then). The spindle
    tuning's entry is on disk first (decision 2006: a batch worker then never imports the
    search)."""
    warm = f"""
from millsense.cli.batch_tasks import process_recording
process_recording({str(recording)!r}, {{"out_dir": {str(tmp_path / "warm")!r},
    "do": ["estimate", "wear"], "machine": None, "plan": None, "estimate_method": "spindle",
    "monitor_methods": "chatter-comb", "chunk": 2000, "segment_s": None}})
print("{{}}")
"""
    _python(warm)
    code = f"""
import json, sys
from millsense.core.blas import default_to_one_thread
default_to_one_thread()
import distributed.nanny
from millsense.cli.batch_tasks import TASK_MODULES, process_recording
for name in TASK_MODULES:
    __import__(name)
before = set(sys.modules)
row = process_recording({str(recording)!r}, {{"out_dir": {str(tmp_path)!r},
    "do": ["estimate", "monitor", "wear", "summary"], "machine": None, "plan": None,
    "estimate_method": "spindle", "monitor_methods": "chatter-comb", "chunk": 2000,
    "segment_s": 600.0}})
new = sorted(m for m in set(sys.modules) - before if m.split(".")[0] in {HEAVY!r})
print(json.dumps({{"status": row["status"], "error": row["error"], "new": new}}))
"""
    got = _python(code)
    assert got["status"] == "ok", got["error"]
    assert got["new"] == [], got["new"]


def test_the_workers_are_forked_from_the_server_with_dasks_environment(tmp_path: Path) -> None:
    """The workers of ``local_cluster`` have the tasks' modules before any task (forked from the
    fork server), one BLAS thread, and Dask's hash seed from their start (the hash of a string
    is the one of an interpreter started with PYTHONHASHSEED=6640); a changed environment is
    not served by the old server; at exit the server is stopped and waited for."""
    code = """
import json, os, sys
from multiprocessing import forkserver
from dask.distributed import Client
from millsense.cli import batch_workers
from millsense.cli.batch_run import local_cluster
cluster = local_cluster(2)
server = forkserver._forkserver._forkserver_pid
with Client(cluster) as client:
    got = list(client.run(lambda: (os.getppid(), "millsense.monitoring.chatter" in sys.modules,
        os.environ.get("OPENBLAS_NUM_THREADS"), hash("millsense"))).values())
cluster.close()
os.environ["MILLSENSE_TEST_CHANGED"] = "1"
changed = batch_workers.start_worker_server()
del os.environ["MILLSENSE_TEST_CHANGED"]
same = batch_workers.start_worker_server()
batch_workers._stop_worker_server()
print(json.dumps({"server": server, "workers": got, "changed": changed, "same": same,
                  "server_alive": os.path.exists(f"/proc/{server}")}))
"""
    got = _python(code)
    seeded = subprocess.run([sys.executable, "-c", "print(hash('millsense'))"],
                            capture_output=True, text=True, check=True,
                            env=dict(os.environ, PYTHONHASHSEED="6640"))  # fmt: skip
    workers = got["workers"]
    assert isinstance(workers, list) and len(workers) == 2
    for ppid, preloaded, blas, h in workers:
        assert ppid == got["server"] and preloaded and blas == "1"
        assert h == int(seeded.stdout)
    assert got["changed"] is False and got["same"] is True
    assert got["server_alive"] is False


def test_a_forked_worker_killed_mid_batch_loses_nothing(tmp_path: Path) -> None:
    """The local cluster's own workers, forked from the server: one killed after the first row;
    its nanny starts another, and the batch ends with every row and every fragment (decision
    2003). A fresh interpreter, so that the server is this batch's."""
    folder = tmp_path / "fleet"
    simulate_fleet(folder, tools=1, runs=4, part_cut_min=25.0, seed=5)
    code = f"""
import json, os, signal
from pathlib import Path
from multiprocessing import forkserver
import pyarrow.parquet as pq
from millsense.cli.batch_run import run_batch
out = Path({str(tmp_path / "out")!r})
recs = sorted(Path({str(folder)!r}).glob("*.h5"))
killed = []
def progress(done, _total):
    if done >= 1 and not killed:
        # a finished fragment, not a writer's hidden temporary (renamed under the glob's feet)
        row = pq.read_table(next((out / "runs").glob("[!.]*.parquet"))).to_pylist()[0]
        pid = int(row["worker_pid"])
        ppid = int(Path(f"/proc/{{pid}}/stat").read_text().rsplit(")", 1)[1].split()[1])
        os.kill(pid, signal.SIGKILL)
        killed.append((pid, ppid, forkserver._forkserver._forkserver_pid))
res = run_batch(recs, out, do="monitor,summary", workers=2, on_progress=progress)
res.closing.join()
print(json.dumps({{"killed": killed, "status": [r["status"] for r in res.rows],
                  "errors": [r.get("error") for r in res.rows],
                  "fragments": [(out / "runs" / (r.stem + ".parquet")).is_file() for r in recs]}}))
"""
    got = _python(code)
    killed = got["killed"]
    assert isinstance(killed, list) and len(killed) == 1
    _pid, ppid, server = killed[0]
    assert ppid == server  # a forked worker was killed
    assert got["status"] == ["ok"] * 4, got["errors"]
    assert got["fragments"] == [True] * 4  # (a killed writer may leave its hidden temporary)


def test_a_fork_server_started_elsewhere_is_not_used() -> None:
    """A fork server the program started itself (its environment and modules unknown) does
    not serve the batch's workers: they are spawned."""
    code = """
import json
from multiprocessing import forkserver
from millsense.cli.batch_workers import start_worker_server
forkserver.ensure_running()
print(json.dumps({"used": start_worker_server()}))
"""
    assert _python(code) == {"used": False}
