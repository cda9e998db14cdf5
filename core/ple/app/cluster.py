"""Running the parts of a job (``ple.app.jobs``) on Dask: an embedded local cluster by default
(one single-threaded worker process per core), a real one with ``--scheduler tcp://HOST:PORT``
(started by ``dask scheduler`` / ``dask worker`` or any Dask deployment), or ``sync`` (in this
process, one part after the other: the reference path).

A worker killed in the middle of a part loses nothing: Dask reruns the part on another worker,
and the part is written atomically, so no half-written part remains. A worker runs the job's
program contained, under the job's limits (``Job.limits``). A part that fails (a program that
raises, or runs past its time or memory limit) is recorded by name in the manifest; the others
go on. On a terminal a job shows Dask's own progress bar and the address of its dashboard, both
on stderr.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import os
import posixpath
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from concurrent.futures import CancelledError

from ..errors import PleError, echo
from .jobs import (
    FORMAT,
    MANIFEST,
    Job,
    check_job_folder,
    compute_part,
    location,
    read_manifest,
    valid_parts,
    write_atomic,
)
from .progress import Progress

CONNECT_TIMEOUT = 5  # seconds to reach a scheduler before giving up with a message
PROBE_TIMEOUT = 2  # seconds to ask a scheduler's web server whether it serves a dashboard
RETRIES = 2  # reruns of a part that raised other than a PleError (Dask reruns the parts of a dead worker itself)
SAVE_EVERY = 1.0  # seconds between two writes of a running job's manifest


@contextlib.contextmanager
def dask_client(scheduler: str | None = "local", workers: int | None = None,
                dashboard: bool | None = None) -> Iterator:
    """A ``dask.distributed.Client``: ``local`` (default) starts an embedded cluster of
    ``workers`` processes (default: the cores), an address joins a running scheduler; ``sync``
    yields None (no Dask). The embedded cluster serves Dask's dashboard (on a free port) when
    ``dashboard`` is true, by default when stderr is a terminal: where its address is printed
    (``run_tasks``), not for runs that nobody watches."""
    scheduler = scheduler or "local"
    if scheduler == "sync":
        yield None
        return
    from dask.distributed import Client, LocalCluster  # optional: only distributed runs need Dask

    if scheduler == "local":  # its logs stay quiet: a failed part is reported by name, not as a worker's traceback
        n = max(1, int(workers or os.cpu_count() or 1))
        # its web server on a free port in any case (its health checks), the dashboard's pages only when shown
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, silence_logs=50, dashboard_address=":0",
                          scheduler_kwargs={"dashboard": showing(dashboard)}) as cluster, Client(cluster) as client:
            client.run(_warm)
            yield client
        return
    if "://" not in scheduler:
        raise PleError(f"--scheduler {echo(scheduler)}: expected local, sync or an address such as tcp://HOST:8786")
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise PleError(f"--scheduler {scheduler}: cannot reach the scheduler ({exc})") from None
    with client:
        client.run(_warm)
        yield client


def showing(progress: bool | None) -> bool:
    """Whether a job's progress (and its dashboard's address) is shown: ``progress``, by default
    when stderr is a terminal."""
    return sys.stderr.isatty() if progress is None else bool(progress)


def _warm() -> None:
    """Run on each worker when the client connects: unpickling this function imports this module
    and with it the job code (``ple.app.jobs``), so no part pays the library's import."""


def run_tasks(client, fn, args_list: list[tuple], items: list, label: str = "tasks", names: list | None = None,
              progress: bool | None = None):
    """Yield ``(item, result or exception)`` as the calls ``fn(*args)`` finish, on Dask
    (``client``) or in this process (``client`` None). A PleError, or a task whose worker died
    more than Dask allows, comes back as its exception; nothing else stops the others.

    Progress (on a terminal, or ``progress`` True): Dask's own bar on Dask, after the dashboard's
    address, the project's bar (``names`` as its notes) in this process; both on stderr, so the
    command's result on stdout stays clean."""
    names = names or [""] * len(items)
    if client is None:
        bar = Progress(len(items), label, enabled=progress)
        try:
            for item, args, name in zip(items, args_list, names):
                try:
                    result = fn(*args)
                except PleError as exc:
                    result = exc
                yield item, result
                bar.update(1, name)
        finally:
            bar.close()
        return
    from dask.distributed import as_completed  # optional: only distributed runs need Dask

    futures = {client.submit(_kept_errors, fn, *args, retries=RETRIES, pure=False): (item, args)
               for item, args in zip(items, args_list)}
    bar = DaskBar(client, futures, label) if showing(progress) else None
    finished, resubmitted = False, 0
    try:
        running = as_completed(futures)
        for fut in running:
            item, args = futures[fut]
            try:
                result = fut.result()
            except CancelledError as exc:  # its result was lost with a worker and Dask let it go: run it again
                if resubmitted < RETRIES * len(items):
                    resubmitted += 1
                    again = client.submit(_kept_errors, fn, *args, retries=RETRIES, pure=False)
                    futures[again] = (item, args)
                    running.add(again)
                    continue
                result = exc
            except Exception as exc:  # KilledWorker (its worker died too often), or a bug: reported by name
                result = exc
            yield item, result
            if bar is not None:
                bar.follow(futures)
        finished = True
    finally:
        if bar is not None:
            bar.close(wait=finished)


def _kept_errors(fn, *args):
    """``fn(*args)``, a PleError returned rather than raised: a bad part is a result (reported by
    name), not an erred task that Dask would retry and that would stop Dask's progress bar."""
    try:
        return fn(*args)
    except PleError as exc:
        return exc


class DaskBar:
    """Dask's text progress bar (``distributed.diagnostics.progressbar.TextProgressBar``) over a
    job's futures, drawn on stderr; it listens to the scheduler on the client's event loop (its
    thread), while this thread consumes the results. An erred task stops Dask's bar: ``follow``
    then starts another over the futures still pending, drawn against the job's total."""

    def __init__(self, client, futures, label: str) -> None:
        self.client, self.label, self.total, self.t0 = client, label, max(1, len(futures)), time.perf_counter()
        link = dashboard_link(client)
        if link:
            print(f"dask dashboard: {link}", file=sys.stderr, flush=True)
        self._start(list(futures))

    def _start(self, futures) -> None:
        self.bar = _stderr_bar_class()(futures, scheduler=self.client.scheduler.address, interval="200ms",
                                       loop=self.client.loop, start=False)
        self.bar.label, self.bar.total, self.bar._start_time = self.label, self.total, self.t0
        self.listening = asyncio.run_coroutine_threadsafe(self.bar.listen(), self.client.loop.asyncio_loop)

    def follow(self, futures) -> None:
        """After a result: a bar stopped by an erred task gives way to one over the pending futures."""
        if self.listening.done() and getattr(self.bar, "status", None) == "error":
            pending = [f for f in futures if f.status == "pending"]
            if pending:
                self._start(pending)

    def close(self, wait: bool = True, timeout: float = 5.0) -> None:
        """Wait for the bar's last drawing (the scheduler's next report; not when the job was
        interrupted), then stop it: no listener outlives the job."""
        try:
            if wait:
                self.listening.result(timeout=timeout)
        except Exception:  # a timeout, or the connection lost: the bar only stops
            pass
        finally:
            self.listening.cancel()


@functools.cache
def _stderr_bar_class():
    """Dask's ``TextProgressBar`` drawing on stderr (it writes to stdout, which carries the
    command's result), its last state kept on its line, against the job's total."""
    from distributed.diagnostics.progress import format_time
    from distributed.diagnostics.progressbar import TextProgressBar  # optional: only distributed runs need Dask

    class StderrBar(TextProgressBar):
        label, total, drawn = "", 1, False

        def _draw_bar(self, remaining, all, **kwargs):
            done = min(self.total, max(0, self.total - remaining))  # of the job's total (see ``follow``)
            bar = "#" * (self.width * done // self.total)
            sys.stderr.write(f"\r{self.label} [{bar:<{self.width}}] | {100 * done // self.total}% Completed | "
                             f"{format_time(self.elapsed)}")
            sys.stderr.flush()
            self.drawn = True

        def _draw_stop(self, **kwargs):
            if self.drawn:  # the last state stays on its line
                sys.stderr.write("\n")
                sys.stderr.flush()
            self.drawn = False

        async def listen(self):
            try:
                await super().listen()
            finally:  # also when cancelled (an interrupted job): the line ends, the connection closes
                self._draw_stop()
                comm = getattr(self, "comm", None)
                if comm is not None:
                    comm.abort()

    return StderrBar


def dashboard_link(client) -> str | None:
    """The address of the scheduler's dashboard, or None when it serves none (an embedded
    cluster started without one, a scheduler started with ``--no-dashboard``: their web server
    answers 404 there). An address that cannot be reached from here is still given (a tunnel may
    reach it)."""
    if "dashboard" not in client.scheduler_info().get("services", {}):
        return None
    link = client.dashboard_link
    try:  # HEAD: the dashboard's page is not rendered (a page that only answers GET says 405)
        urllib.request.urlopen(urllib.request.Request(link, method="HEAD"), timeout=PROBE_TIMEOUT).close()
    except urllib.error.HTTPError as exc:
        return None if exc.code == 404 else link
    except OSError:
        pass
    return link


def check_scheduler(scheduler: str | None, workers: int | None) -> None:
    """``--scheduler``/``--workers`` as ``dask_client`` takes them, checked before any work."""
    if scheduler not in (None, "local", "sync") and "://" not in str(scheduler):
        raise PleError(f"--scheduler {echo(scheduler)}: expected local, sync or an address such as tcp://HOST:8786")
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
    fs, root = location(url, create=None)
    check_job_folder(fs, root, url)  # new, empty or a job's: never another folder of the user's
    old = read_manifest(fs, root)
    if old and (old.get("kind") != job.kind or old.get("settings") != job.settings):
        raise PleError(f"{url}: holds the parts of another job ({old.get('kind')}, other settings); "
                       "choose another --out or remove it")
    done = valid_parts(fs, root, old) & {p.name for p in job.parts}  # size and SHA-256 as recorded
    manifest = {"format": FORMAT, "kind": job.kind, "settings": job.settings, "order": [p.name for p in job.parts],
                "parts": {n: e for n, e in old.get("parts", {}).items() if n in done}, "failures": {}}
    todo = [p for p in job.parts if p.name not in done]
    path = posixpath.join(root, MANIFEST)

    def save() -> None:
        write_atomic(fs, path, (json.dumps(manifest, indent=1, allow_nan=False) + "\n").encode())

    with contextlib.ExitStack() as stack:
        if todo and client is None:  # the scheduler is reached before anything is created
            client = stack.enter_context(dask_client(scheduler, workers, showing(progress)))
        location(url)
        save()
        if todo:
            _run_parts(client, job, todo, url, manifest, save, progress)
    return {"written": len(todo) - len(manifest["failures"]), "skipped": len(done), "failed": manifest["failures"],
            "manifest": f"{url.rstrip('/')}/{MANIFEST}", "seconds": round(time.perf_counter() - t0, 3)}


def _run_parts(client, job: Job, todo, url, manifest, save, progress) -> None:
    """Every part of ``todo`` through ``run_tasks``; the manifest is saved at most every
    SAVE_EVERY seconds and at the end (a part finished but not yet recorded when the client dies
    is only computed again), so thousands of small parts do not rewrite it thousands of times."""
    args = [(job.kind, job.settings, part, url, job.limits) for part in todo]  # the limits go to every worker
    last = -SAVE_EVERY  # the first finished part is recorded at once
    try:
        for part, result in run_tasks(client, compute_part, args, todo, job.kind, [p.name for p in todo], progress):
            if isinstance(result, Exception):
                error = str(result) if isinstance(result, PleError) else f"{type(result).__name__}: {result}"
                manifest["failures"][part.name] = {"params": part.params, "error": error}
            else:
                manifest["parts"][part.name] = result
            if time.monotonic() - last >= SAVE_EVERY:
                save()
                last = time.monotonic()
    finally:
        save()
