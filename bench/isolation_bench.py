"""What reading a STEP or IGES file in a child process costs (exchange/isolation.py; issue 12, bad input).

    python bench/isolation_bench.py [--repeat 5] [FILES...]

For each file (default ``parts/plate.step`` and ``parts/filleted_block.igs``), in this one process: Open CASCADE's
read and transfer in-process (the reader's ``transfer``, no child), then through `read_isolated` with no other
thread running (a child forked from this process), then with another thread running (a child of the reading
server): the server's first read, which starts it, and the reads after it. Prints the best wall time of each
and the overheads per file against the in-process read, in milliseconds and as ratios.
Timings on a shared machine are approximate: compare ratios, not seconds.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from functools import partial
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rtreflect.exchange import iges, step  # noqa: E402
from rtreflect.exchange.isolation import _SERVER, read_isolated  # noqa: E402
from rtreflect.exchange.occt import import_ocp  # noqa: E402


def best(repeat: int, call) -> float:
    """Best wall time of ``repeat`` calls, in seconds."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*", type=Path,
                    default=[ROOT / "parts" / "plate.step", ROOT / "parts" / "filleted_block.igs"])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    for path in args.files:
        reader = step if path.suffix.lower() in (".step", ".stp") else iges
        import_ocp(path, "CAD files")
        what = f"{reader.__name__.rsplit('.', 1)[1].upper()} file"
        read = partial(reader.transfer, path)
        read()  # warm: OCP's modules loaded, the file in the page cache
        inprocess = best(args.repeat, read)
        assert threading.active_count() == 1
        forked = best(args.repeat, lambda: read_isolated(path, what, read))
        stop = threading.Event()
        thread = threading.Thread(target=stop.wait)
        thread.start()
        try:
            _SERVER.close()
            start = time.perf_counter()
            read_isolated(path, what, read)
            first = time.perf_counter() - start
            served = best(args.repeat, lambda: read_isolated(path, what, read))
        finally:
            stop.set()
            thread.join()
        print(f"{path.name}: in-process {inprocess * 1e3:.0f} ms; forked child {forked * 1e3:.0f} ms "
              f"(+{(forked - inprocess) * 1e3:.0f} ms, {forked / inprocess:.2f}x); other threads running: "
              f"server's child {served * 1e3:.0f} ms (+{(served - inprocess) * 1e3:.0f} ms, {served / inprocess:.2f}x), "
              f"the read that starts the server {first * 1e3:.0f} ms (+{(first - served) * 1e3:.0f} ms once)")


if __name__ == "__main__":
    main()
