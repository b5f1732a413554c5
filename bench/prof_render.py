"""One-thread cProfile of the full-HD render benchmark (bench/render_bench.py, issue 14 goal 2), in CPU seconds.

Renders once to warm up (kernels loaded, the second look's fine mesh built), then profiles a second render with
the process's CPU clock as cProfile's timer (on a machine other jobs load, wall time counts their turns too) and
prints its `RenderStats` stage times and the functions with the most time of their own, then who calls the Embree
queries (the per-ray floor: embreex builds each ray in turn, whatever its segment).

    python bench/prof_render.py [--width 1920 --height 1080 --top 30]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import tempfile
import time
from pathlib import Path

from render_bench import bench_scene_text

from rtreflect.exchange.scene import load_scene
from rtreflect.integrator.renderer import Renderer


def profiled(renderer: Renderer, top: int) -> pstats.Stats:
    """One render to warm up, then a second under cProfile with the process's CPU clock as timer: prints its stage
    times and the ``top`` functions by their own time, and returns the profile (also bench/prof_cad_render.py's)."""
    renderer.render(threads=1)
    profile = cProfile.Profile(time.process_time)
    profile.enable()
    result = renderer.render(threads=1)
    profile.disable()
    print("stages (wall seconds, one thread):")
    for stage, seconds in sorted(result.stats.stages.items(), key=lambda kv: -kv[1]):
        print(f"  {stage:<22} {seconds:.3f}")
    stats = pstats.Stats(profile).sort_stats("tottime")
    stats.print_stats(top)
    return stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--top", type=int, default=30, help="functions listed by their own time")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(bench_scene_text(args.width, args.height))
        scene = load_scene(path)
    stats = profiled(Renderer(scene), args.top)
    stats.print_callers(r"accelerator.py.*\((intersect|occluded)\)")


if __name__ == "__main__":
    main()
