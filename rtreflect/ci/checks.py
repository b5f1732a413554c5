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
  golden image is not compared (``status: "missing"``): not a failure, and not silent;
- ``continuity``: `analysis.seamcheck.check_scene` (exact G0/G1/G2 at every shared edge and the
  reflection lines' kinks there, as `rtreflect continuity`) with the counts per class, the worst values, one short row per
  edge, and its full report and charts written as ``OUTDIR/NAME.continuity.json`` and
  ``.continuity.charts.png``; it fails when an edge falls short of the required class.
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


def continuity_file(name: str, outdir: Path) -> Path:
    """``OUTDIR/NAME.continuity.json``: the full `rtreflect continuity --json` report of a batch's scene."""
    return Path(outdir) / f"{name}.continuity.json"


def continuity_record(scene: Scene, require: str, outdir: Path) -> dict:
    """The continuity check of one scene at the default tolerances: passed when every edge reaches ``require``."""
    from ..analysis.continuity import class_rank
    from ..analysis.seamcheck import check_scene, document
    from ..analysis.seampicture import charts_path, write_charts
    from ..output.imagefiles import write_json

    start = time.perf_counter()
    report = continuity_file(scene.output.name, outdir)
    record = {"require": require, "passed": False, "edges": [], "counts": {}, "worst_class": None, "worst": {},
              "json": None, "charts": None, "error": None}
    try:
        # With the reflection lines' kinks, as `rtreflect continuity`: they add ~35 % to the teapot's check since
        # their crossings are bisected for all lights at once (they were ~7x the check before).
        result = check_scene(scene, lines=True)
        write_json(report, document([result], require))
        charts = charts_path(report) if result.edges else None
        if charts is not None:
            write_charts(charts, [result])
    except RtreflectError as exc:
        record.update(error=str(exc), seconds=time.perf_counter() - start)
        return record
    edges = result.edges
    peak = lambda values: max((v for v in values if v is not None), default=None)  # noqa: E731
    record.update(
        passed=result.meets(require), counts=result.counts(), json=str(report),
        charts=None if charts is None else str(charts),
        worst_class=min((e.cls for e in edges), key=class_rank, default=None),
        worst={"g0_max": peak(e.g0_max for e in edges), "g1_max_deg": peak(e.g1_max_deg for e in edges),
               "g2_max_rel": peak(e.g2_max_rel for e in edges),
               "line_kink_max_deg": peak(e.line_kink_max_deg for e in edges)},
        edges=[{"patches": [e.seam.a.patch, e.seam.b.patch], "class": e.cls, "g0_max": e.g0_max,
                "g1_max_deg": e.g1_max_deg, "g2_max_rel": e.g2_max_rel, "line_kink_max_deg": e.line_kink_max_deg}
               for e in edges],
        seconds=time.perf_counter() - start)
    return record
