"""Regenerate the README's images in docs/ (run from the project root).

docs/hood.png: `rtreflect render scenes/hood.toml` at the scene's settings (the default look).
docs/looks.png: parts/filleted_block.step in its automatic scene (`rtreflect init`) at 480×270, three
ways side by side: `shading = "flat"`, the default `"lambert"`, and `"lambert"` with `blur = 0.5`.
docs/g1_join_overlay.png: `rtreflect render scenes/g1_join.toml --overlay` at the scene's settings.
docs/hood_t4_exact_vs_mesh.png: the hood with tessellation = 4, a crop enlarged 6× (nearest),
exact normals on the left, mesh normals on the right, the analytic contours drawn over both
1 px wide (`overlay_width = 1`: at 6× a thin line shows the mesh's drift off the centre best).
docs/SCENE.png (and SCENE.legend.svg for the map modes): the README's gallery of modes, `rtreflect render
scenes/SCENE.toml --width 480 --height 270 --samples 3` for each scene of `GALLERY`.
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


def run(*args: str, cwd: Path | None = None) -> str:
    """``rtreflect ARGS``' standard output; a failure raises with its last line of stderr."""
    result = subprocess.run([*RTREFLECT, *args], capture_output=True, text=True, cwd=cwd)
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[-1]
        raise RuntimeError(f"rtreflect {' '.join(args[:2])} failed: {last}")
    return result.stdout


def render(scene: Path, outdir: Path, *options: str, overlay: bool = True) -> Path:
    """Render (with the overlay unless told not to); the PNG's path follows the scene's `[output] name`."""
    run("render", str(scene), "-o", str(outdir), *(["--overlay"] if overlay else []), *options)
    return outdir / f"{load_scene(scene).output.name}.png"


def copy_to_docs(png: Path, name: str) -> None:
    with atomic_path(DOCS / name) as target:
        target.write_bytes(png.read_bytes())


def looks(folder: Path) -> None:
    """docs/looks.png: the filleted block flat, shaded (the default), shaded with soft stripe edges."""
    text = run("init", str(ROOT / "parts/filleted_block.step"), cwd=folder)
    for line in ('shading = "lambert"', "blur = 0.0"):
        if text.count(line) != 1:
            raise RuntimeError(f"rtreflect init: expected one line starting {line!r} to vary")
    panels = []
    for name, change in (("flat", ('shading = "lambert"', 'shading = "flat"')), ("lambert", ("", "")),
                         ("blur", ("blur = 0.0", "blur = 0.5"))):
        scene = folder / f"{name}.toml"
        scene.write_text(text.replace(*change) if change[0] else text)
        panels.append(linear(render(scene, folder / name, "--width", "480", "--height", "270", "--samples", "4",
                                    overlay=False)))
    final = DOCS / "looks.png"
    with atomic_path(final) as target:
        write_png(target, np.concatenate(panels, axis=1), final=final)


def linear(png: Path) -> np.ndarray:
    """The 8-bit sRGB PNG back to linear RGBA (write_png encodes again), opaque."""
    pixels, _, _ = read_image(png)
    rgb = colour.cctf_decoding(pixels[..., :3], function="sRGB")
    return np.concatenate([rgb, np.ones_like(pixels[..., 3:4])], axis=-1).astype(np.float32)


def coarse_hood(folder: Path) -> Path:
    """scenes/hood.toml with `tessellation = 4` and a 1 px overlay; fails loudly if it no longer says `tessellation = 16`."""
    text = (ROOT / "scenes/hood.toml").read_text()
    if text.count("tessellation = 16") != 1:
        raise RuntimeError("scenes/hood.toml: expected one line 'tessellation = 16' to replace with 4")
    path = folder / "hood.toml"
    path.write_text(text.replace("tessellation = 16", "tessellation = 4\noverlay_width = 1.0"))
    return path


#: The README's gallery: one shipped scene per interrogation mode besides reflection lines (docs/hood.png).
GALLERY = ("cylinder_highlight", "g1_join_isophote", "hood_curvature", "cup_draft", "hood_zebra")


def gallery(folder: Path) -> None:
    """docs/SCENE.png and, for the map modes, docs/SCENE.legend.svg, as the README's gallery commands make them."""
    for name in GALLERY:
        png = render(ROOT / f"scenes/{name}.toml", folder / name, "--width", "480", "--height", "270",
                     "--samples", "3", overlay=False)
        copy_to_docs(png, png.name)
        legend = png.with_name(f"{png.stem}.legend.svg")
        if legend.exists():
            copy_to_docs(legend, legend.name)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        copy_to_docs(render(ROOT / "scenes/hood.toml", tmp / "hood", overlay=False), "hood.png")
        looks(tmp)
        gallery(tmp)
        copy_to_docs(render(ROOT / "scenes/g1_join.toml", tmp / "g1"), "g1_join_overlay.png")
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
