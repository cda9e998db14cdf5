"""Running the parts of a job (``ple.app.jobs``) on Dask: an embedded local cluster by default
(one single-threaded worker process per core), a real one with ``--scheduler tcp://HOST:PORT``
(started by ``dask scheduler`` / ``dask worker`` or any Dask deployment), or ``sync`` (in this
process, one part after the other: the reference path).

A worker killed in the middle of a part loses nothing: Dask reruns the part on another worker,
and the part is written atomically, so no half-written part remains. A part that fails (a
program that raises) is recorded by name in the manifest; the others go on.
"""

from __future__ import annotations

import contextlib
import json
import os
import posixpath
import sys
import time
from collections.abc import Iterator

from ..errors import PleError
from .jobs import FORMAT, MANIFEST, Job, compute_part, location, read_manifest, valid_parts, write_atomic
from .progress import Progress

CONNECT_TIMEOUT = 5  # seconds to reach a scheduler before giving up with a message
RETRIES = 2  # reruns of a part whose worker died (Dask also reruns lost tasks by itself)
SAVE_EVERY = 1.0  # seconds between two writes of a running job's manifest


@contextlib.contextmanager
def dask_client(scheduler: str | None = "local", workers: int | None = None) -> Iterator:
    """A ``dask.distributed.Client``: ``local`` (default) starts an embedded cluster of
    ``workers`` processes (default: the cores), an address joins a running scheduler; ``sync``
    yields None (no Dask)."""
    scheduler = scheduler or "local"
    if scheduler == "sync":
        yield None
        return
    from dask.distributed import Client, LocalCluster  # optional: only distributed runs need Dask

    if scheduler == "local":  # its logs stay quiet: a failed part is reported by name, not as a worker's traceback
        n = max(1, int(workers or os.cpu_count() or 1))
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                          silence_logs=50) as cluster, Client(cluster) as client:
            client.run(_warm)
            yield client
        return
    if "://" not in scheduler:
        raise PleError(f"--scheduler {scheduler!r}: expected local, sync or an address such as tcp://HOST:8786")
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise PleError(f"--scheduler {scheduler}: cannot reach the scheduler ({exc})") from None
    with client:
        client.run(_warm)
        yield client


def _warm() -> None:
    """Run on each worker when the client connects: unpickling this function imports this module
    and with it the job code (``ple.app.jobs``), so no part pays the library's import."""


def run_tasks(client, fn, args_list: list[tuple], items: list):
    """Yield ``(item, result or exception)`` as the calls ``fn(*args)`` finish, on Dask
    (``client``) or in this process (``client`` None). A PleError, or a task whose worker died
    more than RETRIES times, comes back as its exception; nothing else stops the others."""
    if client is None:
        for item, args in zip(items, args_list):
            try:
                yield item, fn(*args)
            except PleError as exc:
                yield item, exc
        return
    from dask.distributed import as_completed  # optional: only distributed runs need Dask

    futures = {client.submit(fn, *args, retries=RETRIES, pure=False): item for item, args in zip(items, args_list)}
    for fut in as_completed(futures):
        try:
            yield futures[fut], fut.result()
        except Exception as exc:  # PleError from the task, or KilledWorker: reported by name
            yield futures[fut], exc


def check_scheduler(scheduler: str | None, workers: int | None) -> None:
    """``--scheduler``/``--workers`` as ``dask_client`` takes them, checked before any work."""
    if scheduler not in (None, "local", "sync") and "://" not in str(scheduler):
        raise PleError(f"--scheduler {scheduler!r}: expected local, sync or an address such as tcp://HOST:8786")
    if workers is not None and workers < 1:
        raise PleError(f"--workers {workers}: must be at least 1")


def run_job(job: Job, url: str, scheduler: str | None = "local", workers: int | None = None,
            progress: bool | None = None, client=None) -> dict:
    """Compute every part of ``job`` not already written and valid under ``url``; returns a
    summary (written, skipped, failed, manifest, seconds). ``client``: an existing Dask client
    (then ``scheduler`` is ignored)."""
    t0 = time.perf_counter()
    if client is None:
        check_scheduler(scheduler, workers)  # before the folder is created
    fs, root = location(url)
    old = read_manifest(fs, root)
    if old and (old.get("kind") != job.kind or old.get("settings") != job.settings):
        raise PleError(f"{url}: holds the parts of another job ({old.get('kind')}, other settings); "
                       "choose another --out or remove it")
    done = valid_parts(fs, root, old) & {p.name for p in job.parts}
    manifest = {"format": FORMAT, "kind": job.kind, "settings": job.settings, "order": [p.name for p in job.parts],
                "parts": {n: e for n, e in old.get("parts", {}).items() if n in done}, "failures": {}}
    todo = [p for p in job.parts if p.name not in done]
    path = posixpath.join(root, MANIFEST)

    def save() -> None:
        write_atomic(fs, path, (json.dumps(manifest, indent=1) + "\n").encode())

    save()
    bar = Progress(len(todo), job.kind, enabled=progress)
    if todo:
        if client is not None:
            _run_parts(client, job, todo, url, manifest, save, bar)
        else:
            with dask_client(scheduler, workers) as c:
                if c is not None and progress is not False and sys.stderr.isatty():
                    print(f"dask dashboard: {c.dashboard_link}", file=sys.stderr)
                _run_parts(c, job, todo, url, manifest, save, bar)
    bar.close()
    return {"written": len(todo) - len(manifest["failures"]), "skipped": len(done), "failed": manifest["failures"],
            "manifest": f"{url.rstrip('/')}/{MANIFEST}", "seconds": round(time.perf_counter() - t0, 3)}


def _run_parts(client, job: Job, todo, url, manifest, save, bar) -> None:
    """Every part of ``todo`` through ``run_tasks``; the manifest is saved at most every
    SAVE_EVERY seconds and at the end (a part finished but not yet recorded when the client dies
    is only computed again), so thousands of small parts do not rewrite it thousands of times."""
    args = [(job.kind, job.settings, part, url) for part in todo]
    last = -SAVE_EVERY  # the first finished part is recorded at once
    try:
        for part, result in run_tasks(client, compute_part, args, todo):
            if isinstance(result, Exception):
                error = str(result) if isinstance(result, PleError) else f"{type(result).__name__}: {result}"
                manifest["failures"][part.name] = {"params": part.params, "error": error}
            else:
                manifest["parts"][part.name] = result
            if time.monotonic() - last >= SAVE_EVERY:
                save()
                last = time.monotonic()
            bar.update(1, part.name)
    finally:
        save()
