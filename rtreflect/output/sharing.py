"""An output folder shared by several runs: temporaries that name their writer, and a lock per output name.

**Temporaries.** Every file is written under a hidden temporary name beside its final one
(`imagefiles.atomic_path`) and renamed into place when complete. A run that dies without
unwinding (SIGKILL, the out-of-memory killer, a power cut) cannot remove them, so each
temporary names its writer: ``.NAME.rtreflect-HOST-PID.XXXXXXXX.ext``. `remove_dead_temporaries`
deletes those whose writer ran on this host and is no longer alive; a temporary written from
another host (a shared network folder) is never touched, since its process cannot be seen.

**A lock per output name.** A scene's outputs (``NAME.exr``, ``NAME.png``, ``NAME.contours.json``)
are renamed into place one after the other. Two runs finishing the same NAME at once (two
scenes with one ``[output] name``, in two processes) could interleave those renames and
leave ``NAME.exr`` from one and ``NAME.png`` from the other. `NameLock` is an advisory
lock (``flock(2)``) on ``.NAME.rtreflect-lock`` held while a set is renamed, so each set
lands whole: the last run to finish wins every file. The lock file is removed by its holder
while still locked; a waiter that then holds a removed file tries again (the classic
lock-file protocol), so no lock file outlives the renames.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
from pathlib import Path
from typing import Iterator

try:
    import fcntl
except ImportError:  # not on Windows: renames are then not serialised between runs
    fcntl = None

#: Marks rtreflect's temporaries and lock files among the user's hidden files.
TAG = "rtreflect"
LOCK_SUFFIX = f".{TAG}-lock"
#: mkstemp's random part: 8 characters of [a-z0-9_].
_TEMPORARY = re.compile(rf"^\.(?P<stem>.+)\.{TAG}-(?P<host>[^.]*)-(?P<pid>\d+)\.[a-z0-9_]{{8}}(?P<suffix>\.[^.]+)?$")


def _host() -> str:
    """This machine's name as it may appear in a file name (no dots or separators)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:64] or "host"


def temporary_prefix(final: Path) -> str:
    """The ``mkstemp`` prefix of a temporary for ``final``: hidden, and naming this host and process."""
    return f".{Path(final).stem}.{TAG}-{_host()}-{os.getpid()}."


def _alive(pid: int) -> bool:
    """True while process ``pid`` runs on this host (a zombie, dead but not yet reaped, counts as dead)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2] != "Z"
    except (OSError, ValueError, IndexError):
        return True  # no /proc: os.kill said it exists


def remove_dead_temporaries(folder: Path, pid: int | None = None) -> list[Path]:
    """Remove the temporaries in ``folder`` left by dead rtreflect processes of this host; the paths removed.

    With ``pid``, only that (dead) process's. Lock files no process holds are removed too.
    """
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    host = _host()
    for entry in entries:
        if not entry.name.startswith(".") or not entry.is_file(follow_symlinks=False):
            continue
        match = _TEMPORARY.match(entry.name)
        if (match and match["host"] == host and int(match["pid"]) != os.getpid() and pid in (None, int(match["pid"]))
                and not _alive(int(match["pid"]))):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
        elif entry.name.endswith(LOCK_SUFFIX):
            with _locked(Path(entry.path), wait=False):
                pass  # acquired: nobody held it; released and removed
    return removed


def _lock_path(folder: Path, name: str) -> Path:
    return Path(folder) / f".{name}{LOCK_SUFFIX}"


@contextlib.contextmanager
def _locked(path: Path, wait: bool = True) -> Iterator[bool]:
    """Hold an exclusive flock on ``path`` (created if missing) for the block; removed on release.

    Yields False without waiting when ``wait`` is False and another process holds it.
    """
    if fcntl is None:
        yield True
        return
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            yield False
            return
        except BaseException:
            os.close(fd)
            raise
        try:
            current = os.stat(path)
        except FileNotFoundError:
            current = None
        held = os.fstat(fd)
        if current is not None and (current.st_dev, current.st_ino) == (held.st_dev, held.st_ino):
            break
        os.close(fd)  # the holder before us removed this file: lock the new one
    try:
        yield True
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)  # while still locked: a waiter on this file will see it gone and retry
        os.close(fd)


class NameLock:
    """The lock on one output name, in two steps for an ExitStack: `acquire` as the renames start, `release`
    after the last (the lock file removed)."""

    def __init__(self, folder: Path, name: str):
        self.path = _lock_path(folder, name)
        self._held: contextlib.ExitStack | None = None

    def acquire(self) -> None:
        if self._held is None:
            stack = contextlib.ExitStack()
            stack.enter_context(_locked(self.path))
            self._held = stack

    def release(self) -> None:
        held, self._held = self._held, None
        if held is not None:
            held.close()

