"""Peer benchmark (issue 14): rtreflect's RMSE against render time on the peer scene, ratios to a bare intersect.

The scene is bench/peer.toml (the issue's side-by-side with a general-purpose renderer). Quality is
the RMSE of the per-pixel tube coverage (the R channel: white lines on a black surface) over the
pixels that see the surface, against rtreflect at samples = 16 (256 samples per pixel) computed in
the same run, and the share of those pixels off by more than 0.1. Times are best of --repeat, and
are printed as ratios to a bare embreex intersect of one float32 ray per pixel in the same run, so
the figures compare across machines (the issue's goal 1: the whole render <= 3x that intersect at
RMSE <= 0.0125 and <= 0.3 % of pixels off by > 0.1). The first row is the default, samples = "analytic"
(one exact sample per pixel, the stripes' coverage in closed form, edge pixels 4×4: integrator/analytic.py);
a line after the table says how many pixels it supersampled.

With --cpu the times are the process's CPU seconds (all its threads summed) instead of wall time: on a
machine other jobs load, the time they hold the cores is not counted (with --threads 1 it is the one
thread's time, the figure to compare two versions by).

    python bench/peer_bench.py [--samples analytic 1 2 4 --repeat 3 --threads 2 --cpu]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from rtreflect.exchange.scene import ANALYTIC, load_scene
from rtreflect.integrator.renderer import Renderer

SCENE = Path(__file__).resolve().parent / "peer.toml"
#: Reference sample grid (s×s per pixel), as in the issue.
REFERENCE_SAMPLES = 16
#: A pixel is "off" where its coverage differs from the reference by more than this.
OFF_BY = 0.1


#: The clock the renders and the bare intersect are timed by: wall time, or with --cpu the process's CPU time.
clock = time.perf_counter


def render(scene, samples: int | str, repeat: int, threads: int | None):
    renderer = Renderer(dataclasses.replace(scene, image=dataclasses.replace(scene.image, samples=samples)))
    best, result = np.inf, None
    for _ in range(repeat):
        t0 = clock()
        result = renderer.render(threads=threads)
        best = min(best, clock() - t0)
    film = result.film
    return best, film.channel("R").astype(np.float64), film.channel("A"), renderer, result.stats


def samples_arg(text: str) -> int | str:
    return text if text == ANALYTIC else int(text)


def label(s: int | str) -> str:
    return "analytic (default)" if s == ANALYTIC else f"samples {s} ({s * s} spp)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=samples_arg, nargs="+", default=[ANALYTIC, 1, 2, 4])
    ap.add_argument("--repeat", type=int, default=3, help="best of N renders")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--cpu", action="store_true", help="time CPU seconds of the process, not wall time")
    args = ap.parse_args()
    global clock
    clock = time.process_time if args.cpu else time.perf_counter
    scene = load_scene(SCENE)

    _, reference, alpha, renderer, _ = render(scene, REFERENCE_SAMPLES, 1, args.threads)
    sees = alpha > 0
    width, height = scene.image.width, scene.image.height
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, directions = renderer.camera.rays(rows, cols)
    o32, d32 = origins.astype(np.float32), directions.astype(np.float32)
    bare = np.inf
    for _ in range(args.repeat):
        t0 = clock()
        renderer.accelerator.scene.run(o32, d32, query="INTERSECT", output=1)
        bare = min(bare, clock() - t0)

    print(f"peer scene {SCENE.name}: {width}×{height}, surface in {100 * sees.mean():.0f}% of the pixels; "
          f"reference samples = {REFERENCE_SAMPLES}")
    print(f"bare embreex intersect, 1 ray/px: {bare:.3f} s (one thread, float32 rays ready)"
          + ("; times are CPU seconds" if args.cpu else ""))
    print(f"{'setting':<26} {'render s':>9} {'× bare':>7} {'RMSE':>8} {'off > 0.1':>10}")
    supersampled = None
    for s in args.samples:
        seconds, coverage, _, _, stats = render(scene, s, args.repeat, args.threads)
        error = coverage[sees] - reference[sees]
        rmse = float(np.sqrt(np.mean(error**2)))
        off = 100.0 * float(np.mean(np.abs(error) > OFF_BY))
        print(f"{label(s):<26} {seconds:>9.3f} {seconds / bare:>7.2f} {rmse:>8.4f} {off:>9.2f}%")
        if s == ANALYTIC:
            supersampled = stats.supersampled
    if supersampled is not None:
        print(f"analytic: {supersampled} pixels supersampled 4×4 (edges), {100 * supersampled / (width * height):.2f}% "
              f"of the image; the rest 1 traced ray per pixel plus a two-row halo per tile")


if __name__ == "__main__":
    main()
