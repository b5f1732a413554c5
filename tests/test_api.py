"""The public Python API (issue 10): `rtreflect.load_scene`, `Scene(...)`, `replace`, `render`, `save`, `validate`.

Each function is checked against the independent path users already trust: a scene built in
code against the TOML reader (same specs, same one-line errors for every defect of
test_scene_errors' table), `save` against the bytes `rtreflect render` writes, `validate`
against `rtreflect validate --json`, and the README's example is run as written.
"""

from __future__ import annotations

import copy
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import rtreflect
from rtreflect.cli import cli
from test_scene_errors import CASES, Case, put, toml_document, valid_scene, write_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
#: Keeps a whole-image render quick; the contracts do not depend on the size.
SMALL = {"width": 64, "height": 36, "samples": 2}


def specs_equal(a, b) -> bool:
    """Two parsed tables (dataclasses of numbers, strings and arrays) hold the same values."""
    return vars(a).keys() == vars(b).keys() and all(np.array_equal(vars(a)[k], vars(b)[k]) for k in vars(a))


def scene_in_code(tables: dict, path: Path | None = None) -> rtreflect.Scene:
    """The scene file's tables passed to `rtreflect.Scene`, arrays as numpy arrays where they are regular."""
    def arrays(value):
        if isinstance(value, list):
            try:
                array = np.asarray(value)
                return array if array.dtype.kind in "if" and array.size else value
            except (ValueError, TypeError):
                return value
        return value

    tables = copy.deepcopy(tables)
    surfaces = [{k: v if k == "degree" else arrays(v) for k, v in entry.items()} if isinstance(entry, dict) else entry
                for entry in tables.pop("surface", [])] if isinstance(tables.get("surface"), list) else tables.pop("surface", None)
    return rtreflect.Scene(path=path, surfaces=surfaces, **tables)


def test_import_is_lazy_and_names_resolve() -> None:
    code = ("import sys, rtreflect; assert 'rtreflect.api' not in sys.modules, 'api imported eagerly'; "
            "assert 'OpenImageIO' not in sys.modules; print(rtreflect.render); assert 'rtreflect.api' in sys.modules")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("<function render")
    for name in rtreflect.__all__:
        assert getattr(rtreflect, name) is not None
    with pytest.raises(AttributeError):
        rtreflect.no_such_name  # noqa: B018


def test_readme_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The README's Python API example, extracted and run as written from a copy of the project folder."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Python API"):]
    code = re.search(r"```python\n(.*?)```", section, re.S)[1]
    shutil.copytree(SCENES, tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    for name in ("hood.exr", "hood.png", "bump.exr", "bump.png"):
        assert (tmp_path / "out" / name).is_file(), name
    assert "lights.raduis: unknown key; did you mean radius?" in done.stdout


def test_scene_in_code_equals_the_scene_file(tmp_path: Path) -> None:
    tables = valid_scene()
    from_file = rtreflect.load_scene(write_scene(tmp_path, Case("base", lambda scene: None, "")))
    built = scene_in_code(tables)
    for name in ("image", "camera", "lights", "render", "output"):
        assert specs_equal(getattr(built, name), getattr(from_file, name)), name
    (a,), (b,) = built.surfaces, from_file.surfaces
    assert (a.degree_u, a.degree_v, a.name) == (b.degree_u, b.degree_v, b.name)
    for key in ("knots_u", "knots_v", "points", "weights"):
        assert np.array_equal(getattr(a, key), getattr(b, key)), key
    # Rendered, the two are the same pixels.
    assert np.array_equal(rtreflect.render(built, **SMALL).film.pixels, rtreflect.render(from_file, **SMALL).film.pixels,
                          equal_nan=True)
    # A NurbsSurface object is accepted too (checked as an inline surface), and the hashes follow the content.
    again = rtreflect.Scene(surfaces=list(from_file.surfaces), lights=tables["lights"], camera=tables["camera"],
                            image=tables["image"], render=tables["render"], output=tables["output"])
    assert again.inputs_sha256 == built.inputs_sha256
    assert rtreflect.Scene(surfaces=list(from_file.surfaces), lights={**tables["lights"], "radius": 0.06}).inputs_sha256 \
        != again.inputs_sha256
    assert built.path == Path("<scene>") and rtreflect.Scene(surfaces=[tables["surface"][0]], lights=tables["lights"]) \
        .output.name == "scene"


#: The defects that a scene built in code can carry (not TOML syntax, not .bpt files: those are the file's).
CODE_CASES = [case for case in CASES if case.geometry is None and case.blamed_file is None
              and "TOML syntax" not in case.field and "toml" not in case.id
              and case.id != "unknown top-level key"]  # in code a Python TypeError: the tables are keyword arguments


@pytest.mark.parametrize("case", CODE_CASES, ids=[case.id for case in CODE_CASES])
def test_scene_in_code_is_checked_like_the_scene_file(case: Case, tmp_path: Path) -> None:
    """Every defect of the scene-file table, given in code, raises the scene file's message (FILE aside)."""
    scene_path = write_scene(tmp_path, case)
    with pytest.raises(rtreflect.SceneError) as in_file:
        rtreflect.load_scene(scene_path)
    tables = copy.deepcopy(valid_scene())
    case.defect(tables)
    with pytest.raises(rtreflect.SceneError) as in_code:
        scene_in_code(tables, path=scene_path)
    assert str(in_code.value) == str(in_file.value)


def test_replace_is_checked_and_rehashes(tmp_path: Path) -> None:
    hood = rtreflect.load_scene(SCENES / "hood.toml")
    # with_image / with_render are replace: the output key follows, the inputs hash does not move.
    smaller = hood.replace(image={"width": 320})
    assert smaller.image.width == 320 and smaller.image.height == hood.image.height
    assert smaller.inputs_sha256 == hood.inputs_sha256 and smaller.output_key != hood.output_key
    assert hood.with_image(320).output_key == smaller.output_key
    # Any other change is a different input: batch must not take an old render for it.
    wide = hood.replace(camera={"fov": 55.0})
    assert wide.camera.fov == 55.0 and wide.inputs_sha256 != hood.inputs_sha256
    assert np.array_equal(wide.camera.eye, hood.camera.eye)
    # Same values as the file with that field changed (the reader is the judge).
    text, edits = re.subn(r"(?m)^fov = .*$", "fov = 55.0", (SCENES / "hood.toml").read_text())
    assert edits == 1
    edited = tmp_path / "hood.toml"
    edited.write_text(text)
    assert specs_equal(wide.camera, rtreflect.load_scene(edited).camera)
    # Tubes by spacing (count kept from the current row), then back to explicit positions.
    spaced = hood.replace(lights={"spacing": 0.1})
    assert len(spaced.lights.positions) == len(hood.lights.positions)
    assert np.allclose(np.diff(spaced.lights.positions), 0.1) and abs(spaced.lights.positions.mean()) < 1e-12
    assert np.array_equal(spaced.replace(lights={"positions": [0.5]}).lights.positions, [0.5])
    # Errors: one line each, all of them, naming the scene file.
    with pytest.raises(rtreflect.SceneErrors) as both:
        hood.replace(camera={"fov": 200}, lights={"raduis": 0.1})
    assert [str(e) for e in both.value.errors] == [
        f"{SCENES / 'hood.toml'}: camera.fov: must be < 180, got 200.0",
        f"{SCENES / 'hood.toml'}: lights.raduis: unknown key; did you mean radius?"]
    # A whole spec replaces its table.
    assert hood.replace(camera=wide.camera).camera.fov == 55.0


def test_render_result_channels() -> None:
    result = rtreflect.render(rtreflect.load_scene(SCENES / "cylinder.toml"), **SMALL)
    assert result.rgba.shape == (36, 64, 4) and result.rgba.dtype == np.float32
    assert result.stats.rays > 0 and result.stats.width == 64
    normals = result.aov("N")
    assert normals.shape == (36, 64, 3)
    hit = result.rgba[..., 3] > 0
    assert np.allclose(np.linalg.norm(normals[hit & ~np.isnan(normals[..., 0])], axis=-1), 1, atol=1e-5)
    assert np.array_equal(result.aov("N.Z"), normals[..., 2], equal_nan=True)
    assert np.all(np.isnan(result.aov("f")[result.aov("patch") < 0]))
    with pytest.raises(ValueError, match="no channel 'F'"):
        result.aov("F")
    # A path stands for its scene file; anything else is a TypeError saying what is expected.
    by_path = rtreflect.render(str(SCENES / "cylinder.toml"), **SMALL)
    assert np.array_equal(by_path.film.pixels, result.film.pixels, equal_nan=True)
    with pytest.raises(TypeError, match="expected an rtreflect.Scene"):
        rtreflect.render({"image": {}})


def test_save_writes_the_bytes_render_writes(tmp_path: Path) -> None:
    """`rtreflect.save` of an in-memory render equals `rtreflect render`'s streamed files, byte for byte, overlay too."""
    scene_path = SCENES / "g1_join.toml"
    done = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(tmp_path / "cli"), "--width", "64",
                                    "--height", "36", "--samples", "2", "--overlay"])
    assert done.exit_code == 0, done.output
    result = rtreflect.render(rtreflect.load_scene(scene_path), **SMALL, overlay=True)
    written = rtreflect.save(result, tmp_path / "api")
    names = sorted(p.name for p in written)
    assert names == sorted(p.name for p in (tmp_path / "cli").iterdir()) == ["g1_join.contours.json", "g1_join.exr",
                                                                             "g1_join.png"]
    for name in names:
        assert (tmp_path / "api" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name


def test_validate_gives_the_numbers_of_validate_json(tmp_path: Path) -> None:
    scene_path = SCENES / "hood.toml"
    done = CliRunner().invoke(cli, ["validate", str(scene_path), "--width", "96", "--height", "54", "--samples", "1",
                                    "--json", str(tmp_path / "r.json")])
    assert done.exit_code == 0, done.output
    report = rtreflect.validate(rtreflect.load_scene(scene_path), width=96, height=54, samples=1)
    assert report.to_json() == json.loads((tmp_path / "r.json").read_text())["scenes"]["hood"]
    assert report.passed and report.points > 0
