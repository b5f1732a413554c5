"""Open CASCADE's file transfer run in a child process, so a crash on a corrupt file is one line, not a dead interpreter.

OCCT's STEP and IGES readers dereference what the file says without checking it: measured with
cadquery-ocp-novtk 8.0.1.1.0, a STEP whose entities reference a missing ``#id`` or lose a
parenthesis passes ``ReadFile`` and kills the process with SIGSEGV in ``TransferRoots``; an IGES
with a mangled parameter or directory section does so in ``ReadFile`` itself. No Python
``except`` can catch that, so the read runs in a child process, which hands the transferred shape back
serialised with ``BinTools`` (binary doubles: the geometry is bit-identical) plus a little JSON. A child
killed by a crash signal (SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL) becomes a `SceneError` naming the file; a
stop signal (Ctrl-C, SIGTERM, SIGHUP) that ended the child is the parent's `Interrupted`; any other death
(SIGKILL: the out-of-memory killer, say) is reported as such, not as a corrupt file. A `SceneError`
raised in the child is re-raised in the parent. A stop signal the process ignores (nohup) stays ignored in
the child.

Which process forks the child. A process running no other Python thread forks it itself (POSIX ``os.fork``:
copy-on-write, a few milliseconds, nothing re-imported); the stop signals are blocked across the fork, so
none can land in the child before its own handlers are set, nor in the parent before it waits. But a forked
child has only the thread that forked it: a lock another thread held at that moment (stdout's, a module's)
stays held in the child for ever, and a read that takes it hangs. So where other threads run (tqdm's monitor
after the first progress bar, Dask's worker threads), the child is forked by this process's *reading
server* (`serve`): a Python process of one thread, started on the first such read (``subprocess``:
fork-and-exec, safe with threads) with Open CASCADE and the readers imported once, and ending when this
process closes its pipe. It gets the read by name (``read`` must pickle: `step.transfer` with the path),
with this process's ``sys.path``, working directory and ignored stop signals, and answers the child's PID,
then its wait status; reads through it run one at a time. Its own stop signals stay blocked: a Ctrl-C
ends its child, which the parent reports, not the server. Measured (docs/cad-reading.md, "Bad CAD input and the reading child process";
bench/isolation_bench.py): ~2 s of CPU to start the server once, then a read costs what a fork costs. (multiprocessing's forkserver would fork from a
clean process too, but a Dask worker is a daemonic process, which may not start one.)

Only Python threads count (`threading.active_count`): native thread pools (OpenBLAS starts one when numpy
is imported, Embree's TBB workers) run no Python and take no lock the reader needs between their tasks.
Where ``os.fork`` does not exist (Windows), or no child can be started (no memory or processes left), the
read runs in-process.
"""

from __future__ import annotations

import atexit
import ctypes
import faulthandler
import importlib
import json
import os
import pickle
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
from functools import partial
from pathlib import Path
from typing import Callable, NoReturn

from ..errors import SceneError
from ..interrupts import STOP_SIGNALS, Interrupted

#: Exit status of a child whose read raised a `SceneError` (its fields are in the JSON file) or another exception.
_USER_ERROR, _FAILED = 3, 4
#: Signals by which Open CASCADE's own faults end the child (a corrupt file); any other death is not the file's.
_CRASHES = frozenset(getattr(signal, name) for name in ("SIGSEGV", "SIGBUS", "SIGABRT", "SIGFPE", "SIGILL")
                     if hasattr(signal, name))
#: What the reading server imports before its first fork, so its children start with it: the readers and the
#: Open CASCADE modules their `transfer` functions import (~2 s of CPU once, instead of in every child).
_PRELOAD = ("OCP.STEPControl", "OCP.IGESControl", "OCP.IFSelect", "OCP.BinTools", "OCP.TopoDS", "OCP.collections",
            "rtreflect.exchange.step", "rtreflect.exchange.iges")
#: One number of the server's pipes: a request's length, a child's PID (−1: it could not fork), a wait status.
_NUMBER = struct.Struct("!i")
#: Seconds the server may take to end after its pipe closes when this process exits (it is waiting for a new
#: request then), and a daemon thread's read still running may take to end before (else it is left to finish).
_SERVER_EXIT_WAIT = 5.0
#: How the reading server starts: this checkout's package first on the path (argv[1]), whatever the environment says.
_SERVE = "import sys; sys.path.insert(0, sys.argv[1]); from rtreflect.exchange.isolation import serve; serve()"


def read_isolated(path: Path, what: str, read: Callable[[], tuple[object, dict]]) -> tuple[object, dict]:
    """``read()`` → (TopoDS_Shape or None, JSON-able info), run in a child process when the platform has fork.

    ``what``: the file's kind for the message ("STEP file"). ``read`` must pickle (a module's function, or a
    `functools.partial` of one) where other threads run. Raises `SceneError` when the child crashed or was
    killed, or its read raised one; `Interrupted` when a stop signal ended it (module doc).
    """
    if not hasattr(os, "fork"):
        return read()
    from OCP.BinTools import BinTools
    from OCP.TopoDS import TopoDS_Shape

    folder = Path(tempfile.mkdtemp(prefix="rtreflect-occt-"))
    try:
        ignored = frozenset(signum for signum in STOP_SIGNALS if signal.getsignal(signum) == signal.SIG_IGN)
        try:
            if threading.active_count() == 1:
                status = _forked(read, folder, ignored)
            else:
                status = _SERVER.run(read, folder, ignored)
        except _ServerLost:
            raise SceneError(path, "", "reading it was killed (its reading server ended)") from None
        if status is None:  # no memory or processes for a child: read in-process
            return read()
        if os.WIFSIGNALED(status):
            signum = os.WTERMSIG(status)
            if signum in STOP_SIGNALS:
                raise Interrupted(signum)
            try:
                name = signal.Signals(signum).name
            except ValueError:  # a number the enum does not know
                name = f"signal {signum}"
            if signum in _CRASHES:
                raise SceneError(path, "", f"Open CASCADE crashed reading it ({name}): the {what} is corrupt "
                                           "(broken references or sections), or uses entities it cannot read")
            raise SceneError(path, "", f"reading it was killed ({name}{': out of memory?' if name == 'SIGKILL' else ''})")
        info_file = folder / "info.json"
        info = json.loads(info_file.read_text()) if info_file.exists() else {}
        code = os.WEXITSTATUS(status)
        if code == _USER_ERROR:
            raise SceneError(path, info.get("field", ""), info.get("reason", "cannot be read"))
        if code != 0 or "null" not in info:
            raise SceneError(path, "", f"Open CASCADE failed reading it ({info.get('reason', f'exit status {code}')})")
        shape = None
        if not info.pop("null"):
            shape = TopoDS_Shape()
            if not BinTools.Read_s(shape, str(folder / "shape.brep")):
                raise SceneError(path, "", "cannot read back the shape Open CASCADE transferred")
        return shape, info
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _forked(read: Callable, folder: Path, ignored: frozenset[int]) -> int | None:
    """Wait status of a child forked from this process (of one thread) to run `_child`; None where fork failed."""
    # Text still buffered would be copied into the child and written twice once the child flushes (quiet_stdout).
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        pid = os.fork()
    except OSError:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return None
    if pid == 0:
        _child(read, folder, ignored, blocked)
    try:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return os.waitpid(pid, 0)[1]
    except BaseException:  # interrupted: do not leave the child running or a zombie behind
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except OSError:
            pass
        raise


def _child(read: Callable, folder: Path, ignored: frozenset[int], mask: set) -> NoReturn:
    """The child: ``read()``, the answer written into ``folder``, exit without running the parent's exit handlers.

    ``mask``: the signal mask to restore once the stop signals' handlers are set (they were blocked across the fork).
    """
    status = _FAILED
    info_file = folder / "info.json"
    try:
        # A stop signal ends the child at once (the parent reports it), unless the process was started
        # with it ignored (nohup): then it stays ignored here too.
        for signum in STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN if signum in ignored else signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        # A crash is reported by the parent in one line: no fault handler's traceback, no OCCT text on stderr.
        faulthandler.disable()
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        shape, info = read()
        info = dict(info, null=shape is None or shape.IsNull())
        if not info["null"]:
            from OCP.BinTools import BinTools

            if not BinTools.Write_s(shape, str(folder / "shape.brep")):
                raise RuntimeError("cannot write the transferred shape")
        info_file.write_text(json.dumps(info))
        status = 0
    except SceneError as exc:
        info_file.write_text(json.dumps({"field": exc.field, "reason": exc.reason}))
        status = _USER_ERROR
    except BaseException as exc:  # reported by the parent as one line
        info_file.write_text(json.dumps({"reason": f"{type(exc).__name__}: {exc}"}))
    finally:
        os._exit(status)


class _ServerLost(Exception):
    """The reading server's pipe closed in the middle of a read (the server was killed)."""


def _exactly(fd: int, size: int) -> bytes:
    """``size`` bytes from the pipe ``fd``; `_ServerLost` where it ends first."""
    data = b""
    while len(data) < size:
        chunk = os.read(fd, size - len(data))
        if not chunk:
            raise _ServerLost
        data += chunk
    return data


def _receive(fd: int) -> int:
    """One `_NUMBER` from the pipe ``fd``."""
    return _NUMBER.unpack(_exactly(fd, _NUMBER.size))[0]


class _Server:
    """The client end of this process's reading server (module doc): started on first use, one read at a time."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._process: subprocess.Popen | None = None
        self._owner = 0  # PID of the process that started it (a forked child must not share its pipes)

    def run(self, read: Callable, folder: Path, ignored: frozenset[int]) -> int | None:
        """Wait status of the server's child running ``read`` (`_child`); None where no child could be started."""
        request = pickle.dumps((str(folder), sorted(ignored), list(sys.path), os.getcwd(), pickle.dumps(read)))
        with self._lock:
            try:
                process = self._started()
            except OSError:  # no memory or processes for the server
                return None
            pid = 0
            try:
                # The child's PID comes back within milliseconds: until then no stop signal may unwind this thread,
                # which could not kill the child it did not know yet.
                blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
                try:
                    process.stdin.write(_NUMBER.pack(len(request)) + request)
                    process.stdin.flush()
                    pid = _receive(process.stdout.fileno())
                finally:
                    signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
                return None if pid < 0 else _receive(process.stdout.fileno())
            except BaseException as exc:  # interrupted or lost: end the child and the server (a new one starts next time)
                if pid > 0:
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except OSError:
                        pass
                self._end(wait=0.0)
                if isinstance(exc, OSError):  # the pipe broke (BrokenPipeError): the server is gone
                    raise _ServerLost from exc
                raise

    def _started(self) -> subprocess.Popen:
        if self._process is not None and (self._owner != os.getpid() or self._process.poll() is not None):
            self._process = None  # ended, or a forked parent's (its pipes are the parent's to use)
        if self._process is None:
            root = str(Path(__file__).resolve().parents[2])
            self._process = subprocess.Popen([sys.executable, "-c", _SERVE, root], stdin=subprocess.PIPE,
                                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
            if not self._owner:
                atexit.register(self.close)
            self._owner = os.getpid()
        return self._process

    def close(self, wait: float = _SERVER_EXIT_WAIT) -> bool:
        """End the server once no read runs (`_end`); False where a read in another thread still ran after ``wait``
        seconds: the server is left to it (ending it would kill the read), and ends once this process's pipe closes
        (at exit at the latest), after the read."""
        if self._owner != os.getpid():  # none started by this process (a forked one's lock may stay held for ever)
            return True
        if not self._lock.acquire(timeout=wait):
            return False
        try:
            self._end(wait)
        finally:
            self._lock.release()
        return True

    def _end(self, wait: float) -> None:
        """End the server, the lock held: its pipe closed (it ends by itself), killed if it has not after ``wait``
        seconds."""
        process, self._process = self._process, None
        if process is None or self._owner != os.getpid():
            return
        for pipe in (process.stdin, process.stdout):
            try:
                pipe.close()
            except OSError:
                pass
        try:
            process.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


_SERVER = _Server()


def serve() -> None:
    """The reading server's loop (module doc), in its own process: per request a forked child runs `_child`; the
    answer is the child's PID (−1 where fork failed), then its wait status. Ends when the client's pipe closes."""
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)  # for good: ours end the child, not the server
    requests, replies = os.dup(0), os.dup(1)
    with open(os.devnull, "r+b") as null:  # the children's stdin and stdout (OCCT prints with printf): not the pipes
        os.dup2(null.fileno(), 0)
        os.dup2(null.fileno(), 1)
    for name in _PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:  # without OCP (or a reader) the children import what they need, or fail as in-process
            pass
    server = os.getpid()
    while True:
        try:
            folder, ignored, path, cwd, read = pickle.loads(_exactly(requests, _receive(requests)))
        except _ServerLost:  # the client closed its end: it has exited or no longer needs us
            return
        try:
            pid = os.fork()
        except OSError:
            pid = -1
        if pid == 0:
            _die_with(server)
            os.close(requests)
            os.close(replies)
            _child(partial(_unpickled, read, path, cwd), Path(folder), frozenset(ignored), mask)
        os.write(replies, _NUMBER.pack(pid))
        if pid > 0:
            os.write(replies, _NUMBER.pack(os.waitpid(pid, 0)[1]))


#: Linux prctl option: the signal a process gets when its parent ends.
_PR_SET_PDEATHSIG = 1


def _die_with(server: int) -> None:
    """In the server's child: SIGKILL when the server ends (Linux ``prctl(PR_SET_PDEATHSIG)``). A client stopped
    before the child's PID came back kills the server, which cannot pass the stop on: the reader must not go on
    alone. Where prctl is missing the child runs to its end, as before."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != server:  # the server ended before prctl took effect
        os.kill(os.getpid(), signal.SIGKILL)


def _unpickled(read: bytes, path: list[str], cwd: str) -> tuple[object, dict]:
    """In the server's child: the client's read run where the client would run it (its module path, its folder)."""
    sys.path[:] = path
    os.chdir(cwd)
    return pickle.loads(read)()
