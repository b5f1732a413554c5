"""Open CASCADE's file transfer run in a child process, so a crash on a corrupt file is one line, not a dead interpreter.

OCCT's STEP and IGES readers dereference what the file says without checking it: measured with
cadquery-ocp-novtk 8.0.1.1.0, a STEP whose entities reference a missing ``#id`` or lose a
parenthesis passes ``ReadFile`` and kills the process with SIGSEGV in ``TransferRoots``; an IGES
with a mangled parameter or directory section does so in ``ReadFile`` itself. No Python
``except`` can catch that, so the read runs in a forked child (POSIX ``os.fork``: copy-on-write,
a few milliseconds, nothing re-imported), which hands the transferred shape back serialised with
``BinTools`` (binary doubles: the geometry is bit-identical) plus a little JSON. A child killed by
a signal becomes a `SceneError` naming the file; a `SceneError` raised in the child is re-raised
in the parent. Where ``os.fork`` does not exist (Windows) the read runs in-process, as before.
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

#: Exit status of a child whose read raised a `SceneError` (its fields are in the JSON file) or another exception.
_USER_ERROR, _FAILED = 3, 4


def read_isolated(path: Path, what: str, read: Callable[[], tuple[object, dict]]) -> tuple[object, dict]:
    """``read()`` → (TopoDS_Shape or None, JSON-able info), run in a forked child when the platform has fork.

    ``what``: the file's kind for the message ("STEP file"). Raises `SceneError` when the child is killed
    (Open CASCADE crashed on the file) or its read raised one.
    """
    if not hasattr(os, "fork"):
        return read()
    from OCP.BinTools import BinTools
    from OCP.TopoDS import TopoDS_Shape

    folder = Path(tempfile.mkdtemp(prefix="rtreflect-occt-"))
    try:
        shape_file, info_file = folder / "shape.brep", folder / "info.json"
        # Text still buffered would be copied into the child and written twice once the child flushes (quiet_stdout).
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the child: read, write the answer, leave without running the parent's exit handlers
            status = _FAILED
            try:
                signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C ends the child at once; the parent handles it
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
            _, status = os.waitpid(pid, 0)
        except BaseException:  # interrupted: do not leave the child running or a zombie behind
            try:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
            except OSError:
                pass
            raise
        if os.WIFSIGNALED(status):
            name = signal.Signals(os.WTERMSIG(status)).name
            raise SceneError(path, "", f"Open CASCADE crashed reading it ({name}): the {what} is corrupt "
                                       "(broken references or sections), or uses entities it cannot read")
        info = json.loads(info_file.read_text()) if info_file.exists() else {}
        code = os.WEXITSTATUS(status)
        if code == _USER_ERROR:
            raise SceneError(path, info.get("field", ""), info.get("reason", "cannot be read"))
        if code != 0:
            raise SceneError(path, "", f"Open CASCADE failed reading it ({info.get('reason', f'exit status {code}')})")
        shape = None
        if not info.pop("null"):
            shape = TopoDS_Shape()
            if not BinTools.Read_s(shape, str(shape_file)):
                raise SceneError(path, "", "cannot read back the shape Open CASCADE transferred")
        return shape, info
    finally:
        shutil.rmtree(folder, ignore_errors=True)
