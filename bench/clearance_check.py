"""How many any-hit queries past a mesh hit the clearance cones skip (trace/clearance.py), and a check of each skip.

For every scenes/*.toml and parts/* (or the inputs given) at 480×270, and the full-HD bench scene of
bench/render_bench.py, the pixel-centre rays are traced on the coarse mesh; every ray the cones clear is then
asked of Embree anyway (the query `trace` no longer makes): a skip Embree would have answered "something" is a
wrong skip, and must be 0. Prints per input: rays, segments past a mesh hit (queries before), cleared, wrong.

    python bench/clearance_check.py [INPUT ...] [--width 480 --height 270] [--no-bench]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace import clearance
from rtreflect.trace.tracing import trace

ROOT = Path(__file__).resolve().parent.parent


def check(path: Path, width: int, height: int) -> tuple[int, int, int, int]:
    """(rays, segments asked about, cleared, wrongly cleared) of the pixel-centre rays of one input."""
    renderer = Renderer(resolve(load_scene(path).with_image(width, height, 1)))
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, directions = renderer.camera.rays(rows, cols)
    counts = [0, 0, 0]
    original = clearance.Cones.drop

    def drop(self, O, D, prim, start, limit, go):
        before = go.copy()
        original(self, O, D, prim, start, limit, go)
        cleared = np.flatnonzero(before & ~go)
        counts[0] += int(before.sum())
        counts[1] += len(cleared)
        if len(cleared):
            shifted = O[cleared] + start[cleared, None] * D[cleared]
            found = renderer.accelerator.occluded(shifted, D[cleared], limit[cleared] - start[cleared])
            counts[2] += int(found.sum())

    clearance.Cones.drop = drop
    payback = clearance.PAYBACK_RAYS_PER_TRIANGLE
    clearance.PAYBACK_RAYS_PER_TRIANGLE = 0  # built for the first trace: every input's cones are checked
    try:
        for first in range(0, len(origins), 1 << 16):  # the renderer's tiles
            span = slice(first, first + (1 << 16))
            trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins[span], directions[span])
    finally:
        clearance.Cones.drop = original
        clearance.PAYBACK_RAYS_PER_TRIANGLE = payback
    return (len(origins), *counts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("inputs", nargs="*", type=Path)
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=270)
    parser.add_argument("--no-bench", action="store_true", help="leave out bench/render_bench.py's scene")
    args = parser.parse_args()
    inputs = args.inputs or sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "parts").glob("*"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        if not args.no_bench:
            import render_bench  # noqa: PLC0415 (beside this file)

            bench = Path(tmp) / "render_bench.toml"
            bench.write_text(render_bench.bench_scene_text(1920, 1080))
            rows.append((bench, 1920, 1080))
        rows += [(path, args.width, args.height) for path in inputs]
        print(f"{'input':28s} {'rays':>9s} {'segments':>9s} {'cleared':>9s} {'share':>6s} {'wrong':>6s}")
        wrong = 0
        for path, width, height in rows:
            rays, asked, cleared, bad = check(path, width, height)
            wrong += bad
            share = cleared / asked if asked else 0.0
            print(f"{path.name:28s} {rays:9d} {asked:9d} {cleared:9d} {share:6.1%} {bad:6d}", flush=True)
    print("wrong skips:", wrong)


if __name__ == "__main__":
    main()
