"""The worker processes of ``millsense batch``'s local cluster: the environment they start with
and the fork server they are forked from (decisions 2003, 2008).

Dask starts each worker process with multiprocessing's ``spawn``: a fresh interpreter that
imports Dask's worker (0.3 s), and then, at its first task, the pipeline's modules (numba,
scipy, h5py, pyarrow and millsense's steps: 0.6 s more), one after the other once the cluster
is up. :func:`start_worker_server` starts multiprocessing's fork server as soon as a batch
knows it needs its local cluster, with those modules imported
(:data:`~millsense.cli.batch_tasks.TASK_MODULES`): the imports run on another core while
the client imports Dask and starts the scheduler, once for every worker, and each worker is a
fork of a process that has them. The fork server is single-threaded (multiprocessing forks
nothing else), so the fork is safe where forking the client, which runs Dask's event loop in
a thread, would not be.
"""

from __future__ import annotations

import atexit
import os

from millsense.cli.batch_tasks import TASK_MODULES
from millsense.core.blas import default_to_one_thread

__all__ = ["start_worker_server", "worker_environment"]

#: Set by Dask in the process of the nanny before each worker process starts (its default
#: ``distributed.nanny.pre-spawn-environ``, and the hash seed ``Nanny`` adds): variables read
#: when a process or a library starts, so the fork server must start with them.
DASK_PRE_SPAWN = {
    "MALLOC_TRIM_THRESHOLD_": "65536",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
}
DASK_HASH_SEED = "6640"

#: The environment the fork server started with (empty: not started by this process).
_SERVER_ENV: dict[str, str] = {}


def worker_environment() -> None:
    """Set, in this process, the environment a worker process starts with: one BLAS and one
    numba thread (decision 2003) and Dask's pre-spawn variables (:data:`DASK_PRE_SPAWN`,
    ``PYTHONHASHSEED``; the nanny sets them in this process too, before each worker it
    starts). The HDF5 codec's thread count is read when a task runs: the local cluster gives
    it to its workers itself (``local_cluster``; importing ``millsense.io`` here would delay
    the fork server by 65 ms)."""
    default_to_one_thread()
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.update(DASK_PRE_SPAWN)
    if os.environ.get("PYTHONHASHSEED") in (None, "0"):
        os.environ["PYTHONHASHSEED"] = DASK_HASH_SEED


def start_worker_server() -> bool:
    """Start multiprocessing's fork server with Dask's worker and the tasks' modules imported
    (module docstring), if it is not running; True when the local cluster's workers can be
    forked from it. False where the platform has no fork server, where this process's
    environment changed since the server started (its workers would not see the change), or
    where another part of the program started multiprocessing's fork server: the workers are
    spawned then, as Dask does by default."""
    import multiprocessing
    from multiprocessing import forkserver

    worker_environment()
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    if _SERVER_ENV:
        return _SERVER_ENV == _environment()
    if getattr(forkserver._forkserver, "_forkserver_pid", None) is not None:
        return False  # started by someone else, with what environment and modules?
    preload = ["distributed.nanny", *TASK_MODULES]
    multiprocessing.get_context("forkserver").set_forkserver_preload(preload)
    forkserver.ensure_running()  # returns at once: the server imports on its own
    _SERVER_ENV.update(_environment())
    atexit.register(_stop_worker_server)
    return True


def _environment() -> dict[str, str]:
    """This process's environment but the variables Dask keeps for itself (``__DASK_*``, set
    in the nanny's process when it starts)."""
    return {k: v for k, v in os.environ.items() if not k.startswith("__DASK_")}


def _stop_worker_server() -> None:
    """At exit (a batch has closed its cluster by then): end the fork server and wait for it,
    so that its CPU time and its workers' are counted as this process's children's, as
    spawned workers' were. It is terminated (SIGTERM): it holds nothing to write, leaves at
    once instead of tearing its modules down (about 0.3 s), and may still be importing when a
    batch ends early."""
    import signal
    from multiprocessing import forkserver

    server = forkserver._forkserver
    pid = getattr(server, "_forkserver_pid", None)
    stop = getattr(server, "_stop", None)
    if pid is None or stop is None:  # not running, or another Python: it ends with us
        return
    try:
        os.kill(pid, signal.SIGTERM)
        stop()  # closes its pipe, waits for it, removes its socket
    except OSError:  # already gone
        pass
