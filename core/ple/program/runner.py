"""Contained programs: run a lattice program in a child process (docs/reliability.md).

The child (``os.fork``: the core is already imported, so a run costs milliseconds) builds the
lattice under a memory limit (``RLIMIT_AS``) and sends it back; the parent waits at most
``timeout`` seconds. ``sys.exit``, ``os._exit``, any ``BaseException``, running out of memory
and crashes of the child become one PleError naming the program file and, where known, the
line. IR files and presets in JSON are plain data and load in-process.

What comes back is the Lattice object, pickled by the child and unpickled by the parent with
an allowlist (classes of this package, numpy arrays and scalars, plain containers), its
filter included: the IR (``ple-lattice/1``) would lose a program's metadata and its
canonical similarities are not bit-exact for composed similarities. Nothing outside the
allowlist can be constructed by the parent; the result is then checked as an IR file is
(``ple.model.budget.check_finite``).
"""

from __future__ import annotations

import faulthandler
import io
import math
import os
import pickle
import select
import signal
import sys
import time
import traceback

from ..errors import PleError
from ..model.budget import check_finite, human
from ..model.lattice import Lattice
from .runtime import ROOT_PACKAGE
from .sources import load_lattice, resolve_source

DEFAULT_TIMEOUT = 30.0
_ROOT = ROOT_PACKAGE  # "ple", or the vendored package name inside the Blender extension
_SAFE_BUILTINS = {"set", "frozenset", "complex", "slice", "range", "tuple", "list", "dict", "bytearray",
                  "getattr", "object"}
_SAFE_NUMPY = ("numpy", "numpy.core.multiarray", "numpy.core.numeric", "numpy._core.multiarray",
               "numpy._core.numeric", "numpy.dtypes", "numpy.random._pickle", "copyreg", "_codecs")


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


def _describe(exc: BaseException, program: str, memory: int | None) -> str:
    where = _where(exc, program)
    if isinstance(exc, SystemExit):
        return f"{where}: the program called sys.exit({exc.code!r}); a program must return a Lattice"
    if isinstance(exc, _ProgramExit):
        return f"{where}: the program called os._exit({exc.args[0]!r}); a program must return a Lattice"
    if isinstance(exc, MemoryError):
        limit = f" (limit {human(memory)})" if memory else ""
        return f"{where}: the program ran out of memory{limit}; raise it with --max-memory"
    if isinstance(exc, RecursionError):
        return f"{where}: the program recursed too deeply"
    return f"{where}: program raised {type(exc).__name__}: {exc}"


def _child(write_fd: int, source: str, params, memory: int | None) -> None:
    """In the forked child: build, send (status, payload), never return."""
    real_exit = os._exit
    status, payload = "error", "the program did not finish"
    try:
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # the parent reports Ctrl-C
        faulthandler.disable()  # a crash is reported once, by the parent
        if memory:
            import resource

            limit = _vm_size() + memory
            hard = resource.getrlimit(resource.RLIMIT_AS)[1]
            if hard != resource.RLIM_INFINITY:
                limit = min(limit, hard)
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))

        def program_exit(code=0):
            raise _ProgramExit(code)

        os._exit = program_exit
        lat = load_lattice(source, params)
        status, payload = "ok", lat
    except PleError as exc:
        payload = str(exc)
    except BaseException as exc:  # noqa: BLE001 - a program may raise anything; report it
        payload = _describe(exc, _program_name(source), memory)
    os._exit = real_exit
    try:
        data = pickle.dumps((status, payload), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as exc:  # noqa: BLE001 - e.g. a filter holding a lambda
        data = pickle.dumps(("error", f"{source}: the program's lattice cannot be returned to PLE "
                                      f"({type(exc).__name__}: {exc})"))
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(write_fd, view):]
    finally:
        real_exit(0)


def _program_name(source: str) -> str:
    try:
        return str(resolve_source(source))
    except PleError:
        return source


def _vm_size() -> int:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def run_program(source: str, params=None, timeout: float | None = DEFAULT_TIMEOUT,
                memory: int | None = None) -> Lattice:
    """Build the lattice of ``source`` (program, IR file or preset) contained in a child process:
    at most ``timeout`` seconds and ``memory`` bytes beyond what this process already maps."""
    path = resolve_source(source)
    if path.suffix == ".json" or not hasattr(os, "fork"):  # data only: nothing to contain (or no fork)
        return load_lattice(source, params)
    if timeout is not None and not (timeout > 0):  # NaN too
        raise PleError(f"--timeout {timeout}: expected a positive number of seconds (inf: no limit)")
    if timeout is not None and math.isinf(timeout):
        timeout = None
    name = str(path)
    read_fd, write_fd = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child (its coverage is not collected)
        os.close(read_fd)
        _child(write_fd, source, params, memory)
    os.close(write_fd)
    chunks, finished = [], False
    deadline = None if timeout is None else time.monotonic() + timeout
    try:
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([read_fd], [], [], wait)
            if not ready:
                break
            data = os.read(read_fd, 1 << 20)
            if not data:
                finished = True
                break
            chunks.append(data)
    finally:
        os.close(read_fd)
        if not finished:
            _kill(pid)
    if not finished:
        raise PleError(f"{name}: the program ran longer than {timeout:g} s; raise the limit with --timeout")
    _, status = os.waitpid(pid, 0)
    if not chunks:
        if os.WIFSIGNALED(status):
            sig = signal.Signals(os.WTERMSIG(status)).name
            why = " (out of memory?)" if sig == "SIGKILL" else ""
            raise PleError(f"{name}: the program crashed with {sig}{why}")
        raise PleError(f"{name}: the program ended the process (exit status {os.WEXITSTATUS(status)})")
    try:
        kind, payload = _SafeUnpickler(io.BytesIO(b"".join(chunks))).load()
    except Exception as exc:  # noqa: BLE001 - anything wrong with the child's answer
        raise PleError(f"{name}: the program's result cannot be read back ({exc})") from None
    if kind != "ok":
        raise PleError(str(payload))
    if not isinstance(payload, Lattice):
        raise PleError(f"{name}: lattice() must return a Lattice")
    payload.validate()
    check_finite(payload, name)
    return payload


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass
