"""Start-up benchmark (issue 14, goal 3): a whole `rtreflect render` process of a small scene, warm and cold.

Runs the command line in a subprocess as the ``rtreflect`` entry point does (``from rtreflect.cli
import main; main()``), best of N wall-clock seconds and the CPU seconds of that run:

* **warm**: numba's machine code already cached (``rtreflect/kernels/__pycache__``, the state after
  any earlier run);
* **cold**: the first run after an install, every kernel compiled: ``NUMBA_CACHE_DIR`` points at an
  empty folder (numba then caches there instead), so nothing cached is found;

then where a warm run's CPU time goes (a probe process timing each phase with ``getrusage``), the
floor that numba sets (``import numba`` plus the registry load of the first cached kernel, which
imports scipy.linalg for its BLAS check) and the import time per top-level package
(``python -X importtime``, self times summed). The ratios to a bare ``python -c pass`` make the
figures comparable across machines.

    python bench/startup_bench.py [--scene scenes/cylinder.toml --repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENTRY = "from rtreflect.cli import main; main()"

#: The probe: CPU seconds (user + system) at the end of each phase of a warm render, as JSON on stderr's last line.
PROBE = r"""
import resource, sys
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
marks = [("interpreter", cpu())]
import numpy
marks.append(("numpy", cpu()))
import numba
marks.append(("numba import", cpu()))
import rtreflect.cli as cli
marks.append(("other imports (click, OpenImageIO, rtreflect, ...)", cpu()))
from numba.core.registry import cpu_target
cpu_target.target_context.refresh()  # what the first cached kernel's load does
marks.append(("numba registry load (+ scipy.linalg)", cpu()))
from numba.core import caching
loads = []
plain_load = caching.Cache.load_overload
def timed_load(self, *args, **kwargs):  # each cached kernel's index + machine code, linked
    start = cpu()
    try:
        return plain_load(self, *args, **kwargs)
    finally:
        loads.append(cpu() - start)
caching.Cache.load_overload = timed_load
sys.argv = ["rtreflect", *sys.argv[1:]]
try:
    getattr(cli, "_run", cli.main)()  # the command without `main`'s exit, which would end the probe
except SystemExit:
    pass
marks.append(("render, files written", cpu()))
import json
print(json.dumps({"marks": marks, "loads": loads}), file=sys.stderr)
"""

#: numba's own floor: the interpreter, numpy, numba and its registry load, nothing of rtreflect.
FLOOR = ("import numpy, numba; from numba.core.registry import cpu_target; "
         "cpu_target.target_context.refresh(); import os; os._exit(0)")


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(args: list[str], env: dict[str, str] | None = None) -> tuple[float, float, subprocess.CompletedProcess]:
    """(wall seconds, CPU seconds, result) of one subprocess run."""
    cpu0, t0 = children_cpu(), time.perf_counter()
    result = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, env=env)
    return time.perf_counter() - t0, children_cpu() - cpu0, result


def best(args: list[str], repeat: int, env: dict[str, str] | None = None) -> tuple[float, float]:
    """Best wall time of ``repeat`` runs and the CPU time of that run."""
    runs = []
    for _ in range(repeat):
        wall, cpu, result = timed(args, env)
        if result.returncode != 0:
            sys.exit(f"{' '.join(args)} failed ({result.returncode}):\n{result.stderr}")
        runs.append((wall, cpu))
    return min(runs)


def import_breakdown(env: dict[str, str]) -> list[tuple[str, float]]:
    """Self import time per top-level package of ``import rtreflect.cli``, seconds, largest first."""
    out = subprocess.run([sys.executable, "-X", "importtime", "-c", "import rtreflect.cli"], capture_output=True,
                         text=True, cwd=ROOT, env=env, check=True).stderr
    total: dict[str, float] = defaultdict(float)
    for line in out.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s*(\S+)", line)
        if m:
            total[m[2].split(".")[0]] += int(m[1]) / 1e6
    return sorted(total.items(), key=lambda kv: -kv[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scenes/cylinder.toml")
    ap.add_argument("--size", default="64x36", help="WIDTHxHEIGHT of the render")
    ap.add_argument("--repeat", type=int, default=5, help="best of N runs")
    args = ap.parse_args()
    width, height = args.size.split("x")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        command = ["render", args.scene, "--width", width, "--height", height, "--samples", "1", "-o", tmp]
        render = [sys.executable, "-c", ENTRY, *command]
        bare_wall, bare_cpu = best([sys.executable, "-c", "pass"], args.repeat, env)
        timed(render, env)  # make sure the kernels are cached where a warm run finds them
        warm_wall, warm_cpu = best(render, args.repeat, env)
        floor_wall, floor_cpu = best([sys.executable, "-c", FLOOR], args.repeat, env)
        cache = Path(tmp) / "numba-cache"
        cold_wall, cold_cpu, result = timed(render, {**env, "NUMBA_CACHE_DIR": str(cache)})
        if result.returncode != 0:
            sys.exit(f"cold run failed:\n{result.stderr}")
        compiled = len(list(cache.rglob("*.nbi")))
        _, _, probe = timed([sys.executable, "-c", PROBE, *command], env)
    probed = json.loads(probe.stderr.strip().splitlines()[-1])
    marks, loads = probed["marks"], probed["loads"]

    print(f"`rtreflect render {args.scene} --width {width} --height {height} --samples 1`, whole process, "
          f"best of {args.repeat}:")
    print(f"  warm:  {warm_wall:.3f} s wall, {warm_cpu:.3f} s CPU   ({warm_wall / bare_wall:.1f}× `python -c pass`, "
          f"{bare_wall:.3f} s)")
    print(f"  cold:  {cold_wall:.3f} s wall, {cold_cpu:.3f} s CPU   (first run: {compiled} kernels compiled and cached)")
    print(f"  numba's floor (interpreter + numpy + numba + its registry load): {floor_wall:.3f} s wall, "
          f"{floor_cpu:.3f} s CPU = {floor_cpu / warm_cpu:.0%} of the warm run's CPU")
    print("warm run, CPU seconds per phase (probe process):")
    previous = 0.0
    for name, seconds in marks:
        print(f"  {name:<52} {seconds - previous:.3f}")
        previous = seconds
    print(f"  {'exit (handlers; teardown skipped)':<52} {max(warm_cpu - previous, 0.0):.3f}  (warm run's CPU − probe's)")
    if loads:
        print(f"  of the render: {len(loads)} cached kernels loaded, {sum(loads):.3f} s CPU "
              f"({1000 * sum(loads) / len(loads):.1f} ms each, {1000 * min(loads):.1f}–{1000 * max(loads):.1f})")
    print("import rtreflect.cli, self time per top-level package (-X importtime, wall):")
    for name, seconds in import_breakdown(env)[:12]:
        print(f"  {name:<24} {seconds:.3f}")


if __name__ == "__main__":
    main()
