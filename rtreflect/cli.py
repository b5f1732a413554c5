"""Command line: `rtreflect render SCENE... -o DIR` (DESIGN.md, "Command line").

Exit status: 0 success, 1 a check failed, 2 bad input (one line naming file and field),
128 + signal number when stopped by SIGINT, SIGTERM or SIGHUP (one line; unfinished files removed).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click
from tqdm import tqdm

from . import __version__
from .errors import RtreflectError, one_line
from .imagefiles import output_paths, prepare_output_folder, save_render
from .interrupts import Interrupted, signals_as_exceptions
from .render import Renderer
from .scene import MAX_SAMPLES, MAX_SIDE, load_scene

EXIT_BAD_INPUT = 2
#: Raised by click (8.2+) for a group called without a command; older click prints the help itself.
NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


def fail(message: str) -> "NoReturn":  # noqa: F821
    click.echo(f"rtreflect: error: {one_line(message)}", err=True)
    sys.exit(EXIT_BAD_INPUT)


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
def render(scenes: tuple[Path, ...], outdir: Path, width, height, samples, threads) -> None:
    """Render the reflection lines of each SCENE file to OUTPUT/NAME.exr and .png.

    The EXR holds linear RGBA plus per-pixel AOVs from the pixel-centre ray
    (P.X P.Y P.Z N.X N.Y N.Z u v patch Z f line.id line.dist); the PNG is 8-bit sRGB.
    NAME is [output] name, by default the scene file's stem.

    \b
    Example:
      rtreflect render scenes/hood.toml -o out/
      rtreflect render scenes/*.toml -o out/ --width 480 --height 270 --samples 2
    """
    try:
        loaded = [load_scene(path).with_image(width, height, samples) for path in scenes]
        check_distinct_outputs(loaded)
        prepare_output_folder(outdir, [path for scene in loaded for path in output_paths(scene, outdir)])
    except RtreflectError as exc:
        fail(str(exc))
    for scene in loaded:
        image = scene.image
        try:
            renderer = Renderer(scene)
            with tqdm(total=image.width * image.height, unit="px", unit_scale=True, desc=scene.output.name,
                      leave=False, disable=None, file=sys.stderr) as bar:
                result = renderer.render(progress=bar.update, threads=threads)
            written = save_render(result, outdir)
        except RtreflectError as exc:
            fail(str(exc))
        st = result.stats
        click.echo(
            f"{scene.output.name}: {image.width}×{image.height}, {image.samples**2} samples/px, "
            f"{st.seconds:.2f} s, {st.mrays_per_second:.2f} Mrays/s, "
            f"{st.fallbacks} Newton fallbacks in {st.fallback_pixels} pixels"
            f" → {', '.join(str(p) for p in written)}"
        )


def check_distinct_outputs(scenes) -> None:
    """Two scenes of one run writing the same NAME would silently overwrite each other's images."""
    first: dict[str, Path] = {}
    for scene in scenes:
        earlier = first.setdefault(scene.output.name, scene.path)
        if earlier != scene.path:
            raise RtreflectError(f"{scene.path}: output.name: {scene.output.name!r} is also the output name of {earlier}")


def main() -> None:
    # Ctrl-C, kill and a closed terminal unwind the stack (temporary files removed) and exit 128 + signal.
    with signals_as_exceptions():
        try:
            # Not standalone: click would print a usage block over several lines for a bad option.
            status = cli.main(prog_name="rtreflect", standalone_mode=False)
        except Interrupted as exc:
            click.echo(f"rtreflect: interrupted by {exc}: unfinished output removed, finished files kept", err=True)
            sys.exit(exc.exit_status)
        except NO_ARGS_IS_HELP as exc:  # `rtreflect` alone: the help is the answer
            exc.show()
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            command = exc.ctx.command_path if exc.ctx else "rtreflect"
            fail(f"{command}: {exc.format_message()} (see '{command} --help')")
        except click.ClickException as exc:
            click.echo(f"rtreflect: error: {one_line(exc.format_message())}", err=True)
            sys.exit(exc.exit_code)
        except click.Abort:  # end of input at a prompt, or Ctrl-C where SIGINT could not be caught
            click.echo("rtreflect: aborted", err=True)
            sys.exit(128 + 2)
    sys.exit(status if isinstance(status, int) else 0)
