"""Contours against the render (issue 14 goal 4): `analytic_contours` time over the default render's, in one run.

    python bench/contours_bench.py [SCENE ...] [--width 960 --height 540 --threads N --repeat 2]

Per scene (default: the teapot): a small warm-up render (kernels compiled or loaded), then, back to
back, the scene's default render and its analytic contours (`contours.field_of`, as `--overlay` and
`validate` compute them), each the best of ``--repeat``, and the ratio contours/render (issue 14 goal 4: under 1);
then `--overlay`'s drawing of them (`overlay.coverage`) and (contours + drawing)/render.
Also the contour point count, so a speed-up that drops points shows. A shared machine makes seconds
noisy: read the ratio.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rtreflect.analysis.contours import analytic_contours, field_of
from rtreflect.analysis.overlay import coverage
from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer

ROOT = Path(__file__).resolve().parent.parent


def best_of(repeat: int, work) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=[str(ROOT / "scenes" / "teapot.toml")])
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    parser.add_argument("--threads", type=int, default=None, help="render threads (default: the renderer's)")
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    for path in args.scenes:
        loaded = load_scene(path)
        Renderer(resolve(loaded.with_image(64, 36, loaded.image.samples))).render(threads=args.threads)  # warm-up
        renderer = Renderer(resolve(loaded.with_image(args.width, args.height, loaded.image.samples)))
        render = best_of(args.repeat, lambda: renderer.render(threads=args.threads))
        field = field_of(renderer)
        found = []
        contours = best_of(args.repeat, lambda: found.append(analytic_contours(field)))
        points = sum(len(p.px) for line in found[-1].lines for p in line.polylines)
        spec = renderer.scene
        drawn = best_of(args.repeat, lambda: coverage(found[-1], args.width, args.height, spec.render.overlay_width))
        print(f"{Path(path).stem} {args.width}x{args.height}: render {render:.2f} s, contours {contours:.2f} s, "
              f"contours/render {contours / render:.2f} ({points} contour points); the overlay's drawing "
              f"(`overlay.coverage`) {drawn:.2f} s, (contours + drawing)/render {(contours + drawn) / render:.2f}",
              flush=True)


if __name__ == "__main__":
    main()
