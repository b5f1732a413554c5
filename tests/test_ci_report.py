"""CI outputs of issue 17: the HTML report opened in a real browser, JUnit XML against the common schema.

The page is checked in headless Chromium (tests/browser.py) as a person would see it:
every image loads (naturalWidth > 0, the browser's own decoding), one row per scene of
the batch, the broken scene marked failed with its reason, sorting by status puts the
failures first; a full-page screenshot is written for people to look at. The JUnit
files are validated against tests/data/junit.xsd (the common Ant/Jenkins schema) by
xmlschema, an independent validator, and must list the verdicts the batch's JSON has.
"""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from click.testing import CliRunner

from browser import Browser, chromium_path
from rtreflect.cli import cli
from rtreflect.ci.report import THUMB_WIDTH
from test_batch import small_scene

XSD = Path(__file__).resolve().parent / "data" / "junit.xsd"
SHIPPED = ("cylinder", "g1_join", "hood", "teapot")


def run(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output


def junit_schema():
    xmlschema = pytest.importorskip("xmlschema")
    return xmlschema.XMLSchema(str(XSD))


def junit_verdicts(path: Path) -> dict[tuple[str, str], str]:
    """(scene, check) → pass | fail | skipped, read from a JUnit file."""
    verdicts = {}
    for case in ET.parse(path).getroot().iter("testcase"):
        kind = "fail" if case.find("failure") is not None else "skipped" if case.find("skipped") is not None else "pass"
        verdicts[(case.get("classname"), case.get("name"))] = kind
    return verdicts


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory) -> dict:
    """The shipped scenes (small) and a broken one, batched with --validate, --golden, --continuity, --report and --junit.
    Goldens: cylinder's rendered at other samples (a mismatch), hood's missing, the others the same render."""
    root = tmp_path_factory.mktemp("ci_report")
    scenes, golden, out = root / "scenes", root / "golden", root / "out"
    for name in SHIPPED:
        small_scene(name, scenes / f"{name}.toml", samples=2 if name == "cylinder" else 1)
    code, output = run("batch", scenes, "-o", golden, "-j", "1")
    assert code == 0, output
    for path in golden.glob("hood.*"):
        path.unlink()
    small_scene("cylinder", scenes / "cylinder.toml", samples=1)
    (scenes / "broken.toml").write_text((scenes / "hood.toml").read_text().replace("radius", "radios", 1))
    code, output = run("batch", scenes, "-o", out, "-j", "1", "--validate", "--golden", golden, "--continuity",
                       "--report", out / "report.html", "--junit", out / "junit.xml", "--json", out / "batch.json")
    assert code == 1, output  # a scene failed, and cylinder failed its golden check
    return {"root": root, "out": out, "output": output, "report": json.loads((out / "batch.json").read_text())}


@pytest.fixture(scope="module")
def page(batch_run, tmp_path_factory):
    if chromium_path() is None:
        pytest.skip("needs Debian's chromium (.ci/run installs it)")
    browser = Browser(tmp_path_factory.mktemp("chromium_profile"))
    try:
        browser.open((batch_run["out"] / "report.html").as_uri())
        yield browser
    finally:
        browser.close()


ROWS = """[...document.querySelectorAll('#scenes tbody tr')].map(tr => ({
    name: tr.dataset.name, verdict: tr.dataset.verdict, badge: tr.querySelector('.verdict').textContent,
    text: tr.innerText}))"""

#: Every image as the browser decoded it, after asking the lazy ones to load now (a person scrolling would).
IMAGES = """(async () => {
    const images = [...document.images];
    const lazy = images.map(img => img.getAttribute('loading'));
    images.forEach(img => { img.loading = 'eager'; });
    await Promise.all(images.map(img => img.complete ? null : new Promise(done => {
        img.addEventListener('load', done); img.addEventListener('error', done); })));
    return images.map((img, i) => ({src: img.getAttribute('src'), width: img.naturalWidth, loading: lazy[i]}));
})()"""


def test_report_in_a_browser_shows_every_scene_the_failure_and_loads_every_image(batch_run, page, tmp_path):
    rows = page.evaluate(ROWS)
    scenes = batch_run["report"]["scenes"]
    assert len(rows) == len(scenes) == 5
    by_name = {row["name"]: row for row in rows}
    assert by_name["broken"]["verdict"] == "failed" and by_name["broken"]["badge"] == "FAILED"
    assert "lights.radios: unknown key" in by_name["broken"]["text"]
    assert by_name["cylinder"]["verdict"] == "check failed" and "MISMATCH" in by_name["cylinder"]["text"]
    assert all(by_name[name]["verdict"] == "passed" for name in ("g1_join", "hood", "teapot"))
    assert "no golden image" in by_name["hood"]["text"]

    images = page.evaluate(IMAGES)
    # a thumbnail per rendered scene and cylinder's colour diff image, each decoded by the browser
    assert len(images) == 5, images
    broken = [image for image in images if image["width"] == 0]
    assert not broken, broken
    # thumbnails are at most THUMB_WIDTH wide, never enlarged: these renders are 160 px wide
    assert all(image["loading"] == "lazy" and image["width"] == min(THUMB_WIDTH, 160) for image in images), images
    assert all(image["src"].startswith("report_files/") for image in images)  # thumbnails, not the full images

    shot = page.screenshot(tmp_path / "report.png")
    shutil.copy(shot, batch_run["root"] / "report-screenshot.png")  # for people: pytest's temp folder keeps it
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


#: The seam-classes cell of each row: its text, and the links it holds.
CONTINUITY = """[...document.querySelectorAll('#scenes tbody tr')].map(tr => {
    const cell = tr.querySelector('td.continuity');
    return {name: tr.dataset.name, text: cell.innerText,
            links: Object.fromEntries([...cell.querySelectorAll('a')].map(a => [a.textContent, a.href]))}; })"""


def test_report_shows_the_seam_classes_of_batch_continuity(batch_run, page):
    """Issue 17's row shows issue 16's seam classes: g1_join one G1 edge (its known class), the teapot's seams G1
    and G2 as `rtreflect continuity` finds them, no seams on the single-patch scenes, nothing for the broken one."""
    cells = {cell["name"]: cell for cell in page.evaluate(CONTINUITY)}
    records = {Path(s["scene"]).stem: s["continuity"] for s in batch_run["report"]["scenes"]}
    assert records["broken"] is None and "not run" in cells["broken"]["text"]
    assert records["g1_join"]["counts"] == {"open": 0, "G0": 0, "G1": 1, "G2": 0}
    assert "PASS" in cells["g1_join"]["text"] and "1 G1" in cells["g1_join"]["text"]
    teapot = records["teapot"]["counts"]
    assert teapot["open"] == 0 and teapot["G1"] > 0 and teapot["G2"] > 0
    assert f"{teapot['G1']} G1, {teapot['G2']} G2" in cells["teapot"]["text"]
    jump = records["g1_join"]["worst"]["g2_max_rel"]
    assert jump > 0.05 and f"curvature jump {100 * jump:.0f}%" in cells["g1_join"]["text"]
    for name in ("hood", "cylinder"):
        assert "no shared edges" in cells[name]["text"] and records[name]["edges"] == []
    for name in ("g1_join", "teapot"):  # the links lead to the files written beside the renders
        links = cells[name]["links"]
        assert set(links) == {"continuity JSON", "charts"}, links
        for href in links.values():
            assert Path(href.removeprefix("file://")).is_file(), href
        document = json.loads((batch_run["out"] / f"{name}.continuity.json").read_text())
        assert len(document["edges"]) == len(records[name]["edges"])


def test_batch_continuity_measures_the_line_kinks_as_rtreflect_continuity(batch_run):
    """`batch --continuity` includes the reflection lines' kinks: g1_join's G1 seam kinks its lines by tens of degrees
    (the paper's statement, as `rtreflect continuity` prints it); the teapot's G2 seams do not kink them."""
    records = {Path(s["scene"]).stem: s["continuity"] for s in batch_run["report"]["scenes"]}
    assert records["g1_join"]["worst"]["line_kink_max_deg"] > 10.0
    document = json.loads((batch_run["out"] / "g1_join.continuity.json").read_text())
    assert document["edges"][0]["line_kink_max_deg"] == records["g1_join"]["worst"]["line_kink_max_deg"]
    teapot = [e for e in records["teapot"]["edges"] if e["class"] == "G2" and e["line_kink_max_deg"] is not None]
    assert teapot and max(e["line_kink_max_deg"] for e in teapot) < 1e-3


def test_batch_continuity_fails_below_require_in_exit_status_and_junit(batch_run, tmp_path):
    scenes = batch_run["root"] / "scenes"
    code, output = run("batch", scenes / "g1_join.toml", "-o", tmp_path, "--continuity", "--require", "G2",
                       "--junit", tmp_path / "j.xml")
    assert code == 1 and "g1_join: continuity FAIL (require G2): 1 G1" in output, output
    junit_schema().validate(str(tmp_path / "j.xml"))
    assert junit_verdicts(tmp_path / "j.xml") == {("g1_join", "render"): "pass", ("g1_join", "continuity"): "fail"}
    failure = ET.parse(tmp_path / "j.xml").getroot().find(".//testcase[@name='continuity']/failure")
    assert failure.get("message") == "1 edge short of G2: 0-1 G1"
    code, output = run("batch", scenes / "g1_join.toml", "-o", tmp_path, "--continuity", "--require", "G3")
    assert code == 2 and "--require: unknown class" in output


def test_sorting_by_status_puts_failures_first(page):
    page.evaluate("document.querySelector('th[data-key=name]').click()")
    assert [row["name"] for row in page.evaluate(ROWS)] == ["broken", "cylinder", "g1_join", "hood", "teapot"]
    page.evaluate("document.querySelector('th[data-key=rank]').click()")
    assert [row["verdict"] for row in page.evaluate(ROWS)][:2] == ["failed", "check failed"]
    page.evaluate("document.querySelector('th[data-key=rank]').click()")  # again: reversed
    assert [row["verdict"] for row in page.evaluate(ROWS)][-2:] == ["check failed", "failed"]


def test_batch_junit_is_valid_and_lists_the_batch_verdicts(batch_run):
    path = batch_run["out"] / "junit.xml"
    junit_schema().validate(str(path))
    verdicts = junit_verdicts(path)
    assert verdicts[("broken", "render")] == "fail"
    assert verdicts[("cylinder", "golden colour")] == "fail"
    assert verdicts[("hood", "golden")] == "skipped"
    for name in ("cylinder", "g1_join", "hood", "teapot"):
        assert verdicts[(name, "render")] == "pass"
        assert verdicts[(name, "validate")] == "pass"
        assert verdicts[(name, "continuity")] == "pass"  # no open seam (--require G0)
    failing = {scene for (scene, _), kind in verdicts.items() if kind == "fail"}
    report = batch_run["report"]["scenes"]
    assert failing == {Path(s["scene"]).stem for s in report
                       if s["status"] == "failed" or s["golden"] and s["golden"]["status"] != "match"
                       and s["golden"]["status"] != "missing" or s["validate"] and not s["validate"]["passed"]}
    suite = ET.parse(path).getroot().find("testsuite")
    # Failures: broken's render and cylinder's golden colour (the teapot validates since the tracer's second look).
    assert (suite.get("tests"), suite.get("failures"), suite.get("skipped")) == (str(len(verdicts)), "2", "1")
    failure = ET.parse(path).getroot().find(".//testcase[@classname='broken']/failure")
    assert "\n" not in failure.get("message") and "lights.radios" in failure.get("message")
    assert all(float(case.get("time")) > 0 for case in ET.parse(path).getroot().iter("testcase")
               if case.get("name") in ("render", "validate") and case.get("classname") != "broken")


def test_schema_rejects_what_ci_servers_would_not_read(batch_run, tmp_path):
    """The validation can fail: a test case without its time, a suite without its timestamp."""
    schema = junit_schema()
    text = (batch_run["out"] / "junit.xml").read_text()
    for broken in (text.replace(' time="', ' duration="', 2), text.replace("timestamp=", "stamp=")):
        (tmp_path / "bad.xml").write_text(broken)
        assert not schema.is_valid(str(tmp_path / "bad.xml"))


def test_validate_and_diff_write_valid_junit(batch_run, tmp_path):
    schema = junit_schema()
    scenes, out = batch_run["root"] / "scenes", batch_run["out"]
    code, output = run("validate", scenes / "hood.toml", scenes / "g1_join.toml", "--junit", tmp_path / "v.xml")
    assert code == 0, output
    schema.validate(str(tmp_path / "v.xml"))
    assert junit_verdicts(tmp_path / "v.xml") == {("hood", "validate"): "pass", ("g1_join", "validate"): "pass"}
    golden = batch_run["root"] / "golden"
    code, _ = run("diff", out / "cylinder.exr", golden / "cylinder.exr", "--junit", tmp_path / "d.xml")
    assert code == 1
    schema.validate(str(tmp_path / "d.xml"))
    failure = ET.parse(tmp_path / "d.xml").getroot().find(".//failure")
    assert "does not match" in failure.get("message") and "failing pixels" in failure.text


def test_report_command_rebuilds_the_page_from_the_json_or_the_folder(batch_run, tmp_path):
    out = batch_run["out"]
    code, output = run("report", out, "--json", out / "batch.json", "-o", tmp_path / "again.html")
    assert code == 1 and "5 scenes, 1 failed, 1 failed a check" in output, output
    html = (tmp_path / "again.html").read_text()
    assert html.count('<tr data-verdict=') == 5 and "lights.radios: unknown key" in html
    # The batch ran with relative paths elsewhere: its outputs are found in OUTDIR by name.
    document = json.loads((out / "batch.json").read_text())
    for scene in document["scenes"]:
        scene["outputs"] = [f"elsewhere/{Path(p).name}" for p in scene["outputs"]]
    (tmp_path / "relative.json").write_text(json.dumps(document))
    code, output = run("report", out, "--json", tmp_path / "relative.json", "-o", tmp_path / "relative.html")
    assert code == 1 and len(list((tmp_path / "relative_files").glob("*.png"))) == 5, output  # 4 scenes, 1 diff
    code, output = run("report", out, "-o", tmp_path / "folder.html")  # no JSON: the images in the folder
    assert code == 0 and "4 scenes, 0 failed" in output, output
    assert len(list((tmp_path / "folder_files").glob("*.png"))) == 4
    code, output = run("report", tmp_path / "nowhere")
    assert code == 2 and output.count("\n") == 1 and "no such folder" in output


def test_a_golden_folder_that_does_not_exist_is_bad_input_before_rendering(batch_run, tmp_path):
    """A mistyped --golden would otherwise report every scene as "no golden image" and pass."""
    result = CliRunner().invoke(cli, ["batch", str(batch_run["root"] / "scenes" / "hood.toml"), "-o",
                                      str(tmp_path / "out"), "--golden", str(tmp_path / "nowhere")])
    assert result.exit_code == 2 and "--golden" in result.output and "does not exist" in result.output
    assert not (tmp_path / "out").exists()


def test_thumbnail_of_an_exr_looks_like_the_png(batch_run, tmp_path):
    """A scene with `png = false` has only its EXR (17 float channels; before, its thumbnail could not be written).
    Its thumbnail is R,G,B,A scaled in linear light and sRGB-encoded as rtreflect writes PNGs, so it shows what the
    same render's PNG shows: the same codes where nothing is scaled (a 160 px render), and where it is scaled
    (the 320 px golden) the same picture up to the lines' edges, where averaging in linear light is brighter."""
    import numpy as np

    from rtreflect.ci.report import thumbnail
    from rtreflect.output.imagefiles import read_image

    def visible(path):  # colour as seen over the page: RGB × alpha, in code values
        rgba = read_image(path)[0].astype(float)
        return rgba[..., :3] * rgba[..., 3:] * 255

    golden_images = Path(__file__).resolve().parent.parent / "golden_images"
    for stem, width, limits in ((batch_run["out"] / "hood", 160, (0.01, 1.0)), (golden_images / "hood", THUMB_WIDTH,
                                                                               (2.0, 24.0))):
        assert thumbnail(stem.with_suffix(".exr"), tmp_path / "from_exr.png")
        assert thumbnail(stem.with_suffix(".png"), tmp_path / "from_png.png")
        from_exr, from_png = visible(tmp_path / "from_exr.png"), visible(tmp_path / "from_png.png")
        assert from_exr.shape == from_png.shape == (width * 9 // 16, width, 3)
        difference = np.abs(from_exr - from_png)
        mean_limit, p99_limit = limits
        assert difference.mean() <= mean_limit and np.percentile(difference, 99) <= p99_limit, (
            stem, difference.mean(), np.percentile(difference, 99))
        assert from_png.std() > 10  # a real picture, not a blank
