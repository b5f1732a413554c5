"""Second-look benchmark (issues 12 and 14): CPU seconds of the second look (trace/secondlook.py) on the
pixel-centre rays of a scene, against a bare Embree intersect of the same rays in the same run.

The coarse trace runs first (not timed); the second look runs once to build its finer mesh, then
``--repeat`` times on fresh copies of the coarse hits (best CPU time of this process, one thread).
Defaults: render_bench.py's single bicubic patch at 1920×1080 and the 206-face plate at 960×540.
Prints the suspects, the stage's seconds and their ratio to the bare intersect.

    python bench/secondlook_bench.py [SCENE_OR_PART WIDTH HEIGHT ...] [--repeat 3]
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.tracing import trace

from render_bench import bench_scene_text

ROOT = Path(__file__).resolve().parent.parent


def measure(scene, repeat: int) -> tuple[int, int, float, float]:
    """(rays, suspects, best CPU seconds of the second look, CPU seconds of a bare intersect)."""
    renderer = Renderer(scene)
    width, height = scene.image.width, scene.image.height
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    far = np.full(len(origins), np.inf)
    look = renderer.second_look
    suspects = look.suspects(hits, origins, directions, far)
    suspects = len(suspects[0] if isinstance(suspects, tuple) else suspects)  # older checkouts: the indices only
    look.apply(copy.deepcopy(hits), origins, directions, far)  # builds the finer mesh
    best = np.inf
    for _ in range(repeat):
        again = copy.deepcopy(hits)
        start = time.process_time()
        look.apply(again, origins, directions, far)
        best = min(best, time.process_time() - start)
    start = time.process_time()
    renderer.accelerator.intersect(origins, directions)
    return len(origins), suspects, best, time.process_time() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", help="triples SCENE_OR_PART WIDTH HEIGHT")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        patch = Path(tmp) / "patch.toml"
        patch.write_text(bench_scene_text(1920, 1080))
        triples = args.inputs or [str(patch), "1920", "1080", str(ROOT / "parts" / "plate.step"), "960", "540"]
        for name, width, height in zip(triples[::3], triples[1::3], triples[2::3]):
            scene = resolve(load_scene(name).with_image(int(width), int(height), 1))
            rays, suspects, seconds, bare = measure(scene, args.repeat)
            label = "single patch" if name == str(patch) else Path(name).name
            print(f"{label:<16} {width}×{height}: {suspects} suspects of {rays} rays; second look {seconds:.3f} s CPU, "
                  f"bare intersect {bare:.3f} s, ratio {seconds / bare:.2f}")


if __name__ == "__main__":
    main()
