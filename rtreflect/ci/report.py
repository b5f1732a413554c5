"""The HTML report of a batch: one static page to open from a CI job's artefacts.

`write_report` renders ``templates/report.html.j2`` (Jinja2, autoescaped) from the batch's
scene records (``rtreflect batch --json``, with the ``validate`` and ``golden`` records of
`rtreflect.ci.checks`): a summary line, then a row per scene with a thumbnail linking to
the full image, the overlay, the validation numbers, the golden comparison with its diff
image, the seam classes of the continuity check (counts per class, worst values, links to
its JSON and charts), and a failed scene's one-line reason. The page needs no server and no network:
thumbnails are small PNGs in ``STEM_files/`` beside the page (lazy-loaded, so hundreds of
rows open fast), full images are linked by relative path, and the few lines of script
(sorting by a column) are inline.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import OpenImageIO as oiio

from .. import __version__
from ..errors import RtreflectError
from ..integrator.film import COLOR_CHANNELS
from ..output.imagefiles import atomic_path, encode_srgb, muted_stderr

#: Thumbnail width in pixels: a row stays about this tall at 16:9, hundreds of rows stay light (~20 kB each).
THUMB_WIDTH = 240
#: Row verdicts, worst first: the order of a sort by status.
VERDICTS = ("failed", "check failed", "interrupted", "passed", "up to date")


def thumbnail(source: Path, target: Path, width: int = THUMB_WIDTH) -> bool:
    """``source`` scaled to ``width`` pixels wide (at most) as an 8-bit PNG at ``target``; False when the source cannot be read
    (the page then says so instead of showing a broken image).

    An 8-bit image (the PNG) is scaled as it is. A float image (an EXR of a scene with ``png = false``) has its
    R, G, B, A scaled in linear light, then encoded as rtreflect encodes its PNGs (`encode_srgb`); its AOVs are
    left out, so the thumbnail looks like the PNG would.
    """
    with muted_stderr():
        image = oiio.ImageBuf(str(source))
        spec = image.spec()
        if image.has_error or spec.width <= 0:
            oiio.geterror()
            return False
        linear = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
        if linear:
            if not all(channel in spec.channelnames for channel in COLOR_CHANNELS):
                return False
            image = oiio.ImageBufAlgo.channels(image, COLOR_CHANNELS)
        width = min(width, spec.width)  # never enlarged: a small render is its own thumbnail
        height = max(1, round(spec.height * width / spec.width))
        small = oiio.ImageBufAlgo.resize(image, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, image.nchannels))
        if linear:
            encoded = encode_srgb(small.get_pixels(oiio.FLOAT))
            small = oiio.ImageBuf(oiio.ImageSpec(width, height, len(COLOR_CHANNELS), oiio.UINT8))
            small.set_pixels(oiio.ROI(0, width, 0, height, 0, 1, 0, len(COLOR_CHANNELS)), encoded)
        target.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(target) as tmp:
            if not small.write(str(tmp), "uint8", "png"):
                raise RtreflectError(f"{target}: cannot write thumbnail ({small.geterror()})")
    return True


def _verdict(record: dict) -> str:
    if record["status"] in ("failed", "interrupted"):
        return record["status"]
    checks = [record.get("validate"), record.get("golden"), record.get("continuity")]
    if any(c is not None and (c.get("passed") is False or c.get("status") in ("mismatch", "error")) for c in checks):
        return "check failed"
    return "up to date" if record["status"] == "skipped" else "passed"


def summary(records: list[dict]) -> dict:
    """Counts for the summary line: rendered/skipped/failed scenes, validated ones and golden results."""
    count = lambda test: sum(1 for r in records if test(r))  # noqa: E731
    return {
        "scenes": len(records),
        "rendered": count(lambda r: r["status"] == "rendered"),
        "skipped": count(lambda r: r["status"] == "skipped"),
        "failed": count(lambda r: r["status"] in ("failed", "interrupted")),
        "validated": count(lambda r: r.get("validate") is not None),
        "validate_failed": count(lambda r: r.get("validate") is not None and not r["validate"]["passed"]),
        "golden": count(lambda r: r.get("golden") is not None),
        "golden_failed": count(lambda r: (r.get("golden") or {}).get("status") in ("mismatch", "error")),
        "golden_missing": count(lambda r: (r.get("golden") or {}).get("status") == "missing"),
        "continuity": count(lambda r: r.get("continuity") is not None),
        "continuity_failed": count(lambda r: r.get("continuity") is not None and not r["continuity"]["passed"]),
        "checks_failed": count(lambda r: _verdict(r) == "check failed"),
    }


def _relative(path: str | Path, start: Path) -> str:
    """A link from the page's folder to ``path`` (as a URL path: forward slashes, characters escaped)."""
    from urllib.parse import quote

    return quote(Path(os.path.relpath(Path(path).resolve(), start.resolve())).as_posix())


def write_report(path: Path, records: list[dict], outdir: Path, title: str | None = None) -> Path:
    """Write the page at ``path`` and its thumbnails in ``STEM_files/`` beside it; returns ``path``."""
    import jinja2

    path = Path(path)
    folder = path.parent
    assets = folder / f"{path.stem}_files"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if assets.exists():  # thumbnails of an earlier report: scenes since removed must not linger
            shutil.rmtree(assets)
        rows = [_row(record, folder, assets, Path(outdir)) for record in records]
        environment = jinja2.Environment(loader=jinja2.PackageLoader("rtreflect.ci", "templates"),
                                         autoescape=True, undefined=jinja2.StrictUndefined)
        page = environment.get_template("report.html.j2").render(
            title=title or f"rtreflect report: {outdir}", rows=rows, counts=summary(records), version=__version__,
            verdicts=VERDICTS)
        with atomic_path(path) as tmp:
            tmp.write_text(page, encoding="utf-8")
    except OSError as exc:
        raise RtreflectError(f"{exc.filename or path}: cannot write report ({exc.strerror or exc})") from None
    return path


def _found(path: str | Path, outdir: Path) -> Path:
    """A file a report names: as named, or else by its name in ``outdir`` (a batch's paths are relative to the
    folder it ran in, which need not be where the report is made)."""
    path = Path(path)
    return path if path.exists() or not (outdir / path.name).exists() else outdir / path.name


def _row(record: dict, folder: Path, assets: Path, outdir: Path) -> dict:
    """What the template shows of one scene: links relative to the page, thumbnails made."""
    name = record.get("name") or Path(record["scene"]).stem
    outputs = [_found(p, outdir) for p in record.get("outputs", [])]
    png = next((p for p in outputs if p.suffix == ".png"), None)
    exr = next((p for p in outputs if p.suffix == ".exr"), None)
    image = png or exr
    thumb = None
    if image is not None and image.is_file():
        target = assets / f"{name}.png"
        if thumbnail(image, target):
            thumb = _relative(target, folder)
    contours = next((p for p in outputs if p.name.endswith(".contours.json")), None)
    golden = record.get("golden")
    golden_checks = []
    if golden:
        for check, result in golden["checks"].items():
            diff = None
            diff_image = _found(result["diff_image"], outdir) if result.get("diff_image") else None
            if diff_image is not None and diff_image.is_file():
                target = assets / f"{name}.{check}.diff.png"
                diff = {"href": _relative(diff_image, folder),
                        "thumb": _relative(target, folder) if thumbnail(diff_image, target) else None}
            golden_checks.append({"check": check, **result, "diff": diff})
    return {
        "name": name, "scene": record["scene"], "status": record["status"], "verdict": _verdict(record),
        "rank": VERDICTS.index(_verdict(record)), "seconds": record.get("seconds") or 0.0,
        "error": record.get("error"), "image": _relative(image, folder) if image is not None else None,
        "image_kind": image.suffix[1:].upper() if image is not None else None, "thumb": thumb,
        "exr": _relative(exr, folder) if exr is not None else None,
        "contours": _relative(contours, folder) if contours is not None else None,
        "validate": record.get("validate"), "golden": golden, "golden_checks": golden_checks,
        "continuity": _continuity(record.get("continuity"), folder, outdir),
    }


def _continuity(record: dict | None, folder: Path, outdir: Path) -> dict | None:
    """The continuity cell: the record with its JSON and charts linked relative to the page (when they exist)."""
    if record is None:
        return None
    links = {}
    for key in ("json", "charts"):
        found = _found(record[key], outdir) if record.get(key) else None
        links[key] = _relative(found, folder) if found is not None and found.is_file() else None
    return {**record, "links": links}


def records_from_folder(outdir: Path) -> list[dict]:
    """Scene records for a folder rendered without a ``--json`` report (``rtreflect report OUTDIR``): every NAME.png
    or NAME.exr in it (not diff images), as rendered; the images do not record their scene file, so NAME stands in."""
    names: dict[str, list[str]] = {}
    for image in sorted(Path(outdir).iterdir()):
        # Not diff images, nor the charts of a batch's --continuity (NAME.continuity.charts.png).
        if (image.suffix in (".png", ".exr") and not {".diff", ".continuity"} & set(image.suffixes)
                and not image.name.startswith(".")):
            names.setdefault(image.stem, []).append(str(image))
    contours = {p.name.removesuffix(".contours.json") for p in Path(outdir).glob("*.contours.json")}
    records = []
    for name, outputs in names.items():
        if name in contours:
            outputs.append(str(Path(outdir) / f"{name}.contours.json"))
        records.append({"scene": name, "name": name, "status": "rendered", "seconds": 0.0, "outputs": outputs,
                        "error": None, "validate": None, "golden": None, "continuity": None})
    return records
