"""Regenerate the README's overlay images in docs/ (run from the project root).

docs/g1_join_overlay.png: `rtreflect render scenes/g1_join.toml --overlay` at the scene's settings.
docs/hood_t4_exact_vs_mesh.png: the hood with tessellation = 4, a crop enlarged 6× (nearest),
exact normals on the left, mesh normals on the right, the analytic contours drawn over both.
Each picture is written atomically; on failure the script prints one line and exits 1.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import colour
import numpy as np

from rtreflect.errors import RtreflectError
from rtreflect.output.imagefiles import atomic_path, read_image, write_png
from rtreflect.exchange.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
RTREFLECT = [str(Path(sys.executable).parent / "rtreflect")]


def render(scene: Path, outdir: Path, *options: str) -> Path:
    """Render with the overlay; the PNG's path follows the scene's `[output] name`."""
    result = subprocess.run([*RTREFLECT, "render", str(scene), "-o", str(outdir), "--overlay", *options],
                            capture_output=True, text=True)
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[-1]
        raise RuntimeError(f"rtreflect render {scene.name} failed: {last}")
    return outdir / f"{load_scene(scene).output.name}.png"


def linear(png: Path) -> np.ndarray:
    """The 8-bit sRGB PNG back to linear RGBA (write_png encodes again), opaque."""
    pixels, _, _ = read_image(png)
    rgb = colour.cctf_decoding(pixels[..., :3], function="sRGB")
    return np.concatenate([rgb, np.ones_like(pixels[..., 3:4])], axis=-1).astype(np.float32)


def coarse_hood(folder: Path) -> Path:
    """scenes/hood.toml with `tessellation = 4`; fails loudly if the scene no longer says `tessellation = 16`."""
    text = (ROOT / "scenes/hood.toml").read_text()
    if text.count("tessellation = 16") != 1:
        raise RuntimeError("scenes/hood.toml: expected one line 'tessellation = 16' to replace with 4")
    path = folder / "hood.toml"
    path.write_text(text.replace("tessellation = 16", "tessellation = 4"))
    return path


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        overlay = render(ROOT / "scenes/g1_join.toml", tmp / "g1")
        with atomic_path(DOCS / "g1_join_overlay.png") as target:
            target.write_bytes(overlay.read_bytes())
        coarse = coarse_hood(tmp)
        exact = linear(render(coarse, tmp / "exact", "--normals", "exact"))
        mesh = linear(render(coarse, tmp / "mesh", "--normals", "mesh"))
        crop = (slice(326, 376), slice(340, 440))  # the outer tubes, where the mesh errs most
        gap = np.ones((50, 2, 4), dtype=np.float32)
        both = np.concatenate([exact[crop], gap, mesh[crop]], axis=1)
        final = DOCS / "hood_t4_exact_vs_mesh.png"
        with atomic_path(final) as target:
            write_png(target, np.repeat(np.repeat(both, 6, axis=0), 6, axis=1), final=final)


if __name__ == "__main__":
    try:
        main()
    except (RtreflectError, RuntimeError, OSError) as exc:
        print(f"make_overlay_docs: error: {exc}", file=sys.stderr)
        sys.exit(1)
