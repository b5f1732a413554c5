"""`rtreflect diff` benchmark (issue 11): wall time and peak memory on two large float EXRs, as ratios to idiff.

    python bench/diff_bench.py [--size 4096 --repeat 2]

Writes two SIZE×SIZE RGBA float32 EXRs (random values; B differs from A in one value in
a thousand) to a temporary folder and runs ``rtreflect diff A B`` and, when OpenImageIO's
``idiff`` is on the PATH, ``idiff A B``, each under ``/usr/bin/time -v``, alternating. It
prints the best wall time and the peak resident memory of each, and rtreflect's as a
ratio to idiff's (absolute figures only when idiff is missing). A shared machine makes
seconds approximate: compare the ratios.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

RTREFLECT = Path(sys.executable).parent / "rtreflect"
#: Rows generated and written at a time: the benchmark's own memory stays small too.
BLOCK_ROWS = 256


def write_exr(path: Path, size: int, seed: int, changed: float = 0.0) -> None:
    """A size×size RGBA float EXR of uniform noise, written in blocks of rows; ``changed`` of its values offset."""
    spec = oiio.ImageSpec(size, size, 4, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A")
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    for row in range(0, size, BLOCK_ROWS):
        rows = min(BLOCK_ROWS, size - row)
        block = np.random.default_rng(seed + row).uniform(0, 1, (rows, size, 4)).astype(np.float32)
        if changed:
            mask = np.random.default_rng(seed + row + 1).uniform(size=block.shape) < changed
            block[mask] += 0.5
        assert out.write_scanlines(row, row + rows, 0, block)
    assert out.close()


def measure(command: list[str], verdicts: tuple[int, ...]) -> tuple[float, int]:
    """Wall seconds and peak RSS in KiB of one run; ``verdicts``: the exit statuses of a finished comparison."""
    start = time.perf_counter()
    run = subprocess.run(["/usr/bin/time", "-v", *command], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if run.returncode not in verdicts:
        raise SystemExit(f"{command[0]} failed ({run.returncode}): {run.stderr.strip().splitlines()[-1:]}")
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr)[1])
    return seconds, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    idiff = shutil.which("idiff")
    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "a.exr", Path(tmp) / "b.exr"
        write_exr(a, args.size, seed=1)
        write_exr(b, args.size, seed=1, changed=1e-3)
        # rtreflect: 0 match, 1 mismatch; idiff: 0 match, 1 warning, 2 failure.
        tools = {"rtreflect diff": ([str(RTREFLECT), "diff", str(a), str(b)], (0, 1))}
        if idiff:
            tools["idiff"] = ([idiff, str(a), str(b)], (0, 1, 2))
        results: dict[str, list[tuple[float, int]]] = {name: [] for name in tools}
        for _ in range(args.repeat):  # alternate, so a burst of load from elsewhere hits both alike
            for name, (command, verdicts) in tools.items():
                results[name].append(measure(command, verdicts))
    best = {name: (min(s for s, _ in runs), max(p for _, p in runs)) for name, runs in results.items()}
    for name, (seconds, peak) in best.items():
        print(f"{name}: best {seconds:.2f} s, peak RSS {peak / 1024:.0f} MiB "
              f"({args.size}×{args.size} RGBA float32, best of {args.repeat})")
    if idiff:
        (s_r, p_r), (s_i, p_i) = best["rtreflect diff"], best["idiff"]
        print(f"rtreflect diff / idiff: time {s_r / s_i:.2f}×, peak memory {p_r / p_i:.2f}×")
    else:
        print("idiff not found: absolute figures only")


if __name__ == "__main__":
    main()
