"""Which pixel-centre hits `tracing._crossing_on_face` changes, per shipped scene and part (issue 12).

For every scenes/*.toml and parts/* (or the inputs given) at 480×270 the pixel-centre rays are traced
(`Renderer.trace`: the candidate search and the second look) twice in one process, with the other
crossing switched off (as before it existed) and on; prints how many candidate rows left their face,
how many the other crossing made valid, and the pixels whose hit, face, t, P, N or fallback flag differ:

    python bench/crossing_changes.py
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace import tracing

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    args = ap.parse_args()
    inputs = args.inputs or sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "parts").iterdir())
    real, calls = tracing._crossing_on_face, []

    def counting(tessellation, surfaces, rows, *rest):
        won = real(tessellation, surfaces, rows, *rest)
        calls.append((len(rows), len(won)))
        return won

    width, height = args.width, args.height
    for path in inputs:
        renderer = Renderer(resolve(load_scene(path).with_image(width, height, 1)))
        rows, cols = np.divmod(np.arange(width * height), width)
        origins, directions = renderer.camera.rays(rows, cols)
        tracing._crossing_on_face = lambda tessellation, surfaces, rows, *rest: rows[:0]  # off: as before
        before = renderer.trace(origins, directions)
        calls.clear()
        tracing._crossing_on_face = counting
        after = renderer.trace(origins, directions)
        tracing._crossing_on_face = real
        same = lambda x: np.nan_to_num(getattr(before, x), nan=-1.0) == np.nan_to_num(getattr(after, x), nan=-1.0)  # noqa: E731
        changed = np.flatnonzero(~(same("hit") & same("patch") & same("t") & same("fallback")
                                   & same("P").all(axis=1) & same("N").all(axis=1)))
        print(f"{path.name:<24} left their face {sum(c[0] for c in calls):7d}  other crossing won "
              f"{sum(c[1] for c in calls):4d}  pixels changed {len(changed)}")
        for i in changed[:10]:
            r, c = divmod(int(i), width)
            print(f"    pixel ({r}, {c}): face {before.patch[i]} t {before.t[i]!r} -> face {after.patch[i]} t {after.t[i]!r}")


if __name__ == "__main__":
    main()
