"""Cost of validate's nearest-hit check (`nearer_surface`) against the rest of validate, per shipped scene.

    python bench/validate_nearer_bench.py [--width 960 --height 540] [SCENE ...]

For each scene: the time of `validate` without the check (render, AOVs, contours, comparison)
and of the check alone on the same film, and their ratio; also the count of pixels it flags.
Timings on a shared machine are approximate: compare ratios, not seconds.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from rtreflect.analysis import validate as V
from rtreflect.exchange.load import load_scene
from rtreflect.integrator.renderer import Renderer

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=[str(p) for p in sorted((ROOT / "scenes").glob("*.toml"))])
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    args = parser.parse_args()
    for path in args.scenes:
        scene = load_scene(path).with_image(args.width, args.height, load_scene(path).image.samples)
        start = time.perf_counter()
        renderer = Renderer(scene)
        film = renderer.render().film
        aovs = V.film_aovs(renderer, film)
        V.compare(renderer, aovs, V.analytic_contours(V.UlmetField.of(renderer)), V.DEFAULT_TOLERANCE_PX)
        whole = time.perf_counter() - start
        rows, cols = np.nonzero((aovs.patch >= 0) & ~aovs.fallback)
        origins, directions = renderer.camera.rays(rows, cols)
        start = time.perf_counter()
        nearer = V.nearer_surface(renderer, aovs.patch[rows, cols].astype(int), aovs.Z[rows, cols], origins, directions)
        check = time.perf_counter() - start
        print(f"{Path(path).stem}: validate without the check {whole - check:.1f} s, the check {check:.2f} s "
              f"(ratio {check / (whole - check):.3f}), {int(nearer.sum())} pixels flagged", flush=True)


if __name__ == "__main__":
    main()
