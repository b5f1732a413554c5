"""Command line: `rtreflect render SCENE... -o DIR` (DESIGN.md, "Command line").

Exit status: 0 success, 1 a check failed, 2 bad input (one line naming file and field).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click
from tqdm import tqdm

from . import __version__
from .errors import RtreflectError
from .scene import MAX_SAMPLES, MAX_SIDE, load_scene
from .streaming import render_to_files
from .tiling import parse_size

EXIT_BAD_INPUT = 2


def fail(message: str) -> "NoReturn":  # noqa: F821
    click.echo(f"rtreflect: error: {message}", err=True)
    sys.exit(EXIT_BAD_INPUT)


def memory_option(text: str | None) -> int | None:
    """--max-memory SIZE in bytes (None: the default budget); a malformed size exits 2."""
    if text is None:
        return None
    try:
        return parse_size(text)
    except ValueError as exc:
        fail(f"--max-memory: {exc}")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rtreflect")
def cli() -> None:
    """Ray-traced reflection lines on NURBS surfaces, with exact normals.

    A row of parallel tube lights is mirrored in the surface; kinks and wobbles
    in the mirrored lines reveal curvature breaks and dents. Scene files (TOML)
    describe the image, camera, light tubes and NURBS surfaces: see scenes/ and
    DESIGN.md.
    """


@cli.command()
@click.argument("scenes", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=click.Path(path_type=Path), default=Path("out"), show_default=True,
              help="Folder for NAME.exr and NAME.png (created if missing).")
@click.option("--width", type=click.IntRange(1, MAX_SIDE), help="Image width in pixels (overrides [image] width).")
@click.option("--height", type=click.IntRange(1, MAX_SIDE), help="Image height in pixels (overrides [image] height).")
@click.option("--samples", type=click.IntRange(1, MAX_SAMPLES),
              help="s: s×s stratified samples per pixel for anti-aliasing (overrides [image] samples).")
@click.option("--threads", type=click.IntRange(1, 64), default=None, help="Render threads (default: up to 2).")
@click.option("--max-memory", "max_memory", metavar="SIZE", default=None,
              help="Working memory for tiles in flight, e.g. 512M or 2G (default: a quarter of RAM). "
                   "Images are rendered and written in tiles, so any size fits.")
def render(scenes: tuple[Path, ...], outdir: Path, width, height, samples, threads, max_memory) -> None:
    """Render the reflection lines of each SCENE file to OUTPUT/NAME.exr and .png.

    The EXR holds linear RGBA plus per-pixel AOVs from the pixel-centre ray
    (P.X P.Y P.Z N.X N.Y N.Z u v patch Z f line.id line.dist); the PNG is 8-bit sRGB.
    NAME is [output] name, by default the scene file's stem.

    \b
    Example:
      rtreflect render scenes/hood.toml -o out/
      rtreflect render scenes/*.toml -o out/ --width 480 --height 270 --samples 2
    """
    budget = memory_option(max_memory)
    try:
        loaded = [load_scene(path).with_image(width, height, samples) for path in scenes]
    except RtreflectError as exc:
        fail(str(exc))
    for scene in loaded:
        image = scene.image
        try:
            with tqdm(total=image.width * image.height, unit="px", unit_scale=True, desc=scene.output.name,
                      leave=False, disable=None, file=sys.stderr) as bar:
                done = render_to_files(scene, outdir, threads=threads, max_memory=budget, progress=bar.update)
        except RtreflectError as exc:
            fail(str(exc))
        st, written = done.stats, done.files
        click.echo(
            f"{scene.output.name}: {image.width}×{image.height}, {image.samples**2} samples/px, "
            f"{st.seconds:.2f} s, {st.mrays_per_second:.2f} Mrays/s, {st.fallbacks} Newton fallbacks"
            f" → {', '.join(str(p) for p in written)}"
        )


def main() -> None:
    cli(prog_name="rtreflect")
