"""A real Dask cluster for tests (importable as ``daskcluster``): ``dask scheduler`` and ``dask
worker`` started as separate processes on 127.0.0.1, bounded in time and stopped by the test."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path


@contextlib.contextmanager
def dask_cluster(tmp: Path, workers: int = 2, env: dict | None = None, worker_args: tuple = ()):
    """Yield (scheduler address, [scheduler, worker …] processes). Workers run without a nanny
    (killing one kills it) and one thread each; ``env`` is added to their environment and
    ``worker_args`` to their command line. Their stderr goes to ``tmp/worker<N>.log``."""
    info = tmp / "scheduler.json"
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__DAEMON="False", **(env or {}))
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    logs = []
    try:
        deadline = time.monotonic() + 60
        while not info.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        for n in range(workers):
            logs.append(open(tmp / f"worker{n}.log", "w"))
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads",
                                           "1", "--no-nanny", "--no-dashboard", "--name", f"w{n}", *worker_args],
                                          stdout=subprocess.DEVNULL, stderr=logs[-1], env=env))
        from dask.distributed import Client

        with Client(address, timeout=30) as c:
            c.wait_for_workers(workers, timeout=120)
        yield address, procs
    finally:
        for p in procs:
            p.kill()
            p.wait(timeout=30)
        for log in logs:
            log.close()
