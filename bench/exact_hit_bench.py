"""The exact-hit trace alone (trace/tracing.py, no second look) on a scene's or part's pixel-centre rays.

CPU seconds of one thread, best of ``--repeat``, the rays in 64k-ray tiles as the renderer sends them,
and the Newton fallbacks; against a bare Embree intersect of the same rays in the same run (the ratio
is what to compare between machines and checkouts):

    python bench/exact_hit_bench.py [parts/plate.step ...] [--width 960 --height 540 --repeat 3]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.tracing import trace

ROOT = Path(__file__).resolve().parent.parent
#: Rays per call, as the renderer's tiles.
TILE = 65536


def best_of(repeat: int, run) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.process_time()
        out = run()
        best = min(best, time.process_time() - start)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", type=Path, default=[ROOT / "parts" / "plate.step"])
    ap.add_argument("--width", type=int, default=960)
    ap.add_argument("--height", type=int, default=540)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    for path in args.inputs:
        renderer = Renderer(resolve(load_scene(path).with_image(args.width, args.height, 1)))
        rows, cols = np.divmod(np.arange(args.width * args.height), args.width)
        O, D = renderer.camera.rays(rows, cols)
        tiles = [slice(s, s + TILE) for s in range(0, len(O), TILE)]
        trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, O[:1000], D[:1000])  # lazy caches, JIT
        exact, fallbacks = best_of(args.repeat, lambda: sum(
            int(trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, O[t], D[t]).fallback.sum())
            for t in tiles))
        bare, _ = best_of(args.repeat, lambda: [renderer.accelerator.intersect(O[t], D[t]) for t in tiles])
        print(f"{path.name:<22} {args.width}×{args.height}: exact hits {exact:.3f} s, bare intersect {bare:.3f} s, "
              f"ratio {exact / bare:.1f}, {fallbacks} fallbacks", flush=True)


if __name__ == "__main__":
    main()
