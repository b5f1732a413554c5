"""Stop signals (Ctrl-C, `kill`, a closed terminal) as an exception, so cleanup runs.

Python turns SIGINT into KeyboardInterrupt but leaves SIGTERM and SIGHUP to their
default action, which ends the process on the spot: temporary image files
(`imagefiles.atomic_path`) would stay behind. Raising `Interrupted` instead unwinds
the stack through every ``finally``/``except`` that removes them, and the command
line then exits with the conventional status 128 + signal number.
"""

from __future__ import annotations

import contextlib
import signal
from typing import Iterator

#: The signals turned into `Interrupted` (SIGHUP does not exist on Windows).
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Interrupted(BaseException):
    """A stop signal arrived. A BaseException, like KeyboardInterrupt, so ``except Exception`` does not swallow it."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def interruption(exc: BaseException) -> Interrupted | None:
    """The `Interrupted` ``exc`` is, or that it was raised while handling (its ``__context__`` chain), else None.

    Raised from the signal handler, `Interrupted` can land inside a threading primitive at a point where it leaves
    it broken: in `threading.Condition.wait` between releasing its lock and taking it back, the ``with`` around it
    then fails to release a lock it does not hold and a RuntimeError replaces the interruption (`rtreflect render`
    killed while waiting for a tile: exit 1 instead of 143, once in four CI runs). Its context is still the signal.
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Interrupted):
            return exc
        seen.add(id(exc))
        exc = exc.__context__
    return None


def _raise_interrupted(signum: int, frame: object) -> None:
    raise Interrupted(signum)


@contextlib.contextmanager
def signals_as_exceptions() -> Iterator[None]:
    """Within the block, a stop signal raises `Interrupted` in the main thread; old handlers return afterwards.

    A signal that was ignored when the process started (``nohup``, background jobs
    of a non-interactive shell) stays ignored, as the caller asked.
    """
    previous = {}
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) == signal.SIG_IGN:
            continue
        previous[signum] = signal.signal(signum, _raise_interrupted)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
