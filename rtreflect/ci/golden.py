"""Golden-image testing: `assert_images_match` for pytest, and renders at golden size.

A CI pipeline renders each part's scene and compares the result with a reviewed
*golden* image; a changed surface moves the reflection lines and fails the test::

    from rtreflect.testing import assert_images_match, render_golden

    def test_hood(tmp_path):
        actual = render_golden("scenes/hood.toml", tmp_path)
        assert_images_match(actual, "golden_images/hood.exr", failpercent=0.05)

On failure the assertion message carries the report and the path of a diff image
written next to the actual file (``NAME.diff.png``: see `rtreflect.diff.diff_image`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from .diff import DiffReport, Tolerance, compare_images
from ..errors import RtreflectError
from ..integrator.film import COLOR_CHANNELS
from ..output.imagefiles import read_image, save_render
from ..integrator.autorig import resolve
from ..integrator.renderer import Renderer
from ..exchange.load import load_scene
from ..exchange.partscene import format_qualified_name
from ..exchange.scene import Scene

__all__ = ["GOLDEN_WIDTH", "GOLDEN_HEIGHT", "GOLDEN_MAX_SAMPLES", "GOLDEN_CHECKS", "golden_name", "golden_scene",
           "render_golden",
           "golden_reports", "assert_matches_golden", "assert_images_match"]

#: Golden images are rendered at this size (small: the folder stays a few MB, a render takes a second).
GOLDEN_WIDTH, GOLDEN_HEIGHT = 320, 180
#: At most s = 4 (16 samples per pixel): the scene's own s if smaller (``"analytic"`` stays analytic).
GOLDEN_MAX_SAMPLES = 4


def golden_name(path: str | Path) -> str:
    """The golden image's name for a scene file: its stem (``hood``); for a CAD part rendered in its default scene,
    stem and format (``filleted_block_step``, ``filleted_block_igs``), as one part may ship in several formats."""
    path = Path(path)
    return path.stem if path.suffix.lower() == ".toml" else format_qualified_name(path)


def golden_scene(path: str | Path) -> Scene:
    """The scene file (or CAD part) at golden size, writing ``NAME.exr`` and ``NAME.png`` (NAME: `golden_name`)."""
    scene = load_scene(path)
    samples = scene.image.samples
    samples = min(samples, GOLDEN_MAX_SAMPLES) if isinstance(samples, int) else samples
    scene = scene.with_image(GOLDEN_WIDTH, GOLDEN_HEIGHT, samples)
    return resolve(replace(scene, output=replace(scene.output, name=golden_name(path), exr=True, png=True)))


def render_golden(path: str | Path, outdir: str | Path, threads: int | None = None) -> Path:
    """Render a scene file at golden size into ``outdir`` as STEM.exr and STEM.png (byte for byte the same
    on every run on one machine); returns the EXR's path."""
    written = save_render(Renderer(golden_scene(path)).render(threads=threads), Path(outdir))
    return next(p for p in written if p.suffix == ".exr")


#: rtreflect's own golden checks of an EXR render, as keyword arguments of `assert_images_match`.
#: Colour: the default channels R G B A (after checking that both files have the same channel set).
#: They are blends of s² samples, so any change is a sample that flipped between line, surface and
#: background, worth ≥ 1/s² of a colour step; 0.01% of the pixels (5 at 320×180) may flip where a
#: sample lies exactly on a tube edge or silhouette and float rounding differs between machines.
#: AOVs: every other channel. Continuous values stored as float32, so rounding noise is ~1e-7
#: relative; a value fails beyond 1e-4 absolute *and* relative (the relative part keeps huge f near
#: grazing reflections from failing on their last bit), again with 0.01% of the pixels allowed (a
#: hit turned miss at a silhouette, a tie between two tubes or patches).
GOLDEN_CHECKS: dict[str, dict] = {
    "colour": {"fail": 1e-6, "failpercent": 0.01},
    "AOVs": {"fail": 1e-4, "failrelative": 1e-4, "failpercent": 0.01},
}


def golden_reports(actual: str | Path, golden: str | Path) -> dict[str, DiffReport]:
    """The report of each of `GOLDEN_CHECKS` for an EXR render against its golden EXR (no verdict);
    raises `DiffInputError` when the two cannot be compared (missing, other size or channel set)."""
    aovs = tuple(c for c in read_image(golden)[1] if c not in COLOR_CHANNELS) if Path(golden).exists() else ()
    reports = {}
    for check, options in GOLDEN_CHECKS.items():
        if check == "AOVs" and not aovs:
            continue
        tolerance = Tolerance(**options)
        reports[check] = compare_images(Path(actual), Path(golden), aovs if check == "AOVs" else None, tolerance)
    return reports


def assert_matches_golden(actual: str | Path, golden: str | Path) -> dict[str, DiffReport]:
    """Assert that an EXR render matches its golden EXR under every one of `GOLDEN_CHECKS`.

    The message shows every check that failed, and names a diff image per failed check,
    ``ACTUAL_STEM.CHECK.diff.png`` next to ``actual``.
    """
    actual = Path(actual)
    try:
        reports = golden_reports(actual, golden)
    except RtreflectError as exc:
        raise AssertionError(f"cannot compare {actual} with golden {golden}: {exc}") from None
    failures = []
    for check, report in reports.items():
        if not report.passed:
            target = actual.with_name(f"{actual.stem}.{check}.diff.png")
            report.write_diff_image(target)
            failures += [f"[{check}] {actual} does not match golden {golden}", *report.summary(),
                         f"diff image: {target}"]
    if failures:
        raise AssertionError("\n".join(failures))
    return reports


def assert_images_match(actual: str | Path, golden: str | Path, fail: float | None = None, failpercent: float = 0.0,
                        channels: tuple[str, ...] | str | None = None, failrelative: float = 0.0,
                        hardfail: float = math.inf, diff_image: str | Path | None = None) -> DiffReport:
    """Assert that image ``actual`` matches ``golden`` within the tolerance; return the report.

    ``fail``, ``failpercent``, ``failrelative``, ``hardfail`` and ``channels`` mean what the options of
    ``rtreflect diff`` mean (default ``fail``: 1e-6 for float images, 1/255 for 8-bit ones;
    default channels R,G,B,A). On a mismatch, or images that cannot be compared (missing
    golden, different size or channels), raises AssertionError with the report; on a
    mismatch also writes the diff image to ``diff_image`` (default: ``ACTUAL_STEM.diff.png``
    next to ``actual``) and names it in the message.
    """
    actual, golden = Path(actual), Path(golden)
    if isinstance(channels, str):
        channels = tuple(c.strip() for c in channels.split(","))
    try:
        report = compare_images(actual, golden, channels,
                                Tolerance(fail=fail, failrelative=failrelative, failpercent=failpercent,
                                          hardfail=hardfail))
    except RtreflectError as exc:
        raise AssertionError(f"cannot compare {actual} with golden {golden}: {exc}") from None
    if not report.passed:
        target = Path(diff_image) if diff_image else actual.with_name(f"{actual.stem}.diff.png")
        report.write_diff_image(target)
        raise AssertionError("\n".join([f"{actual} does not match golden {golden}", *report.summary(),
                                        f"diff image: {target}"]))
    return report
