"""The process tree of a contained run (docs/reliability.md, *Contained programs*): OS plumbing
kept at the edge of the runner.

A ``runner.Job`` child calls ``detach`` first: it leads a session (and process group) of its
own, so what it forks is in that session unless it leaves; on Linux it also becomes a *child
subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``), so a descendant orphaned by a double fork is
re-parented to it instead of to init and stays its descendant even after calling ``setsid``.
Its answer sent, the child does not exit: it waits (``wait_for_end``) so that its descendants
stay its own until the parent ends them with it. When the run ends, errs,
times out or is cancelled, the parent calls ``end_tree``: every descendant of the child (read
from ``/proc``), every process of its session and of its process group is stopped, looked for
again (a fork racing the scan is caught stopped), then killed; the child is reaped last, so its
pid, and the group and session named by it, are not reused meanwhile. A pid that is no longer
this process's child (reaped elsewhere, SIGCHLD ignored) is left alone: it may name another
process by then.

While the run goes on, the parent watches the memory of the whole tree (``TreeMemory``): the
per-process address-space limit (``RLIMIT_AS``, inherited by what the child forks) alone lets a
program fork children that each stay under it.

Elsewhere: macOS (no ``/proc``, no subreaper) ends the child's process group; a descendant
that calls ``setsid`` or ``setpgid`` there escapes, and the tree's memory is not watched (each
process keeps its ``RLIMIT_AS``). Windows has no ``fork``: the runner works in-process and there
is no tree to end.
"""

from __future__ import annotations

import ctypes
import math
import os
import signal
import sys
import time

PR_SET_CHILD_SUBREAPER = 36
KILL_WAIT = 2.0  # seconds end_tree waits at most for killed processes to exit
ORPHAN_CHECK = 0.5  # seconds between a waiting child's looks at whether its parent is alive
ROUNDS = 20  # scans of a tree that keeps forking while it is being stopped
WATCH_EVERY = 0.05  # seconds between looks at a tree's memory
WATCH_SHARE = 20  # a count by PSS not forced by the limit waits 20 times its own cost: 5 % of a core
PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
TREE_MEMORY = os.path.exists("/proc/self/statm")  # Linux: a tree's memory can be watched
HAS_PSS = os.path.exists("/proc/self/smaps_rollup")  # Linux 4.14 and later


def detach() -> None:
    """In a freshly forked child: a session and process group of its own; on Linux a child
    subreaper too."""
    try:
        os.setsid()
    except OSError:  # already a session leader (cannot happen right after fork)
        pass
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the session and the group still hold
            pass


def wait_for_end(parent: int) -> None:
    """In the child, its answer sent: wait to be ended with its tree (``end_tree``) by
    ``parent``, or return when ``parent`` is gone (the child then exits by itself)."""
    while os.getppid() == parent:
        time.sleep(ORPHAN_CHECK)


def _table() -> dict[int, tuple[int, int, int]] | None:
    """pid -> (parent pid, process group, session) of every process, from /proc; None without it."""
    try:
        names = os.listdir("/proc")
    except OSError:
        return None
    out = {}
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                text = fh.read().decode("ascii", "replace")
        except OSError:  # ended meanwhile
            continue
        fields = text.rpartition(")")[2].split()  # after the command name, which may hold spaces
        if len(fields) >= 4 and fields[0] != "Z":  # zombies are dead already (reaped by their parent)
            out[int(name)] = (int(fields[1]), int(fields[2]), int(fields[3]))
    return out


def _descendants(pid: int) -> set[int] | None:
    """Every descendant of a live ``pid``, walking ``/proc/P/task/T/children`` (a subreaper's
    orphans included); None where the kernel lists no children or ``pid`` is gone or a zombie."""
    if not _running(pid):
        return None
    found: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:  # ended meanwhile
            continue
        for t in tasks:
            try:
                with open(f"/proc/{p}/task/{t}/children") as fh:
                    kids = {int(x) for x in fh.read().split()}
            except FileNotFoundError:
                if p == pid:
                    return None
                continue
            except OSError:
                continue
            todo.extend(kids - found)
            found |= kids
    return found


def members(pid: int) -> set[int] | None:
    """The processes of the tree led by ``pid`` (``pid`` itself not included): while it lives,
    its descendants (a subreaper keeps them all); once it has exited, the members of the session
    and process group it led and their descendants. None where /proc is missing."""
    kids = _descendants(pid)
    if kids is not None:
        return kids
    table = _table()
    if table is None:
        return None
    found = {p for p, (_, group, session) in table.items() if group == pid or session == pid}
    children: dict[int, list[int]] = {}
    for p, (parent, _, _) in table.items():
        children.setdefault(parent, []).append(p)
    todo = [pid, *found]
    while todo:
        for c in children.get(todo.pop(), ()):
            if c not in found:
                found.add(c)
                todo.append(c)
    found.discard(pid)
    found.discard(os.getpid())
    return found


def _signal(pids, sig) -> None:
    for p in pids:
        try:
            os.kill(p, sig)
        except (ProcessLookupError, PermissionError):
            pass


def end_tree(pid: int) -> int | None:
    """Kill the child ``pid`` (a ``detach``ed one) and every process of its tree; reap the child.
    Its wait status, or None if it was reaped already."""
    if not _is_child(pid):  # reaped elsewhere (SIGCHLD ignored): its pid may name a stranger now
        return None
    _signal([pid], signal.SIGSTOP)  # a stopped subreaper keeps its orphans while its tree is ended
    stopped: set[int] = set()
    group = False
    for _ in range(ROUNDS):
        tree = members(pid)
        if tree is None:  # no /proc: the process group the child leads
            group = True
            _signal_group(pid, signal.SIGKILL)
            break
        new = tree - stopped
        if not new:
            break
        _signal(new, signal.SIGSTOP)
        stopped |= new
    _signal(stopped, signal.SIGKILL)
    _signal([pid], signal.SIGKILL)
    _wait_gone(stopped)
    try:
        status = os.waitpid(pid, 0)[1]
    except ChildProcessError:
        status = None
    if group:  # the group outlives its reaped leader while a member lives: wait for it to empty
        end = time.monotonic() + KILL_WAIT
        while _signal_group(pid, 0) and time.monotonic() < end:
            time.sleep(0.002)
    return status


def _is_child(pid: int) -> bool:
    """Whether ``pid`` is still this process's child, alive or a zombie (not reaped)."""
    try:
        os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:
        return False
    return True


def _signal_group(pgid: int, sig: int) -> bool:
    """Send ``sig`` to process group ``pgid``; False once no process is in it."""
    try:
        os.killpg(pgid, sig)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            return fh.read().rpartition(b")")[2].split()[:1] != [b"Z"]
    except OSError:
        return False


def _wait_gone(pids, limit: float = KILL_WAIT) -> None:
    """Wait until the killed ``pids`` have exited (a SIGKILL is delivered, not awaited, by
    ``kill``), at most ``limit`` seconds (a process in uninterruptible sleep dies when it wakes)."""
    end = time.monotonic() + limit
    left = set(pids)
    while left and time.monotonic() < end:
        left = {p for p in left if _running(p)}
        if left:
            time.sleep(0.002)


def resident(pids) -> dict[int, int]:
    """Bytes resident in each live process of ``pids`` (zombies and ended ones left out), from
    ``/proc/P/statm``: kernel counters, microseconds a process. A page that k of them share
    (copy-on-write after a fork) counts in each of the k."""
    out = {}
    for p in pids:
        try:
            with open(f"/proc/{p}/statm", "rb") as fh:
                pages = int(fh.read().split()[1])
        except (OSError, IndexError, ValueError):  # ended meanwhile
            continue
        if pages:
            out[p] = pages * PAGE
    return out


def proportional(pids) -> dict[int, int]:
    """The proportional set size (PSS) in bytes of each live process of ``pids``, from
    ``/proc/P/smaps_rollup``: a page shared by k processes counts 1/k in each, so summed over a
    tree a page its members share counts once. The kernel walks their page tables for it: the
    cost grows with the resident pages, unlike ``resident``'s."""
    out = {}
    for p in pids:
        try:
            with open(f"/proc/{p}/smaps_rollup", "rb") as fh:
                for line in fh:
                    if line.startswith(b"Pss:"):
                        out[p] = int(line.split()[1]) * 1024
                        break
        except (OSError, ValueError):  # ended meanwhile, or a zombie
            continue
    return out


class TreeMemory:
    """The memory the tree of the ``detach``ed child ``pid`` holds beyond what the child held at
    its fork, against ``limit`` bytes; ``runner.Job.poll`` calls ``over`` when it is ``due``
    (every ``WATCH_EVERY`` s).

    Resident sets are cheap to read but count a page shared after a fork once per process
    (workers forked by a program that built its data; any child of Blender), so a stop is decided
    by PSS (``proportional``). The tree is counted so when its resident sets, less ``shared``
    (what the last such count found them counting more than once), pass the limit; and, while
    ``shared`` is not zero, when a process starts or ends and every ``WATCH_SHARE`` times the
    count's cost (a shared page that a process writes becomes its own). At the fork the child
    shared all of ``base`` with this process: half of it was in the child's PSS."""

    def __init__(self, pid: int, limit: int):
        self.pid, self.limit = pid, limit
        self.base = resident([pid]).get(pid, 0)
        self.shared = 0
        self.counted: set[int] = set()  # the processes of the last count by PSS
        self.due = time.monotonic() + WATCH_EVERY
        self.recount = math.inf  # when PSS is counted again although the sum is within the limit

    def over(self) -> tuple[int, int] | None:
        """(bytes held, processes) once the tree holds more than the limit, else None."""
        pids = [self.pid, *(members(self.pid) or ())]
        held = resident(pids)
        total = sum(held.values()) - self.base
        start = time.monotonic()
        stale = self.shared > 0 and (start >= self.recount or held.keys() != self.counted)
        if HAS_PSS and (total - self.shared > self.limit or stale):
            summed, self.counted = total, set(held)
            held = proportional(pids)
            total = sum(held.values()) - self.base // 2
            self.shared = max(0, summed - total)
            cost = time.monotonic() - start
            self.recount = start + WATCH_SHARE * cost if self.shared else math.inf
        else:
            total -= self.shared
        self.due = time.monotonic() + WATCH_EVERY
        return (total, len(held)) if total > self.limit else None
