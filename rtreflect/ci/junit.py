"""JUnit XML test reports (``--junit FILE`` of `validate`, `diff` and `batch`).

The format is the Ant JUnit task's, which GitLab, Jenkins and the GitHub test-report
actions read: ``<testsuites>`` holding one ``<testsuite>`` whose ``<testcase>``
elements are rtreflect's checks, one per scene and check (``classname`` the scene,
``name`` the check). A failed check carries ``<failure message=... type=...>`` with the
one-line reason as message and the key numbers as text; a check not run (no golden
image, a scene up to date) is ``<skipped>``. Every attribute the common schema requires
is written (``timestamp`` without a time zone, ``hostname``, ``time`` in seconds, the
suite's ``package`` and ``id``), so the file validates against that schema
(tests/data/junit.xsd).
"""

from __future__ import annotations

import datetime
import socket
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from .. import __version__
from ..errors import RtreflectError, one_line
from ..output.imagefiles import atomic_path

#: Failure types: the check's verdict (a test that ran and failed) or a scene that could not run at all.
FAILED_CHECK, BAD_INPUT = "rtreflect.CheckFailed", "rtreflect.Error"


@dataclass
class TestCase:
    """One check of one scene: passed (no ``failure``, no ``skipped``), failed, or not run."""

    __test__ = False  # not a pytest test class, despite the name

    classname: str  # the scene: its [output] name, or its file when it could not be read
    name: str  # the check: render, validate, golden colour, diff, ...
    seconds: float = 0.0
    failure: str | None = None  # the one-line reason
    failure_type: str = FAILED_CHECK
    skipped: str | None = None  # why the check did not run
    details: str = ""  # the key numbers, one line: in the failure's text, and in the suite's output

    @property
    def passed(self) -> bool:
        return self.failure is None and self.skipped is None


def junit_document(suite: str, cases: list[TestCase], seconds: float | None = None) -> ET.ElementTree:
    """The XML tree of one suite named ``suite`` (``rtreflect.batch``, ``rtreflect.validate``, ...)."""
    total = sum(case.seconds for case in cases) if seconds is None else seconds
    root = ET.Element("testsuites")  # the schema gives the aggregate no attributes of its own
    testsuite = ET.SubElement(root, "testsuite", {
        "name": suite, "package": suite, "id": "0", "tests": str(len(cases)),
        "failures": str(sum(c.failure is not None for c in cases)), "errors": "0",
        "skipped": str(sum(c.skipped is not None and c.failure is None for c in cases)), "time": f"{total:.3f}",
        # The schema's timestamp has no zone and no fraction: local wall time is what CI servers show.
        "timestamp": datetime.datetime.now().replace(microsecond=0).isoformat(),
        "hostname": socket.gethostname() or "localhost"})
    properties = ET.SubElement(testsuite, "properties")
    ET.SubElement(properties, "property", name="rtreflect.version", value=__version__)
    for case in cases:
        element = ET.SubElement(testsuite, "testcase", classname=case.classname, name=case.name,
                                time=f"{case.seconds:.3f}")
        if case.failure is not None:
            failure = ET.SubElement(element, "failure", message=one_line(case.failure), type=case.failure_type)
            failure.text = "\n".join(filter(None, [one_line(case.failure), one_line(case.details)]))
        elif case.skipped is not None:
            ET.SubElement(element, "skipped", message=one_line(case.skipped))
    # The schema allows no output per test case: every case's numbers go to the suite's output, one line each.
    ET.SubElement(testsuite, "system-out").text = "\n".join(
        f"{case.classname} {case.name}: {'PASS' if case.passed else 'SKIPPED' if case.failure is None else 'FAIL'}"
        + (f" ({case.details})" if case.details else "") for case in cases)
    ET.SubElement(testsuite, "system-err").text = ""
    ET.indent(root)
    return ET.ElementTree(root)


def write_junit(path: Path, suite: str, cases: list[TestCase], seconds: float | None = None) -> None:
    """Write the suite to ``path`` atomically (folder created); an unwritable path is an `RtreflectError`."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            junit_document(suite, cases, seconds).write(tmp, encoding="UTF-8", xml_declaration=True)
    except OSError as exc:
        raise RtreflectError(f"{path}: cannot write JUnit report ({exc.strerror or exc})") from None


# -- test cases of rtreflect's commands --------------------------------------------------------
def _px(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def validate_case(classname: str, record: dict) -> TestCase:
    """A validation record (`checks.validate_summary`) as the case ``validate``."""
    if record.get("error"):
        return TestCase(classname, "validate", record["seconds"], failure=record["error"], failure_type=BAD_INPUT)
    details = (f"max_px {_px(record['max_px'])}, p95_px {_px(record['p95_px'])}, points {record['points']}, "
               f"misses {record['misses']}, colour_mismatches {record['colour_mismatches']}, "
               f"tolerance {record['tolerance']:g} px")
    failure = None
    if not record["passed"]:
        failure = "; ".join(record["reasons"]) or (
            f"max deviation {_px(record['max_px'])} px > {record['tolerance']:g} px" if (record["max_px"] or 0) >
            record["tolerance"] else f"{record['misses']} misses, {record['colour_mismatches']} colour mismatches")
    return TestCase(classname, "validate", record["seconds"], failure=failure, details=details)


def golden_cases(classname: str, record: dict) -> list[TestCase]:
    """A golden record (`checks.golden_record`): one case per check (``golden colour``, ``golden AOVs``), or one
    ``golden`` case skipped (no golden image) or failed (the two could not be compared)."""
    from .checks import GOLDEN_ERROR, GOLDEN_MISSING

    seconds = record["seconds"]
    if record["status"] == GOLDEN_MISSING:
        return [TestCase(classname, "golden", seconds, skipped=record["error"])]
    if record["status"] == GOLDEN_ERROR:
        return [TestCase(classname, "golden", seconds, failure=record["error"], failure_type=BAD_INPUT)]
    cases = []
    share = seconds / max(1, len(record["checks"]))  # one comparison per check, of about equal cost
    for check, result in record["checks"].items():
        details = (f"failing pixels {result['failing_pixels']} of {result['pixels']} "
                   f"(allowed {result['failpercent']:g}%)" + (f", diff image {result['diff_image']}"
                                                             if result["diff_image"] else ""))
        failure = None if result["passed"] else f"{check}: does not match golden {record['golden']}"
        cases.append(TestCase(classname, f"golden {check}", share, failure=failure, details=details))
    return cases


def batch_cases(records: list[dict]) -> list[TestCase]:
    """The batch's scene records (its ``--json`` report): per scene a ``render`` case, then its checks."""
    cases = []
    for record in records:
        classname = record.get("name") or Path(record["scene"]).stem  # as the HTML report names the row
        status = record["status"]
        if status == "failed":
            cases.append(TestCase(classname, "render", record["seconds"], failure=record["error"],
                                  failure_type=BAD_INPUT))
        elif status == "interrupted":
            cases.append(TestCase(classname, "render", record["seconds"], failure="interrupted before it finished",
                                  failure_type=BAD_INPUT))
        else:
            detail = "up to date, not rendered again" if status == "skipped" else (
                f"{record['tiles']} tiles, {record['rays']} rays")
            cases.append(TestCase(classname, "render", record["seconds"], details=f"{status}: {detail}; "
                                  f"{', '.join(record['outputs'])}"))
        if record.get("validate"):
            cases.append(validate_case(classname, record["validate"]))
        if record.get("golden"):
            cases.extend(golden_cases(classname, record["golden"]))
        if record.get("continuity"):
            cases.append(continuity_case(classname, record["continuity"]))
    return cases


def continuity_case(classname: str, record: dict) -> TestCase:
    """A continuity record (`checks.continuity_record`) as the case ``continuity``: fails on an edge short of
    the required class (open, by default)."""
    if record.get("error"):
        return TestCase(classname, "continuity", record["seconds"], failure=record["error"], failure_type=BAD_INPUT)
    counts = ", ".join(f"{n} {cls}" for cls, n in record["counts"].items() if n) or "no shared edges"
    worst = record["worst"]
    n = len(record["edges"])
    details = (f"{n} edge{'' if n == 1 else 's'} ({counts}); worst g0 {_g(worst.get('g0_max'))}, "
               f"g1 {_g(worst.get('g1_max_deg'))} deg, g2 {_g(worst.get('g2_max_rel'))} relative; "
               f"require {record['require']}")
    failure = None
    if not record["passed"]:
        from ..analysis.continuity import class_rank

        short = [f"{e['patches'][0]}-{e['patches'][1]} {e['class']}" for e in record["edges"]
                 if class_rank(e["class"]) < class_rank(record["require"])]
        failure = (f"{len(short)} edge{'' if len(short) == 1 else 's'} short of {record['require']}: "
                   f"{', '.join(short[:5])}{' ...' if len(short) > 5 else ''}")
    return TestCase(classname, "continuity", record["seconds"], failure=failure, details=details)


def _g(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def diff_case(report, seconds: float) -> TestCase:
    """`rtreflect diff`'s `DiffReport` as one case: classname image A, name ``diff B``."""
    details = (f"failing pixels {report.failing_pixels} of {report.pixels} (allowed {report.failpercent:g}%), "
               f"max error {report.max_error or 0}, PSNR {report.psnr:.2f} dB")
    failure = None if report.passed else f"{report.a} does not match {report.b}"
    return TestCase(str(report.a), f"diff {report.b}", seconds, failure=failure, details=details)
