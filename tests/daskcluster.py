"""A real Dask cluster for tests (importable as ``daskcluster``): ``dask scheduler`` and ``dask
worker`` started as separate processes on 127.0.0.1, bounded in time and stopped by the test; and
the tools of the tests that kill one of its workers in the middle of a job or watch a job's
progress on a terminal."""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import threading
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


def in_flight(client) -> dict:
    """Worker name -> keys of the tasks the scheduler has given it and not yet seen finish."""
    return client.run_on_scheduler(
        lambda dask_scheduler: {ws.name: [ts.key for ts in ws.processing] for ws in dask_scheduler.workers.values()})


def kill_when(proc, ready, timeout: float = 300) -> float:
    """SIGKILL ``proc`` as soon as ``ready()`` holds (polled every 50 ms; the test fails after
    ``timeout`` seconds); returns the moment the process is known dead (``time.time()``, as file
    times, taken after it is reaped: a file it finished in the instant before the signal landed
    is older than that)."""
    deadline = time.monotonic() + timeout
    while not ready():
        if time.monotonic() > deadline:
            raise AssertionError(f"the job never reached the moment to kill a worker ({timeout} s)")
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    return time.time()


def eventually(holds, timeout: float = 30.0) -> bool:
    """Whether ``holds()`` becomes true within ``timeout`` seconds (polled every 50 ms): for work
    that ends on another thread, such as a progress bar's listener on the client's event loop,
    which a fixed sleep would race on a loaded machine."""
    deadline = time.monotonic() + timeout
    while not holds():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def on_terminal(argv: list[str], env: dict, cwd: Path, timeout: float = 300) -> tuple[int, str, str]:
    """Run ``argv`` with its stderr on a pseudo-terminal (a tty, as in a shell) and its stdout on a
    pipe; returns (exit status, stdout, stderr). The process is killed after ``timeout`` seconds."""
    master, slave = os.openpty()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=slave, stdin=subprocess.DEVNULL, env=env, cwd=cwd)
    os.close(slave)
    out = []
    reader = threading.Thread(target=lambda: out.append(proc.stdout.read()))
    reader.start()
    err, deadline = b"", time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            if select.select([master], [], [], 0.2)[0]:
                try:
                    chunk = os.read(master, 1 << 16)
                except OSError:  # the terminal's other side closed: the command ended
                    break
                if not chunk:
                    break
                err += chunk
            elif proc.poll() is not None:
                break
        proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        proc.kill()
        os.close(master)
        reader.join(timeout=30)
        proc.stdout.close()
    return proc.returncode, out[0].decode(), err.decode()
