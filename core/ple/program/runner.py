"""Contained work: lattice programs and long core calls in a child process (docs/reliability.md).

A ``Job`` runs a function in a child (``os.fork``: the core is already imported, so a start
costs milliseconds) under a memory limit: each process's address space (``RLIMIT_AS``, which
stops one fast allocation) and, on Linux, the whole tree's memory, which the parent looks at
every few tens of ms (``proctree.TreeMemory``). The parent waits at most ``timeout`` seconds
and may cancel it at any moment (Blender's Esc). What the function yields on the way
(progress fractions, mesh chunks) comes back as messages; what it returns is the result.
``sys.exit``, ``os._exit``, any ``BaseException``, running out of memory and crashes of the
child become one PleError naming the program file and, where known, the line. A hang or a
memory bomb costs the child, never the caller (the CLI, batch workers, Blender).

``run_program`` builds a lattice from a program file, a preset or (``run_text``) program text;
IR files and presets in JSON are plain data and load in-process. What comes back is the
Lattice object, pickled by the child and unpickled by the parent with an allowlist (classes of
this package, numpy arrays and scalars, plain containers), its filter included: the IR
(``ple-lattice/1``) would lose a program's metadata and its canonical similarities are not
bit-exact for composed similarities. Nothing outside the allowlist can be constructed by the
parent; a lattice is then checked as an IR file is (``ple.model.budget.check_lattice``).
"""

from __future__ import annotations

import faulthandler
import io
import math
import os
import pickle
import select
import signal
import struct
import sys
import time
import traceback
import types
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..algebra.similarity import Similarity
from ..errors import PleError, echo
from ..filters.base import Filter
from ..model.becots import BeCOTS
from ..model.budget import check_lattice, human
from ..model.grading import RadiusField
from ..model.groupmap import GroupMap
from ..model.lattice import MAX_COUNT, BeamPattern, Direction, Lattice, Node
from . import proctree
from .runtime import ROOT_PACKAGE, compile_program, load_program_file
from .sources import load_lattice, resolve_source

DEFAULT_TIMEOUT = 30.0
EXIT_CHECK = 0.1  # seconds between looks at whether the child exited, where there is no pidfd
_ROOT = ROOT_PACKAGE  # "ple", or the vendored package name inside the Blender extension
_SAFE_BUILTINS = {"set", "frozenset", "complex", "slice", "range", "tuple", "list", "dict", "bytearray",
                  "getattr", "object"}
_SAFE_NUMPY = ("numpy", "numpy.core.multiarray", "numpy.core.numeric", "numpy._core.multiarray",
               "numpy._core.numeric", "numpy.dtypes", "numpy.random._pickle", "copyreg", "_codecs")
_FRAME = struct.Struct("<Q")  # each message: its length, then its pickle


@dataclass(frozen=True)
class Hints:
    """How the user raises a limit, in the words of the door that set it."""

    timeout: str = "raise the limit with --timeout"
    memory: str = "raise it with --max-memory"


CLI_HINTS = Hints()


class _ProgramExit(BaseException):
    """``os._exit`` called by a program inside the child."""


class _SafeUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        if module == "builtins" and name in _SAFE_BUILTINS:
            return super().find_class(module, name)
        if module == _ROOT or module.startswith(_ROOT + ".") or module in _SAFE_NUMPY:
            if module == "copyreg" and name not in ("_reconstructor", "__newobj__", "__newobj_ex__"):
                raise pickle.UnpicklingError(f"{module}.{name} is not allowed")
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"{module}.{name} is not allowed in a program's result")


def _where(exc: BaseException, program: str) -> str:
    for frame in reversed(traceback.extract_tb(exc.__traceback__)):
        if frame.filename == program:
            return f"{program}:{frame.lineno}"
    return program


def _describe(exc: BaseException, program: str, memory: int | None, hints: Hints, what: str) -> str:
    where = _where(exc, program)
    if isinstance(exc, SystemExit):
        return f"{where}: the program called sys.exit({exc.code!r}); a program must return a Lattice"
    if isinstance(exc, _ProgramExit):
        return f"{where}: the program called os._exit({exc.args[0]!r}); a program must return a Lattice"
    if isinstance(exc, MemoryError):
        limit = f" (limit {human(memory)})" if memory else ""
        return f"{where}: {what} ran out of memory{limit}; {hints.memory}"
    if isinstance(exc, RecursionError):
        return f"{where}: {what} recursed too deeply"
    if isinstance(exc, ModuleNotFoundError) and exc.name:  # a package this Python lacks (trimesh, imported where used)
        return (f"{where}: {what.removeprefix('the ')} needs the Python package {exc.name!r}, "
                "which this Python does not have")
    return f"{where}: {what.removeprefix('the ')} raised {type(exc).__name__}: {exc}"


def _send(fd: int, message) -> None:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(_FRAME.pack(len(data)) + data)
    while view:
        view = view[os.write(fd, view):]


def _limit_memory(memory: int | None) -> None:
    if not memory:
        return
    import resource

    limit = _vm_size() + int(memory)
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def _child(write_fd: int, work: Callable[[], Any], name: str, memory: int | None, hints: Hints,
           what: str) -> None:
    """In the forked child: run ``work``, send what it yields and then (status, payload), wait to
    be ended with the processes the work started (``proctree``); never return."""
    real_exit = os._exit
    status, payload = "error", f"{name}: the work did not finish"
    child, parent = os.getpid(), os.getppid()
    try:
        proctree.detach()  # its own session: the parent ends the whole tree (end_tree)
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # the parent reports Ctrl-C
        faulthandler.disable()  # a crash is reported once, by the parent
        _limit_memory(memory)

        me = os.getpid()

        def program_exit(code=0):
            if os.getpid() != me:  # a process the work forked (multiprocessing ends its children so)
                real_exit(code)  # exits: unwinding the inherited stack would run our finally blocks
            raise _ProgramExit(code)

        os._exit = program_exit
        out = _drain(work(), lambda item: _send(write_fd, ("item", item)))
        status, payload = "ok", out
    except PleError as exc:
        payload = str(exc)
    except BaseException as exc:  # noqa: BLE001 - a program may raise anything; report it
        payload = _describe(exc, name, memory, hints, what)
    os._exit = real_exit
    if os.getpid() != child:  # a process the work forked, come back here: only the child answers
        real_exit(1)
    try:
        try:
            _send(write_fd, (status, payload))
        except Exception as exc:  # noqa: BLE001 - e.g. a filter holding a lambda
            _send(write_fd, ("error", f"{name}: the result cannot be returned to PLE ({type(exc).__name__}: {exc})"))
        proctree.wait_for_end(parent)
    finally:
        real_exit(0)


def _drain(out, send) -> Any:
    """``out`` itself, or if it is a generator, its return value after ``send``ing what it yields."""
    if not isinstance(out, types.GeneratorType):
        return out
    while True:
        try:
            send(next(out))
        except StopIteration as stop:
            return stop.value


def _vm_size() -> int:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def check_timeout(timeout: float | None) -> float | None:
    """``timeout`` in seconds, None for no limit (None or inf); PleError if not positive (NaN too)."""
    if timeout is None:
        return None
    if not (timeout > 0):
        raise PleError(f"--timeout {timeout}: expected a positive number of seconds (inf: no limit)")
    return None if math.isinf(timeout) else float(timeout)


class Job:
    """``work()`` running contained in a child process: at most ``timeout`` seconds (None: no
    limit) and ``memory`` bytes beyond what this process already maps, in each process and (on
    Linux) in the child's whole tree together. ``name`` names it in errors ("<file>: the program
    ran longer than …"); ``what`` says what ran ("the program", "the tessellation"). Where there
    is no ``os.fork`` the work runs in-process at ``start``."""

    def __init__(self, work: Callable[[], Any], name: str, timeout: float | None = DEFAULT_TIMEOUT,
                 memory: int | None = None, what: str = "the program", hints: Hints = CLI_HINTS):
        self.name, self.what, self.hints = name, what, hints
        self.timeout = check_timeout(timeout)
        self.memory = memory
        self.items: list = []  # what the work yielded, not yet taken
        self.done = False
        self._result = None
        self._error: str | None = None
        self._buffer = bytearray()
        self._pid = None
        self._fd = None
        self._exit_fd = None  # readable once the child has exited (a pidfd; None: looked at by waitid)
        self._deadline = None
        self._memory: proctree.TreeMemory | None = None  # the tree's, looked at while polling
        self._start(work)

    def _start(self, work) -> None:
        if not hasattr(os, "fork"):  # pragma: no cover - Windows: nothing to contain with
            self._result, self.done = _drain(work(), self.items.append), True
            return
        read_fd, write_fd = os.pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child (its coverage is not collected)
            os.close(read_fd)
            _child(write_fd, work, self.name, self.memory, self.hints, self.what)
        os.close(write_fd)
        self._pid, self._fd = pid, read_fd
        try:
            self._exit_fd = os.pidfd_open(pid)
        except (AttributeError, OSError):  # macOS, Linux before 5.3
            self._exit_fd = None
        self._deadline = None if self.timeout is None else time.monotonic() + self.timeout
        if self.memory and proctree.TREE_MEMORY:
            self._memory = proctree.TreeMemory(pid, int(self.memory))

    def poll(self, wait: float = 0.0) -> bool:
        """Read what the child sent (waiting at most ``wait`` seconds for something); True once
        the work has finished. PleError when it failed, ran out of time or memory, or was killed."""
        end = time.monotonic() + wait
        while not self.done:
            if self._memory is not None and time.monotonic() >= self._memory.due:
                self._look_at_memory()
                if self.done:
                    break
            left = max(0.0, end - time.monotonic())
            if self._deadline is not None:
                left = min(left, max(0.0, self._deadline - time.monotonic()))
            if self._memory is not None:
                left = min(left, max(0.0, self._memory.due - time.monotonic()))
            watch = [self._fd] if self._exit_fd is None else [self._fd, self._exit_fd]
            ready, _, _ = select.select(watch, [], [], left if self._exit_fd is not None else min(left, EXIT_CHECK))
            if self._fd not in ready:
                if self._exited():  # a process it started may hold the pipe open: no end of file
                    self._ended()
                    break
                if self._deadline is not None and time.monotonic() >= self._deadline:
                    self._stop(f"{self.name}: {self.what} ran longer than {self.timeout:g} s; {self.hints.timeout}")
                    break
                if time.monotonic() >= end:
                    return False
                continue
            data = os.read(self._fd, 1 << 20)
            if not data:
                self._ended()
                break
            self._buffer += data
            self._messages()
            if self.done:  # its answer is in: end the child and whatever it started
                self._finish()
        if self._error is not None:
            raise PleError(self._error)
        return True

    def _look_at_memory(self) -> None:
        """Stop the run if its process tree holds more than ``memory`` together."""
        over = self._memory.over()
        if over is not None:
            held, count = over
            who = "its process held" if count == 1 else f"its {count} processes together held"
            self._stop(f"{self.name}: {self.what} ran out of memory: {who} {human(held)} "
                       f"(limit {human(self.memory)}); {self.hints.memory}")

    def _stop(self, why: str) -> None:
        """End the run over a limit: the child and its tree now; ``why`` is its error."""
        self.cancel()
        self._error = why

    def _messages(self) -> None:
        while len(self._buffer) >= _FRAME.size:
            (size,) = _FRAME.unpack_from(self._buffer)
            if len(self._buffer) < _FRAME.size + size:
                return
            data = bytes(self._buffer[_FRAME.size:_FRAME.size + size])
            del self._buffer[:_FRAME.size + size]
            try:
                kind, payload = _SafeUnpickler(io.BytesIO(data)).load()
            except Exception as exc:  # noqa: BLE001 - anything wrong with the child's answer
                kind, payload = "error", f"{self.name}: the result cannot be read back ({exc})"
            if kind == "item":
                self.items.append(payload)
            elif kind == "ok":
                self._result, self.done = payload, True
            else:
                self._error, self.done = str(payload), True

    def _exited(self) -> bool:
        """Whether the child has exited (it is not reaped: ``end_tree`` does that)."""
        if self._pid is None:
            return True
        if self._exit_fd is not None:
            return bool(select.select([self._exit_fd], [], [], 0)[0])
        try:
            info = os.waitid(os.P_PID, self._pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return True
        return info is not None

    def _finish(self) -> int | None:
        """The run is over: its pipe closed, the child and every process of its tree ended
        (``proctree.end_tree``); the child's wait status (None if there was no child)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        status = None
        if self._pid is not None:
            status = proctree.end_tree(self._pid)
            self._pid = None
        if self._exit_fd is not None:
            os.close(self._exit_fd)
            self._exit_fd = None
        return status

    def _ended(self) -> None:
        """The child ended (its pipe closed, or it exited while a process it started holds the
        pipe): end its tree, and say why if it sent no result."""
        if self._fd is not None:  # what it sent before it ended
            os.set_blocking(self._fd, False)
            try:
                while data := os.read(self._fd, 1 << 20):
                    self._buffer += data
            except BlockingIOError:
                pass
            self._messages()
        status = self._finish()
        if self.done:
            return
        self.done = True
        if status is None:
            self._error = f"{self.name}: {self.what} ended without an answer"
        elif os.WIFSIGNALED(status):
            sig = signal.Signals(os.WTERMSIG(status)).name
            why = " (out of memory?)" if sig == "SIGKILL" else ""
            self._error = f"{self.name}: {self.what} crashed with {sig}{why}"
        else:
            self._error = f"{self.name}: {self.what} ended the process (exit status {os.WEXITSTATUS(status)})"

    def take(self) -> list:
        """What the work yielded since the last call."""
        out, self.items = self.items, []
        return out

    def result(self):
        """Wait for the work to finish; its return value (PleError if it failed). Interrupted
        while waiting (Ctrl-C, or SIGTERM/SIGHUP unwinding as ``KeyboardInterrupt``), it kills
        the child before the interruption goes on: a long call in the child never delays it."""
        try:
            while not self.poll(3600.0):
                pass
        except BaseException:
            self.cancel()
            raise
        return self._result

    def cancel(self) -> None:
        """Stop the child and every process it started now (Esc, a time limit); nothing it
        computed is kept."""
        self._finish()
        self.done = True

    def __del__(self):
        self.cancel()


def _checked(lat, name: str) -> Lattice:
    if not isinstance(lat, Lattice):
        raise PleError(f"{name}: lattice() must return a Lattice")
    check_structure(lat, name)
    lat.validate()
    check_lattice(lat, name)
    return lat


def check_structure(lat: Lattice, name: str) -> None:
    """Every attribute of a Lattice a program returns has the type the core expects: a program
    may assign them directly (``lat.filter = 5``, ``lat.u = 'hello'``), which ``add_node`` and the
    setters would have refused. Raises PleError naming the attribute."""
    def bad(attr: str, value, expected: str) -> PleError:
        return PleError(f"{name}: the returned lattice's {attr} is {type(value).__name__} {echo(value)}; "
                        f"expected {expected}")

    def integer(x) -> bool:
        return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))

    if not isinstance(lat.nodes, list):
        raise bad("nodes", lat.nodes, "a list of nodes (use lat.add_node)")
    for n, node in enumerate(lat.nodes):
        if not isinstance(node, Node):
            raise bad(f"nodes[{n}]", node, "a node (use lat.add_node)")
        c = np.asarray(node.center) if isinstance(node.center, (np.ndarray, list, tuple)) else None
        if c is None or c.shape != (3,) or c.dtype.kind not in "fiu":
            raise bad(f"nodes[{n}].center", node.center, "a point of 3 numbers")
        if not isinstance(node.radius, (float, int, np.floating, np.integer)) or isinstance(node.radius, bool) \
                or not (math.isfinite(node.radius) and node.radius > 0):
            raise bad(f"nodes[{n}].radius", node.radius, "a positive number")
    if not isinstance(lat.beams, list):
        raise bad("beams", lat.beams, "a list of beam-patterns (use lat.add_beam)")
    for n, b in enumerate(lat.beams):
        if not isinstance(b, BeamPattern):
            raise bad(f"beams[{n}]", b, "a beam-pattern (use lat.add_beam)")
        for f in ("n1", "n2", "di", "dj", "dk"):
            if not integer(getattr(b, f)):
                raise bad(f"beams[{n}].{f}", getattr(b, f), "an integer")
        if not (0 <= b.n1 < len(lat.nodes) and 0 <= b.n2 < len(lat.nodes)):
            raise PleError(f"{name}: the returned lattice's beams[{n}] joins node {b.n1} to {b.n2}, "
                           f"outside the {len(lat.nodes)} nodes")
    for attr in ("u", "v", "w"):
        d = getattr(lat, attr)
        if not isinstance(d, Direction):
            raise bad(attr, d, f"a direction (use lat.set_{attr})")
        if not integer(d.count) or not 1 <= d.count <= MAX_COUNT:
            raise bad(f"{attr}.count", d.count, f"an integer in 1..{MAX_COUNT:,}")
        if not isinstance(d.similarity, Similarity):
            raise bad(f"{attr}.similarity", d.similarity, "a Similarity")
        if not isinstance(d.cumulative, (bool, np.bool_)):
            raise bad(f"{attr}.cumulative", d.cumulative, "True or False")
    for attr, cls, expected in (("placement", Similarity, "a Similarity (use lat.set_placement)"),
                                ("filter", Filter, "None or a filter (use lat.set_filter)"),
                                ("group_map", GroupMap, "None or a GroupMap (use lat.set_group_map)"),
                                ("radius_field", RadiusField, "None or a RadiusField (use lat.set_radius_field)"),
                                ("becots", BeCOTS, "None or a BeCOTS slab (use lat.set_becots)")):
        value = getattr(lat, attr, None)
        if not isinstance(value, cls) and (attr == "placement" or value is not None):
            raise bad(attr, value, expected)
    if not isinstance(getattr(lat, "meta", None), dict):
        raise bad("meta", getattr(lat, "meta", None), "a dict")


def run_program(source: str, params=None, timeout: float | None = DEFAULT_TIMEOUT,
                memory: int | None = None, hints: Hints = CLI_HINTS) -> Lattice:
    """Build the lattice of ``source`` (program, IR file or preset) contained in a child process:
    at most ``timeout`` seconds and ``memory`` bytes beyond what this process already maps."""
    path = resolve_source(source)
    if path.suffix == ".json" or not hasattr(os, "fork"):  # data only: nothing to contain (or no fork)
        return load_lattice(source, params)
    check_timeout(timeout)
    name = str(path)
    lat = Job(lambda: load_lattice(source, params), name, timeout, memory, hints=hints).result()
    return _checked(lat, name)


def program_inputs(source: str, timeout: float | None = DEFAULT_TIMEOUT, memory: int | None = None,
                   hints: Hints = CLI_HINTS) -> list:
    """The inputs (``runtime.Param``) of the program file or preset ``source``, its module's top
    level run contained as ``run_program`` runs it (``lattice()`` itself is not called)."""
    path = resolve_source(source)
    return Job(lambda: load_program_file(path).parameters(), str(path), timeout, memory, hints=hints).result()


def run_text(text: str, name: str, params: dict | None = None, timeout: float | None = DEFAULT_TIMEOUT,
             memory: int | None = None, hints: Hints = CLI_HINTS) -> tuple[Lattice, list]:
    """Program ``text`` (``name``: its file or text block, in errors) run contained with
    ``params``: (its lattice, its inputs as ``runtime.Param``). The module's own top level runs
    in the child too, so a loop there is stopped as well."""

    def build():
        prog = compile_program(text, name)
        return prog.run(**(params or {})), prog.parameters()

    lat, inputs = Job(build, name, timeout, memory, hints=hints).result()
    return _checked(lat, name), inputs

