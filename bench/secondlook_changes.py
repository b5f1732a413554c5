"""Which rays the second look selects and which hits it changes, per shipped scene and part (issues 11, 12, 14).

For every scenes/*.toml and parts/* (or the inputs given) at 480×270, the pixel-centre rays are traced
on the coarse mesh, then the second look (trace/secondlook.py) applied; a ray is *changed* when its
hit, face, distance or fallback flag differs afterwards. Prints the counts; ``--save FILE.npz`` keeps
the sets, ``--compare FILE.npz`` says per input whether the changed sets are identical to (or contain)
those saved, e.g. by another checkout of the code:

    python bench/secondlook_changes.py --save before.npz      # in the old checkout
    python bench/secondlook_changes.py --compare before.npz   # in the new one
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.tracing import trace

ROOT = Path(__file__).resolve().parent.parent


def changes(path: Path, width: int, height: int) -> tuple[int, np.ndarray, np.ndarray]:
    """(coarse hits, suspects, changed rays) of the pixel-centre rays of one input."""
    renderer = Renderer(resolve(load_scene(path).with_image(width, height, 1)))
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    before = {name: getattr(hits, name).copy() for name in ("hit", "patch", "t", "fallback")}
    far = np.full(len(origins), np.inf)
    suspects = renderer.second_look.suspects(hits, origins, directions, far)
    suspects = suspects[0] if isinstance(suspects, tuple) else suspects  # older checkouts return the indices only
    renderer.second_look.apply(hits, origins, directions, far)
    t, t0 = np.nan_to_num(hits.t, nan=-1.0), np.nan_to_num(before["t"], nan=-1.0)
    changed = np.flatnonzero((hits.hit != before["hit"]) | (hits.patch != before["patch"]) | (t != t0)
                             | (hits.fallback != before["fallback"]))
    return int(before["hit"].sum()), suspects, changed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    ap.add_argument("--save", type=Path)
    ap.add_argument("--compare", type=Path)
    args = ap.parse_args()
    inputs = args.inputs or sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "parts").iterdir())
    saved = dict(np.load(args.compare)) if args.compare else {}
    out = {}
    for path in inputs:
        hits, suspects, changed = changes(path, args.width, args.height)
        out[f"{path.name}:suspects"], out[f"{path.name}:changed"] = suspects, changed
        line = f"{path.name:<24} hits {hits:7d}  suspects {len(suspects):6d}  changed {len(changed):4d}"
        if f"{path.name}:changed" in saved:
            old = set(saved[f"{path.name}:changed"].tolist())
            line += f"  (saved {len(old)}: identical {old == set(changed.tolist())}, contained {old <= set(changed.tolist())})"
        print(line, flush=True)
    if args.save:
        np.savez(args.save, **out)


if __name__ == "__main__":
    main()
