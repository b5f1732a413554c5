"""Regenerate golden_images/: every scene in scenes/ and every CAD part in parts/ (in its default scene) rendered
at golden size, as NAME.exr and NAME.png (NAME: the scene's stem; a part's stem and format, e.g. plate_step).

Run from the project folder:

    python tools/make_goldens.py                  # every scenes/*.toml and parts/*.step|igs|3dm
    python tools/make_goldens.py hood plate_step  # only scenes/hood.toml and parts/plate.step

Golden size is `rtreflect.testing.GOLDEN_WIDTH` × `GOLDEN_HEIGHT` (320×180) with the scene's own
samples s, capped at `GOLDEN_MAX_SAMPLES` (4); `"analytic"` (the default) stays analytic. Renders are deterministic, so running this twice on
one machine writes the same pixels; review the images (and the diff images the failing tests wrote)
before committing them: see the README, "Golden images".
"""

from __future__ import annotations

import sys
from pathlib import Path

from rtreflect.exchange.cad import is_cad_path
from rtreflect.testing import GOLDEN_HEIGHT, GOLDEN_WIDTH, golden_name, render_golden

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
PARTS = ROOT / "parts"
GOLDENS = ROOT / "golden_images"


def golden_inputs() -> list[Path]:
    """Every input with a golden image: the shipped scenes, then the shipped CAD parts."""
    return sorted(SCENES.glob("*.toml")) + sorted(p for p in PARTS.iterdir() if is_cad_path(p))


def main(names: list[str]) -> int:
    inputs = {golden_name(p): p for p in golden_inputs()}
    missing = [name for name in names if name not in inputs]
    if missing:
        print(f"make_goldens: no such scene or part: {', '.join(missing)} (names: {', '.join(inputs)})", file=sys.stderr)
        return 2
    scenes = [inputs[name] for name in names] if names else list(inputs.values())
    GOLDENS.mkdir(exist_ok=True)
    for scene in scenes:
        exr = render_golden(scene, GOLDENS)
        print(f"{scene.relative_to(ROOT)} → {exr.relative_to(ROOT)}, {exr.with_suffix('.png').relative_to(ROOT)} "
              f"({GOLDEN_WIDTH}×{GOLDEN_HEIGHT})")
    stale = sorted(p.name for p in GOLDENS.iterdir() if p.suffix in (".exr", ".png") and p.stem not in inputs)
    if stale:
        print(f"make_goldens: golden images without a scene (delete them?): {', '.join(stale)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
