"""Per-stage wall-clock accounting, shared by the render threads (seconds are summed over threads)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections import defaultdict
from typing import Iterator


class StageClock:
    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self._lock = threading.Lock()

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            elapsed = time.perf_counter() - start
            with self._lock:
                self.seconds[name] += elapsed


#: For callers that do not want timings.
NULL_CLOCK = StageClock()
