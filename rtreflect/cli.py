"""Command line: `rtreflect render SCENE... -o DIR` (DESIGN.md, "Command line").

Exit status: 0 success, 1 a check failed, 2 bad input (one line naming file and field).
"""

from __future__ import annotations

import sys
import time
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


# -- rtreflect batch ----------------------------------------------------------------------
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130


@cli.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=click.Path(path_type=Path), required=True,
              help="Folder for every scene's NAME.exr and NAME.png (created if missing).")
@click.option("-r", "--recursive", is_flag=True, help="Search folders' sub-folders for *.toml too.")
@click.option("-j", "--jobs", type=click.IntRange(1, 1024), default=None,
              help="Scenes rendered at once on this machine (default: the number of cores).")
@click.option("--force", is_flag=True, help="Render every scene, even those whose outputs are up to date.")
@click.option("--json", "report_path", type=click.Path(path_type=Path), metavar="REPORT",
              help="Also write the summary as JSON to REPORT.")
@click.option("--max-memory", "max_memory", metavar="SIZE", default=None,
              help="Working memory for tiles, e.g. 512M or 2G (default: a quarter of RAM), shared by the -j "
                   "workers; with --scheduler, per tile task.")
@click.option("--scheduler", metavar="tcp://HOST:PORT", default=None,
              help="Render on this dask.distributed cluster instead of locally (needs rtreflect[dask]).")
def batch(paths, outdir, recursive, jobs, force, report_path, max_memory, scheduler) -> None:
    """Render folders of scenes: every *.toml in each PATH (or PATH itself) to OUTPUT/NAME.exr and .png.

    Scenes render in parallel; one that fails is reported and the others go on.
    A scene whose outputs exist and were rendered from the same scene and
    geometry files by the same rtreflect version is skipped (--force renders it
    again), so an interrupted batch resumes where it stopped. Ctrl-C leaves only
    complete files. At the end a table lists scene, status, seconds and files.

    \b
    Exit status: 0 all scenes rendered or up to date, 1 some scene failed,
    2 bad input (no scenes, two scenes writing the same NAME, ...), 130 interrupted.

    \b
    Examples:
      rtreflect batch scenes/ -o out/
      rtreflect batch parts/ variants/door.toml -o out/ --recursive -j 4 --json out/report.json
      rtreflect batch scenes/ -o out/ --scheduler tcp://10.0.0.5:8786
    """
    from . import batch as batching

    start = time.perf_counter()
    budget = memory_option(max_memory)
    try:
        loaded = batching.load_jobs(batching.discover(list(paths), recursive))
        batching.check_collisions(loaded, outdir)
        todo, reports = batching.plan(loaded, outdir, force)
    except RtreflectError as exc:
        fail(str(exc))
    except KeyboardInterrupt:
        click.echo("rtreflect: interrupted before rendering; nothing written", err=True)
        sys.exit(EXIT_INTERRUPTED)
    for report in reports:
        _print_scene(report)
    order = {str(job.path): i for i, job in enumerate(loaded)}
    total_pixels = sum(job.scene.image.width * job.scene.image.height for job in todo)
    bar = tqdm(total=total_pixels, unit="px", unit_scale=True, disable=None, file=sys.stderr, dynamic_ncols=True,
               desc=f"0/{len(todo)} scenes")

    finished = [0]

    def on_done(report) -> None:
        reports.append(report)
        finished[0] += 1
        bar.set_description(f"{finished[0]}/{len(todo)} scenes")
        _print_scene(report)

    where = scheduler or f"local, -j {jobs or batching.default_jobs()}"
    try:
        with bar:
            if scheduler and todo:
                from .cluster import run_on_cluster

                run_on_cluster(scheduler, todo, outdir, max_memory=budget, on_progress=bar.update, on_done=on_done)
            elif todo:
                batching.run_local(todo, outdir, workers=jobs or batching.default_jobs(), max_memory=budget,
                                   on_progress=bar.update, on_done=on_done)
    except KeyboardInterrupt:
        done = {r.scene for r in reports}
        reports.extend(batching.SceneReport(str(job.path), job.scene.output.name, batching.INTERRUPTED)
                       for job in todo if str(job.path) not in done)
        _finish_batch(reports, order, outdir, report_path, start, where, quiet=True)
        tally = batching.counts(reports)
        click.echo(f"rtreflect: interrupted: {tally['rendered']} rendered, {tally['interrupted']} not finished; "
                   "no partial files left, run again to resume", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except RtreflectError as exc:
        fail(str(exc))
    failed = _finish_batch(reports, order, outdir, report_path, start, where)
    sys.exit(EXIT_FAILED if failed else 0)


def _print_scene(report) -> None:
    """The line printed as a scene finishes (written above the progress bar)."""
    name = report.name or Path(report.scene).stem
    if report.status == "failed":
        line = f"{name}: FAILED: {report.error}"
    elif report.status == "skipped":
        line = f"{name}: up to date, skipped"
    else:
        tiles = f"{report.tiles} tile{'' if report.tiles == 1 else 's'}"
        line = f"{name}: rendered in {report.seconds:.2f} s ({tiles}) → {', '.join(report.outputs)}"
    tqdm.write(line, file=sys.stdout)


def _finish_batch(reports, order, outdir, report_path, start, where, quiet=False) -> int:
    """Print the summary table, write the JSON report; the number of failed scenes."""
    from . import batch as batching

    reports.sort(key=lambda r: order.get(r.scene, len(order)))
    tally = batching.counts(reports)
    seconds = time.perf_counter() - start
    if not quiet:
        click.echo("")
        click.echo(batching.summary_table(reports))
        click.echo(f"{tally['rendered']} rendered, {tally['skipped']} up to date, {tally['failed']} failed "
                   f"in {seconds:.1f} s ({where})")
    if report_path:
        try:
            batching.write_report(report_path, reports, outdir, seconds, where)
        except RtreflectError as exc:
            click.echo(f"rtreflect: error: {exc}", err=True)
            return max(1, tally["failed"])
    return tally["failed"]


def main() -> None:
    cli(prog_name="rtreflect")
