"""The CI checks of a batch's outputs: `rtreflect batch --validate` and `--golden DIR`.

Each check turns into a JSON-ready record stored with the scene's batch record (the
``--json`` report), which the HTML report (`rtreflect.ci.report`) and the JUnit XML
(`rtreflect.ci.junit`) are drawn from:

- ``validate``: `validate_scene` (Ulmet's analytic reflection lines against the traced
  ones, paper section 4) with its headline numbers: max and p95 deviation in pixels,
  misses, colour mismatches, the verdict and its reasons;
- ``golden``: `golden_reports`, the checks of `GOLDEN_CHECKS` (colour, AOVs) of
  ``OUTDIR/NAME.exr`` against ``DIR/NAME.exr``; a failed check writes its diff image
  ``OUTDIR/NAME.CHECK.diff.png`` (as `assert_matches_golden` does). A scene without a
  golden image is not compared (``status: "missing"``): not a failure, and not silent.
"""

from __future__ import annotations

import time
from pathlib import Path

from .golden import golden_reports
from ..errors import RtreflectError
from ..exchange.scene import Scene

#: Golden record statuses: every check matched, some check failed, no golden image to compare with,
#: or the two could not be compared (missing render, other size or channel set).
GOLDEN_MATCH, GOLDEN_MISMATCH, GOLDEN_MISSING, GOLDEN_ERROR = "match", "mismatch", "missing", "error"


def validate_record(scene: Scene, tolerance: float, threads: int | None = None) -> dict:
    """`validate_scene`'s verdict and headline numbers for one scene, with the seconds it took."""
    from ..analysis.validate import validate_scene

    start = time.perf_counter()
    try:
        report = validate_scene(scene, tolerance, threads=threads)
    except RtreflectError as exc:
        return {"passed": False, "error": str(exc), "reasons": [str(exc)], "seconds": time.perf_counter() - start}
    return validate_summary(report, time.perf_counter() - start)


def validate_summary(report, seconds: float) -> dict:
    """The headline of a validation `SceneReport` (what the HTML report and JUnit XML show)."""
    return {"passed": report.passed, "tolerance": report.tolerance, "max_px": report.max_px, "p95_px": report.p95_px,
            "points": report.points, "misses": report.misses, "colour_mismatches": report.colour_mismatches,
            "reasons": list(report.reasons), "notes": list(report.notes), "error": None, "seconds": seconds}


def golden_record(name: str, outdir: Path, golden_dir: Path) -> dict:
    """The golden checks of ``outdir/NAME.exr`` against ``golden_dir/NAME.exr``; diff images for failed checks."""
    start = time.perf_counter()
    actual, golden = Path(outdir) / f"{name}.exr", Path(golden_dir) / f"{name}.exr"
    record = {"golden": str(golden), "status": GOLDEN_MATCH, "checks": {}, "error": None}
    if not golden.is_file():
        record.update(status=GOLDEN_MISSING, error=f"{golden}: no golden image")
    else:
        try:
            reports = golden_reports(actual, golden)
        except RtreflectError as exc:
            record.update(status=GOLDEN_ERROR, error=str(exc))
            reports = {}
        for check, report in reports.items():
            diff_image = None
            if not report.passed:
                record["status"] = GOLDEN_MISMATCH
                diff_image = actual.with_name(f"{name}.{check}.diff.png")
                report.write_diff_image(diff_image)
            record["checks"][check] = {"passed": report.passed, "failing_pixels": report.failing_pixels,
                                       "pixels": report.pixels, "failpercent": report.failpercent,
                                       "diff_image": None if diff_image is None else str(diff_image)}
    record["seconds"] = time.perf_counter() - start
    return record
