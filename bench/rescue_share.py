"""Where the Levenberg–Marquardt search (`trace.tracing._rescue`) spends a render (sweep part sphere_pole_view.step).

A sphere whose axis points at the camera renders several times slower than the same sphere turned (sphere_hole):
its silhouette is a latitude circle, so along it S_v lies along the ray (|S_v ⊥ D| ≈ 4e-4·|S_v|), J's v column
vanishes, and the search on the rays that pass between the sphere and its enclosing mesh (`_enclosing`) descends
only linearly: it stops neither converged nor stationary within `RESCUE_STEPS`, and `_passes_by` decides them.
Per input: CPU seconds of a one-thread render, the search's rays, CPU seconds and outcomes per caller, and the
render again with ``--steps`` search steps (ratio of CPU times, and whether every pixel is the same).

    python tools/make_sweep_parts.py /tmp/sweep sphere_pole_view.step sphere_hole.step
    python bench/rescue_share.py /tmp/sweep/sphere_pole_view.step /tmp/sweep/sphere_hole.step [--size 480x270]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict

import numpy as np

import rtreflect.trace.secondlook as secondlook
import rtreflect.trace.tracing as tracing
from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer


def render(path: str, width: int, height: int, calls: dict) -> tuple[float, np.ndarray]:
    """CPU seconds of a one-thread render and its pixels; ``calls`` gathers the search's per-caller counts."""
    search = tracing._rescue

    def counted(surfaces, patch, u, v, O, D, tol, steps=None):
        start = time.process_time()
        result = search(surfaces, patch, u, v, O, D, tol, steps)
        row = calls[sys._getframe(1).f_code.co_name]
        row += [len(u), time.process_time() - start, result[3].sum(), result[4].sum(), result[5].sum()]
        return result

    tracing._rescue = secondlook._rescue = counted
    try:
        renderer = Renderer(resolve(load_scene(path).with_image(width, height)))
        start = time.process_time()
        film = renderer.render(threads=1).film
        return time.process_time() - start, film.pixels
    finally:
        tracing._rescue = secondlook._rescue = search


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("inputs", nargs="+")
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--steps", type=int, default=20, help="search steps of the second render (default 20)")
    args = parser.parse_args()
    width, height = (int(x) for x in args.size.split("x"))
    for path in args.inputs:
        calls = defaultdict(lambda: np.zeros(5))
        render(path, width, height, defaultdict(lambda: np.zeros(5)))  # compile and warm caches
        seconds, pixels = render(path, width, height, calls)
        print(f"{path}: {seconds:.2f} s CPU")
        for caller, (rays, cpu, converged, stationary, edge) in calls.items():
            print(f"  {caller:12s} {int(rays):7d} rays {cpu:6.2f} s  converged {int(converged)} stationary "
                  f"{int(stationary)} on the edge {int(edge)} undecided {int(rays - converged - stationary - edge)}")
        kept = tracing.RESCUE_STEPS
        tracing.RESCUE_STEPS = args.steps
        try:
            fewer, other = render(path, width, height, defaultdict(lambda: np.zeros(5)))
        finally:
            tracing.RESCUE_STEPS = kept
        same = np.array_equal(pixels.view(np.uint32), other.view(np.uint32))
        print(f"  RESCUE_STEPS {args.steps}: {fewer:.2f} s CPU (ratio {tracing.RESCUE_STEPS} / {args.steps} steps: "
              f"{seconds / fewer:.2f}); pixels "
              f"{'the same' if same else 'DIFFERENT'}")


if __name__ == "__main__":
    main()
