"""Start-up benchmark (issue 14, goal 3): a whole `rtreflect render` process of a small scene, warm and cold.

Runs the command line in a subprocess as the ``rtreflect`` entry point does (``from rtreflect.cli
import main; main()``), best of N wall-clock seconds and the CPU seconds of that run:

* **warm**: the kernels compiled ahead of time (``rtreflect/kernels/_aot``, built by ``pip install``
  or ``python -m rtreflect.kernels.build``): no numba in the process; where that module is missing or
  stale, numba's JIT with its machine code cached (the state after any earlier run), which says so;
* **cold**, the first run after an install: the AOT build (``--build``: compiled into a temporary
  folder, timed; otherwise not measured) plus a first render; and for reference the JIT's cold start,
  ``RTREFLECT_KERNELS=jit`` with ``NUMBA_CACHE_DIR`` at an empty folder, so every kernel the render
  needs is compiled;

then where a warm run's CPU time goes (a probe process timing each phase with ``getrusage``), the
floors (the interpreter, numpy and the AOT module; numba's, ``import numba`` plus the registry load
of the first cached kernel, which imports scipy.linalg for its BLAS check) and the import time per
top-level package (``python -X importtime``, self times summed). The ratios to a bare
``python -c pass`` make the figures comparable across machines.

    python bench/startup_bench.py [--scene scenes/cylinder.toml --repeat 5 --build]
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
from rtreflect.kernels import compiled
aot = compiled.aot_module()
marks.append(("kernels: AOT module + sources hash" if aot is not None else "kernels: (no AOT module: JIT)", cpu()))
if aot is None:
    import numba
    marks.append(("numba import", cpu()))
import rtreflect.cli as cli
marks.append(("other imports (click, OpenImageIO, rtreflect, ...)", cpu()))
if aot is None:
    from numba.core.registry import cpu_target
    cpu_target.target_context.refresh()  # what the first cached kernel's load does
    marks.append(("numba registry load (+ scipy.linalg)", cpu()))
sys.argv = ["rtreflect", *sys.argv[1:]]
try:
    getattr(cli, "_run", cli.main)()  # the command without `main`'s exit, which would end the probe
except SystemExit:
    pass
marks.append(("render, files written", cpu()))
import json
print(json.dumps({"marks": marks, "numba": "numba" in sys.modules}), file=sys.stderr)
"""

#: numba's own floor: the interpreter, numpy, numba and its registry load, nothing of rtreflect.
FLOOR = ("import numpy, numba; from numba.core.registry import cpu_target; "
         "cpu_target.target_context.refresh(); import os; os._exit(0)")
#: The floor with the AOT kernels: the interpreter, numpy and the AOT module with its freshness check.
AOT_FLOOR = "import numpy; from rtreflect.kernels import compiled; compiled.aot_module(); import os; os._exit(0)"
#: Whether this checkout's AOT module is used (fresh): "aot", else the reason.
AOT_STATE = ("from rtreflect.kernels import compiled; m = compiled.aot_module(); "
             "print('aot' if m is not None else compiled._state['why'])")


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
    ap.add_argument("--build", action="store_true", help="also time the AOT build (`pip install`'s compilation)")
    args = ap.parse_args()
    width, height = args.size.split("x")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("RTREFLECT_KERNELS", None)
    jit_env = {**env, "RTREFLECT_KERNELS": "jit"}
    state = subprocess.run([sys.executable, "-c", AOT_STATE], capture_output=True, text=True, cwd=ROOT, env=env,
                           check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        command = ["render", args.scene, "--width", width, "--height", height, "--samples", "1", "-o", tmp]
        render = [sys.executable, "-c", ENTRY, *command]
        bare_wall, bare_cpu = best([sys.executable, "-c", "pass"], args.repeat, env)
        build_wall = build_cpu = None
        if args.build:
            build_wall, build_cpu, result = timed([sys.executable, "-m", "rtreflect.kernels.build", "--output-dir", tmp],
                                                  env)
            if result.returncode != 0:
                sys.exit(f"AOT build failed:\n{result.stderr}")
        first_wall, first_cpu, _ = timed(render, env)  # with the AOT module: the first run after an install
        warm_wall, warm_cpu = best(render, args.repeat, env)
        timed(render, jit_env)  # the JIT's kernels cached where a warm JIT run finds them
        jit_wall, jit_cpu = best(render, args.repeat, jit_env)
        floor_wall, floor_cpu = best([sys.executable, "-c", FLOOR], args.repeat, env)
        aot_floor_wall, aot_floor_cpu = best([sys.executable, "-c", AOT_FLOOR], args.repeat, env)
        cache = Path(tmp) / "numba-cache"
        cold_wall, cold_cpu, result = timed(render, {**jit_env, "NUMBA_CACHE_DIR": str(cache)})
        if result.returncode != 0:
            sys.exit(f"cold run failed:\n{result.stderr}")
        compiled = len(list(cache.rglob("*.nbi")))
        _, _, probe = timed([sys.executable, "-c", PROBE, *command], env)
    probed = json.loads(probe.stderr.strip().splitlines()[-1])
    marks = probed["marks"]

    print(f"`rtreflect render {args.scene} --width {width} --height {height} --samples 1`, whole process, "
          f"best of {args.repeat} ({'AOT kernels' if state == 'aot' else 'AOT kernels not used: ' + state}):")
    print(f"  warm:  {warm_wall:.3f} s wall, {warm_cpu:.3f} s CPU   ({warm_wall / bare_wall:.1f}× `python -c pass`, "
          f"{bare_wall:.3f} s; numba imported: {probed['numba']})")
    print(f"  warm, numba's JIT (RTREFLECT_KERNELS=jit, cached): {jit_wall:.3f} s wall, {jit_cpu:.3f} s CPU "
          f"(AOT/JIT wall {warm_wall / jit_wall:.2f})")
    if build_wall is not None:
        print(f"  cold, first run after install: AOT build {build_wall:.1f} s wall, {build_cpu:.1f} s CPU + first render "
              f"{first_wall:.3f} s wall = {build_wall + first_wall:.1f} s")
    else:
        print(f"  cold, first run after install: first render {first_wall:.3f} s wall (+ the AOT build: --build)")
    print(f"  cold, numba's JIT for reference: {cold_wall:.3f} s wall, {cold_cpu:.3f} s CPU "
          f"({compiled} kernels compiled and cached)")
    print(f"  floor with the AOT kernels (interpreter + numpy + AOT module): {aot_floor_wall:.3f} s wall, "
          f"{aot_floor_cpu:.3f} s CPU = {aot_floor_cpu / warm_cpu:.0%} of the warm run's CPU")
    print(f"  numba's floor (interpreter + numpy + numba + its registry load): {floor_wall:.3f} s wall, "
          f"{floor_cpu:.3f} s CPU")
    print("warm run, CPU seconds per phase (probe process):")
    previous = 0.0
    for name, seconds in marks:
        print(f"  {name:<52} {seconds - previous:.3f}")
        previous = seconds
    print(f"  {'exit (handlers; teardown skipped)':<52} {max(warm_cpu - previous, 0.0):.3f}  (warm run's CPU − probe's)")
    print("import rtreflect.cli, self time per top-level package (-X importtime, wall):")
    for name, seconds in import_breakdown(env)[:12]:
        print(f"  {name:<24} {seconds:.3f}")


if __name__ == "__main__":
    main()
