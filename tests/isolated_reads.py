"""Stand-in reads for `rtreflect.exchange.isolation`'s tests (tests/test_cad_input.py).

A module of its own, so a reading child started afresh (the reading server's, where other threads run) can
import them by name, as it imports the STEP and IGES readers' transfer functions.
"""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

#: The lock a thread of the test holds while the read runs; the read takes it. A child forked while the
#: thread held it inherits it held, and no thread of the child will ever release it.
LOCK = threading.Lock()
#: Seconds `take_lock` waits for `LOCK` before it gives up (a forked child would otherwise hang for ever): far
#: above the microseconds a free lock takes, well below the test's timeout.
LOCK_WAIT = 20.0
#: Seconds `wait_for_release` waits for its release before it gives up: the test releases it at once, on a loaded
#: machine within seconds.
RELEASE_WAIT = 120.0
#: Seconds between its looks for the release file.
RELEASE_POLL = 0.01


def take_lock() -> tuple[None, dict]:
    """A read that takes `LOCK`, as Python code in the child takes its module locks (stdout's, logging's)."""
    if not LOCK.acquire(timeout=LOCK_WAIT):
        raise TimeoutError(f"the lock stayed held for {LOCK_WAIT:g} s")
    LOCK.release()
    return None, {"took": True}


def raise_signal(name: str) -> tuple[None, dict]:
    """A read that sends itself the signal ``name`` (its own process: the reading child's) and, when the
    signal neither ended nor interrupted it (ignored), says so."""
    signal.raise_signal(getattr(signal, name))
    return None, {"survived": name}


def wait_for_release(folder: str) -> tuple[None, dict]:
    """A read that runs until the test lets it end: it writes ``started`` in ``folder``, then waits for the file
    ``release`` there (another process: no Event reaches it), at most `RELEASE_WAIT` s."""
    Path(folder, "started").touch()
    deadline = time.monotonic() + RELEASE_WAIT
    while not Path(folder, "release").exists():
        if time.monotonic() > deadline:
            raise TimeoutError(f"not released within {RELEASE_WAIT:g} s")
        time.sleep(RELEASE_POLL)
    return None, {"released": True}
