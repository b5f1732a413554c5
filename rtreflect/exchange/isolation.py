"""Open CASCADE's file transfer run in a child process, so a crash on a corrupt file is one line, not a dead interpreter.

OCCT's STEP and IGES readers dereference what the file says without checking it: measured with
cadquery-ocp-novtk 8.0.1.1.0, a STEP whose entities reference a missing ``#id`` or lose a
parenthesis passes ``ReadFile`` and kills the process with SIGSEGV in ``TransferRoots``; an IGES
with a mangled parameter or directory section does so in ``ReadFile`` itself. No Python
``except`` can catch that, so the read runs in a forked child (POSIX ``os.fork``: copy-on-write,
a few milliseconds, nothing re-imported), which hands the transferred shape back serialised with
``BinTools`` (binary doubles: the geometry is bit-identical) plus a little JSON. A child killed by
a crash signal (SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL) becomes a `SceneError` naming the file; a
stop signal (Ctrl-C, SIGTERM, SIGHUP) that ended the child is the parent's `Interrupted`; any other death
(SIGKILL: the out-of-memory killer, say) is reported as such, not as a corrupt file. A `SceneError`
raised in the child is re-raised in the parent. The stop signals are blocked across the fork, so none
can land in the child before its own handlers are set, nor in the parent before it waits.

Where ``os.fork`` does not exist (Windows) or fails, the read runs in-process, as before. (A forked
child has only the thread that forked it: a lock another Python thread held at that moment would stay
held in the child. The child takes none but its own streams' before it reads, and those are flushed
just before the fork; reading in-process instead where other threads run would let a corrupt file
kill the whole process, a Dask worker or a test run, which is what this module exists to prevent.)
"""

from __future__ import annotations

import faulthandler
import json
import os
import shutil
import signal
import sys
import tempfile
from pathlib import Path
from typing import Callable

from ..errors import SceneError
from ..interrupts import STOP_SIGNALS, Interrupted

#: Exit status of a child whose read raised a `SceneError` (its fields are in the JSON file) or another exception.
_USER_ERROR, _FAILED = 3, 4
#: Signals by which Open CASCADE's own faults end the child (a corrupt file); any other death is not the file's.
_CRASHES = frozenset(getattr(signal, name) for name in ("SIGSEGV", "SIGBUS", "SIGABRT", "SIGFPE", "SIGILL")
                     if hasattr(signal, name))


def read_isolated(path: Path, what: str, read: Callable[[], tuple[object, dict]]) -> tuple[object, dict]:
    """``read()`` → (TopoDS_Shape or None, JSON-able info), run in a forked child when the platform has fork.

    ``what``: the file's kind for the message ("STEP file"). Raises `SceneError` when the child crashed or was
    killed, or its read raised one; `Interrupted` when a stop signal ended it (module doc).
    """
    if not hasattr(os, "fork"):
        return read()
    from OCP.BinTools import BinTools
    from OCP.TopoDS import TopoDS_Shape

    folder = Path(tempfile.mkdtemp(prefix="rtreflect-occt-"))
    try:
        shape_file, info_file = folder / "shape.brep", folder / "info.json"
        # Text still buffered would be copied into the child and written twice once the child flushes (quiet_stdout).
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
        try:
            pid = os.fork()
        except OSError:  # no memory or processes for a child: read in-process
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            return read()
        if pid == 0:  # the child: read, write the answer, leave without running the parent's exit handlers
            status = _FAILED
            try:
                # A stop signal ends the child at once (the parent reports it), unless the process was started
                # with it ignored (nohup): then it stays ignored here too.
                for signum in STOP_SIGNALS:
                    if signal.getsignal(signum) != signal.SIG_IGN:
                        signal.signal(signum, signal.SIG_DFL)
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
                # A crash is reported by the parent in one line: no fault handler's traceback, no OCCT text on stderr.
                faulthandler.disable()
                with open(os.devnull, "wb") as null:
                    os.dup2(null.fileno(), 2)
                shape, info = read()
                info = dict(info, null=shape is None or shape.IsNull())
                if not info["null"] and not BinTools.Write_s(shape, str(shape_file)):
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
        try:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            _, status = os.waitpid(pid, 0)
        except BaseException:  # interrupted: do not leave the child running or a zombie behind
            try:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
            except OSError:
                pass
            raise
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
        info = json.loads(info_file.read_text()) if info_file.exists() else {}
        code = os.WEXITSTATUS(status)
        if code == _USER_ERROR:
            raise SceneError(path, info.get("field", ""), info.get("reason", "cannot be read"))
        if code != 0 or "null" not in info:
            raise SceneError(path, "", f"Open CASCADE failed reading it ({info.get('reason', f'exit status {code}')})")
        shape = None
        if not info.pop("null"):
            shape = TopoDS_Shape()
            if not BinTools.Read_s(shape, str(shape_file)):
                raise SceneError(path, "", "cannot read back the shape Open CASCADE transferred")
        return shape, info
    finally:
        shutil.rmtree(folder, ignore_errors=True)
