"""One-thread profile of a CAD part's render (issue 12; cad_render_bench.py's part, default parts/plate.step), in CPU
seconds: where the time per covered pixel goes, and what batching the tracer's rounds could save at most.

Renders once to warm up (kernels loaded, the second look's fine mesh built), then:

1. a cProfile of a second render with the process's CPU clock as timer (`prof_render.profiled`): its `RenderStats`
   stages and the functions with the most time of their own;
2. the candidate rounds (`tracing._candidates`, one per query round of every `trace`: the coarse trace, the second
   look's fine trace, the trimmed occlusion test): calls, rays and CPU seconds of each kind, and of the calls of at
   most ``--small`` rays, whose cost is mostly fixed (numpy set-up, kernel dispatch, the rare paths' steps);
3. render CPU with the default spans (`renderer.RAYS_PER_TILE` rays) against one span for the whole frame, best of
   ``--repeat`` interleaved: every round of every trace then runs once per frame, not per span, an upper bound on
   what batching rounds across spans could save (the film must be the same bytes: the tracer is per ray).

    python bench/prof_cad_render.py [parts/plate.step] [--width 960 --height 540 --top 25 --repeat 3]
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator import renderer as renderer_module
from rtreflect.integrator.renderer import RAYS_PER_TILE, Renderer
from rtreflect.trace import secondlook, tracing

from prof_render import profiled

ROOT = Path(__file__).resolve().parent.parent


def rounds(renderer: Renderer, small: int) -> None:
    """Item 2 of the module doc: one render with `tracing._candidates` and the fine trace wrapped (then restored)."""
    calls, kind = defaultdict(list), ["coarse"]
    candidates, fine_trace, occluded = tracing._candidates, secondlook.trace, renderer_module.occluded

    def timed_candidates(*args):
        start = time.process_time()
        out = candidates(*args)
        calls[kind[0]].append((len(args[4]), time.process_time() - start))
        return out

    def as_kind(name, function):
        def call(*args, **kwargs):
            kind[0] = name
            try:
                return function(*args, **kwargs)
            finally:
                kind[0] = "coarse"
        return call

    tracing._candidates, secondlook.trace = timed_candidates, as_kind("fine", fine_trace)
    renderer_module.occluded = as_kind("occlusion", occluded)
    try:
        renderer.render(threads=1)
    finally:
        tracing._candidates, secondlook.trace, renderer_module.occluded = candidates, fine_trace, occluded
    print(f"candidate rounds (tracing._candidates), CPU seconds; 'small': at most {small} rays")
    for name, rows in calls.items():
        rays, seconds = np.array([r for r, _ in rows]), np.array([s for _, s in rows])
        few = rays <= small
        print(f"  {name:<10} {len(rows):4d} calls {rays.sum():8d} rays {seconds.sum():7.3f} s"
              f"   small: {few.sum():3d} calls {seconds[few].sum():6.3f} s")


def spans(renderer: Renderer, width: int, height: int, repeat: int) -> None:
    """Item 3 of the module doc."""
    sizes = {"default spans": RAYS_PER_TILE, "one span": width * height}
    best, films = {name: np.inf for name in sizes}, {}
    for _ in range(repeat):
        for name, rays in sizes.items():
            start = time.process_time()
            result = renderer.render(threads=1, rays_per_tile=rays)
            best[name] = min(best[name], time.process_time() - start)
            films[name] = result.film.pixels.tobytes()
    print(f"render CPU, one thread, best of {repeat}: " + ", ".join(f"{name} {s:.3f} s" for name, s in best.items())
          + f"; one span / default {best['one span'] / best['default spans']:.3f}, film identical "
          f"{films['one span'] == films['default spans']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("part", nargs="?", default=str(ROOT / "parts" / "plate.step"))
    ap.add_argument("--width", type=int, default=960)
    ap.add_argument("--height", type=int, default=540)
    ap.add_argument("--top", type=int, default=25, help="functions listed by their own time")
    ap.add_argument("--small", type=int, default=60, help="rounds of at most this many rays counted apart")
    ap.add_argument("--repeat", type=int, default=3, help="best of N renders per span size")
    args = ap.parse_args()
    renderer = Renderer(resolve(load_scene(args.part).with_image(args.width, args.height, 1)))
    profiled(renderer, args.top)
    rounds(renderer, args.small)
    spans(renderer, args.width, args.height, args.repeat)


if __name__ == "__main__":
    main()
