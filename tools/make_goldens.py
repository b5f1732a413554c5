"""Regenerate golden_images/: every scene in scenes/ rendered at golden size, as NAME.exr and NAME.png.

Run from the project folder:

    python tools/make_goldens.py            # every scenes/*.toml
    python tools/make_goldens.py hood       # only scenes/hood.toml

Golden size is `rtreflect.testing.GOLDEN_WIDTH` × `GOLDEN_HEIGHT` (320×180) with the scene's own
samples s, capped at `GOLDEN_MAX_SAMPLES` (4). Renders are deterministic, so running this twice on
one machine writes the same pixels; review the images (and the diff images the failing tests wrote)
before committing them: see the README, "Golden images".
"""

from __future__ import annotations

import sys
from pathlib import Path

from rtreflect.testing import GOLDEN_HEIGHT, GOLDEN_WIDTH, render_golden

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
GOLDENS = ROOT / "golden_images"


def main(names: list[str]) -> int:
    scenes = [SCENES / f"{name}.toml" for name in names] if names else sorted(SCENES.glob("*.toml"))
    missing = [p for p in scenes if not p.is_file()]
    if missing:
        print(f"make_goldens: no such scene: {', '.join(str(p) for p in missing)}", file=sys.stderr)
        return 2
    GOLDENS.mkdir(exist_ok=True)
    for scene in scenes:
        exr = render_golden(scene, GOLDENS)
        print(f"{scene.relative_to(ROOT)} → {exr.relative_to(ROOT)}, {exr.with_suffix('.png').relative_to(ROOT)} "
              f"({GOLDEN_WIDTH}×{GOLDEN_HEIGHT})")
    stale = sorted(p.name for p in GOLDENS.iterdir()
                   if p.suffix in (".exr", ".png") and not (SCENES / f"{p.stem}.toml").exists())
    if stale:
        print(f"make_goldens: golden images without a scene (delete them?): {', '.join(stale)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
