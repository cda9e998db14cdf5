"""File output that never destroys what the user had (docs/reliability.md).

* Regular files are written to a temporary sibling, then renamed over the destination: on any
  error (or SIGINT/SIGTERM/SIGHUP) the destination is left as it was and the temporary removed.
* A symlink is followed: its target is replaced, the link stays.
* A destination that exists and is not a regular file is never replaced: a character device or
  FIFO (``/dev/null``, ``/dev/stdout``, a pipe) is written directly, once the whole output is
  ready; a folder, block device or socket is refused.
* Output folders carry a marker (``.ple-output.json``: kind, version, command); a command
  replaces a folder only when the marker says it wrote it, and refuses any other folder.
* Temporaries are named ``.NAME.ple-tmp-PID-…``; a run removes those of dead processes (left by
  a SIGKILL) from the folder it writes to.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import os
import queue
import shutil
import signal
import stat
import tempfile
import threading
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import PleError, echo

WRITE_BEHIND = 128 << 20  # bytes of a streamed file between write-behind steps (``WriteBehind``)
DIRECT_BLOCK = 4096  # alignment of O_DIRECT buffers, offsets and sizes (the largest logical block in use)
DIRECT_BUFFER = 32 << 20  # bytes per O_DIRECT write (``DirectWriter``)
DIRECT_BUFFERS = 3  # staged buffers: one filling, the others being written
_SYNC_WRITE, _SYNC_WAIT = 2, 1 | 2 | 4  # sync_file_range: start writeback; wait before, write, wait after


def _sync_file_range():
    try:
        fn = ctypes.CDLL(None, use_errno=True).sync_file_range
    except (OSError, AttributeError):  # not Linux
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_int64, ctypes.c_int64, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_SYNC_RANGE = _sync_file_range()


class WriteBehind:
    """Write-behind for a large file written front to back (a streamed STL): every ``window``
    bytes the kernel starts writing the last window back, waits for the window before it and
    drops that one's pages from the page cache. A file of many GB then holds about two windows
    of page cache, whose pages are recycled instead of taken fresh (on this VM the first touch
    of a page costs more than copying into it: 3.3 GB written plainly took 1.1–8.6 s, with
    write-behind 1.5–2.2 s), and one export does not push everything else out of the cache.
    Call ``wrote()`` after each write. A no-op where Linux's ``sync_file_range`` is missing or
    refused (pipes, some file systems)."""

    def __init__(self, fh, window: int | None = None):
        self.fh, self.window = fh, int(WRITE_BEHIND if window is None else window)
        self.start = fh.tell()
        self.prev: tuple[int, int] | None = None
        self.on = _SYNC_RANGE is not None and hasattr(os, "posix_fadvise")

    def wrote(self) -> None:
        if not self.on:
            return
        pos = self.fh.tell()
        if pos - self.start < self.window:
            return
        self.fh.flush()
        fd = self.fh.fileno()
        if _SYNC_RANGE(fd, self.start, pos - self.start, _SYNC_WRITE) != 0:
            self.on = False  # refused here: plain writes from now on
            return
        if self.prev is not None:
            _SYNC_RANGE(fd, self.prev[0], self.prev[1], _SYNC_WAIT)
            os.posix_fadvise(fd, self.prev[0], self.prev[1], os.POSIX_FADV_DONTNEED)
        self.prev = (self.start, pos - self.start)
        self.start = pos


class DirectWriter:
    """Appends bytes to a new regular file through O_DIRECT, bypassing the page cache: they are
    copied into one of a few reused, aligned buffers, and a thread of its own writes each full
    buffer while the next one fills (the copy into the page cache and its pages cost more CPU
    on this 2-core VM than encoding the records; a direct write is the device's DMA). The last
    partial block goes through a plain descriptor. Where the file system refuses O_DIRECT at
    open, the constructor raises OSError (use buffered writes); where it refuses a write, that
    write and the rest go through the plain descriptor (the same bytes at the same offsets).
    ``close()`` finishes the file and raises the first error; ``abort()`` stops without it."""

    def __init__(self, path, buffer: int = DIRECT_BUFFER, buffers: int = DIRECT_BUFFERS):
        if not hasattr(os, "O_DIRECT"):
            raise OSError(errno.EINVAL, "O_DIRECT is not available here")
        self.path = os.fspath(path)
        self.fd = os.open(self.path, os.O_WRONLY | os.O_DIRECT)
        self.plain = -1
        size = max(DIRECT_BLOCK, buffer // DIRECT_BLOCK * DIRECT_BLOCK)
        self.free: queue.Queue = queue.Queue()
        for _ in range(max(2, buffers)):
            raw = np.empty(size + DIRECT_BLOCK, np.uint8)
            skip = -raw.ctypes.data % DIRECT_BLOCK
            self.free.put(raw[skip:skip + size])
        self.todo: queue.Queue = queue.Queue()
        self.error: BaseException | None = None
        self.direct = True
        self.cur, self.fill, self.offset = self.free.get(), 0, 0
        self.thread = threading.Thread(target=self._run, name="ple-direct-writer", daemon=True)
        self.thread.start()

    def write(self, data) -> None:
        """Append ``data`` (any buffer of bytes)."""
        src = np.frombuffer(memoryview(data).cast("B"), np.uint8)
        at = 0
        while at < len(src):
            k = min(len(src) - at, len(self.cur) - self.fill)
            self.cur[self.fill:self.fill + k] = src[at:at + k]
            self.fill += k
            at += k
            if self.fill == len(self.cur):
                self._send(self.fill)

    def _send(self, n: int) -> None:
        if self.error is not None:
            raise self.error
        self.todo.put((self.cur, n, self.offset))
        self.offset += n
        self.cur, self.fill = self.free.get(), 0

    def _pwrite(self, view, offset: int) -> None:
        while len(view):
            fd = self.fd if self.direct else self._plain()
            try:
                done = os.pwrite(fd, view, offset)
            except OSError as e:
                if not self.direct or e.errno != errno.EINVAL:
                    raise
                self.direct = False  # refused here: the same bytes through the page cache
                continue
            view, offset = view[done:], offset + done

    def _plain(self) -> int:
        if self.plain < 0:
            self.plain = os.open(self.path, os.O_WRONLY)
        return self.plain

    def _run(self) -> None:
        while (item := self.todo.get()) is not None:
            buf, n, offset = item
            try:
                if self.error is None:
                    self._pwrite(memoryview(buf)[:n], offset)
            except BaseException as e:  # noqa: BLE001 - handed to the writing thread
                self.error = e
            self.free.put(buf)

    def close(self) -> int:
        """Write what is left, wait for the writes, close. Returns the file's size."""
        whole = self.fill // DIRECT_BLOCK * DIRECT_BLOCK
        tail = self.cur[whole:self.fill].copy()
        try:
            if whole:
                self._send(whole)
        finally:
            self._stop()
        try:
            if self.error is not None:
                raise self.error
            self.direct = False  # the writer thread has ended: a part block goes through the plain descriptor
            self._pwrite(memoryview(tail), self.offset)
        finally:
            self._close_fds()
        return self.offset + len(tail)

    def abort(self) -> None:
        """Stop the writer thread and close (after an error elsewhere: the file is left as it is)."""
        self.error = self.error or PleError("aborted")
        self._stop()
        self._close_fds()

    def _stop(self) -> None:
        if self.thread.is_alive():
            self.todo.put(None)
            self.thread.join()

    def _close_fds(self) -> None:
        for fd in (self.fd, self.plain):
            if fd >= 0:
                os.close(fd)
        self.fd = self.plain = -1


TMP_TAG = ".ple-tmp-"
MARKER = ".ple-output.json"
MARKER_VERSION = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised like Ctrl-C so that every ``finally`` removes its temporaries."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_terminated(signum, frame) -> None:
    raise Terminated(signum)


def install_signal_handlers() -> dict:
    """SIGTERM and SIGHUP unwind the stack as Ctrl-C does (main thread only). Returns the handlers
    they replace, for ``restore_signal_handlers``: only the console script ``ple`` installs them,
    never a library call."""
    old = {}
    for sig in (signal.SIGTERM, signal.SIGHUP):
        with contextlib.suppress(ValueError, OSError):  # not the main thread / not allowed
            old[sig] = signal.signal(sig, _raise_terminated)
    return old


def restore_signal_handlers(old: dict) -> None:
    """Put back the handlers ``install_signal_handlers`` replaced."""
    for sig, handler in old.items():
        with contextlib.suppress(ValueError, OSError, TypeError):
            signal.signal(sig, handler)


# ----- OS errors as user errors ------------------------------------------------------------------
USER_ERRNOS = {errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG, getattr(errno, "EDQUOT", -1)}


def is_user_oserror(exc: BaseException) -> bool:
    """A full disk, a read-only file system, a refused permission or a quota: the user's to fix."""
    return isinstance(exc, OSError) and exc.errno in USER_ERRNOS


def oserror_message(exc: OSError, path=None) -> str:
    """One line for an OS error while writing ``path`` (default: the error's own file name)."""
    where = path if path is not None else exc.filename
    what = exc.strerror or os.strerror(exc.errno or 0) or type(exc).__name__
    hint = {errno.ENOSPC: "; free some space or write elsewhere",
            getattr(errno, "EDQUOT", -1): "; the disk quota is exhausted, free some space or write elsewhere",
            errno.EROFS: "; write to a writable folder"}.get(exc.errno, "")
    return f"{where}: cannot write ({what}){hint}" if where is not None else f"cannot write ({what}){hint}"


# ----- finite arrays --------------------------------------------------------------------------------
def check_finite_array(arr, what: str) -> None:
    """Refuse to write an array holding NaN or infinity (PleError naming ``what``): a writer never
    writes garbage, it names the input that overflowed."""
    a = np.asarray(arr)
    if a.dtype.kind in "fc" and not np.isfinite(a).all():
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise PleError(f"{what} holds {bad:,} non-finite value(s) (NaN or infinity; an input overflows); "
                       "nothing written")


# ----- strict JSON ----------------------------------------------------------------------------------
def strict_json(obj, what: str = "the output", **kwargs) -> str:
    """``json.dumps(obj, allow_nan=False, **kwargs)``: NaN and infinities are not JSON, so an
    output holding one is refused (PleError naming ``what``), never written as ``Infinity``."""
    try:
        return json.dumps(obj, allow_nan=False, **kwargs)
    except ValueError:
        raise PleError(f"{what} holds a non-finite number (NaN or infinity); not writing it — "
                       "an input makes it overflow or degenerate") from None


# ----- outputs apart from inputs -------------------------------------------------------------------
def _local(text) -> str | None:
    """The local path of ``text`` (a path or ``file://`` URL), None for other URLs."""
    text = os.fspath(text)
    if text.startswith("file://"):
        return text[len("file://"):]
    return None if "://" in text else text


def _inside(path: str, folder: str) -> bool:
    a, b = os.path.realpath(path), os.path.realpath(folder)
    return a != b and os.path.commonpath([a, b]) == b


def check_apart(outputs: dict, inputs: dict) -> None:
    """Refuse outputs that would overwrite an input, before any work (docs/reliability.md §1).

    ``outputs`` and ``inputs`` map a flag (``--out``, ``--body``, …) to a path. An output is
    refused when it is the same file as an input (``os.path.samefile``: symlinks and hard links
    included), or when it is a folder that holds an input (folders are replaced or written into as
    a whole). Devices and FIFOs are written in place and never replaced, so they are not compared."""
    for oflag, out in outputs.items():
        out = _local(out) if out is not None else None
        if not out or not os.path.lexists(out):
            continue
        try:
            st = os.stat(out)
        except OSError:
            continue
        if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
            continue
        for iflag, src in inputs.items():
            src = _local(src) if src is not None else None
            if not src or not os.path.exists(src):
                continue
            with contextlib.suppress(OSError):
                if os.path.samefile(out, src):
                    raise PleError(f"{oflag} {out}: is the same file as the input {iflag} {src}; "
                                   "not overwriting an input — give another output")
            if stat.S_ISDIR(st.st_mode) and _inside(src, out):
                raise PleError(f"{oflag} {out}: the output folder holds the input {iflag} {src}; "
                               "not writing over an input — give another folder")


def plain_name(name, what: str) -> str:
    """``name`` if it is a plain file name (no folder part, not ``.``/``..``, no NUL), else a
    PleError: names read from a manifest stay inside their folder."""
    if (not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name
            or "\0" in name or os.path.isabs(name)):
        raise PleError(f"{what}: {echo(name)} is not a plain file name inside the folder; move the manifest away "
                       "to start afresh")
    return name


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_stale_temporaries(folder) -> list[Path]:
    """Remove ``.*.ple-tmp-PID-*`` files and folders in ``folder`` whose process is gone (a run
    killed by SIGKILL); returns what was removed."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not name.startswith(".") or TMP_TAG not in name:
            continue
        pid_text = name.rsplit(TMP_TAG, 1)[1].split("-", 1)[0]  # the last tag: the writer (a temp of a temp)
        if not pid_text.isdigit() or int(pid_text) == os.getpid() or _alive(int(pid_text)):
            continue
        with contextlib.suppress(OSError):
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def temp_prefix(name: str) -> str:
    return f".{name}{TMP_TAG}{os.getpid()}-"


def make_temp_dir(parent: Path, name: str) -> Path:
    """A fresh temporary folder beside an output (removed by the next run if we are killed), with a
    normal folder's permissions (not ``mkdtemp``'s 0700): it becomes the output folder. An OS
    error (a read-only or full disk) is a PleError naming the output, not the temporary."""
    try:
        path = Path(tempfile.mkdtemp(prefix=temp_prefix(name), dir=parent))
    except OSError as exc:
        raise PleError(oserror_message(exc, parent / name)) from None
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o777 & ~umask)
    return path


def _destination(path: Path) -> tuple[Path, str]:
    """(where to write, how): 'file' (atomic replace of a regular file or a new one) or 'direct'
    (a character device or FIFO, written in place); anything else is refused."""
    try:
        st = os.stat(path)  # follows symlinks
    except FileNotFoundError:
        if path.is_symlink():  # a dangling link: create its target
            return Path(os.path.realpath(path)), "file"
        return path, "file"
    except OSError as exc:
        raise PleError(f"{path}: cannot write ({exc.strerror})") from None
    if stat.S_ISREG(st.st_mode):
        return Path(os.path.realpath(path)), "file"
    if stat.S_ISCHR(st.st_mode) or stat.S_ISFIFO(st.st_mode):
        return path, "direct"
    what = ("a folder" if stat.S_ISDIR(st.st_mode) else "a block device" if stat.S_ISBLK(st.st_mode)
            else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
    raise PleError(f"{path}: is {what}; not writing over it (give a file name)")


def check_output_file(path) -> None:
    """Refuse, before any work, an output file that ``atomic_path`` would refuse (a folder, block
    device or socket; a missing folder; a folder on a read-only file system or not writable)."""
    path = Path(path)
    target, how = _destination(path)
    parent = target.parent if str(target.parent) else Path(".")
    if how == "file" and not parent.is_dir():
        raise PleError(f"{path}: output folder {parent} does not exist")
    if how == "file" and not os.access(parent, os.W_OK | os.X_OK):
        why = "Read-only file system" if os.statvfs(parent).f_flag & os.ST_RDONLY else "Permission denied"
        raise PleError(f"{path}: cannot write in {parent} ({why})")


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """Yield a temporary path for the output ``path``; on success its content goes to ``path``
    (renamed over a regular file, copied into a device or FIFO), on any error it is removed and
    ``path`` is left as it was."""
    path = Path(path)
    target, how = _destination(path)
    parent = target.parent if str(target.parent) else Path(".")
    if how == "direct":
        parent = Path(tempfile.gettempdir())
    elif not parent.is_dir():
        raise PleError(f"{path}: output folder {parent} does not exist")
    if how == "file":
        remove_stale_temporaries(parent)
    try:
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(target.name), suffix=target.suffix, dir=parent)
    except OSError as exc:
        raise PleError(f"{path}: cannot write in {parent} ({exc.strerror})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        if how == "file":
            umask = os.umask(0)
            os.umask(umask)
            mode = stat.S_IMODE(os.stat(target).st_mode) if target.exists() else 0o666 & ~umask
            os.chmod(tmp, mode)  # a normal file's permissions (or the replaced file's), not mkstemp's 0600
        yield tmp_path
        if how == "file":
            os.replace(tmp_path, target)
        else:
            with open(tmp_path, "rb") as src, open(path, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
    except OSError as exc:  # a full disk, a read-only file system, …: the user's, the old file intact
        if is_user_oserror(exc):
            raise PleError(oserror_message(exc, path)) from None
        raise
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


def atomic_write_text(path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def atomic_write_bytes(path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def save_npz(path, arrays: dict) -> None:
    """Write arrays to ``path`` (.npz, as ``np.savez``) atomically. The zip is closed before its
    file, also when interrupted (``np.savez`` on a handle leaves that to the garbage collector)."""
    for name, arr in arrays.items():
        check_finite_array(arr, f"{path}: array {name!r}")
    with atomic_path(path) as tmp, open(tmp, "wb") as fh, zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for name, arr in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(arr), allow_pickle=False)


# ----- output folders ---------------------------------------------------------------------------
def read_marker(folder) -> dict | None:
    """The ``.ple-output.json`` marker of a folder, or None."""
    try:
        data = json.loads((Path(folder) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def write_marker(folder, kind: str, command: str) -> None:
    doc = {"kind": kind, "version": MARKER_VERSION, "command": command}
    (Path(folder) / MARKER).write_text(json.dumps(doc) + "\n")


def check_output_dir(path, kind: str, flag: str = "--out") -> bool:
    """May ``kind`` write the folder ``path``? True when it exists with our marker (replace or
    update it), False when it does not exist or is empty; otherwise PleError (nothing deleted)."""
    path = Path(path)
    if not os.path.lexists(path):
        parent = path.parent if str(path.parent) else Path(".")
        if not parent.is_dir():
            raise PleError(f"{flag} {path}: folder {parent} does not exist")
        return False
    if not path.is_dir():
        raise PleError(f"{flag} {path}: exists and is not a folder; not overwriting")
    marker = read_marker(path)
    if marker is not None and marker.get("kind") == kind:
        return True
    try:
        empty = not any(path.iterdir())
    except OSError as exc:
        raise PleError(f"{flag} {path}: cannot read the folder ({exc.strerror})") from None
    if empty:
        return False
    found = f"it was written by {marker.get('command', '?')!r}" if marker else "it has no PLE output marker"
    raise PleError(f"{flag} {path}: folder exists and is not a {kind} output of PLE ({found}); "
                   "not touching it — give a new or empty folder")


@contextlib.contextmanager
def atomic_dir(out: Path, kind: str, command: str) -> Iterator[Path]:
    """Yield a temporary folder beside the output folder ``out`` (checked by ``check_output_dir``
    first); once the caller has filled it, it gets the marker of ``kind`` and replaces ``out``
    (``replace_dir``). On any error it is removed and ``out`` is left as it was: a folder appears
    complete or not at all."""
    out = Path(out)
    parent = out.parent if str(out.parent) else Path(".")
    remove_stale_temporaries(parent)
    tmp = make_temp_dir(parent, out.name)
    try:
        yield tmp
        write_marker(tmp, kind, command)
        replace_dir(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


def replace_dir(tmp: Path, out: Path) -> None:
    """Put the finished folder ``tmp`` at ``out``, whose old content (checked by
    ``check_output_dir``) is removed only after the new one is in place."""
    if not os.path.lexists(out):
        tmp.rename(out)
        return
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
        tmp.rename(out)
        return
    trash = make_temp_dir(out.parent if str(out.parent) else Path("."), out.name + ".old")
    out.rename(trash / "old")
    tmp.rename(out)
    shutil.rmtree(trash)
