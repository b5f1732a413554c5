"""Command line: `rtreflect render SCENE... -o DIR` (contracts in docs/scene-format.md, "Command line").

Exit status: 0 success, 1 a check failed, 2 bad input (one line naming file and field),
128 + signal number when stopped by SIGINT, SIGTERM or SIGHUP (one line; unfinished files removed).
"""

from __future__ import annotations

import atexit
import gc
import os
import signal
import sys
import threading
import time
from dataclasses import asdict
from pathlib import Path

# The imports below create ~10⁵ objects that live as long as the process and no garbage: the cyclic
# collector's passes over them are pure cost (~0.1 s of a small render). Paused while they run only.
_COLLECTING = gc.isenabled()
gc.disable()
try:  # the collector back on even where an import fails (a caller importing cli goes on)
    import click  # noqa: E402
    from tqdm import tqdm  # noqa: E402

    # No tqdm monitor thread: a second CAD file read while it ran would need the reading server (~2 s CPU to
    # start; exchange/isolation.py), and the monitor only re-tunes the refresh rate of stalled bars.
    tqdm.monitor_interval = 0

    from . import __version__  # noqa: E402
    from .errors import WARNING, RtreflectError, error_lines, one_line  # noqa: E402
    from .output.imagefiles import check_distinct_outputs, output_paths, prepare_output_folder, removed_note, write_json  # noqa: E402,E501
    from .interrupts import Interrupted, interruption, signals_as_exceptions  # noqa: E402
    from .analysis.overlay import contours_file_name  # noqa: E402
    from .exchange.load import load_scene  # noqa: E402
    from .integrator.autorig import resolve  # noqa: E402
    from .exchange.scene import ANALYTIC, MAX_SAMPLES, MAX_SIDE, NORMALS_MODES, OVERLAY_SIDE  # noqa: E402
    from .output.streaming import render_to_files  # noqa: E402
    from .integrator.tiling import parse_size  # noqa: E402
    from .analysis.validate import DEFAULT_TOLERANCE_PX, validate_scene  # noqa: E402
finally:
    if _COLLECTING:
        gc.enable()

EXIT_BAD_INPUT = 2
EXIT_CHECK_FAILED = 1
#: --strict: a render that printed a warning (empty picture, no lines, ...) exits with this status.
EXIT_WARNED = 1
#: Raised by click (8.2+) for a group called without a command; older click prints the help itself.
NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


def fail(message: str | RtreflectError) -> "NoReturn":  # noqa: F821
    """Exit 2 with ``rtreflect: error: ...``: one line per problem (several for a scene with several errors)."""
    lines = error_lines(message) if isinstance(message, RtreflectError) else [message]
    for line in lines:
        click.echo(f"rtreflect: error: {one_line(line)}", err=True)
    sys.exit(EXIT_BAD_INPUT)


def samples_text(s: int | str) -> str:
    """Samples per pixel as the s×s grid they are: "4×4 = 16 samples/px", "1×1 = 1 sample/px"; or "analytic AA"."""
    if s == ANALYTIC:
        return "analytic AA"
    return f"{s}×{s} = {s * s} sample{'' if s == 1 else 's'}/px"


class SamplesType(click.ParamType):
    """``--samples``: ``analytic`` (one exact sample per pixel, stripes anti-aliased in closed form) or s in 1..16."""

    name = "analytic|S"

    def convert(self, value, param, ctx):
        if value == ANALYTIC or isinstance(value, int):
            return value
        try:
            s = int(value)
        except ValueError:
            self.fail(f"{value!r} is not {ANALYTIC!r} nor an integer from 1 to {MAX_SAMPLES}.", param, ctx)
        if not 1 <= s <= MAX_SAMPLES:
            self.fail(f"{s} is not in the range 1<=x<={MAX_SAMPLES}.", param, ctx)
        return s


SAMPLES = SamplesType()


def unique_scenes(paths: tuple[Path, ...]) -> list[Path]:
    """Each scene file once, in the order given (as `batch` does): a file named twice renders once."""
    seen: set[Path] = set()
    unique = []
    for path in paths:
        key = Path(path).resolve() if Path(path).exists() else Path(path)
        if key not in seen:
            seen.add(key)
            unique.append(path)
    return unique


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
    docs/scene-format.md.
    """


def warn(scene_path, message: str) -> None:
    """``rtreflect: warning: SCENE: message`` on stderr: the render succeeded but shows little (issue 13)."""
    click.echo(f"{WARNING}{scene_path}: {one_line(message)}", err=True)


STRICT_HELP = ("Exit 1 when a render prints a warning (empty image, no lines reflected, lines missing most of the part, "
               "a CAD face read short of the reader's promise).")


def _print_notes(scenes) -> bool:
    """What each scene's CAD files gave (faces, unit, bounding box, skipped faces), before rendering; a note that is a
    warning (a face read short of the reader's promise, starting with `errors.WARNING`) on stderr. Returns whether one
    was."""
    warned = False
    for scene in scenes:
        for line in getattr(scene, "notes", ()):
            warning = line.startswith(WARNING)
            click.echo(line, err=warning)
            warned = warned or warning
    return warned


class OverlayValueCommand(click.Command):
    """A command whose flag ``--overlay`` may also be spelled ``--overlay=side``.

    Click's flags take no value, and an option whose value may be left out would swallow the next
    word (``render --overlay scene.toml`` would read the scene as the value): so the one spelling
    with ``=`` is handed to the hidden option ``--overlay-layout``.
    """

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        end = args.index("--") if "--" in args else len(args)
        for arg in args[:end]:
            if arg.startswith("--overlay=") and arg.partition("=")[2] != OVERLAY_SIDE:
                raise click.BadOptionUsage("--overlay", f"--overlay takes no value but {OVERLAY_SIDE!r} "
                                                        f"(--overlay={OVERLAY_SIDE}), got {arg.partition('=')[2]!r}", ctx)
        args = [f"--overlay-layout={OVERLAY_SIDE}" if i < end and arg.startswith("--overlay=") else arg
                for i, arg in enumerate(args)]
        return super().parse_args(ctx, args)


@cli.command(cls=OverlayValueCommand)
@click.argument("scenes", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=click.Path(path_type=Path), default=Path("out"), show_default=True,
              help="Folder for NAME.exr and NAME.png (created if missing).")
@click.option("--width", type=click.IntRange(1, MAX_SIDE), help="Image width in pixels (overrides [image] width).")
@click.option("--height", type=click.IntRange(1, MAX_SIDE), help="Image height in pixels (overrides [image] height).")
@click.option("--samples", type=SAMPLES,
              help="analytic: stripes anti-aliased in closed form from one exact sample per pixel, edge pixels "
                   "4×4 (the default); or s: s×s stratified samples per pixel (overrides [image] samples).")
@click.option("--threads", type=click.IntRange(1, 64), default=None, help="Render threads (default: up to 2).")
@click.option("--max-memory", "max_memory", metavar="SIZE", default=None,
              help="Working memory for tiles in flight, e.g. 512M or 2G (default: a quarter of RAM). "
                   "Images are rendered and written in tiles, so any size fits.")
@click.option("--overlay/--no-overlay", default=None,
              help="Draw the analytic reflection lines (f = c_k) over the PNG and write NAME.contours.json "
                   "(overrides [render] overlay). --overlay=side: NAME.png stays plain and NAME.side.png shows "
                   "it and the overlaid picture side by side.")
@click.option("--overlay-layout", "overlay_layout", type=click.Choice([OVERLAY_SIDE]), hidden=True, default=None)
@click.option("--seams", is_flag=True,
              help="Run the continuity check and draw each seam over the PNG, coloured by its class, worst value "
                   "labelled, with a legend (as `rtreflect continuity --png`; the EXR is unchanged).")
@click.option("--normals", type=click.Choice(NORMALS_MODES), default=None,
              help="exact: the NURBS normal at the exact hit; mesh: the CAD analysis-mesh normal, for comparison "
                   "(overrides [render] normals).")
@click.option("--skip-bad-faces", "skip_bad_faces", is_flag=True,
              help="CAD input: render the faces that read and list those that do not (default: a bad face is an error).")
@click.option("--strict", is_flag=True, help=STRICT_HELP)
def render(scenes: tuple[Path, ...], outdir: Path, width, height, samples, threads, max_memory, overlay,
           overlay_layout, seams, normals, skip_bad_faces, strict) -> None:
    """Render the reflection lines of each SCENE file to OUTPUT/NAME.exr and .png.

    The EXR holds linear RGBA plus per-pixel AOVs from the pixel-centre ray
    (P.X P.Y P.Z N.X N.Y N.Z u v patch Z f line.id line.dist phi K H k1 k2: the mode's
    φ and the curvatures at the exact hit); the PNG is 8-bit sRGB.
    NAME is [output] name, by default the scene file's stem. With --overlay the PNG also
    shows the analytic reflection lines in [render] overlay_color, and NAME.contours.json
    holds them (per line: light index, polylines in pixels and in (u, v)); with
    --overlay=side NAME.png stays plain and NAME.side.png shows it beside the overlaid one. With --seams
    the PNG also shows every shared edge coloured by its continuity class (open, G0, G1,
    G2 at `rtreflect continuity`'s default tolerances), its worst value labelled, and a legend.

    \b
    A STEP, IGES or .3dm file in place of a SCENE renders the part in the automatic scene
    (camera framing the part, tubes placed where its reflections land); NAME is the file's stem.
    A scene without [camera] or [lights] gets the same automatic choices; they are printed
    and recorded in the EXR header (rtreflect:camera, rtreflect:lights).

    \b
    Warnings (stderr, exit 0; --strict: exit 1): no pixel sees the surface, no reflected
    ray reaches the light plane, fewer than two lines visible, most of the surface
    reflecting past the tube bank, a CAD face read short of the reader's promise
    (its trims coarser than asked).

    \b
    Example:
      rtreflect render scenes/hood.toml -o out/
      rtreflect render scenes/*.toml -o out/ --width 480 --height 270 --samples 2
      rtreflect render parts/plate.step -o out/
    """
    budget = memory_option(max_memory)
    if overlay_layout is not None:  # --overlay=side (`OverlayValueCommand`)
        overlay = OVERLAY_SIDE
    for path in scenes:
        if Path(path).is_dir():
            fail(f"{path}: is a folder; `rtreflect render` takes scene files: render every scene in a folder with "
                 f"`rtreflect batch {path} -o {outdir}`")
    try:
        loaded = [resolve(load_scene(path, skip_bad_faces).with_image(width, height, samples).with_render(overlay, normals))
                  for path in unique_scenes(scenes)]
        check_distinct_outputs(loaded, outdir)
        removed = prepare_output_folder(outdir, [path for scene in loaded for path in output_paths(scene, outdir)])
    except RtreflectError as exc:
        fail(exc)
    if removed:
        click.echo(f"{outdir}: {removed_note(removed)}")
    warned = _print_notes(loaded)
    for scene in loaded:
        image = scene.image
        try:
            with tqdm(total=image.width * image.height, unit="px", unit_scale=True, desc=scene.output.name,
                      leave=False, disable=None, file=sys.stderr) as bar:
                done = render_to_files(scene, outdir, threads=threads, max_memory=budget, progress=bar.update,
                                       seams=_seams_of(scene) if seams and scene.output.png else None)
            if scene.render.overlay and not scene.output.png:
                click.echo(f"{scene.output.name}: overlay not drawn ([output] png = false; the EXR never shows it), "
                           f"contours in {contours_file_name(scene)}")
            if seams and not scene.output.png:
                click.echo(f"{scene.output.name}: seams not drawn ([output] png = false; the EXR never shows them)")
        except RtreflectError as exc:
            fail(str(exc))
        st, written = done.stats, done.files
        click.echo(
            f"{scene.output.name}: {image.width}×{image.height}, {samples_text(image.samples)}, "
            f"{st.seconds:.2f} s, {st.mrays_per_second:.2f} Mrays/s, "
            f"{st.fallbacks} Newton fallbacks in {st.fallback_pixels} pixels"
            f" → {', '.join(str(p) for p in written)}" + "".join(f"; {choice}" for choice in scene.rig)
        )
        for message in done.warnings:
            warn(scene.path, message)
            warned = True
    if strict and warned:
        sys.exit(EXIT_WARNED)


def _seams_of(scene):
    """`render --seams`: the scene's continuity at the default tolerances (no line kinks: only the classes are drawn)."""
    from .analysis.seamcheck import check_scene

    return check_scene(scene, lines=False)


# -- rtreflect diff (issue 4): logic in rtreflect/diff.py ---------------------------------------
def _channel_list(ctx, param, value: str | None) -> tuple[str, ...] | None:
    if value is None:
        return None
    names = tuple(name.strip() for name in value.split(","))
    if not all(names):
        raise click.BadParameter(f"{value!r}: give channel names separated by commas, e.g. R,G,B,A or N.X,N.Y,N.Z")
    return names


@cli.command()
@click.argument("a", type=click.Path(path_type=Path))
@click.argument("b", type=click.Path(path_type=Path))
@click.option("--fail", "fail_threshold", type=click.FloatRange(min=0), default=None, metavar="T",
              help="A pixel fails when any compared channel differs by more than T "
                   "[default: 1e-6 for float images (EXR), one code value (1/255) for 8-bit images (PNG)].")
@click.option("--failrelative", type=click.FloatRange(0, 2, max_open=True), default=0.0, metavar="R",
              help="If not 0, a value fails only when it also differs by more than R times the mean of the two "
                   "values' magnitudes (for AOVs with large values, e.g. f near grazing reflections).")
@click.option("--failpercent", type=click.FloatRange(0, 100), default=0.0, show_default=True, metavar="P",
              help="Percent of pixels allowed to fail before the images mismatch.")
@click.option("--hardfail", type=click.FloatRange(min=0), default=float("inf"), metavar="T",
              help="Mismatch if any single difference exceeds T, whatever --failpercent allows [default: off].")
@click.option("--warn", type=click.FloatRange(min=0), default=None, metavar="T",
              help="A pixel warns when a channel differs by more than T [default: the --fail value].")
@click.option("--warnrelative", type=click.FloatRange(0, 2, max_open=True), default=None, metavar="R",
              help="Relative part of the warning test [default: the --failrelative value].")
@click.option("--warnpercent", type=click.FloatRange(0, 100), default=0.0, show_default=True, metavar="P",
              help="Percent of pixels allowed to warn before the result is a warning (exit 0 still).")
@click.option("--channels", callback=_channel_list, metavar="LIST",
              help="Comma-separated channels to compare, e.g. R,G,B,A or N.X,N.Y,N.Z,f "
                   "[default: the colour channels R,G,B,A; both images must then have the same channel set].")
@click.option("--diff-image", "diff_png", type=click.Path(path_type=Path), metavar="OUT.png",
              help="Write a picture of the differences: A dimmed to grey, differing pixels coloured red "
                   "(just above the threshold) to yellow (the largest error).")
@click.option("--json", "json_path", type=click.Path(path_type=Path), metavar="REPORT",
              help="Also write the report as JSON to REPORT.")
@click.option("--junit", "junit_path", type=click.Path(path_type=Path), metavar="FILE.xml", default=None,
              help="Also write the verdict as JUnit XML (one test case), for CI servers' test views.")
def diff(a: Path, b: Path, fail_threshold, failrelative, failpercent, hardfail, warn, warnrelative, warnpercent, channels,
         diff_png, json_path, junit_path) -> None:
    """Compare images A and B (EXR or PNG) for CI, with OpenImageIO's compare.

    Prints mean, RMS and max error (with its pixel and channel), PSNR and the
    number of failing pixels. The rule follows OpenImageIO's idiff: the images
    MISMATCH when more than --failpercent of the pixels differ by more than
    --fail in some channel (or one value by more than --hardfail); NaN against
    NaN is equal, NaN against a number fails.

    \b
    Exit status: 0 match (or a warning within tolerance), 1 mismatch,
    2 bad input: a missing file, different sizes or channel sets.

    A PNG (8-bit sRGB) against an EXR (linear float): the EXR's R,G,B,A are
    first encoded as rtreflect writes PNGs, and the two compared as PNGs.

    \b
    Examples (the golden images are 320×180):
      rtreflect render scenes/hood.toml -o out/ --width 320 --height 180
      rtreflect diff out/hood.exr golden_images/hood.exr --diff-image out/hood.diff.png --json out/hood.json
      rtreflect diff out/hood.exr golden_images/hood.exr --channels N.X,N.Y,N.Z --fail 1e-5
      rtreflect diff out/hood.png golden_images/hood.exr --json out/report.json
    """
    from .ci.diff import Tolerance, compare_images

    tolerance = Tolerance(fail=fail_threshold, failrelative=failrelative, failpercent=failpercent, hardfail=hardfail, warn=warn,
                          warnrelative=warnrelative, warnpercent=warnpercent)
    start = time.perf_counter()
    try:
        report = compare_images(a, b, channels, tolerance)
        report.write_files(diff_png, json_path)
        if junit_path is not None:
            from .ci.junit import diff_case, write_junit

            write_junit(junit_path, "rtreflect.diff", [diff_case(report, time.perf_counter() - start)])
    except RtreflectError as exc:
        fail(str(exc))
    click.echo("\n".join(report.summary()))
    sys.exit(0 if report.passed else EXIT_CHECK_FAILED)


# -- rtreflect validate ------------------------------------------------------------------------


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


@cli.command()
@click.argument("scenes", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--json", "report_path", type=click.Path(path_type=Path), default=None,
              help="Also write the report as JSON: scenes → NAME → max_px, p95_px, mean_px, points, misses, "
                   "colour_mismatches, colour_checked, reasons, lines.")
@click.option("--tolerance", type=click.FloatRange(0, min_open=True), default=DEFAULT_TOLERANCE_PX, show_default=True,
              help="Largest allowed deviation in pixels between traced and analytic line centres.")
@click.option("--width", type=click.IntRange(1, MAX_SIDE), help="Image width in pixels (overrides [image] width).")
@click.option("--height", type=click.IntRange(1, MAX_SIDE), help="Image height in pixels (overrides [image] height).")
@click.option("--samples", type=SAMPLES,
              help="analytic or s (s×s samples per pixel) of the checked colour image (overrides [image] samples).")
@click.option("--normals", type=click.Choice(NORMALS_MODES), default=None,
              help="Validate the exact renderer or the analysis-mesh one (overrides [render] normals).")
@click.option("--threads", type=click.IntRange(1, 64), default=None, help="Render threads (default: up to 2).")
@click.option("--skip-bad-faces", "skip_bad_faces", is_flag=True,
              help="CAD input: render the faces that read and list those that do not (default: a bad face is an error).")
@click.option("--junit", "junit_path", type=click.Path(path_type=Path), metavar="FILE.xml", default=None,
              help="Also write JUnit XML: a test case per scene, failures with the reason and the numbers.")
def validate(scenes: tuple[Path, ...], report_path: Path | None, tolerance: float, width, height, samples, normals,
             threads, skip_bad_faces, junit_path) -> None:
    """Check each SCENE's render against the analytic reflection lines (Ulmet's theorem).

    The reflection line of tube k is the image of the level set f(u, v) = c_k. The
    scene is rendered in memory (colour at its samples, AOVs from the pixel-centre rays)
    and each traced line's centre is found at sub-pixel precision where the f AOV
    crosses c_k between neighbouring pixel centres. It is compared with the analytic
    contour projected into the image: per light line and overall, the number of points,
    the mean, 95th percentile and maximum deviation in pixels, and misses (analytic
    points away from silhouettes and occlusion edges with no traced centre within
    1.5 px, and traced centres with no analytic line nearby). The colour image is
    checked too: a pixel whose every sample lies within a tube's radius (line.dist and
    its gradient, eq. 4) with the reflected ray unblocked must be fully lit, one whose
    every sample lies outside must show no line; "colour" counts the pixels that do not.

    In another [render] mode the lines are the mode's own: the phi AOV's crossings of
    the mode's levels against the analytic level sets phi(u, v) = c_k, by the same
    rules; a zebra scene also reports its parallax against equivalent physical tubes.

    Exit status 0 when every scene's maximum deviation is within --tolerance, there are
    no misses and no colour mismatches, and something was compared; 1 otherwise (the
    reason is printed), 2 on bad input.

    \b
    Example:
      rtreflect validate scenes/*.toml --json out/validate.json
      rtreflect validate scenes/hood.toml --normals mesh
    """
    try:
        loaded = [resolve(load_scene(path, skip_bad_faces).with_image(width, height, samples).with_render(normals=normals))
                  for path in scenes]
    except RtreflectError as exc:
        fail(exc)
    _print_notes(loaded)
    reports, seconds = [], []
    for scene in loaded:
        image = scene.image
        start = time.perf_counter()
        try:
            with tqdm(total=image.width * image.height, unit="px", unit_scale=True, desc=scene.output.name,
                      leave=False, disable=None, file=sys.stderr) as bar:
                report = validate_scene(scene, tolerance, progress=bar.update, threads=threads)
        except RtreflectError as exc:
            fail(str(exc))
        reports.append(report)
        seconds.append(time.perf_counter() - start)
        click.echo(f"{scene.output.name} ({scene.path}, {image.width}×{image.height}, {scene.render.normals} normals)")
        click.echo(f"  {'light':>5} {'c_k':>9} {'points':>7} {'mean_px':>8} {'p95_px':>8} {'max_px':>8} {'misses':>6}"
                   f" {'colour':>6}")
        for line in report.lines:
            click.echo(f"  {line.light:>5} {line.position:>9.4g} {line.points:>7} {_fmt(line.mean_px):>8} "
                       f"{_fmt(line.p95_px):>8} {_fmt(line.max_px):>8} {line.misses:>6} {line.colour_mismatches:>6}")
        click.echo(f"  {'all':>5} {'':>9} {report.points:>7} {_fmt(report.mean_px):>8} {_fmt(report.p95_px):>8} "
                   f"{_fmt(report.max_px):>8} {report.misses:>6} {report.colour_mismatches:>6}  "
                   f"{'PASS' if report.passed else 'FAIL'} (tolerance {tolerance:g} px; "
                   f"{report.colour_checked} pixels' colour checked)")
        if report.parallax is not None:
            par = report.parallax
            click.echo(f"  zebra parallax against tubes in the light plane (seen alike from the part's centre): "
                       f"{par['points']} points, mean {_fmt(par['mean_px'])} px, p95 {_fmt(par['p95_px'])} px, "
                       f"max {_fmt(par['max_px'])} px ({par['unmatched']} with no reflection line of their tube in "
                       f"view)")
        for reason in report.reasons:
            click.echo(f"  FAIL: {reason}")
        for note in report.notes:
            click.echo(f"  note: {note}")
    if report_path is not None:
        document = {"scenes": {}}
        for report in reports:
            # Keyed by [output] name; two scenes sharing a name are told apart by their paths.
            key = report.name if report.name not in document["scenes"] else report.path
            document["scenes"][key] = report.to_json()
        try:
            write_json(report_path, document)
        except RtreflectError as exc:
            fail(str(exc))
    if junit_path is not None:
        from .ci.checks import validate_summary
        from .ci.junit import validate_case, write_junit

        cases = [validate_case(report.name, validate_summary(report, took)) for report, took in zip(reports, seconds)]
        try:
            write_junit(junit_path, "rtreflect.validate", cases)
        except RtreflectError as exc:
            fail(str(exc))
    sys.exit(0 if all(report.passed for report in reports) else EXIT_CHECK_FAILED)


# -- rtreflect continuity (issue 16): logic in rtreflect/analysis/seamcheck.py ---------------------------
@cli.command("continuity")
@click.argument("scenes", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--json", "report_path", type=click.Path(path_type=Path), metavar="REPORT",
              help="Also write the report as JSON (edges, summary); the per-edge charts go to REPORT's stem "
                   "+ .charts.png beside it.")
@click.option("--png", "png_path", type=click.Path(path_type=Path), metavar="OUT.png",
              help="Render the scene and draw each seam over it, coloured by its class, worst value labelled.")
@click.option("--g0", type=float, default=None, metavar="TOL",
              help="Largest gap of a G0 seam, model units [default: 1e-6 of the part's size].")
@click.option("--g1", type=float, default=None, metavar="DEG", help="Largest normal angle of a G1 seam [default: 0.1].")
@click.option("--g2", type=float, default=None, metavar="FRACTION",
              help="Largest relative curvature jump |kA - kB| / max(|kA|, |kB|) of a G2 seam [default: 0.05].")
@click.option("--require", default="G0", show_default=True, metavar="G0|G1|G2",
              help="Exit 1 unless every shared edge reaches this class.")
@click.option("--lines/--no-lines", default=True, show_default=True,
              help="Measure the kink of each reflection line where it crosses a seam (needs the scene's camera "
                   "and tubes).")
@click.option("--width", type=click.IntRange(1, MAX_SIDE), help="Width of the --png render (overrides [image] width).")
@click.option("--height", type=click.IntRange(1, MAX_SIDE), help="Height of the --png render (overrides [image] height).")
@click.option("--samples", type=SAMPLES, help="analytic or s (s×s samples per pixel) of the --png render.")
@click.option("--skip-bad-faces", "skip_bad_faces", is_flag=True,
              help="CAD input: leave out faces that cannot be used (listed) instead of refusing the part.")
def continuity_command(scenes, report_path, png_path, g0, g1, g2, require, lines, width, height, samples,
                       skip_bad_faces) -> None:
    """Continuity at every shared edge of each SCENE: G0 gap, G1 angle, G2 curvature jump, exact.

    SCENE is a scene file or a CAD part (STEP, IGES, .3dm; shown in the default part scene).
    Shared edges are found geometrically (boundary curves of two faces, trim loops for CAD faces,
    that coincide over a common stretch, partial overlaps and T-junctions included). Along each edge, sampled
    adaptively, the matching point on the other patch is found by Newton, and the gap, the
    angle between the normals and the normal curvatures across the edge are computed from the
    exact NURBS derivatives. With --lines (default), each analytic reflection line crossing a
    G1 or G2 edge gets the kink angle between its two sides (the paper: a G1 seam with a
    curvature jump kinks the lines, a G2 seam does not).

    \b
    Exit status: 0 every edge reaches --require (default G0: no open seam), 1 otherwise,
    2 bad input. A scene with no shared edges is not an error.

    \b
    Examples:
      rtreflect continuity scenes/g1_join.toml --require G2
      rtreflect continuity scenes/teapot.toml --json out/teapot.json --png out/teapot.seams.png
      rtreflect continuity parts/filleted_block.step --require G1
    """
    from .analysis import seamcheck
    from .errors import quote

    require = require.upper()
    if require not in seamcheck.REQUIRE_CHOICES:
        fail(f"--require: unknown class {quote(require)}; choose one of {', '.join(seamcheck.REQUIRE_CHOICES)}")
    try:
        seamcheck.check_tolerances(g0, g1 if g1 is not None else 0.0, g2 if g2 is not None else 0.0)
        loaded = [load_scene(path, skip_bad_faces).with_image(width, height, samples) for path in unique_scenes(scenes)]
    except RtreflectError as exc:
        fail(exc)
    if png_path is not None and len(loaded) > 1:  # before anything is computed or written
        fail(f"--png: one picture per run; give one scene (got {len(loaded)})")
    g1 = seamcheck.DEFAULT_G1_DEG if g1 is None else g1
    g2 = seamcheck.DEFAULT_G2 if g2 is None else g2
    results = []
    try:
        for scene in loaded:
            result = seamcheck.check_scene(scene, g0, g1, g2, lines=lines)
            results.append(result)
            for row in seamcheck.table(result):
                click.echo(row)
            click.echo(seamcheck.summary_line(result, require))
        if report_path is not None:
            from .analysis.seampicture import charts_path, write_charts

            write_json(report_path, seamcheck.document(results, require))
            if any(r.edges for r in results):
                write_charts(charts_path(report_path), results)
        if png_path is not None:
            from .analysis.seampicture import write_seam_picture

            write_seam_picture(png_path, results[0])
    except RtreflectError as exc:
        fail(exc)
    sys.exit(0 if all(r.meets(require) for r in results) else EXIT_CHECK_FAILED)


# -- rtreflect batch ----------------------------------------------------------------------
#: Stops a batch reports before exiting: Ctrl-C (KeyboardInterrupt where `main`'s handlers are not installed,
#: e.g. click's test runner) and the stop signals `main` turns into `Interrupted`.
STOPS = (KeyboardInterrupt, Interrupted)


def stop_name(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, Interrupted) else "SIGINT"


def stop_status(exc: BaseException) -> int:
    return exc.exit_status if isinstance(exc, Interrupted) else Interrupted(signal.SIGINT).exit_status


@cli.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=click.Path(path_type=Path), default=Path("out"), show_default=True,
              help="Folder for every scene's NAME.exr and NAME.png (created if missing), as for `render`.")
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
@click.option("--skip-bad-faces", "skip_bad_faces", is_flag=True,
              help="CAD input: render the faces that read and list those that do not (default: a bad face is an error).")
@click.option("--validate", "run_validate", is_flag=True,
              help="Then check each scene against the analytic reflection lines, as `rtreflect validate` does "
                   f"(tolerance {DEFAULT_TOLERANCE_PX:g} px); a failed check exits 1.")
@click.option("--golden", "golden_dir", type=click.Path(path_type=Path, exists=True, file_okay=False), metavar="DIR",
              default=None,
              help="Then compare each OUTPUT/NAME.exr with DIR/NAME.exr by the golden checks (colour, AOVs); a "
                   "mismatch writes OUTPUT/NAME.CHECK.diff.png and exits 1; a scene without a golden is noted.")
@click.option("--continuity", "run_continuity", is_flag=True,
              help="Check every scene's seams (as `rtreflect continuity`): counts per class in --json, --report, "
                   "--junit; OUTPUT/NAME.continuity.json and .continuity.charts.png; an edge short of --require "
                   "fails the scene.")
@click.option("--require", default="G0", show_default=True, metavar="G0|G1|G2",
              help="With --continuity: the class every shared edge must reach (G0: no open seam).")
@click.option("--report", "html_path", type=click.Path(path_type=Path), metavar="FILE.html", default=None,
              help="Also write an HTML report: a row per scene with thumbnail, checks and failure reason.")
@click.option("--junit", "junit_path", type=click.Path(path_type=Path), metavar="FILE.xml", default=None,
              help="Also write JUnit XML: a test case per scene and check, for CI servers' test views.")
@click.option("--strict", is_flag=True, help=STRICT_HELP)
def batch(paths, outdir, recursive, jobs, force, report_path, max_memory, scheduler, skip_bad_faces, run_validate,
          golden_dir, run_continuity, require, html_path, junit_path, strict) -> None:
    """Render folders of scenes: every *.toml in each PATH (or PATH itself) to OUTPUT/NAME.exr and .png.

    CAD files in the folders (.step .stp .igs .iges .3dm) render too, each in the default
    scene around its part (as `rtreflect render PART`).

    Scenes render in parallel; one that fails is reported and the others go on.
    A scene whose outputs exist and were rendered from the same scene and
    geometry files by the same rtreflect version is skipped (--force renders it
    again), so an interrupted batch resumes where it stopped. Ctrl-C leaves only
    complete files. At the end a table lists scene, status, seconds and files.

    \b
    Exit status: 0 all scenes rendered or up to date, 1 some scene failed (or
    failed a --validate or --golden check), 2 bad input (no scenes, two scenes
    writing the same NAME, ...), 130 interrupted.

    \b
    Examples:
      rtreflect batch scenes/ -o out/
      rtreflect batch parts/ variants/door.toml -o out/ --recursive -j 4 --json out/report.json
      rtreflect batch scenes/ -o out/ --scheduler tcp://10.0.0.5:8786
      rtreflect batch scenes/ -o out/ --validate --report out/report.html --junit out/junit.xml
      rtreflect batch scenes/ -o out/ --continuity --require G1 --report out/report.html
    """
    from . import batch as batching
    from .analysis.seamcheck import REQUIRE_CHOICES
    from .errors import quote

    start = time.perf_counter()
    budget = memory_option(max_memory)
    if require.upper() not in REQUIRE_CHOICES:
        fail(f"--require: unknown class {quote(require)}; choose one of {', '.join(REQUIRE_CHOICES)}")
    require = require.upper()
    try:
        loaded = batching.load_jobs(batching.discover(list(paths), recursive), skip_bad_faces)
        batching.check_collisions(loaded, outdir)
        todo, reports = batching.plan(loaded, outdir, force)
        # As `render`: an unusable folder is one error up front, not one failure per scene.
        removed = prepare_output_folder(outdir, [p for job in todo for p in output_paths(job.scene, outdir)]) if todo else []
    except RtreflectError as exc:
        fail(str(exc))
    except STOPS as exc:
        click.echo(f"rtreflect: interrupted by {stop_name(exc)} before rendering; nothing written", err=True)
        sys.exit(stop_status(exc))
    if removed:
        click.echo(f"{outdir}: {removed_note(removed)}")
    notes_warned = _print_notes([job.scene for job in loaded if job.scene is not None])
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

    # The workers that run: never more than the scenes to render (run_local caps them alike).
    where = scheduler or f"local, -j {max(1, min(jobs or batching.default_jobs(), len(todo)))}"
    try:
        with bar:
            if scheduler and todo:
                from .cluster import run_on_cluster

                run_on_cluster(scheduler, todo, outdir, max_memory=budget, on_progress=bar.update, on_done=on_done)
            elif todo:
                batching.run_local(todo, outdir, workers=jobs or batching.default_jobs(), max_memory=budget,
                                   on_progress=bar.update, on_done=on_done)
    except STOPS as exc:
        done = {r.scene for r in reports}
        reports.extend(batching.SceneReport(str(job.path), job.scene.output.name, batching.INTERRUPTED)
                       for job in todo if str(job.path) not in done)
        _finish_batch(reports, order, outdir, report_path, start, where, quiet=True, html_path=html_path,
                      junit_path=junit_path)
        tally = batching.counts(reports)
        click.echo(f"rtreflect: interrupted by {stop_name(exc)}: {tally['rendered']} rendered, "
                   f"{tally['interrupted']} not finished; no partial files left, run again to resume", err=True)
        sys.exit(stop_status(exc))
    except RtreflectError as exc:
        fail(str(exc))
    if run_validate or golden_dir is not None or run_continuity:
        _check_batch(reports, loaded, outdir, run_validate, golden_dir, require if run_continuity else None)
    failed = _finish_batch(reports, order, outdir, report_path, start, where, html_path=html_path,
                           junit_path=junit_path)
    warned = notes_warned or any(getattr(report, "warnings", None) for report in reports)
    sys.exit(EXIT_CHECK_FAILED if failed or (strict and warned) else 0)


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
        line += "".join(f"; {choice}" for choice in getattr(report, "rig", None) or ())
    tqdm.write(line, file=sys.stdout)
    for message in getattr(report, "warnings", None) or ():
        tqdm.write(f"{WARNING}{report.scene}: {one_line(message)}", file=sys.stderr)


def _check_batch(reports, loaded, outdir, run_validate, golden_dir, continuity_require=None) -> None:
    """`--validate`, `--golden` and `--continuity` (``continuity_require`` the class asked): check every scene that
    rendered or was up to date, one line per check."""
    from .batch import FAILED, INTERRUPTED
    from .ci.checks import GOLDEN_MATCH, GOLDEN_MISSING, golden_record, validate_record

    scenes = {str(job.path): job.scene for job in loaded}
    for report in reports:
        scene = scenes.get(report.scene)
        if report.status in (FAILED, INTERRUPTED) or scene is None:
            continue
        if run_validate:
            report.validate = record = validate_record(scene, DEFAULT_TOLERANCE_PX)
            verdict = "PASS" if record["passed"] else f"FAIL: {'; '.join(record['reasons']) or 'see the report'}"
            numbers = "" if record.get("error") else f" (max {_fmt(record['max_px'])} px, {record['misses']} misses)"
            tqdm.write(f"{report.name}: validate {verdict}{numbers}", file=sys.stdout)
        if golden_dir is not None:
            report.golden = record = golden_record(report.name, outdir, golden_dir)
            text = {GOLDEN_MATCH: "matches", GOLDEN_MISSING: "not compared"}.get(record["status"], "FAILS")
            detail = record["error"] or ", ".join(f"{check} {c['failing_pixels']} failing px"
                                                  for check, c in record["checks"].items())
            tqdm.write(f"{report.name}: golden {text} ({detail})", file=sys.stdout)
        if continuity_require is not None:
            from .ci.checks import continuity_record

            report.continuity = record = continuity_record(scene, continuity_require, outdir)
            counts = ", ".join(f"{n} {c}" for c, n in record["counts"].items() if n) or "no shared edges"
            verdict = record["error"] or ("PASS" if record["passed"] else f"FAIL (require {continuity_require})")
            tqdm.write(f"{report.name}: continuity {verdict}: {counts}", file=sys.stdout)


def _finish_batch(reports, order, outdir, report_path, start, where, quiet=False, html_path=None,
                  junit_path=None) -> int:
    """Print the summary table, write the JSON, HTML and JUnit reports; the number of failed scenes and checks."""
    from . import batch as batching

    reports.sort(key=lambda r: order.get(r.scene, len(order)))
    tally = batching.counts(reports)
    seconds = time.perf_counter() - start
    records = [asdict(r) for r in reports]
    checks_failed = sum(1 for r in reports if (r.validate and not r.validate["passed"])
                        or (r.golden and r.golden["status"] in ("mismatch", "error"))
                        or (r.continuity and not r.continuity["passed"]))
    if not quiet:
        click.echo("")
        click.echo(batching.summary_table(reports))
        checked = f", {checks_failed} failed a check" if any(r.validate or r.golden or r.continuity
                                                              for r in reports) else ""
        click.echo(f"{tally['rendered']} rendered, {tally['skipped']} up to date, {tally['failed']} failed{checked} "
                   f"in {seconds:.1f} s ({where})")
    try:
        if report_path:
            batching.write_report(report_path, reports, outdir, seconds, where)
        if html_path:
            from .ci.report import write_report

            write_report(html_path, records, outdir)
        if junit_path:
            from .ci.junit import batch_cases, write_junit

            write_junit(junit_path, "rtreflect.batch", batch_cases(records), seconds)
    except RtreflectError as exc:
        click.echo(f"rtreflect: error: {one_line(str(exc))}", err=True)
        return max(1, tally["failed"] + checks_failed)
    return tally["failed"] + checks_failed


@cli.command("report")
@click.argument("outdir", type=click.Path(path_type=Path))
@click.option("-o", "--output", "html_path", type=click.Path(path_type=Path), default=None, metavar="FILE.html",
              help="Where to write the page [default: OUTDIR/report.html].")
@click.option("--json", "batch_json", type=click.Path(path_type=Path), default=None, metavar="REPORT",
              help="The batch's --json report: statuses, failure reasons and the --validate/--golden checks "
                   "[default: every NAME.png or NAME.exr in OUTDIR, shown as rendered].")
@click.option("--golden", "golden_dir", type=click.Path(path_type=Path, exists=True, file_okay=False), metavar="DIR",
              default=None,
              help="Compare each OUTDIR/NAME.exr with DIR/NAME.exr now (as `batch --golden`).")
@click.option("--junit", "junit_path", type=click.Path(path_type=Path), metavar="FILE.xml", default=None,
              help="Also write the same verdicts as JUnit XML.")
def report_command(outdir: Path, html_path, batch_json, golden_dir, junit_path) -> None:
    """Write the HTML report of an output folder rendered earlier (as `batch --report` does).

    One static page, no server needed: a summary line, then a row per scene with a
    thumbnail linking to the full image, the validation numbers, the golden comparison
    with its diff image, and a failed scene's reason; sortable by status. Thumbnails go
    to FILE_files/ beside the page.

    \b
    Exit status: 0 written (and nothing failed), 1 some scene or check failed, 2 bad input.

    \b
    Examples:
      rtreflect batch scenes/ -o out/ --json out/batch.json --validate
      rtreflect report out/ --json out/batch.json --golden golden_images/
    """
    import json

    from .ci.checks import golden_record
    from .ci.report import records_from_folder, summary, write_report

    if not Path(outdir).is_dir():
        fail(f"{outdir}: no such folder")
    html_path = html_path or Path(outdir) / "report.html"
    if batch_json is not None:
        try:
            records = json.loads(Path(batch_json).read_text(encoding="utf-8"))["scenes"]
            for record in records:
                record.setdefault("validate", None)
                record.setdefault("golden", None)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            fail(f"{batch_json}: not a `rtreflect batch --json` report ({getattr(exc, 'strerror', None) or exc})")
    else:
        records = records_from_folder(outdir)
    try:
        if golden_dir is not None:
            for record in records:
                if record["status"] in ("rendered", "skipped"):
                    record["golden"] = golden_record(record.get("name") or Path(record["scene"]).stem, outdir,
                                                     golden_dir)
        write_report(html_path, records, outdir)
        if junit_path is not None:
            from .ci.junit import batch_cases, write_junit

            write_junit(junit_path, "rtreflect.batch", batch_cases(records))
    except RtreflectError as exc:
        fail(str(exc))
    counts = summary(records)
    click.echo(f"{html_path}: {counts['scenes']} scenes, {counts['failed']} failed, "
               f"{counts['checks_failed']} failed a check")
    sys.exit(EXIT_CHECK_FAILED if counts["failed"] or counts["checks_failed"] else 0)


# -- rtreflect init ----------------------------------------------------------------------------
@cli.command()
@click.argument("source", type=click.Path(path_type=Path))
@click.option("--skip-bad-faces", "skip_bad_faces", is_flag=True,
              help="CAD input: leave out the faces that do not read (default: a bad face is an error).")
def init(source: Path, skip_bad_faces: bool) -> None:
    """Print the full scene file of SOURCE (a CAD part or a scene file) with the automatic choices made explicit.

    Every key is present and commented: the camera that frames the part and the tubes placed
    where its reflections land (as `render` would choose them), ready to edit and to keep
    fixed across versions of the part. Geometry paths are written relative to the working
    folder: redirect the output into a file there.

    \b
    Example:
      rtreflect init parts/plate.step > plate.toml
      rtreflect init scenes/hood.toml > hood_full.toml
    """
    from .exchange.scenewriter import scene_text, source_surfaces

    try:
        scene = resolve(load_scene(source, skip_bad_faces))
        surfaces = source_surfaces(Path(source))
    except RtreflectError as exc:
        fail(exc)
    header = (f"Scene written by `rtreflect init {source}` (rtreflect {__version__}).\n"
              "Every key is present; the automatic camera and tubes are written out, so the lines stay put\n"
              "when the part changes: keep [camera] and [lights] fixed to compare versions of a part.")
    click.echo(scene_text(scene, Path(source), surfaces, Path.cwd(), header), nl=False)


def main() -> None:
    """The `rtreflect` command: runs it, then exits at once (`exit_now`) with its status."""
    try:
        _run()
    except SystemExit as exc:
        exit_now(exc.code)
    exit_now(0)


def exit_now(code: int | str | None) -> "NoReturn":  # noqa: F821
    """Exit with ``code`` (as `sys.exit`) without the interpreter's teardown, once the command is done.

    The exit handlers still run (`atexit`: temporary folders removed, log and worker-process cleanup),
    and stdout and stderr are flushed; every output file is closed by then (written to a temporary,
    closed, renamed). What is skipped is freeing every module and object one by one, numba's and
    LLVM's above all: 0.3–0.4 s CPU after a small render, which the OS reclaims at once. Where a
    thread other than daemons is still running, the ordinary exit waits for it instead.
    """
    if isinstance(code, str):
        print(code, file=sys.stderr)
        code = 1
    code = 0 if code is None else code
    if any(t is not threading.main_thread() and not t.daemon for t in threading.enumerate()):
        sys.exit(code)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`| head`) or stream: nothing more to say
            pass
    os._exit(code)


def _run() -> None:
    # Ctrl-C, kill and a closed terminal unwind the stack (temporary files removed) and exit 128 + signal.
    with signals_as_exceptions():
        try:
            # Not standalone: click would print a usage block over several lines for a bad option.
            status = cli.main(prog_name="rtreflect", standalone_mode=False)
        except Interrupted as exc:
            _stopped(exc)
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
            sys.exit(stop_status(KeyboardInterrupt()))
        except Exception as exc:  # an error raised while the stack unwound from a signal is that signal's
            if interruption(exc) is None:
                raise
            _stopped(interruption(exc))
    sys.exit(status if isinstance(status, int) else 0)


def _stopped(exc: Interrupted) -> "NoReturn":  # noqa: F821
    click.echo(f"rtreflect: interrupted by {exc}: unfinished output removed, finished files kept", err=True)
    sys.exit(exc.exit_status)
