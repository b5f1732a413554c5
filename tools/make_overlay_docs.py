"""Regenerate the README's overlay images in docs/ (run from the project root).

docs/g1_join_overlay.png: `rtreflect render scenes/g1_join.toml --overlay` at the scene's settings.
docs/hood_t4_exact_vs_mesh.png: the hood with tessellation = 4, a crop enlarged 6× (nearest),
exact normals on the left, mesh normals on the right, the analytic contours drawn over both.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from rtreflect.imagefiles import read_image, write_png

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
RTREFLECT = [str(Path(sys.executable).parent / "rtreflect")]


def render(scene: Path, outdir: Path, *options: str) -> Path:
    subprocess.run([*RTREFLECT, "render", str(scene), "-o", str(outdir), "--overlay", *options], check=True)
    return outdir / f"{scene.stem}.png"


def linear(png: Path) -> np.ndarray:
    """The 8-bit sRGB PNG back to linear RGBA (write_png encodes again)."""
    pixels, _, _ = read_image(png)
    rgb = pixels[..., :3]
    rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return np.concatenate([rgb, np.ones_like(pixels[..., 3:4])], axis=-1)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (DOCS / "g1_join_overlay.png").write_bytes(render(ROOT / "scenes/g1_join.toml", tmp / "g1").read_bytes())
        coarse = tmp / "hood.toml"
        coarse.write_text((ROOT / "scenes/hood.toml").read_text().replace("tessellation = 16", "tessellation = 4"))
        exact = linear(render(coarse, tmp / "exact", "--normals", "exact"))
        mesh = linear(render(coarse, tmp / "mesh", "--normals", "mesh"))
        crop = (slice(326, 376), slice(340, 440))  # the outer tubes, where the mesh errs most
        gap = np.ones((50, 2, 4), dtype=np.float32)
        both = np.concatenate([exact[crop], gap, mesh[crop]], axis=1)
        write_png(DOCS / "hood_t4_exact_vs_mesh.png", np.repeat(np.repeat(both, 6, axis=0), 6, axis=1))


if __name__ == "__main__":
    main()
