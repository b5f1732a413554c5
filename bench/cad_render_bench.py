"""CAD render benchmark (issue 12, "Speed and memory"): time per covered pixel on a multi-face trimmed
part against a single patch covering the same share of the frame.

The part (default parts/plate.step: 206 trimmed faces with holes) renders in its default scene; the
single patch is render_bench.py's 10×10 bicubic patch, its camera's field of view set (by bisection)
so the patch covers the same fraction of the frame as the part. Both at 1 sample per pixel, one
thread, CPU time of this process (best of ``--repeat``), so other load on the machine matters less.
Prints seconds per million covered pixels for each, the ratio part / patch (issue 12 asks ≤ 1.5),
and the per-stage breakdown.

    python bench/cad_render_bench.py [parts/plate.step] [--width 960 --height 540 --repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer

from render_bench import bench_scene_text

ROOT = Path(__file__).resolve().parent.parent
#: Image size of the coverage probes in the field-of-view bisection (mesh hits only: cheap).
PROBE_WIDTH, PROBE_HEIGHT = 320, 180


def coverage(renderer: Renderer, width: int, height: int) -> float:
    """Fraction of pixel-centre rays that hit the mesh (a probe: the exact tracer is not needed to match shares)."""
    camera = type(renderer.camera)(renderer.scene.camera, width, height)
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, directions = camera.rays(rows, cols)
    return float((renderer.accelerator.intersect(origins, directions).prim >= 0).mean())


def matched_patch_scene(target: float, width: int, height: int):
    """render_bench's patch with the field of view that makes it cover ``target`` of the frame."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "patch.toml"
        path.write_text(bench_scene_text(width, height))
        scene = load_scene(path)
    lo, hi = 5.0, 150.0  # wider view, smaller share
    for _ in range(20):
        fov = 0.5 * (lo + hi)
        probe = Renderer(replace(scene, camera=replace(scene.camera, fov=fov)))
        if coverage(probe, PROBE_WIDTH, PROBE_HEIGHT) > target:
            lo = fov
        else:
            hi = fov
    return replace(scene, camera=replace(scene.camera, fov=0.5 * (lo + hi)))


def timed(scene, repeat: int):
    renderer = Renderer(scene)
    best = None
    for _ in range(repeat):
        start = time.process_time()
        result = renderer.render(threads=1)
        seconds = time.process_time() - start
        if best is None or seconds < best[0]:
            best = (seconds, result)
    seconds, result = best
    covered = float(result.film.channel("A").sum())
    return seconds, covered, result.stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("part", nargs="?", default=str(ROOT / "parts" / "plate.step"))
    ap.add_argument("--width", type=int, default=960)
    ap.add_argument("--height", type=int, default=540)
    ap.add_argument("--repeat", type=int, default=3, help="best of N renders (CPU time)")
    args = ap.parse_args()

    # A CAD file loads as its default scene (exchange/load.py), whose automatic camera and tubes resolve here.
    part_scene = resolve(load_scene(args.part).with_image(args.width, args.height, 1))
    part_renderer = Renderer(part_scene)
    share = coverage(part_renderer, PROBE_WIDTH, PROBE_HEIGHT)
    patch_scene = matched_patch_scene(share, args.width, args.height)

    rows = []
    for label, scene in ((f"part ({len(part_scene.surfaces)} faces)", part_scene), ("single patch", patch_scene)):
        seconds, covered, stats = timed(scene, args.repeat)
        rows.append((label, seconds, covered, stats))
    print(f"image {args.width}×{args.height}, 1 sample/px, one thread, CPU seconds (best of {args.repeat})")
    for label, seconds, covered, stats in rows:
        print(f"{label:<22} {seconds:7.3f} s, covers {covered / (args.width * args.height):5.1%} of the frame, "
              f"{seconds / covered * 1e6:7.3f} s per million covered pixels, {stats.fallbacks} fallbacks")
        for stage, s in sorted(stats.stages.items(), key=lambda kv: -kv[1]):
            print(f"    {stage:<22} {s:.3f}")
    ratio = (rows[0][1] / rows[0][2]) / (rows[1][1] / rows[1][2])
    print(f"ratio part / single patch, per covered pixel: {ratio:.2f} (issue 12 asks ≤ 1.5)")


if __name__ == "__main__":
    main()
